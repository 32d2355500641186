"""The third first-time user's trial (a vase, a bowl, a canopy, a car; docs/trial/*.png), in Chromium at 1400 x 900
against `somwidget serve --preset bowl`, done as the person did it: the preset menu, the view's keys, the mouse on
the view, typing in the controls table. What the page shows is read from the page (the table, the menu, the view's
hint) and through the view's read-only `describe()`, `controlScreen`, `controlModel` and `modelScreen`; the
session's state through GET /api/state. Nothing here sends an intent or sets state itself.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from helpers import CHROMIUM
from sphere_app import VIEW, drag, model_screen, open_page, press_key_in_view, screen, serve_sphere, shot, view

pytestmark = pytest.mark.browser

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)


@pytest.fixture(scope="module")
def server():
    yield from serve_sphere("bowl")


@pytest.fixture
def page(browser, server):
    yield from open_page(browser, server)


def test_a_drag_of_the_rim_in_the_left_view_keeps_it_in_its_plane_and_the_ring_even(page, server):
    """Bowl (16 copies about z), key 3 (Left: looking along y), the mouse drags the rim control (#2) out and up,
    pressed a few pixels towards the ghost copy lying in front of it. The control stays at y = 0 (the controls table
    says so) and its 16 images keep their equal angles about the axis."""
    st0 = server.idle()
    press_key_in_view(page, "3")
    v = view(page)
    assert v["group"] == "radial-16-z"
    k, ids = v["k"], v["controlIds"]
    i = ids.index(2)
    start = page.evaluate(f"() => {VIEW}.controlModel({i})")
    assert abs(start[1]) < 1e-6
    at = screen(page, i)
    # the ghost drawn nearest it on screen, in front of it: the person pressed between the two
    copies = [i + g * k for g in range(1, v["kEff"] // k)]
    near = min(copies, key=lambda j: np.linalg.norm(screen(page, j) - at)
               + 1e3 * (page.evaluate(f"() => {VIEW}.controlModel({j})")[1] < 0))
    gap = screen(page, near) - at
    assert 0 < np.linalg.norm(gap) < 20, gap  # the copies at +-22.5 degrees lie just beside it on screen
    press = at + 0.6 * gap
    axis = model_screen(page, [0.0, 0.0, start[2]])
    out = (at - axis) / np.linalg.norm(at - axis)
    drag(page, press, 70 * out + np.array([0.0, -60.0]))
    st = server.wait(lambda s: s["session"]["history"][0] > st0["session"]["history"][0] and
                     not s["session"]["frame"]["running"] and s["session"]["pending_intents"] == 0,
                     what="the drag in the session")
    moved = np.asarray(st["session"]["controls"][i], float)
    assert np.hypot(moved[0], moved[1]) > np.hypot(start[0], start[1]) + 0.1, (start, moved)  # out
    assert moved[2] > start[2] + 0.1, (start, moved)  # and up
    # what the person reads: the table's row for control 2, y = 0
    cell = page.locator("#controls-table tr").nth(i).locator(".position-cell input")
    page.wait_for_function(f"() => document.querySelectorAll('#controls-table .position-cell input')[{i}]"
                           f".value.startsWith('{moved[0]:.3g}'.slice(0, 3))", timeout=10000)
    x, y, z = (float(t) for t in cell.input_value().split(","))
    assert abs(y) < 1e-3, cell.input_value()
    # what the person sees: the ring of the control's images, equal angles (float64 from where the view draws them)
    page.wait_for_timeout(300)
    ring = np.asarray([page.evaluate(f"() => {VIEW}.controlModel({j})") for j in [i, *copies]], np.float64)
    angles = np.sort(np.mod(np.degrees(np.arctan2(ring[:, 1], ring[:, 0])), 360.0))
    steps = np.diff(np.append(angles, angles[0] + 360.0))
    np.testing.assert_allclose(steps, 22.5, atol=0.1)
    assert abs(math.remainder(angles[0], 22.5)) < 0.1  # the ring has not turned
    shot(page, "trial3-bowl-left-drag")


def test_the_position_cells_look_like_fields_with_a_focus_ring(page):
    """Each typed cell of the controls table has an outline (a field, not text), a text cursor, and a focus ring
    when clicked; the drawer still holds the table (nothing runs past its right edge)."""
    cell = page.locator("#controls-table tr").nth(0).locator(".position-cell")
    field = cell.locator(".v-field")
    look = field.evaluate("e => { const s = getComputedStyle(e); return [s.outlineStyle, s.outlineWidth, "
                          "s.outlineColor, getComputedStyle(e.querySelector('input')).cursor]; }")
    assert look[0] == "solid" and float(look[1].rstrip("px")) >= 1 and look[3] == "text", look
    cell.locator("input").click()
    page.wait_for_timeout(200)
    focused = field.evaluate("e => { const s = getComputedStyle(e); return [s.outlineWidth, s.outlineColor]; }")
    assert float(focused[0].rstrip("px")) >= 2 and focused[1] != look[2], (look, focused)
    drawer = page.locator(".v-navigation-drawer").bounding_box()
    table = page.locator("#controls-table table").bounding_box()
    assert table["x"] + table["width"] <= drawer["x"] + drawer["width"] + 0.5, (table, drawer)
    shot(page, "trial3-table-field", "#controls-table")
    page.keyboard.press("Escape")


def test_the_preset_menu_shows_every_preset_without_scrolling(page, server):
    """The preset menu, opened at 900 px: every preset's entry lies inside the menu's visible box (Tube and Bowl
    were below its fold)."""
    page.locator(".v-select:has(#preset-select) .v-field").click()
    page.wait_for_selector(".v-overlay .v-list-item", timeout=10000)
    page.wait_for_timeout(500)
    n = len(server.state()["presets"]) if "presets" in server.state() else None
    items = page.locator(".v-overlay .v-list-item")
    boxes = [items.nth(m).bounding_box() for m in range(items.count())]
    menu = page.locator(".v-overlay .v-list").first.bounding_box()
    assert len(boxes) >= (n or 11), len(boxes)
    for b in boxes:
        assert menu["y"] - 0.5 <= b["y"] and b["y"] + b["height"] <= menu["y"] + menu["height"] + 0.5, (b, menu)
        assert b["y"] + b["height"] <= 900
    labels = [t.strip() for t in items.all_inner_texts()]
    assert any(t.startswith("Tube") for t in labels) and any(t.startswith("Bowl") for t in labels), labels
    shot(page, "trial3-preset-menu", "body")
    page.keyboard.press("Escape")


def test_an_orbit_stopped_by_the_ground_says_so_once_a_drag(page):
    """Key 3 (Left: the camera level with the ground), then a drag upward on empty space (the camera would go under
    the ground): the view does not turn, and a hint says why and what looks from below, once for the drag."""
    press_key_in_view(page, "3")
    v0 = view(page)
    assert v0["hint"] is None
    box = page.locator("#clay-view canvas").bounding_box()
    start = (box["x"] + 60, box["y"] + box["height"] - 80)  # empty space: no clay, no control
    assert page.evaluate(f"() => {VIEW}.surfaceAt({start[0]}, {start[1]})") is None
    drag(page, start, (0, -150), steps=15)
    v = view(page)
    np.testing.assert_allclose(v["camera"], v0["camera"], atol=1e-6)  # the view did not turn
    hint = page.locator("#clay-view .somview-hint")
    assert hint.is_visible() and hint.inner_text() == "The camera stays above the ground: 6 looks from below"
    assert v["hint"] == hint.inner_text() and v["desktop"]["groundStops"] == 1  # once for the drag
    shot(page, "trial3-ground-hint")
    drag(page, start, (0, 150), steps=6)  # downward: the camera rises, no hint more
    assert view(page)["desktop"]["groundStops"] == 1
    page.wait_for_timeout(3200)
    assert not hint.is_visible()


def test_after_a_revolve_the_copies_are_lines_and_the_disc_is_the_default_rim(page, server):
    """Key 3, Revolve, a vase profile drawn beside the bowl's axis: the profile keeps its spheres, each of its 15
    copies is one thin line (no ghost sphere per sample); the disc under the cursor shows the default radius (the
    controls' own, the preset's) as a rim only, filled once the person chooses a radius with ]."""
    press_key_in_view(page, "3")
    steps = server.idle()["session"]["history"][0]
    page.locator(".somview-revolve").click()
    profile = [[0.3, 0.0, -0.9], [0.6, 0.0, -0.5], [0.75, 0.0, 0.0], [0.5, 0.0, 0.4], [0.7, 0.0, 0.8]]
    dense = [np.add(a, t * np.subtract(b, a)) for a, b in zip(profile[:-1], profile[1:]) for t in np.linspace(0, 1, 8,
                                                                                                          endpoint=False)]
    at = [model_screen(page, p) for p in [*dense, profile[-1]]]
    page.mouse.move(*at[0])
    page.mouse.down()
    for p in at[1:]:
        page.mouse.move(*p, steps=2)
    page.mouse.up()
    st = server.wait(lambda s: s["session"]["history"][0] == steps + 1 and s["session"]["pending_intents"] == 0,
                     what="the revolve")
    n = st["session"]["strokes"][0]
    assert len(st["session"]["strokes"]) == 1 and n >= 4 and len(st["session"]["controls"]) == n
    page.wait_for_function(f"() => {VIEW}.describe().kEff === {16 * n}", timeout=10000)
    page.wait_for_timeout(400)
    v = view(page)
    assert v["ghostSpheres"] == 0 and v["strokeCopyLines"] == 15, (v["ghostSpheres"], v["strokeCopyLines"])
    # what the person sees: the stroke's own spheres, and no ghost sphere drawn (their draw holds nothing visible)
    drawn = page.evaluate(f"""() => {{ const c = {VIEW}.clay; const d = c.controlDraws[1];
        const m = new ({VIEW}.clay.content.matrix.constructor)(); let shown = 0;
        for (let a = 0; a < d.count; a++) {{ d.getMatrixAt(a, m); if (m.determinant() !== 0) shown += 1; }}
        return [c.controlDraws[0].count, shown, c.strokeCopies.lines.visible,
                c.strokeCopies.lines.geometry.drawRange.count]; }}""")
    assert drawn[0] == n and drawn[1] == 0 and drawn[2] and drawn[3] == 15 * 2 * (n - 1), drawn
    # the disc under the cursor: the default radius, its rim alone
    default = float(np.median(st["session"]["radii"]))
    box = page.locator("#clay-view canvas").bounding_box()
    spot = next(p for p in (model_screen(page, [0.0, -0.2, z]) for z in (0.0, 0.2, -0.3, 0.4))
                if page.evaluate(f"() => {VIEW}.surfaceAt({p[0]}, {p[1]})") is not None)
    assert box["x"] < spot[0] < box["x"] + box["width"]
    page.mouse.move(*spot)
    page.wait_for_timeout(300)
    d = view(page)["radiusDisc"]
    assert d["of"] == "new" and d["shown"] and not d["filled"] and d["radius"] == pytest.approx(default, rel=1e-4), d
    shot(page, "trial3-revolved")
    page.keyboard.press("BracketLeft")
    page.wait_for_timeout(200)
    d = view(page)["radiusDisc"]
    assert d["filled"] and d["radius"] == pytest.approx(default / 1.1, rel=1e-3), d
