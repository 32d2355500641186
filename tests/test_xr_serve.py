"""The WebXR page through the real command: `somwidget serve` (a subprocess) serves /xr/ and /xr/ws next to the
trame app, on the same Session; `somwidget serve --lan` serves everything over HTTPS behind an access token.

The headset is Chromium on an emulated Quest 3 (iwer, /xr/emulator.html); Playwright moves its controller and pulls
its trigger. The desktop app's side is read through its read-only debug route GET /api/state.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import socket
import ssl
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

import aiohttp
import numpy as np
import pytest

from somwidget.frontend.xr import protocol
from somwidget.frontend.xr.server import DIST

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = "/usr/bin/chromium"
NOT_WIRED = ("`somwidget serve` does not serve /xr/: app.py must call somwidget.frontend.xr.attach(wslink_server, "
             "session, token=...) from ctrl.on_server_bind (see the XR helper's report)")


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _insecure() -> ssl.SSLContext:
    ctx = ssl.create_default_context()
    ctx.check_hostname = False
    ctx.verify_mode = ssl.CERT_NONE
    return ctx


class Serve:
    """`python -m somwidget.cli serve ...` on a free loopback port."""

    def __init__(self, *args: str, env: dict | None = None, scheme: str = "http"):
        self.port = _free_port()
        self.base = f"{scheme}://127.0.0.1:{self.port}"
        full_env = dict(os.environ)
        full_env["PYTHONPATH"] = os.pathsep.join([str(ROOT), full_env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        full_env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
        full_env.update(env or {})
        self.log_path = Path(tempfile.mkdtemp(prefix="somwidget-xr-serve-")) / "serve.log"
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen([sys.executable, "-m", "somwidget.cli", "serve", "--port", str(self.port),
                                      "--device", "cpu", *args], cwd=ROOT, env=full_env, stdout=self.log,
                                     stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 120
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"somwidget serve exited with {self.proc.returncode}:\n{self.output()[-3000:]}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=1):
                    pass
                if "somwidget" in self.output():  # the announcement: the server is ready
                    break
            except OSError:
                pass
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError("somwidget serve did not come up within 120 s")
            time.sleep(0.25)

    def output(self) -> str:
        self.log.flush()
        return self.log_path.read_text(errors="replace")

    def get(self, path: str, token: str | None = None):
        url = self.base + path + (("&" if "?" in path else "?") + f"token={token}" if token else "")
        try:
            with urllib.request.urlopen(url, timeout=20, context=_insecure()) as r:
                return r.status, r.read()
        except urllib.error.HTTPError as exc:
            return exc.code, exc.read()

    def state(self, token: str | None = None) -> dict:
        status, body = self.get("/api/state", token)
        assert status == 200, (status, body[:200])
        return json.loads(body)

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.log.close()


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
        pytest.skip("the WebXR client is not built (npm run build in somwidget/frontend/xr)")
    assert status == 200 and b"somwidget" in body

    async def main():
        async with aiohttp.ClientSession() as cs:
            async with cs.ws_connect(serve.base + "/xr/ws") as ws:
                topo = json.loads((await ws.receive(timeout=20)).data)
                frame = protocol.decode_frame((await ws.receive(timeout=20)).data)
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
        browser = p.chromium.launch(executable_path=CHROMIUM, args=xb.CHROMIUM_ARGS, headless=True)
        try:
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
        finally:
            browser.close()
    deadline = time.monotonic() + 30
    while True:
        st = serve.state()
        controls = np.array(st["session"]["controls"])
        widget = np.array(st["view"]["widget_centres"][index])
        if np.allclose(controls[index, :3], expected, atol=2e-3) and np.allclose(widget, expected, atol=2e-3):
            break
        assert time.monotonic() < deadline, (controls[index], widget, expected)
        time.sleep(0.3)
    assert np.linalg.norm(controls[index, :3] - start[index, :3]) > 0.3
    np.testing.assert_allclose(np.delete(controls, index, axis=0), np.delete(start, index, axis=0))


def test_serve_lan_https_token(tmp_path):
    """`serve --lan`: HTTPS with the certificate made in the data dir, the token printed in the URL with a QR code,
    403 for every page and socket without it."""
    s = Serve("--lan", "--host", "127.0.0.1", env={"SOMWIDGET_DATA_DIR": str(tmp_path)}, scheme="https")
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
            async with aiohttp.ClientSession(connector=aiohttp.TCPConnector(ssl=_insecure())) as cs:
                for path in ("/xr/ws", "/ws"):
                    with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                        await cs.ws_connect(wss + path)
                    assert info.value.status == 403
                async with cs.ws_connect(wss + "/xr/ws", params={"token": token}) as ws:
                    topo = json.loads((await ws.receive(timeout=20)).data)
                    frame = protocol.decode_frame((await ws.receive(timeout=20)).data)
                return topo, frame

        topo, frame = asyncio.run(main())
        assert topo["type"] == "topology" and frame["n"] == topo["n_vertices"]
    finally:
        s.stop()
