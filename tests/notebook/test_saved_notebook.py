"""A saved notebook keeps its clay (issue 36, item 1): `show()` leaves a still of the clay beside the live view
(frontend/notebook/still.py), so the file shows the clay wherever it is read.

- nbclient runs a notebook (no browser: the still is rendered off screen, then again once the clay has settled);
  the file holds under 200 KB for the widget, and nbconvert's HTML of it shows the clay: the picture's pixels are
  read back, not only its tag.
- In a real JupyterLab 4 and a real Notebook 7 (Chromium): the cell runs, the view draws and its own picture replaces
  the still (hidden while the live view stands); the notebook is saved and its kernel shut down; reopened with a
  fresh kernel (the widget's model gone), the still shows the clay in the output, no "Error displaying widget" is
  shown, and nbconvert's HTML of that very file shows the clay.

SOMWIDGET_SHOTS=<folder> keeps a screenshot of each reopened notebook there.
"""

from __future__ import annotations

import base64
import io
import json
import os
import re

import helpers
import numpy as np
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS

pytest.importorskip("nbclient")
pytest.importorskip("nbconvert")
from test_notebook_panel import notebook_file, open_notebook, run_cell  # noqa: E402

#: The pictures' background (model/picture.py BACKGROUND, the clay view's): what is not clay.
BACKGROUND = np.array([238, 240, 244])
#: At most this much of the saved file for one widget's outputs (the live view's and the still).
WIDGET_BYTES = 200_000

CELLS = ["import somwidget\nview = somwidget.show('car', device='cpu')\nview",
         "import time\nassert view.session.wait_idle(300)\nt = time.monotonic()\n"
         "while not view.stills.updates and time.monotonic() - t < 120:\n    time.sleep(0.1)\n"
         "print('stills', view.stills.updates)"]


def clay_in(png: bytes) -> tuple[float, float]:
    """(share of the picture the largest connected shape that is not background covers, share of the picture's width
    it spans), on the picture scaled to 4 x 4 pixel cells."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    h, w = img.shape[0] // 4 * 4, img.shape[1] // 4 * 4
    drawn = np.abs(img[:h, :w] - BACKGROUND).max(axis=2) > 40  # the page's white is 17 off the background
    cells = drawn.reshape(h // 4, 4, w // 4, 4).any(axis=(1, 3))
    seen = np.zeros_like(cells)
    best, best_span = 0, 0
    for start in zip(*np.nonzero(cells)):
        if seen[start]:
            continue
        seen[start] = True
        todo, members = [start], []
        while todo:  # 4-connected flood fill
            y, x = todo.pop()
            members.append(x)
            for ny, nx in ((y + 1, x), (y - 1, x), (y, x + 1), (y, x - 1)):
                if 0 <= ny < cells.shape[0] and 0 <= nx < cells.shape[1] and cells[ny, nx] and not seen[ny, nx]:
                    seen[ny, nx] = True
                    todo.append((ny, nx))
        if len(members) > best:
            best, best_span = len(members), max(members) - min(members) + 1
    return best / cells.size, best_span / cells.shape[1]


def assert_clay(png: bytes, what: str) -> None:
    """The trained car's body (with the controls on it) is one shape over a tenth of the still or more, across half
    its width or more; the controls alone (the clay drawn to a sliver early in a run) are spheres apart, each under a
    fiftieth of it."""
    share, span = clay_in(png)
    assert share > 0.1 and span > 0.5, f"{what}: no clay in the picture (its largest shape {share:.0%} of it, " \
                                       f"{span:.0%} wide)"


def html_stills(path) -> list[bytes]:
    """The PNGs of the stills in nbconvert's HTML (lab template) of the notebook at `path`."""
    import nbformat
    from nbconvert import HTMLExporter

    body, _ = HTMLExporter().from_notebook_node(nbformat.read(str(path), as_version=4))
    tags = [t for t in re.findall(r"<img [^>]*>", body) if 'class="somwidget-still"' in t]  # attributes reordered
    assert "Error displaying widget" not in body
    return [base64.b64decode(re.search(r'src="data:image/png;base64,([^"]+)"', t).group(1)) for t in tags]


def widget_outputs(path, cell: int = 0) -> tuple[int, list[dict]]:
    """(bytes the cell's outputs take in the file, the outputs)."""
    nb = json.loads(path.read_text())
    outputs = nb["cells"][cell]["outputs"]
    return len(json.dumps(outputs)), outputs


