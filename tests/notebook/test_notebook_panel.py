"""The Jupyter panel (somwidget.frontend.notebook) bound both ways to a real Session, and the view beside it.

ipywidgets objects work in plain Python, so most tests need no Jupyter frontend: they set a widget's value (as the
frontend does when a person moves a slider) and check the session followed, or send an intent to the session and
check the widgets after the next frame. Those tests show the protocol, as does
`test_clay_widget_protocol_over_the_comm` (the clay view's messages, sent by hand).
`test_drag_wheel_and_keys_in_the_widget_in_jupyterlab_and_notebook_7` shows the interaction: a real JupyterLab 4 and
a real Notebook 7 (one Jupyter server, tests/notebook/conftest.py) run the cells in Chromium (Playwright), the mouse
drags a control inside the widget, and the panel and a second output of the widget follow; keys in the panel's
fields, the wheel and a double click in the view act on the same page. The sessions train the real Som on the CPU.
"""

from __future__ import annotations

import functools
import json
import os
import re
import subprocess
import sys
import time

import helpers
import numpy as np
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS
from panel_fit import check_widths

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

pytest.importorskip("ipywidgets")

from somwidget.backend.schedule import MOVE_REACH_MOST  # noqa: E402
from somwidget.frontend.model import Session  # noqa: E402
from somwidget.frontend.notebook import Panel, SomWidget, show  # noqa: E402

pytestmark = pytest.mark.browser

wait_for = functools.partial(helpers.wait_for, timeout=15.0, interval=0.02)


@pytest.fixture
def session():
    s = Session("car", device="cpu")
    yield s
    s.close()


@pytest.fixture
def panel(session):
    p = Panel(session)
    yield p
    p.close()


