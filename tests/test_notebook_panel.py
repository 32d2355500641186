"""The Jupyter panel (somwidget.frontend.notebook) bound both ways to a real Session, and the view beside it.

ipywidgets objects work in plain Python, so most tests need no Jupyter frontend: they set a widget's value (as the
frontend does when a person moves a slider) and check the session followed, or send an intent to the session and
check the widgets after the next frame. Those tests show the protocol. `test_drag_in_the_view_updates_the_panel`
shows the interaction: Chromium (Playwright) loads the widget's iframe, the mouse drags a control in the view, and
the panel's iteration and gap follow. The sessions train the real Som on the CPU.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

pytest.importorskip("ipywidgets")

from somwidget.frontend.notebook import Panel, SomWidget, show  # noqa: E402
from somwidget.frontend.session import Session  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def wait_for(predicate, timeout: float = 15.0, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.02)


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
    panel.symmetry.value = False
    panel.metric[3].value = 0.0
    p = session.parameters  # the session's own copy changes at once
    assert p["iterations"] == 300 and p["l_start"] == pytest.approx(0.4) and p["l_end"] == pytest.approx(0.05)
    assert p["smoothing"] == pytest.approx(0.1) and p["symmetry"] is False
    assert p["metric_weights"] == pytest.approx([1, 1, 1, 0, 1])
    frame = wait_for(lambda: session.frame.iterations == 300 and len(session.frame.effective_controls) == 9
                     and session.frame, what="a frame with the new parameters")  # no mirrored copies any more
    assert frame.iteration <= 300
    assert panel.error.value == ""


def test_refused_value_shows_the_message_and_reverts(panel, session):
    for w in panel.metric[:-1]:
        w.value = 0.0
    panel.metric[-1].value = 0.0  # every weight zero: the session refuses
    assert "at least one weight must be positive" in panel.error.value
    assert session.parameters["metric_weights"][-1] == 1.0
    wait_for(lambda: panel.metric[-1].value == 1.0, what="the widget to return to the session's value")
    panel.metric[0].value = 2.0
    assert panel.error.value == "" and session.parameters["metric_weights"][0] == 2.0


def test_session_intents_update_the_widgets(panel, session):
    assert session.wait_idle(30)
    wait_for(lambda: panel.progress.value == 1000 and "converged" in panel.status.value, what="converged panel")
    seq = panel.last_frame_seq
    session.set_iterations(500)  # as another view (the web app, a script) would
    session.set_l_end(0.02)
    wait_for(lambda: panel.S.value == 500 and panel.progress.max == 500, what="S in the panel")
    assert panel.l_end.value == pytest.approx(0.02)
    assert panel.last_frame_seq > seq

    assert session.wait_idle(30)  # the restarted 500-cycle run converges
    session.pause()
    wait_for(lambda: "iteration 500 / 500 (paused)" in panel.status.value, what="the paused, converged panel")
    gap_before = _gap_of(panel, 2)
    session.move_control(2, [3.6, 0.25, -0.2])  # the nose control, 1 unit forward: the schedule restarts
    wait_for(lambda: "3.60, 0.25, -0.20" in panel.controls_html.value, what="the control's new position")
    wait_for(lambda: panel.progress.value == 0 and "iteration 0 / 500 (paused)" in panel.status.value,
             what="the restarted iteration")
    assert _gap_of(panel, 2) > gap_before + 0.5  # paused: the clay has not followed yet
    assert panel.train_button.description == "Train"


def test_buttons_and_preset(panel, session):
    session.set_iterations(100_000)  # a long run: it is still training while the buttons are pressed
    wait_for(lambda: panel.train_button.description == "Pause" and panel.progress.value > 0
             and "/ 100000 (training)" in panel.status.value, what="the Pause label while training")
    panel.train_button.click()
    assert session.paused
    wait_for(lambda: panel.train_button.description == "Train" and "(paused)" in panel.status.value
             and panel.progress.value > 0, what="the Train label")
    panel.reset_button.click()
    wait_for(lambda: "iteration 0 / 100000 (paused)" in panel.status.value, what="the reset run in the panel")
    assert np.allclose(session.frame.weights, session.preset.weights)  # back to the start mesh
    panel.train_button.click()
    assert not session.paused
    wait_for(lambda: panel.progress.value > 0 and "(training)" in panel.status.value, what="training again")

    # a new Som is built in this thread: pause first, since Warp refuses array copies on the CPU while another
    # thread records a graph (the training thread does, at a new step length)
    session.pause()
    wait_for(lambda: "(paused)" in panel.status.value, what="the paused panel")
    panel.preset.value = "torus"  # the dropdown loads a preset
    assert session.preset.name == "torus", panel.error.value
    wait_for(lambda: [w.description for w in panel.metric] == ["x", "y", "z"], what="the torus's features")
    assert "Torus" in panel.title.value
    session.load_preset("lines")  # and the other way round
    wait_for(lambda: panel.preset.value == "lines" and len(panel.metric) == 8, what="the lines preset in the panel")
    assert "dim 7: length" in panel.features_box.children[7].children[1].value


def _gap_of(panel: Panel, index: int) -> float:
    cells = re.findall(r'<td class="somwidget-gap">([^<]*)</td>', panel.controls_html.value)
    return float(cells[index].split("/")[0])


# -- the widget show() returns: panel + the web app's view on its own server ----------------------------------
def _get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=10) as r:
        return r.read()


@pytest.fixture
def shown():
    session = Session("car", device="cpu")
    widget = show(session)
    yield widget
    widget.close()
    session.close()


def test_show_serves_the_web_app_of_the_same_session(shown):
    assert isinstance(shown, SomWidget) and shown.children[0] is shown.panel
    assert shown.url.startswith("http://127.0.0.1:") and shown.url.endswith("?ui=notebook_view")
    assert f'src="{shown.url}"' in shown.view.value  # the iframe beside the panel
    assert b"<html" in _get(shown.url).lower()
    state = json.loads(_get(shown.server.base_url + "api/state"))  # a route of app.py: the same app
    assert state["session"]["preset"] == "car"
    again = show(shown.session)  # a second view of the session reuses its server
    assert again.server is shown.server
    again.close(stop_server=False)
    port = shown.server.port
    shown.server.stop()
    with pytest.raises(OSError):
        _get(f"http://127.0.0.1:{port}/api/state")


def test_show_makes_a_session_from_a_preset_name():
    widget = show("torus", device="cpu", view=False)
    try:
        assert widget.session.preset.name == "torus" and widget.server is None and widget.owns_session
    finally:
        widget.close()
    assert widget.session.closed


@pytest.mark.skipif(not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} is missing (apt-get install chromium)")
def test_drag_in_the_view_updates_the_panel(shown):
    """Interaction: the mouse drags the nose control in the widget's iframe; the panel's iteration and gap follow."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
    session, panel = shown.session, shown.panel
    assert session.wait_idle(30)
    session.pause()  # so that the restarted iteration stays visible
    wait_for(lambda: "(paused)" in panel.status.value, what="the paused panel")
    assert panel.progress.value == 1000
    before = session.controls[2].copy()
    gap_before = _gap_of(panel, 2)
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1000, "height": 700})
            page.set_content(f"<html><body style='margin:0'>{shown.view.value}</body></html>")  # the cell's iframe
            image = page.frame_locator("iframe").locator("img").first
            image.wait_for(state="visible", timeout=30000)
            state = wait_for(lambda: _view_state(shown, image), timeout=30, what="the view to settle at its size")
            box = image.bounding_box()
            (w, h), (sx, sy) = state["window_size"], state["widget_screen"][2]
            x0, y0 = box["x"] + sx * box["width"] / w, box["y"] + sy * box["height"] / h
            page.mouse.move(x0, y0)
            page.mouse.down()
            for i in range(1, 11):  # 80 px to the right, in steps, as a hand would
                page.mouse.move(x0 + 8 * i, y0)
                time.sleep(0.05)
            page.mouse.up()
            wait_for(lambda: not np.allclose(session.controls[2], before), what="the session to get the drag")
            time.sleep(0.3)  # the release's last move
        finally:
            browser.close()
    assert session.controls[2][0] > before[0] + 0.1  # dragged to the right: towards +x (the nose), in this view
    position = ", ".join(f"{x:.2f}" for x in session.controls[2][:3])
    wait_for(lambda: position in panel.controls_html.value and "iteration 0 / 1000 (paused)" in panel.status.value,
             what="the panel to show the dragged control and the restarted schedule")
    assert panel.progress.value == 0
    assert _gap_of(panel, 2) > gap_before  # the clay has not followed (paused) ...
    panel.train_button.click()  # ... until Train
    wait_for(lambda: "converged" in panel.status.value and _gap_of(panel, 2) < 0.05, timeout=30,
             what="training to close the gap")


def _view_state(widget: SomWidget, image):
    """The view's state once its render window has the image's size (the remote view resizes it on load)."""
    view = json.loads(_get(widget.server.base_url + "api/state"))["view"]
    box = image.bounding_box()
    if box is None or not view["widget_screen"]:
        return None
    w, h = view["window_size"]
    return view if abs(w - box["width"]) <= 2 and abs(h - box["height"]) <= 2 else None
