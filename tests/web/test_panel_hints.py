"""What a first-time user of the web app met on the grid (issue 34's trial): the panel's and the toolbar's buttons say
what they do in a tooltip that shows within half a second of hovering; choosing the preset already in use in the
menu reloads it; a control left off the clay has a line to its nearest node in the view and its gap marked in the
table (one on the clay neither). Done as the person did it in Chromium against `somwidget serve --preset grid`; what
they see is read from the page and through the view's read-only describe(), the session through GET /api/state.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from helpers import CHROMIUM
from sphere_app import VIEW, open_page, serve_sphere

from somwidget.backend.presets import PRESET_LABELS, get_preset
from somwidget.frontend.model.panel import ACTION_HELP as HELP
from somwidget.frontend.model.panel import OFF_CLAY, clay_size

pytestmark = pytest.mark.browser

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)


@pytest.fixture(scope="module")
def server():
    yield from serve_sphere("grid")


@pytest.fixture
def page(browser, server):
    yield from open_page(browser, server, 1200, 800)


def tooltip_after_hover(page, selector: str, wait_ms: int = 700) -> str:
    """Rest the pointer on an element for `wait_ms`; the text of the tooltip then shown ("" for none)."""
    page.mouse.move(0, 0)
    page.wait_for_timeout(200)
    box = page.locator(selector).bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2, steps=4)
    page.wait_for_timeout(wait_ms)
    shown = page.locator(".v-tooltip .v-overlay__content:visible")
    return " ".join(t.strip() for t in shown.all_inner_texts())


def type_position(page, row: int, xyz) -> None:
    cell = page.locator("#controls-table tr").nth(row).locator(".position-cell input")
    cell.fill(", ".join(f"{x:g}" for x in xyz))
    cell.press("Enter")


def test_the_reload_and_reset_buttons_say_what_they_do_within_a_second_of_hovering(page):
    assert tooltip_after_hover(page, "#reload-preset") == HELP["reload_preset"]
    reset = tooltip_after_hover(page, "#reset-button")
    assert reset == HELP["reset"] and "controls stay" in reset  # says whether the controls come back
    assert tooltip_after_hover(page, "#undo-button") == HELP["undo"]  # disabled (nothing to undo), it says it too
    page.mouse.move(0, 0)
    page.wait_for_timeout(600)
    assert tooltip_after_hover(page, "#iteration-label", 300) == ""  # nothing shows where nothing is hovered


def test_choosing_the_grid_again_in_the_menu_starts_the_grid_again(page, server):
    """The person pulled a corner up, then chose Grid (the preset in use) in the menu to start again."""
    preset = get_preset("grid")
    type_position(page, 1, [1.0, 1.0, 0.6])
    server.wait(lambda s: np.allclose(s["session"]["controls"][1], [1.0, 1.0, 0.6], atol=1e-6), what="the move")
    moved = server.idle()
    assert np.abs(np.asarray(moved["session"]["frame"]["positions"])[:, 2]).max() > 0.3  # the clay followed
    steps, gen = moved["session"]["history"][0], moved["session"]["generation"]

    page.locator(".v-select:has(#preset-select) .v-field").click()
    page.locator(".v-overlay .v-list-item", has_text=PRESET_LABELS["grid"]).first.click()
    st = server.wait(lambda s: s["session"]["generation"] > gen, what="the grid reloaded")
    st = server.idle()
    assert st["session"]["preset"] == "grid" and st["session"]["history"][0] == steps + 1  # one new undo step
    np.testing.assert_allclose(st["session"]["frame"]["positions"], preset.weights[:, :3], atol=1e-6)
    np.testing.assert_allclose(st["session"]["controls"], preset.controls, atol=1e-6)
    # what the person sees: the corner's row reads its start again, the view draws the flat grid, Undo is offered
    page.wait_for_function("() => document.querySelectorAll('#controls-table .position-cell input')[1]?.value"
                           " === '1, 1, 0'", timeout=10000)
    page.wait_for_function(f"() => {VIEW}.describe().generation >= {st['session']['generation']}", timeout=10000)
    assert page.evaluate(f"() => {VIEW}.controlModel(1)") == pytest.approx([1.0, 1.0, 0.0], abs=1e-5)
    assert page.locator("#undo-button").is_enabled()


def test_a_control_left_off_the_clay_has_a_line_to_it_and_its_gap_marked(page, server):
    """A stroke drawn beside the grid, in the air (the Stroke tool, S): it lies on the view plane off the clay and
    moves nothing until dragged. The view draws one thin line from it to its nearest node and the table marks its
    gap; the grid's own controls, on the clay, have neither. Undo takes the stroke, its line and its mark away."""
    limit = OFF_CLAY * clay_size(get_preset("grid"))
    st0 = server.idle()
    k, steps = len(st0["session"]["strokes"]), st0["session"]["history"][0]
    assert (np.asarray(st0["session"]["frame"]["gaps"]) <= limit).all()  # the grid's controls lie on it
    page.wait_for_function(f"() => {VIEW}.describe().tethers.length === 0", timeout=10000)
    assert page.locator("#controls-table td.gap-off").count() == 0

    box = page.locator("#clay-view canvas").bounding_box()
    at = (box["x"] + 0.12 * box["width"], box["y"] + 0.2 * box["height"])  # the view's empty top left: no clay
    assert page.evaluate(f"() => {VIEW}.describe().tool") is None
    page.mouse.move(*at)
    page.keyboard.press("s")
    page.mouse.down()
    page.mouse.move(at[0] + 150, at[1] + 10, steps=20)
    page.mouse.up()
    st = server.wait(lambda s: len(s["session"]["strokes"]) == k + 1 and s["session"]["history"][0] == steps + 1,
                     what="the stroke drawn")
    st = server.idle()
    gaps = np.asarray(st["session"]["frame"]["gaps"], np.float64)
    run = st["session"]["strokes"][-1]
    assert run >= 2 and (gaps[-run:] > limit).any() and (gaps[:-run] <= limit).all(), gaps

    page.wait_for_function(f"() => {VIEW}.describe().tethers.length === 1", timeout=10000)
    (line,) = page.evaluate(f"() => {VIEW}.describe().tethers")
    n = len(st["session"]["controls"])
    # from the stroke's sample farthest from the clay, as long as its gap, to the node nearest that sample (float64)
    assert n - run <= line["control"] < n and line["gap"] == pytest.approx(gaps[-run:].max(), rel=1e-4, abs=1e-5)
    nodes = np.asarray(st["session"]["frame"]["positions"], np.float64)
    d = np.linalg.norm(nodes - np.asarray(st["session"]["controls"][line["control"]], np.float64)[:3], axis=1)
    assert d[line["node"]] == pytest.approx(d.min(), abs=1e-5)
    # the table: the stroke's row (the last) has its gap marked, amber; the grid's controls' rows do not
    page.wait_for_function("() => document.querySelectorAll('#controls-table td.gap-off').length === 1",
                           timeout=10000)
    cells = page.locator("#controls-table td.gap-cell")
    assert "gap-off" in cells.nth(k).get_attribute("class")
    colour = "e => getComputedStyle(e).backgroundColor"
    assert cells.nth(k).evaluate(colour) != cells.nth(0).evaluate(colour)

    page.keyboard.press("Escape")
    page.locator("#undo-button").click()  # the stroke goes, and with it its line and its mark
    server.wait(lambda s: len(s["session"]["strokes"]) == k, what="the stroke undone")
    page.wait_for_function(f"() => {VIEW}.describe().tethers.length === 0", timeout=10000)
    page.wait_for_function("() => document.querySelectorAll('#controls-table td.gap-off').length === 0",
                           timeout=10000)