def test_import_somwidget_loads_no_ui_package():
    code = ("import sys, somwidget; "
            "assert callable(somwidget.show) and callable(somwidget.render); "
            "bad = [m for m in ('trame', 'pyvista', 'vtk', 'vtkmodules', 'ipywidgets') if m in sys.modules]; "
            "print(bad); raise SystemExit(1 if bad else 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr


def test_panel_starts_with_the_session(panel, session):
    p = session.parameters
    assert panel.S.value == p["iterations"] == 1000
    assert panel.l_start.value == pytest.approx(p["l_start"]) and panel.l_end.value == pytest.approx(p["l_end"])
    assert panel.symmetry.value is True
    assert panel.preset.value == "car" and "Car" in panel.title.value
    assert [w.description for w in panel.metric] == ["x", "y", "z", "hue", "saturation"]
    assert len(re.findall(r"somwidget-gap", panel.controls_html.value)) == 9


def test_sliders_send_intents(panel, session):
    panel.S.value = 300
    panel.l_start.value = 0.4
    panel.l_end.value = 0.05
    panel.smoothing.value = 0.1
    panel.metric[3].value = 0.0
    # the symmetry last: a value taken after it clears the panel's message line, its notice too, and a loaded run's
    # panel had shown the notice in between
    panel.symmetry.value = False
    p = session.parameters  # the session's own copy changes at once
    assert p["iterations"] == 300 and p["l_start"] == pytest.approx(0.4) and p["l_end"] == pytest.approx(0.05)
    assert p["smoothing"] == pytest.approx(0.1) and p["symmetry"] is False
    assert p["metric_weights"] == pytest.approx([1, 1, 1, 0, 1])
    frame = wait_for(lambda: session.frame.iterations == 300 and session.frame.n_controls == 18
                     and session.frame, what="a frame with the new parameters")  # each copy a control of its own
    assert frame.iteration <= 300
    # the person reads what turning symmetry off did, in the notice colour, and no error
    shown = wait_for(lambda: "symmetry off" in panel.error.value and panel.error.value, what="the symmetry notice")
    assert "18 controls" in shown and "#1d428a" in shown and "#b00020" not in shown


def test_undo_redo_reload_and_reach_from_the_panel(panel, session):
    """The panel's Undo, Redo and reload buttons, and its reach slider, act on the session; the buttons are
    disabled while there is nothing to undo or redo."""
    assert session.wait_idle(60)
    start, original = session.controls, session.preset.controls
    wait_for(lambda: panel.undo_button.disabled and panel.redo_button.disabled, what="nothing to undo yet")
    session.move_control(0, start[0, :3] + np.float32([0.0, 0.0, 0.3]))
    moved = session.controls
    wait_for(lambda: not panel.undo_button.disabled, what="Undo enabled")
    panel.undo_button.click()
    np.testing.assert_array_equal(session.controls, start)
    wait_for(lambda: not panel.redo_button.disabled, what="Redo enabled")
    panel.redo_button.click()
    np.testing.assert_array_equal(session.controls, moved)
    panel.reload_button.click()  # the car again, as it starts: its own controls
    np.testing.assert_array_equal(session.controls, original)
    panel.reach.value = 0.12
    assert session.parameters["reach"] == 0.12
    assert session.wait_applied(30) and session.modelling.som.reach == 0.12
    panel.undo_button.click()  # the reach, then the reload, go back
    assert session.parameters["reach"] == session.preset.reach


def test_the_variants_section_sweeps_shows_a_gallery_and_a_pick_is_one_undo_step(panel, session):
    assert session.wait_idle(60)
    shape = session.frame.weights.copy()
    section = panel.variants
    assert section.pick(0) is False and "no variants yet" in panel.error.value  # nothing swept yet
    section.count.value = 4
    section.jitter.value = 0.08
    section.vary.value = ("l_start",)
    assert section.sweep() is True
    variants = section.result
    assert len(variants) == 4 and len(section.gallery.children) == 4
    assert section.progress.value == 4
    l_start = session.parameters["l_start"]
    assert all(0.7 * l_start - 1e-9 <= p["l_start"] <= 1.3 * l_start + 1e-9 for p in variants.params)
    png = section.gallery.children[2].children[0].value
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 2000
    undo_before = session.history[0]
    section.gallery.children[2].children[1].click()  # "use #2"
    assert session.history[0] == undo_before + 1
    np.testing.assert_array_equal(session.frame.weights, variants.weights[2])
    assert session.parameters["l_start"] == variants.params[2]["l_start"]
    panel.undo_button.click()
    np.testing.assert_array_equal(session.frame.weights, shape)


def test_refused_value_shows_the_message_and_reverts(panel, session):
    for w in panel.metric[:-1]:
        w.value = 0.0
    panel.metric[-1].value = 0.0  # every weight zero: the session refuses
    assert "at least one weight must be positive" in panel.error.value
    assert session.parameters["metric_weights"][-1] == 1.0
    wait_for(lambda: panel.metric[-1].value == 1.0, what="the widget to return to the session's value")
    panel.metric[0].value = 2.0
    assert panel.error.value == "" and session.parameters["metric_weights"][0] == 2.0


def test_a_recovered_session_shows_a_banner_that_can_be_dismissed(tmp_path, monkeypatch):
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(tmp_path / "data"))
    stopped = Session("torus", device="cpu")  # a kernel's session: a step, then the kernel goes
    stopped.settings.set("reach", 0.2)
    assert stopped.wait_idle(30) and stopped.autosave.flush()
    stopped.close()
    recovered = Session.recover(device="cpu")
    plain = Panel(Session("grid", device="cpu", autosave=False), auto_refresh=False)
    panel = Panel(recovered, auto_refresh=False)
    try:
        assert plain.recovered.layout.display == "none"  # nothing to say
        assert panel.recovered.layout.display != "none"
        assert "Brought back your session" in panel.recovered.children[0].value
        assert recovered.recovered["message"] in panel.recovered.children[0].value
        panel.recovered.children[1].click()  # its dismiss button
        assert panel.recovered.layout.display == "none"
    finally:
        for p in (plain, panel):
            p.close()
            p.session.close()


