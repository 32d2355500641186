"""The WebXR page through the real command: `somwidget serve` (a subprocess) serves /xr/ and /view/ws next to the
trame app, on the same Session; `somwidget serve --lan` serves everything over HTTPS behind an access token.

The headset is Chromium on an emulated Quest 3 (iwer, /xr/emulator.html); Playwright moves its controller and pulls
its trigger. The desktop app's side is read through its read-only debug route GET /api/state.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import time

import aiohttp
import numpy as np
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS, Serve, insecure_context

from somwidget.frontend.client import DIST
from somwidget.frontend.transport import frames as wire_frames

pytestmark = pytest.mark.browser

NOT_WIRED = ("`somwidget serve` does not serve /xr/: app.py must call somwidget.frontend.web.hub.attach(wslink_server, "
             "session, token=...) from ctrl.on_server_bind (see the XR helper's report)")

async def next_binary(ws) -> bytes:
    """The next frame on the socket (replies such as "grabs" go out before frames)."""
    import aiohttp

    while True:
        msg = await ws.receive(timeout=20)
        if msg.type == aiohttp.WSMsgType.BINARY:
            return msg.data


@pytest.fixture(scope="module")
def serve():
    s = Serve()
    yield s
    s.stop()


def test_serve_has_the_xr_page_and_socket(serve):
    status, body = serve.get("/xr/")
    assert status != 404, NOT_WIRED
    if not DIST.is_dir():
        assert status == 503 and b"npm" in body  # not built: says how to build it
        pytest.skip("the WebXR client is not built (npm run build in somwidget/frontend/client)")
    assert status == 200 and b"somwidget" in body

    async def main():
        async with aiohttp.ClientSession() as cs:
            async with cs.ws_connect(serve.base + "/view/ws") as ws:
                topo = json.loads((await ws.receive(timeout=20)).data)
                frame = wire_frames.decode_frame(await next_binary(ws))
        return topo, frame

    topo, frame = asyncio.run(main())
    st = serve.state()["session"]
    assert topo["preset"] == st["preset"] and topo["n_nodes"] == st["n_vertices"] == frame["n"]
    np.testing.assert_allclose(frame["control_positions"][:frame["k"]], np.array(st["controls"])[:, :3], atol=1e-5)


@pytest.mark.skipif(not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} is missing")
def test_headset_grab_moves_the_desktop_apps_control(serve):
    """A controller grab on the emulated headset moves the control in the desktop app's session and view."""
    playwright_sync = pytest.importorskip("playwright.sync_api")
    if serve.get("/xr/")[0] == 404:
        pytest.fail(NOT_WIRED)
    if not (DIST / "emulator.html").is_file():
        pytest.skip("the WebXR client is not built")
    import test_xr_browser as xb  # the gesture helpers (tests/ is on sys.path: conftest.py)

    start = np.array(serve.state()["session"]["controls"])
    index = 5
    with playwright_sync.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            desk = browser.new_page()  # the desktop app in another tab
            desk.goto(serve.url)
            view = "document.getElementById('clay-view')?.somview"
            desk.wait_for_function(f"() => {{ const v = {view}; return v && v.describe().frames > 0; }}",
                                   timeout=30000)
            page = xb.open_page(browser, serve.base + "/xr/emulator.html")
            xb.enter_ar(page)
            dev = "iwerDevice.controllers.right"
            target = np.array(page.evaluate(f"somxr.controlWorld({index})"))
            xb.bring_to(page, dev, False, target)
            page.evaluate(f"{dev}.updateButtonValue('trigger', 1)")
            page.wait_for_function(f"somxr.state().held.includes({index})", timeout=10000)
            delta = np.array([0.03, 0.04, 0.05])
            xb.glide(page, dev, delta)
            expected = np.array(page.evaluate("(p) => somxr.worldToModel(p)", [float(v) for v in target + delta]))
            page.evaluate(f"{dev}.updateButtonValue('trigger', 0)")
            page.wait_for_function("somxr.state().held.length === 0", timeout=10000)
            assert not page.errors, page.errors
            deadline = time.monotonic() + 30
            while True:  # the session and the desktop tab's view both have the control where the hand left it
                st = serve.state()
                controls = np.array(st["session"]["controls"])
                shown = np.array(desk.evaluate(f"() => {view}.controlModel({index})"))
                if np.allclose(controls[index, :3], expected, atol=2e-3) and np.allclose(shown, expected, atol=2e-3):
                    break
                assert time.monotonic() < deadline, (controls[index], shown, expected)
                time.sleep(0.3)
        finally:
            browser.close()
    assert np.linalg.norm(controls[index, :3] - start[index, :3]) > 0.3
    np.testing.assert_allclose(np.delete(controls, index, axis=0), np.delete(start, index, axis=0))


