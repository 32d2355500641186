"""The chair shell's side, lifted by mouse as the first-time user of 2026-11-27 did (docs/modelling.md, "Five shapes,
step by step"), in Chromium against `somwidget serve --preset grid`: the side's control given radius 0.4 in the
controls table, then Shift-dragged up 0.8 in the Front view. The side rose in a step with a crease (a lift rolled only
where the radius was at least its height); now the patch widens as the drag goes, so it rolls. The crease is measured
on the frame the view shows (its `positions`), in float64 (metrics.dihedral_angles).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from helpers import CHROMIUM, Serve
from sphere_app import VIEW, centre, open_tab

from somwidget.backend import metrics
from somwidget.backend.presets import PRESETS

pytestmark = pytest.mark.browser

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)

SIDE = 5  # the grid's control at the middle of its x = 1 edge
LIFT, RADIUS = 0.8, 0.4
ROLL_MOST = 45.0


@pytest.fixture(scope="module")
def server():
    srv = Serve("--preset", "grid")
    yield srv
    srv.stop()


@pytest.fixture
def page(browser, server):
    yield from open_tab(browser, server)


def screen(page, j: int) -> np.ndarray:
    return np.array(page.evaluate(f"() => {VIEW}.controlScreen({j})"), np.float64)


def test_a_side_lifted_by_mouse_rolls_where_its_radius_is_less_than_the_lift(page, server):
    st0 = server.idle()
    controls = np.asarray(st0["session"]["controls"], np.float64)[:, :3]
    assert controls[SIDE, 0] > 0.9 and abs(controls[SIDE, 1]) < 0.1, "the preset's side control moved"
    radius = page.locator("#controls-table tr").nth(SIDE).locator(".radius-cell input")
    radius.fill(str(RADIUS))
    radius.press("Enter")
    server.wait(lambda s: abs(s["session"]["radii"][SIDE] - RADIUS) < 1e-6, what="the side's radius")
    st1 = server.idle()
    page.mouse.move(*centre(page, 0, 250))  # over the view: its keys
    page.keyboard.press("1")  # Front (from +x): y across, z up (the radius field, entered, lets the view have them)
    page.keyboard.press("o")
    page.wait_for_function(f"() => {VIEW}.describe().projection == 'orthographic'")
    page.wait_for_timeout(400)
    b = screen(page, SIDE)  # in front of control 0 (x = 0), between the corners 1 (y = 1) and 2 (y = -1)
    per_unit = abs(screen(page, 1)[0] - screen(page, 2)[0]) / abs(controls[1, 1] - controls[2, 1])  # px a unit
    assert per_unit > 50
    page.mouse.move(*b)
    page.wait_for_timeout(50)
    page.keyboard.down("Shift")
    page.mouse.down()
    for s in range(1, 13):
        page.mouse.move(b[0], b[1] - LIFT * per_unit * s / 12)
        page.wait_for_timeout(25)
    page.wait_for_timeout(150)
    page.mouse.up()
    page.keyboard.up("Shift")
    st = server.idle()
    assert st["session"]["history"][0] == st1["session"]["history"][0] + 1  # the drag: one step
    c = np.asarray(st["session"]["controls"][SIDE], np.float64)[:3]
    np.testing.assert_allclose(c[:2], controls[SIDE, :2], atol=0.01)  # straight up (Shift: along one axis)
    assert c[2] >= 1.5 * RADIUS, f"lifted {c[2]:.2f}: not taller than its radius"
    n = 32 * 32
    page.wait_for_function(f"() => Math.max(...{VIEW}.positions({n}).filter((_, i) => i % 3 == 2)) > {c[2] - 0.03}",
                           timeout=30000)
    page.wait_for_timeout(500)  # the last frame of the settled run
    shown = np.asarray(page.evaluate(f"() => {VIEW}.positions({n})"), np.float64).reshape(-1, 3)
    assert len(shown) == 32 * 32
    faces = PRESETS["grid"]().topology.faces
    angles = metrics.dihedral_angles(shown, metrics.triangles_of(faces))
    assert np.isfinite(angles).all()
    assert angles.max() <= ROLL_MOST, f"the side creased: {angles.max():.1f} degrees between faces"
    assert np.linalg.norm(shown - c, axis=1).min() <= 0.03 * metrics.bounding_diagonal(shown)  # the clay reached it
    page.keyboard.press("o")
