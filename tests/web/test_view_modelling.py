"""The clay view as a modelling tool (issue 26, items 1-4), in Chromium against `somwidget serve --preset sphere`, as
a person uses it: Playwright's mouse wheel, clicks, double clicks, drags and keys on the view, typing in the panel's
controls table. What the page draws is read through the view's read-only `describe()` and where it draws things
(`controlScreen`, `surfaceAt`, `handlePoint`); the session's state through GET /api/state. Nothing here sends an
intent or sets state itself.
"""

from __future__ import annotations

import os
import re

import numpy as np
import pytest
from helpers import CHROMIUM
from sphere_app import VIEW, canvas, centre, drag, open_tab, serve_sphere, view

from somwidget.backend import metrics

pytestmark = pytest.mark.browser

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)



@pytest.fixture(scope="module")
def server():
    yield from serve_sphere()


@pytest.fixture
def page(browser, server):
    yield from open_tab(browser, server)


def screen(page, j: int) -> tuple[float, float]:
    x, y = page.evaluate(f"() => {VIEW}.controlScreen({j})")
    return float(x), float(y)


def visible_control(page) -> int:
    """A control on screen that the clay does not hide."""
    page.wait_for_timeout(350)  # the view has looked again which controls the clay hides
    v = view(page)
    box = canvas(page)
    for j in range(v["kEff"]):
        x, y = screen(page, j)
        if j not in v["behind"] and box["x"] + 80 < x < box["x"] + box["width"] - 80 \
                and box["y"] + 80 < y < box["y"] + box["height"] - 80:
            return j
    raise AssertionError(f"no control in plain sight: {v['behind']}")


def test_ten_wheel_ticks_bring_the_camera_closer_towards_the_cursor_down_to_five_percent(page):
    v0 = view(page)
    assert v0["distance"] == pytest.approx(v0["fitDistance"]) and v0["projection"] == "perspective"
    at = centre(page, 60, -40)
    aimed = page.evaluate(f"() => {VIEW}.surfaceAt({at[0]}, {at[1]})")
    assert aimed is not None, "the cursor is not over the clay"
    page.mouse.move(*at)
    distances = []
    for _ in range(10):
        page.mouse.wheel(0, -100)
        page.wait_for_timeout(60)
        distances.append(view(page)["distance"])
    assert all(b < a for a, b in zip([v0["distance"], *distances], distances)), distances
    assert distances[-1] < 0.45 * v0["fitDistance"]
    # the clay point under the cursor stayed under it: the zoom went towards it
    now = page.evaluate(f"() => {VIEW}.surfaceAt({at[0]}, {at[1]})")
    assert np.linalg.norm(np.subtract(now, aimed)) < 0.01, (aimed, now)
    for _ in range(30):
        page.mouse.wheel(0, -100)
    page.wait_for_timeout(200)
    closest = view(page)["distance"]
    assert closest == pytest.approx(0.05 * v0["fitDistance"], rel=1e-3), "the closest is 5% of the Fit distance"
    for _ in range(40):
        page.mouse.wheel(0, 100)
    page.wait_for_timeout(200)
    assert view(page)["distance"] > 1.5 * v0["fitDistance"], "the camera backs away freely"


def test_axis_views_orthographic_and_fit_from_keys_and_buttons(page):
    def looking_from(v):
        d = np.subtract(v["camera"], v["target"])
        return d / np.linalg.norm(d)

    page.mouse.move(*centre(page, 0, 250))  # over the view: its keys
    page.keyboard.press("1")  # front: from model +x (world +x)
    page.wait_for_timeout(100)
    np.testing.assert_allclose(looking_from(view(page)), [1, 0, 0], atol=1e-3)
    page.locator(".somview-look-top").click()  # from model +z (world +y)
    page.wait_for_timeout(100)
    np.testing.assert_allclose(looking_from(view(page)), [0, 1, 0], atol=1e-3)
    page.mouse.move(*centre(page, 0, 250))
    page.keyboard.press("4")  # right: from model -y (world +z)
    page.wait_for_timeout(100)
    np.testing.assert_allclose(looking_from(view(page)), [0, 0, 1], atol=1e-3)
    before = view(page)["distance"]
    page.keyboard.press("o")
    page.wait_for_timeout(100)
    v = view(page)
    assert v["projection"] == "orthographic" and v["distance"] == pytest.approx(before, rel=1e-6)
    assert page.locator(".somview-ortho.on").count() == 1
    page.mouse.move(*centre(page))
    for _ in range(5):
        page.mouse.wheel(0, -100)
    page.wait_for_timeout(100)
    assert view(page)["distance"] < 0.7 * before, "the orthographic camera zooms too"
    page.locator(".somview-ortho").click()
    page.wait_for_timeout(100)
    assert view(page)["projection"] == "perspective"
    page.mouse.move(*centre(page, 0, 250))
    page.keyboard.press("f")
    page.wait_for_timeout(100)
    v = view(page)
    assert v["distance"] == pytest.approx(v["fitDistance"]) and v["desktop"]["fits"] >= 2