def test_serve_lan_https_token(tmp_path):
    """`serve --lan`: HTTPS with the certificate made in the data dir, the token printed in the URL with a QR code,
    403 for every page and socket without it."""
    s = Serve("--lan", "--host", "127.0.0.1", env={"SOMWIDGET_DATA_DIR": str(tmp_path)})
    try:
        out = s.output()
        urls = re.findall(r"https://127\.0\.0\.1:\d+/\S*\?token=([A-Za-z0-9_-]+)", out)
        assert urls, f"no URL with a token in the output:\n{out[-2000:]}"
        token = urls[0]
        assert "\u2588" in out  # the QR code
        assert (tmp_path / "somwidget-cert.pem").is_file()
        for path in ("/", "/index.html", "/api/state", "/xr/", "/xr/emulator.html"):
            assert s.get(path)[0] == 403, path
            assert s.get(path, token="wrong")[0] == 403, path
        assert s.get("/api/state", token)[0] == 200
        status, body = s.get("/xr/", token)
        assert status == 200 and b"somwidget" in body

        async def main():
            wss = s.base.replace("https", "wss")
            async with aiohttp.ClientSession(connector=aiohttp.TCPConnector(ssl=insecure_context())) as cs:
                for path in ("/view/ws", "/xr/ws", "/ws"):
                    with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                        await cs.ws_connect(wss + path)
                    assert info.value.status == 403
                    # the token does not let a page of another site in
                    with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                        await cs.ws_connect(wss + path, params={"token": token},
                                            headers={"Origin": "https://evil.example"})
                    assert info.value.status == 403
                async with cs.ws_connect(wss + "/view/ws", params={"token": token}) as ws:
                    topo = json.loads((await ws.receive(timeout=20)).data)
                    frame = wire_frames.decode_frame(await next_binary(ws))
                return topo, frame

        topo, frame = asyncio.run(main())
        assert topo["type"] == "topology" and frame["n"] == topo["n_vertices"]
    finally:
        s.stop()


def test_serve_refuses_other_sites_and_other_host_names(serve):
    """On loopback: a websocket opened by a page of another site (its Origin) is refused on trame's /ws and on
    /view/ws (and its old name /xr/ws), and a request whose Host is not a loopback name (DNS rebinding) is refused on
    every route; the server's own origin, and localhost / [::1] spellings of it, are served."""
    port = serve.port
    for path in ("/api/state", "/", "/index.html", "/xr/", "/xr/status"):
        status, body = serve.get(path, headers={"Host": "evil.example"})
        assert status == 403 and b"localhost" in body, path
        assert serve.get(path, headers={"Host": f"evil.example:{port}"})[0] == 403, path
    assert serve.get("/api/state", headers={"Host": f"rebind.127.0.0.1.nip.io:{port}"})[0] == 403
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}", "localhost"):
        assert serve.get("/api/state", headers={"Host": host})[0] == 200, host

    async def main():
        ws_base = serve.base.replace("http", "ws")
        async with aiohttp.ClientSession() as cs:
            for path in ("/ws", "/view/ws", "/xr/ws"):
                for origin in ("http://evil.example", f"http://evil.example:{port}", "null",
                               f"http://127.0.0.1:{port + 1}", f"https://localhost:{port}"):
                    with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                        await cs.ws_connect(ws_base + path, headers={"Origin": origin})
                    assert info.value.status == 403, (path, origin)
                with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                    await cs.ws_connect(ws_base + path, headers={"Host": "evil.example"})
                assert info.value.status == 403
            # the page's own origin (what the app's tab and the XR page send) is let in
            async with cs.ws_connect(ws_base + "/xr/ws", headers={"Origin": f"http://127.0.0.1:{port}"}) as ws:
                assert json.loads((await ws.receive(timeout=20)).data)["type"] == "topology"
            async with cs.ws_connect(ws_base + "/ws", headers={"Origin": f"http://127.0.0.1:{port}"}) as ws:
                assert not ws.closed
            async with cs.post(serve.base + "/api/state", headers={"Origin": "http://evil.example"}) as r:
                assert r.status == 403  # state-changing methods are checked too

    asyncio.run(main())
    assert serve.state()["session"]["preset"] == "car"


def test_serve_refuses_an_empty_host(capsys):
    """`--host ""` is an error (it used to mean LAN mode on this machine's LAN address, silently)."""
    from somwidget.cli import main

    assert main(["serve", "--host", "", "--device", "cpu"]) == 2
    err = capsys.readouterr().err
    assert "empty host" in err and "0.0.0.0" in err