def test_session_intents_update_the_widgets(panel, session):
    assert session.wait_idle(30)
    wait_for(lambda: panel.progress.value == 1000 and "converged" in panel.status.value, what="converged panel")
    seq = panel.last_frame_seq
    session.set_iterations(500)  # as another view (the web app, a script) would
    session.settings.set("l_end", 0.02)
    wait_for(lambda: panel.S.value == 500 and panel.progress.max == 500, what="S in the panel")
    assert panel.l_end.value == pytest.approx(0.02)
    assert panel.last_frame_seq > seq

    assert session.wait_idle(30)  # the restarted 500-cycle run converges
    session.pause()
    wait_for(lambda: "iteration 500 / 500 (paused)" in panel.status.value, what="the paused, converged panel")
    gap_before = _gap_of(panel, 2)
    session.move_control(2, [3.6, 0.25, -0.2])  # the nose control, 1 unit forward: the schedule restarts
    wait_for(lambda: "3.6, 0.25, -0.2" in panel.controls_html.value, what="the control's new position")
    # a local restart: s0 = floor((1 - reach) S), the reach widened for a long move (4.6 median edges) to its most,
    # MOVE_REACH_MOST: 410
    s0 = int(np.floor((1 - MOVE_REACH_MOST) * 500))
    wait_for(lambda: panel.progress.value == s0 and f"iteration {s0} / 500 (paused)" in panel.status.value,
             what="the restarted iteration")
    assert _gap_of(panel, 2) > gap_before + 0.5  # paused: the clay has not followed yet
    assert panel.train_button.description == "Resume"  # stopped part way through the restarted schedule


def test_buttons_and_preset(panel, session):
    session.set_iterations(100_000)  # a long run: it is still training while the buttons are pressed
    wait_for(lambda: panel.train_button.description == "Pause" and panel.progress.value > 0
             and "/ 100000 (training)" in panel.status.value, what="the Pause label while training")
    panel.train_button.click()
    assert session.paused
    wait_for(lambda: panel.train_button.description == "Resume" and "(paused)" in panel.status.value
             and panel.progress.value > 0, what="the Resume label")
    panel.reset_button.click()
    wait_for(lambda: "iteration 0 / 100000 (paused)" in panel.status.value, what="the reset run in the panel")
    assert panel.train_button.description == "Resume"
    assert np.allclose(session.frame.weights, session.preset.weights)  # back to the start mesh
    panel.train_button.click()
    assert not session.paused
    wait_for(lambda: panel.progress.value > 0 and "(training)" in panel.status.value, what="training again")

    # a new Som is built in this thread: pause first, since Warp refuses array copies on the CPU while another
    # thread records a graph (the training thread does, at a new step length)
    session.pause()
    wait_for(lambda: "(paused)" in panel.status.value, what="the paused panel")
    panel.preset.value = "torus"  # the dropdown loads a preset, shown as it is and not left paused
    assert session.preset.name == "torus", panel.error.value
    assert not session.paused
    wait_for(lambda: panel.train_button.description == "Train", what="a settled shape's Train label")
    wait_for(lambda: [w.description for w in panel.metric] == ["x", "y", "z"], what="the torus's features")
    assert "Torus" in panel.title.value
    session.load_preset("lines")  # and the other way round
    wait_for(lambda: panel.preset.value == "lines" and len(panel.metric) == 8, what="the lines preset in the panel")
    assert "dim 7: length" in panel.features_box.children[7].children[1].value


def _gap_of(panel: Panel, index: int) -> float:
    cells = re.findall(r'<td class="somwidget-gap"[^>]*>([^<]*)</td>', panel.controls_html.value)
    return float(cells[index].split("/")[0])


# -- the widget show() returns: the panel beside the browser-drawn clay view (anywidget) ----------------------------
class Recorder:
    """What a ClayWidget sends to the browser, as the frontend would receive it (JSON content, binary buffers)."""

    def __init__(self, widget):
        self.messages = []
        widget.send = lambda content, buffers=None: self.messages.append((content, buffers or []))

    def of(self, kind: str) -> list:
        return [(c, b) for c, b in self.messages if c.get("type") == kind]


@pytest.fixture
def shown():
    session = Session("car", device="cpu")
    widget = show(session)
    yield widget
    widget.close()
    session.close()


