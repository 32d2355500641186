"""One panel that fits every host (issue 36, items 2 and 4): the panel beside the live view, opened in a real
JupyterLab 4, Notebook 7, Voila (`voila notebooks/09_modelling_app.ipynb`) and marimo (`marimo run`, the anywidget
panel) in Chromium at 1280 and at 360 pixels wide. At each width every field of the panel (inputs, menus, buttons,
sliders' handles) is in the page's width, on screen once scrolled to, and not covered: the element at its centre
(elementFromPoint) is the field itself; and no label, button or heading is cut (its scrollWidth fits its clientWidth).

SOMWIDGET_SHOTS=<folder> keeps a screenshot of each host at 360 pixels there.
"""

from __future__ import annotations

import os
import subprocess
import sys
import urllib.error
import urllib.request

import helpers
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS

pytestmark = [pytest.mark.browser, pytest.mark.slow]

if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)

from test_notebook_panel import notebook_file, open_notebook, run_cell  # noqa: E402

WIDTHS = (1280, 360)
APP = helpers.ROOT / "notebooks" / "09_modelling_app.ipynb"

#: Every element of the page and of its shadow roots (marimo draws each widget in one) matching a selector.
FIND = """(selector) => { const out = []; const walk = (root) => { for (const e of root.querySelectorAll('*')) {
  if (e.matches(selector)) out.push(e); if (e.shadowRoot) walk(e.shadowRoot); } }; walk(document); return out; }"""

#: What is wrong with the first panel of the page at this width: fields out of the page's width, not on screen once
#: scrolled to, or under another element; labels cut. [] when it fits.
CHECK = """async () => {
  const find = """ + FIND + """;
  const panel = find('.somwidget-panel')[0];
  if (!panel) return ['no panel'];
  const shown = (e) => { const r = e.getBoundingClientRect(); return r.width > 0 && r.height > 0
    && getComputedStyle(e).visibility !== 'hidden'; };
  const inPanel = (selector) => [...panel.querySelectorAll(selector),
    ...[...panel.querySelectorAll('*')].filter((e) => e.shadowRoot)
      .flatMap((e) => [...e.shadowRoot.querySelectorAll(selector)])];
  const fields = inPanel('input, select, button, textarea, a, .noUi-handle, .widget-readout').filter(shown);
  const problems = [];
  const name = (e) => (e.getAttribute('title') || e.getAttribute('aria-label') || e.textContent || e.value
    || e.placeholder || e.className || e.tagName).toString().trim().slice(0, 40);
  // a field's verdict after it was scrolled to and the host settled: a windowed notebook (Notebook 7) places its
  // cells again over a few frames after a scroll, so a field is judged on the last of up to 12 looks
  const frame = () => new Promise((r) => requestAnimationFrame(r));
  const verdict = (f) => {
    const r = f.getBoundingClientRect();
    const x = r.left + r.width / 2, y = r.top + r.height / 2;
    if (r.left < -1 || r.right > innerWidth + 1) {
      return `off the width: ${name(f)} [${Math.round(r.left)}, ${Math.round(r.right)}] of ${innerWidth}`;
    }
    if (y < 0 || y > innerHeight) return `not on screen: ${name(f)}`;
    const hit = f.getRootNode().elementFromPoint(x, y);
    if (!hit || !(hit === f || f.contains(hit) || (hit.tagName === 'LABEL' && hit.contains(f)))) {
      return `covered: ${name(f)} by ${hit ? hit.tagName + '.' + hit.className : 'nothing'}`;
    }
    return null;
  };
  for (const f of fields) {
    let problem = null;
    for (let look = 0; look < 12; look++) {
      f.scrollIntoView({ block: 'center', inline: 'nearest' });
      await frame();
      await frame();
      problem = verdict(f);
      if (!problem) break;
    }
    if (problem) problems.push(problem);
  }
  const labels = 'label, .widget-label, .widget-label-basic, button, .widget-html-content, .widget-readout, th';
  for (const l of inPanel(labels)) {
    if (!shown(l)) continue;
    if (l.scrollWidth > l.clientWidth + 1) problems.push(`cut: ${name(l)} (${l.scrollWidth} > ${l.clientWidth})`);
  }
  return problems.length ? problems : (fields.length > 20 ? [] : [`only ${fields.length} fields`]);
}"""


def make_room(page) -> None:
    """What a person does in a narrow JupyterLab: close the file browser (it keeps its width) and the news toast."""
    tab = page.locator(".jp-SideBar.jp-mod-left .lm-TabBar-tab.lm-mod-current")
    if tab.count():
        tab.first.click()
    no = page.locator(".jp-toast-button", has_text="No")
    if no.count() and no.first.is_visible():
        no.first.click()


def check_widths(page, host: str) -> None:
    """At each width the panel fits (CHECK); a screenshot at 360 pixels where SOMWIDGET_SHOTS says."""
    for width in WIDTHS:
        page.set_viewport_size({"width": width, "height": 900})
        page.wait_for_timeout(1500)  # the page lays itself out again
        if width < 600 and host == "jupyterlab":
            make_room(page)
            page.wait_for_timeout(800)
        problems = page.evaluate(CHECK)
        assert problems == [], f"{host} at {width} px: {problems}"
        if width == 360 and os.environ.get("SOMWIDGET_SHOTS"):
            page.evaluate(f"() => ({FIND})('.somwidget-panel')[0].scrollIntoView({{block: 'start'}})")
            page.wait_for_timeout(300)
            page.screenshot(path=os.path.join(os.environ["SOMWIDGET_SHOTS"], f"panel-{host}-360.png"))


