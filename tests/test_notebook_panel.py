"""The Jupyter panel (somwidget.frontend.notebook) bound both ways to a real Session, and the view beside it.

ipywidgets objects work in plain Python, so most tests need no Jupyter frontend: they set a widget's value (as the
frontend does when a person moves a slider) and check the session followed, or send an intent to the session and
check the widgets after the next frame. Those tests show the protocol. `test_drag_in_the_view_updates_the_panel`
shows the interaction: Chromium (Playwright) loads the widget's iframe, the mouse drags a control in the view, and
the panel's iteration and gap follow. The sessions train the real Som on the CPU.
"""

from __future__ import annotations

import asyncio
import functools
import json
import os
import re
import subprocess
import sys
import time
import urllib.request

import aiohttp
import helpers
import numpy as np
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

pytest.importorskip("ipywidgets")

from somwidget.frontend.notebook import NotebookServer, Panel, SomWidget, show  # noqa: E402
from somwidget.frontend.session import Session  # noqa: E402

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
    assert session.wait_applied(30) and session._som.reach == 0.12
    panel.undo_button.click()  # the reach, then the reload, go back
    assert session.parameters["reach"] == session.preset.reach


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
    # a local restart: s0 = floor((1 - reach) S) = 460
    wait_for(lambda: panel.progress.value == 460 and "iteration 460 / 500 (paused)" in panel.status.value,
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


def test_show_refuses_a_host_beyond_loopback(session):
    """The notebook's server has no token and no TLS: a host other machines could reach is refused, pointing to
    `somwidget serve --lan`; an empty host is an error too (not "every interface" by accident)."""
    for host in ("0.0.0.0", "::", "192.168.1.20", "my-laptop.local"):
        with pytest.raises(ValueError, match="somwidget serve --lan"):
            show(session, host=host)
        with pytest.raises(ValueError, match="somwidget serve --lan"):
            NotebookServer(session, host=host)
    with pytest.raises(ValueError, match="empty host"):
        show(session, host="")
    assert not session.closed


def test_view_server_refuses_other_sites_and_host_names(shown):
    """The view's server answers only loopback Host names and refuses websockets from pages of other sites; its own
    pages (the iframe's, see the drag test) get in."""
    port = shown.server.port
    status, _ = helpers.request(shown.server.base_url + "api/state", headers={"Host": f"evil.example:{port}"})
    assert status == 403
    assert helpers.request(shown.server.base_url + "api/state", headers={"Host": f"localhost:{port}"})[0] == 200

    async def main():
        async with aiohttp.ClientSession() as cs:
            for path in ("/ws", "/xr/ws"):
                with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                    await cs.ws_connect(f"ws://127.0.0.1:{port}{path}", headers={"Origin": "http://evil.example"})
                assert info.value.status == 403, path
            async with cs.ws_connect(f"ws://127.0.0.1:{port}/xr/ws",
                                     headers={"Origin": f"http://127.0.0.1:{port}"}) as ws:
                assert json.loads((await ws.receive(timeout=20)).data)["type"] == "topology"

    asyncio.run(main())


def test_view_server_behind_a_proxy_keeps_the_origin_check(session, monkeypatch):
    """Behind jupyter-server-proxy (SOMWIDGET_JUPYTER_URL) the browser's Host is the Jupyter server's: any Host is
    answered, but a websocket still needs Origin == Host."""
    monkeypatch.setenv("SOMWIDGET_JUPYTER_URL", "/proxy/{port}/")
    widget = show(session)
    try:
        assert widget.url.startswith("/proxy/")
        port = widget.server.port
        hub = {"Host": "hub.example.org"}
        assert helpers.request(f"http://127.0.0.1:{port}/api/state", headers=hub)[0] == 200

        async def main():
            async with aiohttp.ClientSession() as cs:
                with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                    await cs.ws_connect(f"ws://127.0.0.1:{port}/ws",
                                        headers={**hub, "Origin": "https://evil.example"})
                assert info.value.status == 403
                async with cs.ws_connect(f"ws://127.0.0.1:{port}/xr/ws",
                                         headers={**hub, "Origin": "https://hub.example.org"}) as ws:
                    assert json.loads((await ws.receive(timeout=20)).data)["type"] == "topology"

        asyncio.run(main())
    finally:
        widget.close()


def test_stopping_the_view_detaches_its_app_and_xr_hub(shown):
    """After the view's server stops, neither its app nor its XR hub hears the session any more, and the frame pump
    is cancelled."""
    session, app = shown.session, shown.server.app
    hub = app.xr
    assert hub is not None and app._pump_task is not None
    assert session.wait_idle(30)
    seq = hub._latest.seq if hub._latest is not None else -1
    session.move_control(2, session.controls[2, :3] + np.float32([0.0, 0.0, 0.05]))
    wait_for(lambda: hub._latest is not None and hub._latest.seq > seq, timeout=30,
             what="the hub to get frames while the server runs")
    shown.server.stop()
    assert app._pump_task is None
    before_hub, before_app = hub._latest, app._latest
    session.move_control(2, session.controls[2, :3] - np.float32([0.0, 0.0, 0.05]))
    assert session.wait_idle(30)
    time.sleep(0.2)
    assert hub._latest is before_hub and app._latest is before_app


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
    wait_for(lambda: position in panel.controls_html.value and "iteration 920 / 1000 (paused)" in panel.status.value,
             what="the panel to show the dragged control and the locally restarted schedule")
    assert panel.progress.value == 920
    gap_dragged = _gap_of(panel, 2)
    assert gap_dragged > gap_before  # the clay has not followed (paused) ...
    panel.train_button.click()  # ... until Train: the local restart closes most of the gap
    wait_for(lambda: "converged" in panel.status.value and _gap_of(panel, 2) < 0.3 * gap_dragged, timeout=30,
             what="training to close the gap")


def _view_state(widget: SomWidget, image):
    """The view's state once its render window has the image's size (the remote view resizes it on load)."""
    view = json.loads(_get(widget.server.base_url + "api/state"))["view"]
    box = image.bounding_box()
    if box is None or not view["widget_screen"]:
        return None
    w, h = view["window_size"]
    return view if abs(w - box["width"]) <= 2 and abs(h - box["height"]) <= 2 else None