def test_a_double_click_on_the_clay_adds_a_control_there_and_nothing_moves(page, server):
    st0 = server.idle()
    before = server.state(positions=True)["session"]
    at = centre(page, -30, 20)
    aimed = page.evaluate(f"() => {VIEW}.surfaceAt({at[0]}, {at[1]})")
    assert aimed is not None
    page.mouse.dblclick(*at)
    st = server.wait(lambda s: len(s["session"]["controls"]) == len(st0["session"]["controls"]) + 1,
                     what="a control added")
    st = server.idle()
    after = server.state(positions=True)["session"]
    new = np.array(after["controls"][-1][:3])
    np.testing.assert_allclose(new, aimed, atol=1e-5)  # where the double click was, on the surface
    np.testing.assert_array_equal(after["frame"]["positions"], before["frame"]["positions"])  # nothing moved
    assert after["frame"]["iteration"] == before["frame"]["iteration"]  # nothing trained
    assert after["radii"][-1] == pytest.approx(after["radii"][0])  # the default radius
    assert st["session"]["history"][0] == st0["session"]["history"][0] + 1  # one undo step
    page.wait_for_function(f"() => {VIEW}.describe().kEff === {len(after['controls'])}", timeout=5000)
    # it stays put when another control is dragged, and moves when it is dragged itself
    j = len(after["controls"]) - 1
    x, y = screen(page, j)
    drag(page, (x, y), (40, -30))
    st = server.idle()
    assert np.linalg.norm(np.array(st["session"]["controls"][j][:3]) - new) > 0.05


def test_a_control_hidden_behind_the_clay_is_not_grabbed_through_it(page, server):
    st0 = server.idle()
    page.wait_for_timeout(350)
    v = view(page)
    box = canvas(page)
    hidden = [j for j in v["behind"] if box["x"] + 60 < screen(page, j)[0] < box["x"] + box["width"] - 60
              and box["y"] + 60 < screen(page, j)[1] < box["y"] + box["height"] - 60]
    assert hidden, f"no control behind the clay on screen: {v['behind']}"
    j = hidden[0]
    assert page.locator(".somview-label.behind").count() >= 1  # its label is dimmed: it is behind
    camera = v["camera"]
    start = screen(page, j)
    drag(page, start, (50, 30))  # a press on the clay in front of it
    st = server.idle()
    assert st["session"]["controls"] == st0["session"]["controls"], "a hidden control was moved through the clay"
    assert st["session"]["history"][0] == st0["session"]["history"][0]
    v = view(page)
    assert v["desktop"]["hiddenPresses"] >= 1 and v["desktop"]["drags"] == 0
    assert np.linalg.norm(np.subtract(v["camera"], camera)) > 0.05, "the press went to the orbit"


def hidden_original(page, v: dict, box: dict, margin: float = 80) -> int:
    """A control (an original, not a copy) the clay hides, on screen at least `margin` pixels inside the canvas."""
    hidden = [j for j in v["behind"] if j < v["k"] and box["x"] + margin < screen(page, j)[0] < box["x"] + box["width"]
              - margin and box["y"] + margin < screen(page, j)[1] < box["y"] + box["height"] - margin]
    assert hidden, f"no control behind the clay on screen: {v['behind']}"
    return hidden[0]