def test_show_puts_the_clay_view_beside_the_panel_and_opens_no_port(shown):
    from somwidget.frontend.notebook.widget import ClayWidget

    assert isinstance(shown, SomWidget) and shown.children[0] is shown.panel
    assert isinstance(shown.view, ClayWidget) and shown.children[1] is shown.view
    assert "export default" in shown.view._esm or "as default" in shown.view._esm  # the built module itself
    assert not hasattr(shown, "url") and not hasattr(shown, "server")  # no second server, no iframe
    bundle = shown._repr_mimebundle_()
    assert "application/vnd.jupyter.widget-view+json" in bundle
    assert "image/png" not in bundle  # the still is an output of its own (test_saved_notebook.py)
    png = shown.still_png()  # what a saved notebook shows without a kernel
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000


def test_clay_widget_protocol_over_the_comm(shown):
    """The protocol (not the interaction): a new output says hello and gets the topology and a frame as a binary
    buffer; grab, move and release move the control as one undo step; a bad intent gets an error message."""
    from somwidget.frontend.transport import frames as wire_frames

    view, session = shown.view, shown.session
    session.wait_idle(30)
    rec = Recorder(view)
    view._on_message(view, {"type": "hello"}, [])
    topo = rec.of("topology")[-1][0]  # (the sender thread may have sent its own first one too)
    assert topo["n_vertices"] == 602 and topo["n_controls"] == 9
    assert [p["name"] for p in topo["parameters"]] == ["iterations", "l_start", "l_end", "smoothing", "reach",
                                                         "symmetry"]
    _, buffers = rec.of("frame")[-1]
    frame = wire_frames.decode_frame(bytes(buffers[0]))
    np.testing.assert_allclose(frame["positions"], session.frame.positions, atol=1e-6)
    history = session.history[0]
    target = [float(v) for v in session.controls[2][:3] + np.array([0.1, 0.0, 0.2])]
    for intent in ({"type": "grab", "index": 2}, {"type": "move", "index": 2, "position": target},
                   {"type": "release", "index": 2}):
        view._on_message(view, intent, [])
    session.wait_idle(30)
    np.testing.assert_allclose(session.controls[2][:3], target, atol=1e-6)
    assert session.history[0] == history + 1
    assert [c["grabs"] for c, _ in rec.of("grabs")][-1] == []
    view._on_message(view, {"type": "move", "index": 99, "position": [0, 0, 0]}, [])
    assert "out of range" in rec.of("error")[-1][0]["message"]
    # a parameter by the declaration's name, checked against its bounds
    view._on_message(view, {"type": "set", "name": "reach", "value": 0.2}, [])  # taken on the training thread
    wait_for(lambda: session.parameters["reach"] == 0.2, what="the reach set")
    view._on_message(view, {"type": "set", "name": "reach", "value": 1.5}, [])
    assert "reach" in rec.of("error")[-1][0]["message"] and session.parameters["reach"] == 0.2
    # frames keep coming from the sender thread as the session publishes them
    rec.messages.clear()
    session.reset()
    wait_for(lambda: len(rec.of("frame")) >= 2, what="frames after a reset")


def test_a_notebook_views_grab_binds_the_clay_as_the_browsers_does():
    """The notebook's view is the same connection as a browser's: its grab of a control with a radius (the sphere's
    top) binds the clay that control takes, its moves carry the clay, and its release lets go."""
    session = Session("sphere", device="cpu", autosave=False)
    try:
        assert session.wait_idle(60)
        view, som = show(session).view, session.modelling.som
        start = session.frame.positions.copy()
        target = [float(v) for v in session.controls[0][:3] - np.array([0.0, 0.0, 0.5])]
        view._on_message(view, {"type": "grab", "index": 0}, [])
        wait_for(lambda: som.held == (0,), what="the Som holding control 0")
        view._on_message(view, {"type": "move", "index": 0, "position": target}, [])
        view._on_message(view, {"type": "release", "index": 0}, [])
        wait_for(lambda: som.held == (), what="the Som letting go")
        assert session.wait_idle(60)
        end = session.frame.positions
        assert np.linalg.norm(end - np.asarray(target), axis=1).min() < 0.03 * np.ptp(start, axis=0).max()
    finally:
        session.close()