@pytest.mark.slow
def test_a_notebook_run_by_nbclient_keeps_a_small_still_that_nbconvert_shows(tmp_path):
    import nbformat
    from nbclient import NotebookClient

    path = tmp_path / "car.ipynb"
    notebook_file(path, CELLS)
    nb = nbformat.read(str(path), as_version=4)
    env = {"PYTHONPATH": str(helpers.ROOT), "SOMWIDGET_DATA_DIR": str(tmp_path / "data")}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:  # the widget state off, as JupyterLab saves by default
        NotebookClient(nb, timeout=600, store_widget_state=False, resources={"metadata": {"path": str(tmp_path)}}
                       ).execute()
    finally:
        for k, v in old.items():
            os.environ.pop(k) if v is None else os.environ.__setitem__(k, v)
    nbformat.write(nb, str(path))
    assert "stills 1" in nb.cells[1].outputs[-1]["text"]  # the settled clay replaced the first still
    size, outputs = widget_outputs(path)
    assert size < WIDGET_BYTES, size
    live, still = [o for o in outputs if o["output_type"] == "display_data"]
    assert "application/vnd.jupyter.widget-view+json" in live["data"] and "image/png" not in live["data"]
    png = base64.b64decode(still["data"]["image/png"])
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert_clay(png, "the still's image/png")
    shown = html_stills(path)
    assert shown == [png]  # nbconvert's page draws the same picture, from the HTML of the still
    assert_clay(shown[0], "nbconvert's HTML")


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.parametrize("app", ["jupyterlab", "notebook"])
def test_a_saved_notebook_reopened_without_its_kernel_shows_the_clay(jupyter, notebook_dir, app):
    path = notebook_dir / "saved.ipynb"
    notebook_file(path, CELLS)
    stills = "img.somwidget-still"
    url = jupyter.url(path, app)
    with helpers.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = open_notebook(browser, url)
            run_cell(page, 0)
            page.wait_for_function("() => [...document.querySelectorAll('.somview')].some((e) => "
                                   "e.somview.describe().painted > 0)", timeout=120000)
            run_cell(page, 1)  # waits until the view's own picture has replaced the still
            page.get_by_text(re.compile(r"stills [1-9]")).wait_for(timeout=180000)
            assert not page.locator(stills).first.is_visible()  # hidden while the live view stands

            def saved():
                page.keyboard.press("Control+s")
                page.wait_for_timeout(1000)
                try:
                    outputs = widget_outputs(path)[1]
                except (ValueError, IndexError):  # read while Jupyter was writing it: look again
                    return None
                return next((o for o in outputs if "image/png" in o.get("data", {})), None)

            still = helpers.wait_for(saved, timeout=30, what="the saved still")
            png = base64.b64decode(still["data"]["image/png"])
            assert_clay(png, "the saved still")
            assert widget_outputs(path)[0] < WIDGET_BYTES
            page.close()
            jupyter.shut_down_kernels(notebook_dir)  # the kernel goes: the widget's model with it
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(url)
            shown = page.wait_for_selector(stills, state="visible", timeout=90000)
            page.wait_for_function("() => [...document.querySelectorAll('.jp-OutputArea-output')].some((e) => "
                                   "e.textContent.includes('Error displaying widget: model not found'))",
                                   timeout=90000)  # the widget manager has given up on the model: in the page
            page.wait_for_timeout(500)
            box = shown.bounding_box()
            assert box and box["width"] >= 300 and box["height"] >= 150, box
            assert_clay(shown.screenshot(), "the reopened notebook's output")
            for words in ("Error displaying widget", "Loading widget"):  # but not shown
                said = page.get_by_text(words)
                assert all(not said.nth(i).is_visible() for i in range(said.count())), f"{words} is shown"
            if os.environ.get("SOMWIDGET_SHOTS"):
                page.set_viewport_size({"width": 900, "height": 700})
                shown.scroll_into_view_if_needed()
                page.screenshot(path=os.path.join(os.environ["SOMWIDGET_SHOTS"], f"reopened-{app}.png"))
        finally:
            browser.close()
    assert [clay_in(png) for png in html_stills(path)] == [clay_in(png)]  # nbconvert's HTML of the saved file
