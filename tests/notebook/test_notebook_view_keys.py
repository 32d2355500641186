"""Keys in the notebook's clay view (issue 36, item 3), in a real JupyterLab 4 in Chromium, as a person uses them:
with the pointer (or the focus) in the view, the view's keys and Ctrl+Z / Ctrl+Shift+Z act on the clay and never
reach JupyterLab's own shortcuts (in command mode "1" would turn the cell into a heading, Ctrl+Z would undo the
notebook's last cell action); Escape gives the focus back to the notebook, whose keys then work again. What the
view does is read through its read-only `describe()`, the kernel's session by running a cell.
"""

from __future__ import annotations

import os

import helpers
import numpy as np
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS
from test_notebook_panel import notebook_file, open_notebook, run_cell

pytestmark = pytest.mark.browser

VIEWS = "[...document.querySelectorAll('.somview')].map((e) => e.somview)"
SHOTS = os.environ.get("SOMWIDGET_SHOTS")  # a folder: the test leaves its screenshot there


def cells(page) -> list[str]:
    """The notebook's cells, by kind ("code", "markdown")."""
    return page.evaluate("() => [...document.querySelectorAll('.jp-Notebook .jp-Cell')].map((c) => "
                         "c.classList.contains('jp-MarkdownCell') ? 'markdown' : 'code')")


def kernel(page) -> tuple[int, int]:
    """(controls, undo steps) of the kernel's session: the notebook's cell that prints them, run."""
    index = page.evaluate("() => [...document.querySelectorAll('.jp-Notebook .jp-Cell')].findIndex((c) => "
                          "c.innerText.includes(\"print('clay'\"))")
    cell = page.locator(".jp-Notebook .jp-Cell").nth(index)
    run_cell(page, index)
    page.wait_for_function("(el) => !el.innerText.includes('[*]')",
                           arg=cell.locator(".jp-InputPrompt").element_handle(), timeout=30000)
    page.wait_for_timeout(200)
    words = cell.locator(".jp-OutputArea-output").last.inner_text().split()
    assert words[0] == "clay", words
    return int(words[1]), int(words[2])


def looking_from(v: dict) -> np.ndarray:
    d = np.subtract(v["camera"], v["target"])
    return d / np.linalg.norm(d)


def test_view_keys_and_undo_act_on_the_clay_in_jupyterlab_and_escape_gives_the_notebook_its_keys(
        tmp_path, jupyter, notebook_dir):
    notebook_file(notebook_dir / "keys.ipynb", [
        "import somwidget\nview = somwidget.show('sphere', device='cpu')\nview",
        "print('clay', len(view.session.controls), view.session.history[0])",
        "1 + 1"])
    with helpers.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = open_notebook(browser, jupyter.url(notebook_dir / "keys.ipynb"))
            run_cell(page, 0)
            page.wait_for_function(f"() => {{ const v = {VIEWS}; return v.length >= 1 && "
                                   "v[0].describe().painted > 0 && v[0].describe().running === false; }",
                                   timeout=180000)
            view = f"{VIEWS}[0]"
            k0, steps0 = kernel(page)
            # the notebook in command mode, its last cell deleted (Ctrl+Z there would bring it back)
            page.locator(".jp-Notebook .jp-Cell").nth(2).locator(".jp-InputPrompt").click()
            page.keyboard.press("Escape")
            page.keyboard.press("d")
            page.keyboard.press("d")
            page.wait_for_function("() => document.querySelectorAll('.jp-Notebook .jp-Cell').length === 2",
                                   timeout=5000)
            page.locator(".somview").first.scroll_into_view_if_needed()
            page.wait_for_timeout(300)
            box = page.locator(".somview canvas").first.bounding_box()
            mid = (box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)

            # the pointer in the view: its keys
            page.mouse.move(mid[0] + 0.4 * box["width"], mid[1] + 0.4 * box["height"])
            page.keyboard.press("1")
            page.wait_for_timeout(200)
            np.testing.assert_allclose(looking_from(page.evaluate(f"() => {view}.describe()")), [1, 0, 0], atol=1e-3)
            page.keyboard.press("o")
            page.wait_for_timeout(200)
            assert page.evaluate(f"() => {view}.describe().projection") == "orthographic"
            assert cells(page) == ["code", "code"], "a view key reached JupyterLab"

            # a double click adds a control; Ctrl+Z over the view undoes it in the kernel, Ctrl+Shift+Z redoes it
            at = None
            for dx, dy in [(-30, 20), (40, -30), (-50, -50), (60, 40)]:
                spot = (mid[0] + dx, mid[1] + dy)
                if page.evaluate(f"() => {view}.surfaceAt({spot[0]}, {spot[1]})") is not None:
                    at = spot
                    break
            assert at is not None
            page.mouse.dblclick(*at)
            page.wait_for_function(f"() => {view}.describe().k === {k0 + 1}", timeout=15000)
            page.keyboard.press("Control+z")
            page.wait_for_function(f"() => {view}.describe().k === {k0}", timeout=15000)
            page.keyboard.press("Control+Shift+z")
            page.wait_for_function(f"() => {view}.describe().k === {k0 + 1}", timeout=15000)
            d = page.evaluate(f"() => {view}.describe().desktop")
            assert d["undos"] == 1 and d["redos"] == 1
            if SHOTS:  # the view as the person sees it now: from the front, orthographic, the control added
                page.screenshot(path=os.path.join(SHOTS, "jupyterlab-keys.png"), clip=box)
            assert cells(page) == ["code", "code"], "Ctrl+Z reached JupyterLab (its deleted cell came back)"

            # the focus in the view, the pointer out of it: still its keys
            page.mouse.click(*at)  # a click on the clay: the view takes the focus
            page.mouse.move(mid[0], box["y"] + box["height"] + 40)
            page.keyboard.press("3")
            page.wait_for_timeout(200)
            np.testing.assert_allclose(looking_from(page.evaluate(f"() => {view}.describe()")), [0, 0, -1],
                                       atol=1e-3)
            assert cells(page) == ["code", "code"]

            # Escape: the notebook has the focus and its keys again ("b" adds a cell below)
            page.mouse.move(*mid)
            page.keyboard.press("Escape")
            page.wait_for_timeout(200)
            assert page.evaluate("() => { const a = document.activeElement; return !!a?.closest('.jp-Notebook') "
                                 "&& !a.closest('.somview') && !a.isContentEditable; }"), \
                page.evaluate("() => document.activeElement?.outerHTML.slice(0, 120)")
            page.keyboard.press("b")
            page.wait_for_function("() => document.querySelectorAll('.jp-Notebook .jp-Cell').length === 3",
                                   timeout=5000)
            k1, steps1 = kernel(page)
            assert (k1, steps1) == (k0 + 1, steps0 + 1)  # the kernel's session: the add, once
            page.screenshot(path=str(tmp_path / "jupyterlab-keys.png"))
            assert page.evaluate(f"() => {view}.describe().errors") == []
        finally:
            browser.close()