def test_a_hidden_control_is_dragged_by_its_dimmed_label(page, server):
    """A press on the dimmed label of a control behind the clay drags that control as a press on its sphere would
    (a person dragged the label and nothing happened): it follows the pointer, one undo step, and the view does not
    turn."""
    st0 = server.idle()
    page.wait_for_timeout(350)
    v = view(page)
    box = canvas(page)
    j = hidden_original(page, v, box)
    label = page.locator(".somview-label.behind").filter(has_text=re.compile(f"^{j}$")).first
    at = label.bounding_box()
    camera = v["camera"]
    drag(page, (at["x"] + at["width"] / 2, at["y"] + at["height"] / 2), (40, -30))
    st = server.idle()
    moved = np.linalg.norm(np.subtract(st["session"]["controls"][j][:3], st0["session"]["controls"][j][:3]))
    assert moved > 0.05, f"control {j} did not follow the drag of its label ({moved:.3f})"
    others = [c for i, c in enumerate(st["session"]["controls"]) if i != j]
    assert others == [c for i, c in enumerate(st0["session"]["controls"]) if i != j]
    assert st["session"]["history"][0] == st0["session"]["history"][0] + 1  # one undo step
    np.testing.assert_allclose(view(page)["camera"], camera, atol=1e-9)  # the view did not turn


def test_a_hidden_control_is_taken_by_its_dimmed_label_and_moved_by_its_handle(page, server):
    """A control behind the clay is not grabbed through it, but a click on its dimmed label selects it: its handle is
    drawn over the clay and moves it along one axis, without turning the view."""
    st0 = server.idle()
    page.wait_for_timeout(350)
    v = view(page)
    box = canvas(page)
    j = hidden_original(page, v, box)
    label = page.locator(".somview-label.behind").filter(has_text=re.compile(f"^{j}$")).first
    label.click()
    page.wait_for_function(f"() => {VIEW}.describe().selected === {j}", timeout=5000)
    camera = view(page)["camera"]
    c = np.array(screen(page, j))
    tips = {a: np.array(page.evaluate(f"() => {VIEW}.handlePoint('{a}')")) for a in "XYZ"}
    axis = max(tips, key=lambda a: np.linalg.norm(tips[a] - c))
    page.mouse.move(*tips[axis])
    page.wait_for_timeout(50)
    drag(page, tuple(tips[axis]), tuple(0.8 * (tips[axis] - c)))
    st = server.idle()
    moved = np.abs(np.array(st["session"]["controls"][j][:3]) - np.array(st0["session"]["controls"][j][:3]))
    a = "XYZ".index(axis)
    assert moved[a] > 0.05 and np.delete(moved, a).max() < 1e-4, f"not moved along {axis}: {moved}"
    np.testing.assert_allclose(view(page)["camera"], camera, atol=1e-9)  # the view did not turn
    page.keyboard.press("Escape")
    page.wait_for_function(f"() => {VIEW}.describe().selected === null", timeout=5000)
    page.locator(f"#controls-table td.control-index[data-control='{j}']").click()  # its number in the panel
    page.wait_for_function(f"() => {VIEW}.describe().selected === {j}", timeout=5000)
    page.mouse.move(*centre(page, 0, 250))
    page.keyboard.press("Escape")


def test_delete_removes_the_hovered_control_and_the_wheel_over_one_sets_its_radius(page, server):
    st0 = server.idle()
    j = visible_control(page)
    r0 = st0["session"]["radii"][j]
    page.mouse.move(*screen(page, j))
    page.wait_for_function(f"() => {VIEW}.describe().hover.includes({j})", timeout=5000)
    for _ in range(3):
        page.mouse.wheel(0, -100)  # up: larger
        page.wait_for_timeout(40)
    v = view(page)
    assert v["radiusBall"]["of"] == j and v["radiusBall"]["shown"]
    st = server.wait(lambda s: s["session"]["radii"][j] > 1.3 * r0, what="a larger radius")
    assert st["session"]["radii"][j] == pytest.approx(r0 * 1.1 ** 3, rel=1e-3)
    assert v["radiusBall"]["radius"] == pytest.approx(r0 * 1.1 ** 3, rel=1e-3)
    assert v["distance"] == pytest.approx(v["fitDistance"]), "the wheel over a control does not zoom"
    server.idle()
    page.mouse.move(*screen(page, j))
    page.wait_for_function(f"() => {VIEW}.describe().hover.includes({j})", timeout=5000)
    page.keyboard.press("Delete")
    st = server.wait(lambda s: len(s["session"]["controls"]) == len(st0["session"]["controls"]) - 1,
                     what="the control removed")
    gone = st0["session"]["controls"][j]
    assert gone not in st["session"]["controls"]