def test_a_widget_of_a_closed_view_stops_following(session):
    w = show(session)
    view = w.view
    w.close()
    view._sender.join(5)
    assert view._closed and not view._sender.is_alive(), "the widget's sender thread still runs"
    assert view._on_frame not in view.outbox._subscribers  # it no longer follows the session
    seq = session.frame.seq
    session.reset()  # the session goes on without it
    wait_for(lambda: session.frame.seq > seq, what="a frame after the widget closed")


# -- in a real JupyterLab: Playwright's mouse drags a control inside the widget ----------------------------------


def notebook_file(path, cells: list[str]) -> None:
    nb = {"cells": [{"cell_type": "code", "execution_count": None, "metadata": {}, "outputs": [], "source": c}
                    for c in cells],
          "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}},
          "nbformat": 4, "nbformat_minor": 5}
    path.write_text(json.dumps(nb))


@pytest.fixture(scope="module", params=["jupyterlab", "notebook"])
def lab(request, jupyter):
    """A notebook with the widget's cells, opened in JupyterLab 4 or Notebook 7 (the worker's Jupyter server,
    conftest.py); yields (the host's name, its URL). Its kernel is shut down after the host's tests."""
    root = jupyter.root / f"lab-{request.param}"
    root.mkdir()
    notebook_file(root / "clay.ipynb", [
        "import somwidget\nview = somwidget.show('car', device='cpu')\nview",
        "view  # a second output of the same widget",
        "import hashlib\npng = view.view.picture_png() or b''\n"
        "print('picture', png[:8] == b'\\x89PNG\\r\\n\\x1a\\n', len(png), hashlib.md5(png).hexdigest())",
        "print('session', view.session.history[0], *view.session.parameters['metric_weights'])",
        "import hashlib\nassert view.session.wait_idle(120)  # (the weights typed back retrain the car)\n"
        "print('clay', len(view.session.controls), view.session.history[0],\n"
        "      hashlib.md5(view.session.frame.positions.tobytes()).hexdigest())"])
    yield request.param, jupyter.url(root / "clay.ipynb", request.param)
    jupyter.shut_down_kernels(root)


def open_notebook(browser, url: str):
    """A new page on the notebook at `url`, its cells on screen (JupyterLab's workspace reset: it would bring back
    the tabs an earlier test opened beside it)."""
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto(url.replace("?", "?reset&", 1))
    page.wait_for_selector(".jp-Notebook .jp-Cell", timeout=90000)
    return page


def dismiss_dialogs(page) -> None:
    """Answer any modal JupyterLab opens over a freshly opened notebook (a kernel choice, a build notice) with its
    default button, as a person would, so that the clicks that follow reach the cells."""
    for _ in range(3):
        dialog = page.locator(".jp-Dialog")
        if dialog.count() == 0:
            return
        accept = dialog.locator(".jp-Dialog-button.jp-mod-accept")
        (accept.first.click() if accept.count() else page.keyboard.press("Escape"))
        page.wait_for_timeout(500)