def wait_for_view(page, timeout: float = 180000) -> None:
    page.wait_for_function(f"() => ({FIND})('.somview').some((e) => e.somview && e.somview.describe().painted > 0) "
                           f"&& ({FIND})('.somwidget-panel').length > 0", timeout=timeout)


@pytest.mark.parametrize("app", ["jupyterlab", "notebook"])
def test_the_panel_fits_jupyterlab_and_notebook_7(jupyter, notebook_dir, app):
    notebook_file(notebook_dir / "fit.ipynb", ["import somwidget\nview = somwidget.show('car', device='cpu')\nview"])
    with helpers.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = open_notebook(browser, jupyter.url(notebook_dir / "fit.ipynb", app))
            run_cell(page, 0)
            wait_for_view(page)
            check_widths(page, app)
        finally:
            browser.close()


def _answers(url: str) -> bool:
    """The server answers at all (a 404 is an answer: it listens)."""
    try:
        with urllib.request.urlopen(url, timeout=5):
            return True
    except urllib.error.HTTPError:
        return True
    except OSError:
        return False


def test_the_panel_fits_voila_and_the_kernel_goes_with_the_page(tmp_path):
    """`voila notebooks/09_modelling_app.ipynb` (from the checkout's root: its voila.json culls a kernel whose page has
    gone for 30 s): the app page fits at both widths; once the page is closed the kernel that held the session (and
    its memory) is gone."""
    pytest.importorskip("voila")
    psutil = pytest.importorskip("psutil")
    port = helpers.free_port()
    env = {**os.environ, "PYTHONPATH": str(helpers.ROOT), "SOMWIDGET_DATA_DIR": str(tmp_path / "data")}
    with open(tmp_path / "voila.log", "w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "voila", "--no-browser", f"--port={port}",
                                 "--Voila.ip=127.0.0.1", str(APP)], cwd=helpers.ROOT, env=env, stdout=log,
                                stderr=subprocess.STDOUT)
        try:
            helpers.wait_for(lambda: _answers(f"http://127.0.0.1:{port}/voila/static/"), timeout=90,
                             what="voila to start")
            with helpers.sync_playwright() as p:
                browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
                try:
                    page = browser.new_page(viewport={"width": 1280, "height": 900})
                    page.goto(f"http://127.0.0.1:{port}/")
                    wait_for_view(page)
                    kernels = psutil.Process(proc.pid).children(recursive=True)
                    assert kernels, "no kernel process under voila"
                    rss = max(k.memory_info().rss for k in kernels) / 2**20
                    assert rss > 200, rss  # the session's kernel: numpy, warp, the car's session
                    check_widths(page, "voila")
                    page.close(run_before_unload=True)  # as a person closes the tab
                    helpers.wait_for(lambda: not any(k.is_running() and k.status() != psutil.STATUS_ZOMBIE
                                                     for k in kernels), timeout=120,
                                     what=f"voila to shut the page's kernel down ({rss:.0f} MB)")
                finally:
                    browser.close()
        finally:
            proc.terminate()
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()


MARIMO_NOTEBOOK = '''
import marimo

app = marimo.App(width="medium")


@app.cell
def _():
    import marimo as mo
    import somwidget

    view = somwidget.show("car", device="cpu")  # in marimo: the anywidget panel beside the view
    view
    return


if __name__ == "__main__":
    app.run()
'''


def test_the_anywidget_panel_fits_marimo_and_sets_the_session(tmp_path):
    """`marimo run` on a notebook whose cell ends with show()'s widget: the anywidget panel (its fields from the
    declaration) beside the view fits at both widths; a value typed in its S field reaches the kernel's session (the
    panel's status line shows the session's new S)."""
    pytest.importorskip("marimo")
    (tmp_path / "clay.py").write_text(MARIMO_NOTEBOOK)
    port = helpers.free_port()
    env = {**os.environ, "PYTHONPATH": str(helpers.ROOT), "SOMWIDGET_DATA_DIR": str(tmp_path / "data")}
    with open(tmp_path / "marimo.log", "w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "marimo", "run", "--headless", "--no-token", "--host",
                                 "127.0.0.1", "--port", str(port), str(tmp_path / "clay.py")], env=env, stdout=log,
                                stderr=subprocess.STDOUT)
        try:
            helpers.wait_for(lambda: _answers(f"http://127.0.0.1:{port}/"), timeout=90, what="marimo to start")
            with helpers.sync_playwright() as p:
                browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
                try:
                    page = browser.new_page(viewport={"width": 1280, "height": 900})
                    page.goto(f"http://127.0.0.1:{port}/")
                    wait_for_view(page)
                    check_widths(page, "marimo")
                    page.set_viewport_size({"width": 1280, "height": 900})
                    fields = page.evaluate(f"() => ({FIND})('.somwidget-panel input[type=number]').length")
                    assert fields >= 4 + 5  # S, l_start, l_end, smoothing; a metric weight per feature
                    page.evaluate(f"""() => {{ const f = ({FIND})('.somwidget-panel input[type=number]')[0];
                        f.scrollIntoView({{block: 'center'}}); }}""")
                    box = page.evaluate(f"""() => {{ const r = ({FIND})('.somwidget-panel input[type=number]')[0]
                        .getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; }}""")
                    page.mouse.click(*box)  # the S field, as a person types in it
                    page.keyboard.press("Control+a")
                    page.keyboard.type("400")
                    page.keyboard.press("Enter")
                    page.wait_for_function(f"() => ({FIND})('.somwidget-panel .status')[0].textContent"
                                           ".includes('/ 400')", timeout=30000)  # the session's S, shown back
                finally:
                    browser.close()
        finally:
            proc.terminate()
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