def test_a_selected_control_moves_along_one_axis_by_its_handle(page, server):
    st0 = server.idle()
    j = visible_control(page)
    page.mouse.click(*screen(page, j))  # a click selects it: its handle shows
    page.wait_for_function(f"() => {VIEW}.describe().selected === {j}", timeout=5000)
    assert server.idle()["session"]["history"][0] == st0["session"]["history"][0], "a click is not a step"
    c = np.array(screen(page, j))
    tips = {a: np.array(page.evaluate(f"() => {VIEW}.handlePoint('{a}')")) for a in "XYZ"}
    axis = max(tips, key=lambda a: np.linalg.norm(tips[a] - c))  # the arrow longest on screen
    start = tips[axis]
    page.mouse.move(*start)
    page.wait_for_timeout(50)
    drag(page, tuple(start), tuple(0.8 * (tips[axis] - c)))
    st = server.idle()
    moved = np.abs(np.array(st["session"]["controls"][j][:3]) - np.array(st0["session"]["controls"][j][:3]))
    a = "XYZ".index(axis)
    assert moved[a] > 0.05, f"the handle did not move the control along {axis}: {moved}"
    assert np.delete(moved, a).max() < 1e-4, f"the handle moved it off its axis: {moved}"
    assert st["session"]["history"][0] == st0["session"]["history"][0] + 1  # one step
    page.keyboard.press("Escape")
    page.wait_for_function(f"() => {VIEW}.describe().selected === null", timeout=5000)


def test_a_control_pushed_straight_into_the_clay_takes_the_clay_with_it(page, server):
    """Seen from the front (key 1, orthographic: O), the top control is dragged straight down into the sphere in one
    drag: it holds the clay it took (a handle), so the dent follows the mouse: the clay ends within 3% of its size of
    the control and nothing is left standing over it, the far half of the clay does not move, and no node leaves
    the box of the start and the controls grown by their radius. (A control whose nearest node is chosen again at
    every cycle left the top standing and jumped to another node.)"""
    st0 = server.idle()
    start = np.asarray(server.state(positions=True)["session"]["frame"]["positions"], np.float64)
    size = float(np.linalg.norm(start.max(0) - start.min(0)))
    controls = np.asarray(st0["session"]["controls"], np.float64)[:, :3]
    top, bottom = int(np.argmax(controls[:, 2])), int(np.argmin(controls[:, 2]))
    page.mouse.move(*centre(page, 0, 250))  # over the view: its keys
    page.keyboard.press("1")
    page.keyboard.press("o")
    page.wait_for_timeout(400)
    assert top not in view(page)["behind"], "the top control lies on the clay's outline: in sight"
    a, b = np.array(screen(page, top)), np.array(screen(page, bottom))
    per_unit = (b[1] - a[1]) / (controls[top, 2] - controls[bottom, 2])  # pixels down per model unit down
    push = 0.7
    page.mouse.move(*a)
    page.wait_for_timeout(50)
    drag(page, tuple(a), (0.0, push * per_unit), steps=10)
    st = server.idle()
    assert st["session"]["history"][0] == st0["session"]["history"][0] + 1  # one drag, one step
    c = np.asarray(st["session"]["controls"][top], np.float64)[:3]
    np.testing.assert_allclose(c, controls[top] - [0.0, 0.0, push], atol=0.03)  # straight down, as dragged
    end = np.asarray(server.state(positions=True)["session"]["frame"]["positions"], np.float64)
    assert np.linalg.norm(end - c, axis=1).min() <= 0.03 * size, "the dent did not follow the control"
    above = (np.hypot(*(start[:, :2] - c[:2]).T) < 0.05 * size) & (start[:, 2] > c[2])  # the clay it was pushed into
    assert end[above, 2].max() <= c[2] + 0.03 * size, "clay left standing over the pushed control"
    assert metrics.far_half_moved(start, end, controls[top]) <= 0.02, "the far half moved"
    reach = max(st["session"]["radii"]) + 0.01 * size
    lo = np.minimum(start.min(0), np.concatenate([controls, c[None]]).min(0)) - reach
    hi = np.maximum(start.max(0), np.concatenate([controls, c[None]]).max(0)) + reach
    assert np.all(end >= lo) and np.all(end <= hi), "a node left the box"
    page.keyboard.press("o")