def test_drag_wheel_and_keys_in_the_widget_in_jupyterlab_and_notebook_7(lab):
    """Interaction, in JupyterLab 4 and in Notebook 7: the page runs the cells; the mouse drags control 2 inside the
    widget; the panel's controls table (same output) shows the control moved and the second output of the widget
    draws it there too; the picture a saved notebook keeps (the widget's state) is retaken after the drag. Then, on
    the same page and kernel (one setup for the four): the keyboard in the panel's metric weight fields
    (`refused_value_snaps_back`), the wheel and a double click in the view (`wheel_and_double_click`), and last
    the panel fits the page at 1280 and at 360 pixels wide (panel_fit.py, as test_panel_fits.py checks it in Voila
    and marimo)."""
    app, url = lab
    views = "[...document.querySelectorAll('.somview')].map((e) => e.somview)"
    with helpers.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = open_notebook(browser, url)
            run_cell(page, 0)
            run_cell(page, 1)
            try:
                page.wait_for_function(f"() => {{ const v = {views}; return v.length === 2 && v.every((x) => "
                                       "x.describe().painted > 0); }", timeout=120000)
            except Exception:
                page.screenshot(path=str(helpers.ROOT / "lab-failure.png"))
                raise
            table = page.locator(".jp-OutputArea-output table").first
            before = table.inner_text()
            shown = picture(page)  # the still view has taken its picture
            page.locator(".somview").first.scroll_into_view_if_needed()
            page.wait_for_timeout(300)
            x, y = page.evaluate(f"() => {views}[0].controlScreen(2)")
            page.mouse.move(x, y)
            page.mouse.down()
            for k in range(1, 21):
                page.mouse.move(x + 4 * k, y - 2 * k)
                page.wait_for_timeout(30)
            page.mouse.up()
            page.wait_for_function(f"() => {views}[0].describe().local.length === 0", timeout=15000)
            page.wait_for_function("(b) => document.querySelector('.jp-OutputArea-output table').innerText !== b",
                                   arg=before, timeout=15000)
            moved = page.evaluate(f"() => {views}[0].controlModel(2)")
            other = page.evaluate(f"() => {views}[1].controlModel(2)")
            np.testing.assert_allclose(other, moved, atol=1e-5)  # the second output follows the first
            assert view_errors(page, views) == []
            after = picture(page, unlike=shown)  # a new picture of the clay after the drag, in the kernel
            assert after[1] > 5000, after  # a PNG of a drawn clay, not an empty canvas
            refused_value_snaps_back(page)
            wheel_and_double_click(page, views)
            check_widths(page, app)
        finally:
            browser.close()


def kernel_session(page) -> list[float]:
    """Run the notebook's fourth cell: [undo steps, metric weights...] as the kernel's session holds them."""
    cell = page.locator(".jp-Notebook .jp-Cell").nth(3)
    out = cell.locator(".jp-OutputArea-output")
    before = out.last.inner_text() if out.count() else None
    run_cell(page, 3)
    page.wait_for_function("([el, b]) => !el.innerText.includes('[*]')",
                           arg=[cell.locator(".jp-InputPrompt").element_handle(), before], timeout=30000)
    page.wait_for_timeout(200)
    words = out.last.inner_text().split()
    assert words[0] == "session", words
    return [float(x) for x in words[1:]]


def metric_field(page, name: str):
    """The panel's metric weight field of feature `name` (the first output's)."""
    return page.locator(".jp-OutputArea-output .widget-text").filter(
        has=page.locator(f"label:text-is('{name}')")).first.locator("input")


def type_in(page, field, text: str) -> None:
    """Click a field, replace its text by typing, press Enter (as a person does)."""
    field.click()
    page.keyboard.press("Control+a")
    page.keyboard.type(text)
    page.keyboard.press("Enter")


def refused_value_snaps_back(page) -> None:
    """With the keyboard in the panel's metric weight fields: every weight 0 is refused (the last one): the message
    shows and the field goes back to the value in effect. Ctrl+Z in a field undoes the typing there and nothing of
    the session. The car's weights are typed back at the end."""
    names = ["x", "y", "z", "hue", "saturation"]
    metric_field(page, names[-1]).wait_for(timeout=120000)
    steps = kernel_session(page)[0]
    for name in names[:-1]:
        type_in(page, metric_field(page, name), "0")
    last = metric_field(page, names[-1])
    type_in(page, last, "0")
    page.get_by_text("at least one weight must be positive").first.wait_for(timeout=15000)  # (each output's panel)
    page.wait_for_function("(el) => el.value === '1'", arg=last.element_handle(), timeout=15000)
    state = kernel_session(page)
    assert state[1:] == [0.0, 0.0, 0.0, 0.0, 1.0] and state[0] > steps  # taken, the last refused
    field = metric_field(page, "x")
    field.click()
    page.keyboard.press("Control+a")
    page.keyboard.type("3")
    page.keyboard.press("Control+z")  # the field's own undo
    page.wait_for_function("(el) => el.value === '0'", arg=field.element_handle(), timeout=5000)
    page.keyboard.press("Tab")
    assert kernel_session(page) == state  # nothing of the session changed or was undone
    for name in names[:-1]:  # the car's weights again
        type_in(page, metric_field(page, name), "1")
    # (the last field's value reaches the kernel a moment after its Enter: a loaded box ran the cell before it did)
    deadline = time.monotonic() + 30
    while (weights := kernel_session(page)[1:]) != [1.0] * 5 and time.monotonic() < deadline:
        page.wait_for_timeout(500)
    assert weights == [1.0] * 5


