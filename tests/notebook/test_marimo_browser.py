"""The clay view in marimo: a real `marimo run` server on a notebook that shows the view twice
(`mo.ui.anywidget(view.view)`), opened in Chromium (Playwright). marimo renders each widget in a shadow root, so the
view's stylesheet has to live inside the view's own element: the labels, the status line and Fit stay inside the
view's box, the page's head holds none of it, and the cell after the views is below them. The mouse drags a control
in the first output; the kernel's session moves it, and the second output draws it there too.
"""

from __future__ import annotations

import os
import sys

import helpers
import numpy as np
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS

pytest.importorskip("marimo")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)

pytestmark = pytest.mark.browser

NOTEBOOK = '''
import marimo

app = marimo.App(width="medium")


@app.cell
def _():
    import marimo as mo
    import somwidget

    view = somwidget.show("car", device="cpu")
    mo.ui.anywidget(view.view)
    return mo, view


@app.cell
def _(mo, view):
    mo.ui.anywidget(view.view)  # a second output of the same widget
    return


@app.cell
def _(mo):
    mo.md("The cell after the views.").callout()
    return
'''

#: Every .somview element of the page, inside shadow roots too (marimo's widgets live in them).
VIEWS = """(() => { const out = []; const walk = (root) => { for (const e of root.querySelectorAll('*')) {
  if (e.classList.contains('somview')) out.push(e); if (e.shadowRoot) walk(e.shadowRoot); } };
  walk(document); return out.map((e) => e.somview); })()"""


@pytest.fixture(scope="module")
def marimo_app(tmp_path_factory):
    """`marimo run` on the notebook above; yields its URL."""
    root = tmp_path_factory.mktemp("marimo")
    (root / "clay.py").write_text(NOTEBOOK)
    port = helpers.free_port()
    env = {**os.environ, "PYTHONPATH": str(helpers.ROOT), "SOMWIDGET_DATA_DIR": str(root / "data")}
    url = f"http://127.0.0.1:{port}/"
    with helpers.server_process([sys.executable, "-m", "marimo", "run", "--headless", "--no-token", "--host",
                                 "127.0.0.1", "--port", str(port), str(root / "clay.py")], root / "marimo.log", url,
                                "marimo", env=env):
        yield url


def boxes(page) -> list[dict]:
    """Each view's box and where its status line, Fit and visible labels are, in page pixels."""
    return page.evaluate(f"""() => {VIEWS}.map((v) => {{
      const r = (e) => {{ const b = e.getBoundingClientRect(); return [b.left, b.top, b.right, b.bottom]; }};
      const el = v.container;
      return {{ view: r(el), status: r(el.querySelector('.somview-status')), fit: r(el.querySelector('.somview-fit')),
               labels: [...el.querySelectorAll('.somview-label')].filter((d) => !d.hidden).map(r),
               styled: getComputedStyle(el).position === 'relative' && getComputedStyle(el).overflow === 'hidden',
               inShadow: el.getRootNode() instanceof ShadowRoot }};
    }})""")


def inside(inner, outer, slack: float = 1.0) -> bool:
    return (inner[0] >= outer[0] - slack and inner[1] >= outer[1] - slack and inner[2] <= outer[2] + slack
            and inner[3] <= outer[3] + slack)


def zoom_and_place(page) -> None:
    """Ten wheel ticks over the clay bring the first view's camera closer each time, and the page does not scroll;
    then (after Fit) a double click on the clay adds a control there: both outputs show one control more, and no node
    moved (the meshes they draw are the same as before)."""
    box = page.evaluate(f"() => {{ const b = {VIEWS}[0].container.querySelector('canvas').getBoundingClientRect(); "
                        "return [b.left, b.top, b.width, b.height]; }")
    at = (box[0] + box[2] / 2, box[1] + box[3] / 2)
    k0 = page.evaluate(f"() => {VIEWS}[0].describe().k")
    helpers.wheel_ten_ticks_closer(page, f"{VIEWS}[0]", at)
    top = page.evaluate(f"() => {VIEWS}[0].container.querySelector('canvas').getBoundingClientRect().top")
    assert abs(top - box[1]) <= 1, "the wheel scrolled the page"
    page.evaluate(f"() => {VIEWS}[0].container.querySelector('.somview-fit').click()")
    page.wait_for_timeout(300)
    digests = page.evaluate(f"() => {VIEWS}.map((v) => v.describe().digest)")
    at = (round(at[0] - 20), round(at[1] + 15))  # whole pixels, as events' are
    aimed = page.evaluate(f"() => {VIEWS}[0].surfaceAt({at[0]}, {at[1]})")
    assert aimed is not None
    page.mouse.dblclick(*at)
    page.wait_for_function(f"() => {VIEWS}.every((v) => v.describe().k === {k0 + 1})", timeout=15000)
    page.wait_for_timeout(500)
    assert page.evaluate(f"() => {VIEWS}.map((v) => v.describe().digest)") == digests  # nothing moved
    np.testing.assert_allclose(page.evaluate(f"() => {VIEWS}[1].controlModel({k0})"), aimed, atol=1e-4)


def test_the_view_renders_whole_in_marimo_and_a_drag_moves_the_session(marimo_app):
    with helpers.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(marimo_app)
            page.wait_for_function(f"() => {{ const v = {VIEWS}; return v.length === 2 && v.every((x) => "
                                   "x.describe().painted > 0); }", timeout=120000)
            page.wait_for_timeout(500)  # the labels' next animation frame
            first, second = boxes(page)
            for b in (first, second):
                assert b["inShadow"] and b["styled"], b  # the view's own stylesheet reached it
                assert inside(b["status"], b["view"]) and inside(b["fit"], b["view"]), b
                centres = [[(a + c) / 2, (t + d) / 2] * 2 for a, t, c, d in b["labels"]]
                assert centres and all(inside(c, b["view"]) for c in centres), b  # not scattered over the page
            assert page.evaluate("() => document.head.querySelector('.somview-style')") is None
            after = page.get_by_text("The cell after the views.").bounding_box()
            assert after["y"] >= second["view"][3] - 1  # below the views, not under their labels

            page.evaluate(f"() => {VIEWS}[0].container.scrollIntoView()")
            page.wait_for_function(f"() => {VIEWS}.every((v) => v.describe().running === false)", timeout=120000)
            page.wait_for_timeout(300)
            zoom_and_place(page)

            before = page.evaluate(f"() => {VIEWS}[0].controlModel(2)")
            x, y = page.evaluate(f"() => {VIEWS}[0].controlScreen(2)")
            page.mouse.move(x, y)
            page.mouse.down()
            for k in range(1, 21):
                page.mouse.move(x + 4 * k, y - 2 * k)
                page.wait_for_timeout(30)
            page.mouse.up()
            page.wait_for_function(f"() => {VIEWS}[0].describe().local.length === 0", timeout=15000)
            moved = page.evaluate(f"() => {VIEWS}[0].controlModel(2)")
            assert np.linalg.norm(np.subtract(moved, before)) > 0.1  # the control went where the mouse took it
            page.wait_for_function(f"(m) => {{ const o = {VIEWS}[1].controlModel(2); "
                                   "return o.every((x, i) => Math.abs(x - m[i]) < 1e-5); }", arg=moved,
                                   timeout=15000)  # the kernel's session moved it: the second output follows
            assert page.evaluate(f"() => {VIEWS}.flatMap((v) => v.describe().errors)") == []
        finally:
            browser.close()