def test_the_stroke_tool_draws_a_line_on_the_clay_as_one_control(page, server):
    st0 = server.idle()
    page.mouse.move(*centre(page, 0, 250))
    page.keyboard.press("s")
    assert view(page)["tool"] == "stroke"
    drag(page, centre(page, -90, 30), (180, -60), steps=20)
    st = server.wait(lambda s: len(s["session"]["strokes"]) == len(st0["session"]["strokes"]) + 1,
                     what="the stroke added")
    run = st["session"]["strokes"][-1]
    assert run >= 2 and len(st["session"]["controls"]) == len(st0["session"]["controls"]) + run
    st = server.idle(60)
    assert st["session"]["history"][0] == st0["session"]["history"][0] + 1  # the stroke is one step
    page.locator(".somview-stroke").click()  # the tool off: presses orbit again
    assert view(page)["tool"] is None


def test_the_display_menu_turns_the_wireframe_shading_look_floor_axes_and_labels(page):
    v = view(page)["display"]
    assert v == {"wireframe": True, "shading": "smooth", "look": "colours", "grid": False, "axes": False,
                 "labels": True, "wireframeChosen": None}  # 482 nodes: a wireframe by default
    before = page.locator("#clay-view canvas").screenshot()
    page.locator(".somview-display").click()
    page.locator(".somview-setting-wireframe").uncheck()
    page.locator(".somview-setting-shading").select_option("flat")
    page.locator(".somview-setting-look").select_option("studio")
    page.locator(".somview-setting-grid").check()
    page.locator(".somview-setting-axes").check()
    page.locator(".somview-setting-labels").uncheck()
    page.wait_for_timeout(200)
    v = view(page)
    assert v["display"] == {"wireframe": False, "shading": "flat", "look": "studio", "grid": True, "axes": True,
                            "labels": False, "wireframeChosen": False}
    assert v["synapsesShown"] is False and v["labels"] == []
    assert page.locator("#clay-view canvas").screenshot() != before


def test_a_position_typed_in_the_controls_table_moves_the_control(page, server):
    st0 = server.idle()
    cell = page.locator("#controls-table tr").nth(1).locator(".position-cell input")
    cell.fill("0.25, -0.5, 1.25")
    cell.press("Enter")
    server.wait(lambda s: np.allclose(s["session"]["controls"][1][:3], [0.25, -0.5, 1.25], atol=1e-6),
                what="control 1 at the typed position")
    page.wait_for_timeout(300)  # the field's change event after Enter: the same position, no second step
    st = server.idle()
    assert st["session"]["history"][0] == st0["session"]["history"][0] + 1
    page.wait_for_function(f"() => {{ const p = {VIEW}.controlModel(1); return Math.abs(p[2] - 1.25) < 1e-5; }}",
                           timeout=10000)  # the view shows it there
    cell = page.locator("#controls-table tr").nth(1).locator(".position-cell input")
    cell.fill("up, 2")  # refused: the message, and the field shows the position in effect
    cell.press("Enter")
    page.wait_for_function("() => document.querySelector('#error-alert')?.innerText.includes('position')")
    page.wait_for_function("() => document.querySelector('#controls-table tr:nth-child(2) .position-cell input')"
                           ".value.startsWith('0.25')", timeout=10000)
    server.idle()


def test_the_notebook_panel_moves_a_control_to_a_typed_position_and_features():
    """The notebook's panel: choose a control, type its position (and, on the lines preset, its direction and length)
    as a person types into the fields; a refused text shows its message and the field the values in effect."""
    from somwidget.frontend.model import Session
    from somwidget.frontend.notebook import Panel

    session = Session("lines", device="cpu", autosave=False)
    panel = Panel(session, auto_refresh=False)
    try:
        assert session.wait_idle(120)
        panel.radius_of.value = 1
        panel.refresh()
        assert panel.features.placeholder == "dx, dy, dz, length" and panel.features.layout.display == ""
        panel.position.value = "0.5, 0.25, 1.5"
        np.testing.assert_allclose(session.controls[1, :3], [0.5, 0.25, 1.5])
        panel.features.value = "0, 0, 1, 0.4"
        np.testing.assert_allclose(session.controls[1, [3, 4, 5, 7]], [0, 0, 1, 0.4])  # dx, dy, dz, length
        assert session.history[0] == 2 and panel.error.value == ""
        panel.position.value = "up, 2"
        assert "expected 3 numbers" in panel.error.value
        assert session.wait_applied(30)
        panel.refresh()
        assert panel.position.value == "0.5, 0.25, 1.5"  # the position in effect again
    finally:
        panel.close()
        session.close()
