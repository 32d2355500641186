"""The third first-time user's trial (a vase, a bowl, a canopy, a car; docs/trial/*.png), in Chromium at 1400 x 900
against `somwidget serve --preset bowl`, done as the person did it: the preset menu, the view's keys, the mouse on
the view, typing in the controls table. What the page shows is read from the page (the table, the menu, the view's
hint) and through the view's read-only `describe()`, `controlScreen`, `controlModel` and `modelScreen`; the
session's state through GET /api/state. Nothing here sends an intent or sets state itself.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
from helpers import CHROMIUM, Serve

pytestmark = pytest.mark.browser

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)

VIEW = "document.getElementById('clay-view')?.somview"
SHOTS = os.environ.get("SOMWIDGET_SHOTS")  # a folder: the tests leave pictures there


@pytest.fixture(scope="module")
def server():
    srv = Serve("--preset", "bowl")
    yield srv
    srv.stop()


@pytest.fixture
def page(browser, server):
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.goto(server.url)
    page.wait_for_function(f"() => {{ const v = {VIEW}; return v && v.describe().painted > 0; }}", timeout=60000)
    page.wait_for_timeout(400)
    yield page
    page.close()


def shot(page, name: str, selector: str = "#clay-view") -> None:
    if SHOTS:
        os.makedirs(SHOTS, exist_ok=True)
        page.wait_for_timeout(400)
        page.locator(selector).screenshot(path=os.path.join(SHOTS, f"{name}.png"))


def view(page) -> dict:
    return page.evaluate(f"() => {VIEW}.describe()")


def screen(page, j: int) -> np.ndarray:
    return np.asarray(page.evaluate(f"() => {VIEW}.controlScreen({j})"), float)


def model_screen(page, p) -> np.ndarray:
    return np.asarray(page.evaluate(f"() => {VIEW}.modelScreen({json.dumps(list(p))})"), float)


def press_key_in_view(page, key: str) -> None:
    box = page.locator("#clay-view canvas").bounding_box()
    page.mouse.move(box["x"] + 40, box["y"] + box["height"] - 60)  # the pointer on the view: it has the keys
    page.keyboard.press(key)
    page.wait_for_timeout(300)


def drag(page, start, delta, steps: int = 12) -> None:
    page.mouse.move(*start)
    page.mouse.down()
    for s in range(1, steps + 1):
        page.mouse.move(start[0] + delta[0] * s / steps, start[1] + delta[1] * s / steps)
        page.wait_for_timeout(25)
    page.mouse.up()


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