def clay_in_kernel(page) -> tuple[int, int, str]:
    """Run the notebook's fifth cell: (controls, undo steps, md5 of the positions) of the kernel's session, once it
    has settled."""
    cell = page.locator(".jp-Notebook .jp-Cell").nth(4)
    run_cell(page, 4)
    page.wait_for_function("(el) => !el.innerText.includes('[*]')",
                           arg=cell.locator(".jp-InputPrompt").element_handle(), timeout=30000)
    page.wait_for_timeout(200)
    words = cell.locator(".jp-OutputArea-output").last.inner_text().split()
    assert words[0] == "clay", words
    return int(words[1]), int(words[2]), words[3]


def wheel_and_double_click(page, views: str) -> None:
    """The view as a modelling tool inside JupyterLab 4 and Notebook 7 (the same client as the web app), once the
    clay has settled: ten wheel ticks over the clay bring the camera closer each time (and do not scroll the notebook
    away); a double click on the clay adds a control at that point of the surface in the kernel's session, one undo
    step, and no node moves."""
    try:  # the car trained to its end: nothing moves by itself
        page.wait_for_function(f"() => {views}[0].describe().running === false", timeout=180000)
    except Exception:
        d = page.evaluate(f"() => {views}[0].describe()")
        seen = {k: d.get(k) for k in ("running", "status", "painted", "errors")}
        raise AssertionError(f"the car did not settle in the view: {seen}") from None
    page.locator(".somview").first.scroll_into_view_if_needed()
    page.wait_for_timeout(500)
    box = page.locator(".somview canvas").first.bounding_box()
    helpers.wheel_ten_ticks_closer(page, f"{views}[0]", (box["x"] + box["width"] / 2,
                                                         box["y"] + box["height"] / 2))
    assert page.locator(".somview canvas").first.bounding_box()["y"] == pytest.approx(box["y"], abs=1), \
        "the wheel scrolled the notebook"
    n0, steps0, positions0 = clay_in_kernel(page)  # the notebook scrolls to that cell: back to the view
    page.locator(".somview").first.scroll_into_view_if_needed()
    page.locator(".somview-fit").first.click()
    page.wait_for_function(f"() => {{ const d = {views}[0].describe(); "
                           "return Math.abs(d.distance - d.fitDistance) < 1e-6 * d.fitDistance; }",
                           timeout=5000)
    page.wait_for_timeout(300)
    box = page.locator(".somview canvas").first.bounding_box()
    at = (round(box["x"] + box["width"] / 2 - 20), round(box["y"] + box["height"] / 2 + 15))
    # (whole pixels, as a mouse event's clientX / clientY are: half a pixel is 0.006 of the car here)
    aimed = page.evaluate(f"() => {views}[0].surfaceAt({at[0]}, {at[1]})")
    assert aimed is not None
    page.mouse.dblclick(*at)
    page.wait_for_function(f"() => {views}[0].describe().k === {n0 + 1}", timeout=15000)
    placed = page.evaluate(f"() => {views}[0].controlModel({n0})")
    np.testing.assert_allclose(placed, aimed, atol=1e-4)  # where the double click was, on the surface
    n1, steps1, positions1 = clay_in_kernel(page)
    assert (n1, steps1) == (n0 + 1, steps0 + 1)  # one control more, one undo step
    assert positions1 == positions0  # nothing moved
    assert view_errors(page, views) == []


