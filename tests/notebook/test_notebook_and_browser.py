"""One session, many hands (issue 35) across a notebook and a browser: a real JupyterLab 4 runs `somwidget.show()` and
serves the same session to the XR page (XRServer, started in the kernel); Chromium (Playwright) opens the notebook in
one page and the XR page in another, and the mouse acts in each as a person does.

- each view shows the other (notebook, desktop), in its colour;
- a control the browser holds is refused to the notebook's mouse, with a message naming the holder, and the notebook
  draws it in the holder's colour;
- the notebook and the browser dragging at once make two undo steps (the kernel's session says so).
"""

from __future__ import annotations

import helpers
import numpy as np
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS
from test_notebook_panel import notebook_file, open_notebook, run_cell, view_errors

pytest.importorskip("ipywidgets")

pytestmark = pytest.mark.browser

VIEWS = "[...document.querySelectorAll('.somview')].map((e) => e.somview)"


def cell_output(page, index: int, word: str, timeout: float = 60.0) -> list[str]:
    """Run cell `index` and return the words of its output line that starts with `word`."""
    cell = page.locator(".jp-Notebook .jp-Cell").nth(index)
    out = cell.locator(".jp-OutputArea-output")
    before = out.last.inner_text() if out.count() else None
    run_cell(page, index)

    def ready():
        if not out.count() or "[*]" in cell.locator(".jp-InputPrompt").inner_text():
            return None
        text = out.last.inner_text()
        return text if text != before and text.split()[:1] == [word] else None

    return helpers.wait_for(ready, timeout=timeout, what=f"cell {index}'s output").split()


def press_on(page, view: str, index: int) -> tuple[float, float]:
    """The mouse over control `index` of a view (or its mirrored copy, where the clay hides it), pressed; the view
    scrolled into sight first (running a cell scrolls the notebook)."""
    page.locator(".somview").first.scroll_into_view_if_needed()
    page.wait_for_timeout(300)
    for j in (index, index + 9):
        x, y = page.evaluate(f"() => {view}.controlScreen({j})")
        page.mouse.move(x, y)
        try:
            page.wait_for_function(f"() => {view}.describe().hover.some((j) => j % 9 === {index})", timeout=3000)
        except Exception:
            continue
        page.mouse.down()
        return x, y
    page.screenshot(path=str(helpers.ROOT / "hands-failure.png"))
    raise AssertionError(f"control {index} cannot be taken with the mouse (hovering "
                         f"{page.evaluate(f'() => {view}.describe().hover')} at {x:.0f}, {y:.0f})")


def rgb(colour: str) -> np.ndarray:
    return np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])


def test_a_notebook_and_a_browser_share_the_hands(jupyter, notebook_dir):
    notebook_file(notebook_dir / "hands.ipynb", [
        "import somwidget\nview = somwidget.show('car', device='cpu')\nview",
        "from somwidget.frontend.web.standalone import XRServer\nsrv = XRServer(view.session).start()\n"
        "print('serving', srv.base)",
        "s = view.session\nprint('session', s.history[0], *s.controls[2][:3], *s.controls[5][:3])"])
    with helpers.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            lab = open_notebook(browser, jupyter.url(notebook_dir / "hands.ipynb"))
            run_cell(lab, 0)
            lab.wait_for_function(f"() => {VIEWS}.length === 1 && {VIEWS}[0].describe().painted > 0",
                                  timeout=120000)
            base = cell_output(lab, 1, "serving")[1]
            desk = browser.new_page(viewport={"width": 520, "height": 520})
            desk.goto(base + "/xr/")
            desk.wait_for_function("window.somxr && somxr.state().frames > 0", timeout=30000)
            view = f"{VIEWS}[0]"
            lab.locator(".somview").first.scroll_into_view_if_needed()

            # each view shows the other, a colour each
            desk.wait_for_function("document.querySelector('.somview-presence').innerText.includes('notebook')",
                                   timeout=15000)
            lab.wait_for_function("() => document.querySelector('.somview-presence').innerText.includes('desktop')",
                                  timeout=15000)
            hands = {h["kind"]: h for h in desk.evaluate("somxr.state().presence")}
            assert set(hands) == {"desktop", "notebook"} and hands["desktop"]["you"] and not hands["notebook"]["you"]
            assert hands["desktop"]["colour"] != hands["notebook"]["colour"]
            holder = hands["desktop"]["name"]
            steps = float(cell_output(lab, 2, "session")[1])

            # the browser holds control 2: the notebook sees it in the browser's colour, and its mouse is refused it
            xd, yd = press_on(desk, "document.querySelector('#view').somview", 2)
            lab.wait_for_function(f"() => document.querySelector('.somview-presence').innerText.includes("
                                  f"'{holder} \u00b7 holds 2')", timeout=15000)
            look = lab.evaluate(f"() => {view}.controlLook(2)")
            assert np.abs(rgb(look["colour"]) - rgb(hands["desktop"]["colour"])).max() <= 2, look
            xn, yn = press_on(lab, view, 2)
            lab.mouse.move(xn + 12, yn + 8)
            lab.mouse.up()
            lab.wait_for_function(f"() => ({view}.describe().lastError || '').includes("
                                  f"'control 2 is held by {holder}')", timeout=15000)
            assert f"held by {holder}" in lab.locator(".somview-error").first.inner_text()

            # both drag at once: the browser goes on with control 2, the notebook drags control 5
            xn, yn = press_on(lab, view, 5)
            for s in range(1, 9):
                desk.mouse.move(xd + 6 * s, yd - 3 * s)
                lab.mouse.move(xn - 5 * s, yn + 3 * s)
                lab.wait_for_timeout(40)
            desk.mouse.up()
            lab.mouse.up()
            lab.wait_for_function(f"() => {view}.describe().local.length === 0", timeout=15000)
            words = helpers.wait_for(lambda: (w := cell_output(lab, 2, "session")) and float(w[1]) == steps + 2
                                     and w, timeout=60, what="two undo steps in the kernel's session")
            moved = np.array([float(v) for v in words[2:]]).reshape(2, 3)
            assert np.all(np.isfinite(moved))
            assert view_errors(lab, VIEWS) == [f"grab: control 2 is held by {holder}; it is free again when they "
                                               "let go"]
            assert desk.evaluate("somxr.state().errors") == []
        finally:
            browser.close()