def picture(page, unlike=None, timeout: float = 30.0) -> tuple:
    """Run the notebook's third cell until the kernel holds a PNG picture from the view (unlike `unlike`): (is a
    PNG, bytes, md5)."""
    deadline = time.monotonic() + timeout
    out = page.locator(".jp-Notebook .jp-Cell").nth(2).locator(".jp-OutputArea-output")
    while True:
        run_cell(page, 2)
        page.wait_for_function("(el) => !el.innerText.includes('[*]')",
                               arg=page.locator(".jp-Notebook .jp-Cell").nth(2).locator(".jp-InputPrompt")
                               .element_handle(), timeout=30000)
        text = out.last.inner_text() if out.count() else ""
        words = text.split()
        if len(words) == 4 and words[0] == "picture" and words[1] == "True" and (unlike is None or
                                                                                 words[3] != unlike[2]):
            return True, int(words[2]), words[3]
        if time.monotonic() > deadline:
            raise AssertionError(f"the kernel holds no new picture of the view: {text!r}")
        page.wait_for_timeout(1000)


def run_cell(page, index: int, tries: int = 20) -> None:
    """Shift+Enter in cell `index`, again until its prompt shows it queued or run (a press before the kernel is
    connected is dropped, and the page gives no sign of when it is)."""
    cell = page.locator(".jp-Notebook .jp-Cell").nth(index)
    prompt = cell.locator(".jp-InputPrompt")
    for _ in range(tries):
        dismiss_dialogs(page)
        try:
            cell.locator(".jp-InputArea-editor").click(timeout=5000)
        except Exception:  # a dialog opened between the look and the click: the next try answers it
            continue
        page.keyboard.press("Shift+Enter")
        try:
            page.wait_for_function("(el) => /\\[(\\*|\\d+)\\]/.test(el.innerText)", arg=prompt.element_handle(),
                                   timeout=3000)
            return
        except Exception:  # not queued: the kernel was not there yet
            continue
    raise AssertionError(f"cell {index} never ran")


def view_errors(page, views: str) -> list:
    return page.evaluate(f"() => {views}.flatMap((v) => v.describe().errors)")


def test_a_notebook_saved_with_widget_state_shows_the_last_picture_when_reopened(jupyter, notebook_dir):
    """JupyterLab with "Save Widget State Automatically": run the widget, let the view take its picture, save; the
    file holds that picture in its widget state, and the notebook reopened in a fresh kernel (whose widgets are gone)
    shows it in the view's place instead of a blank canvas."""
    path = notebook_dir / "saved.ipynb"
    notebook_file(path, ["import somwidget\nview = somwidget.show('car', device='cpu')\nview"])
    with jupyter.lab_setting("@jupyter-widgets/jupyterlab-manager:plugin", {"saveState": True}):
        url = jupyter.url(path)
        with helpers.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                page = open_notebook(browser, url)
                run_cell(page, 0)
                page.wait_for_function("() => [...document.querySelectorAll('.somview')].some((e) => "
                                       "e.somview.describe().painted > 0)", timeout=120000)

                def saved_picture():
                    page.keyboard.press("Control+s")
                    page.wait_for_timeout(1000)
                    try:
                        state = json.loads(path.read_text()).get("metadata", {}).get("widgets", {})
                    except ValueError:  # read while Jupyter was writing it: look again
                        return None
                    models = state.get("application/vnd.jupyter.widget-state+json", {}).get("state", {})
                    pictures = [m["state"].get("picture", "") for m in models.values()]
                    return next((x for x in pictures if x.startswith("data:image/png;base64,")), None)

                picture = helpers.wait_for(saved_picture, timeout=30, what="the saved widget state's picture")
                page.close()
                # the notebook's kernel shut down: reopened, it gets a fresh one, where the saved widgets have no
                # kernel side (what a reader of the saved file sees)
                jupyter.shut_down_kernels(notebook_dir)
                page = browser.new_page(viewport={"width": 1400, "height": 1000})
                page.goto(url)
                shown = page.wait_for_selector("img.somview-picture", timeout=90000)
                assert shown.get_attribute("src") == picture
                box = shown.bounding_box()
                assert box and box["width"] > 200 and box["height"] > 200  # in the view's place, not a speck
            finally:
                browser.close()
