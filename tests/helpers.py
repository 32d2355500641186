"""Helpers shared by the server and browser tests: Chromium's flags, polling, and `somwidget serve` in a subprocess.

`Serve(*args)` runs `python -m somwidget.cli serve --port 0 --device cpu *args` and reads the port the server picked
from the line it prints once it listens (`somwidget serving ... at http://127.0.0.1:PORT/`, or with --lan
`desktop: https://HOST:PORT/?token=...`), so no port is guessed and raced for.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import ssl
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
#: What `somwidget serve` prints once it listens: loopback (first) or --lan (the desktop URL).
ANNOUNCED = re.compile(r"somwidget serving .* at (http)://(\S+?):(\d+)/|desktop: (https)://(\S+?):(\d+)/")


def skip_unless_browser_and_client() -> None:
    """Skip the calling test file (at its top) unless Playwright, Debian's Chromium and the built client are here."""
    import pytest

    from somwidget.frontend.client import DIST

    pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
    if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
        pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)
    if not all((DIST / page).is_file() for page in ("index.html", "emulator.html")):  # pragma: no cover
        pytest.skip("the client is not built (npm ci && npm run build in somwidget/frontend/client)",
                    allow_module_level=True)


def wave_mesh(path: Path, side: int) -> Path:
    """A side x side wave sheet (triangles) written to `path` (binary PLY: a big mesh uploads in a few MB); 513 makes
    263,169 vertices, just past a CPU session's 262,144."""
    import numpy as np
    import trimesh

    xs = np.linspace(-1.0, 1.0, side)
    x, y = np.meshgrid(xs, xs, indexing="xy")
    pts = np.stack([x.ravel(), y.ravel(), 0.2 * np.sin(3 * x.ravel())], 1)
    v = np.arange(side * side).reshape(side, side)
    quads = np.stack([v[:-1, :-1], v[:-1, 1:], v[1:, 1:], v[1:, :-1]], -1).reshape(-1, 4)
    trimesh.Trimesh(pts, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]), process=False).export(path)
    return path


def read_3dm(path) -> dict:
    """What rhino3dm reads back from a .3dm: {"units": the unit system's name, "layers": [names], "clay": the mesh as a
    trimesh.Trimesh (vertices, faces, vertex colours) or a trimesh.PointCloud, "controls": {name: ((3,) position,
    layer name, radius text)} of the points}."""
    import numpy as np
    import rhino3dm
    import trimesh

    model = rhino3dm.File3dm.Read(str(path))
    assert model is not None, f"rhino3dm cannot read {path}"
    layers = [layer.Name for layer in model.Layers]
    out = {"units": str(model.Settings.ModelUnitSystem).split(".")[-1], "layers": layers, "clay": None,
           "controls": {}}
    for obj in model.Objects:
        g, attrs = obj.Geometry, obj.Attributes
        if isinstance(g, rhino3dm.Point):
            p = g.Location
            out["controls"][attrs.Name] = (np.array([p.X, p.Y, p.Z]), layers[attrs.LayerIndex],
                                           attrs.GetUserString("radius"))
        elif isinstance(g, rhino3dm.Mesh):
            assert attrs.Name == "clay" and layers[attrs.LayerIndex] == "clay"
            v = np.array([[p.X, p.Y, p.Z] for p in g.Vertices.ToPoint3dArray()])
            faces = [g.Faces[i] for i in range(g.Faces.Count)]
            assert all(f[2] == f[3] for f in faces)  # triangles (a quad would have its own fourth corner)
            colours = np.array([g.VertexColors[i] for i in range(len(g.VertexColors))])
            out["clay"] = trimesh.Trimesh(v, np.array([f[:3] for f in faces]), vertex_colors=colours, process=False)
        elif isinstance(g, rhino3dm.PointCloud):
            out["clay"] = trimesh.PointCloud(np.array([[p.X, p.Y, p.Z] for p in g.GetPoints()]))
    return out


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def proc_status_mb(pid: int, field: str) -> float:
    """A memory figure of a process from /proc/PID/status in MB: "VmRSS" (now) or "VmHWM" (its peak)."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(f"{field}:"):
                return int(line.split()[1]) / 1024
    raise AssertionError(f"no {field} for process {pid}")


def wslink_chunk(mid: int, payload: bytes = b"", total: int | None = None, offset: int = 0) -> bytes:
    """One chunk of a wslink websocket message: a 12-byte header (id, offset, total size) and the content."""
    total = len(payload) if total is None else total
    return mid.to_bytes(4, "little") + offset.to_bytes(4, "little") + total.to_bytes(4, "little") + payload


def sync_playwright():
    from playwright.sync_api import sync_playwright as start

    return start()


def wheel_ten_ticks_closer(page, view: str, at) -> None:
    """Ten wheel ticks (towards the screen) at page point `at`, over the clay of `view` (a JS expression of a clay
    view): the camera comes closer at each tick, past 45% of the Fit distance in all."""
    assert page.evaluate(f"() => {view}.surfaceAt({at[0]}, {at[1]})") is not None, "not over the clay"
    d0 = page.evaluate(f"() => {view}.describe()")
    page.mouse.move(*at)
    distances = []
    for _ in range(10):
        page.mouse.wheel(0, -100)
        page.wait_for_timeout(60)
        distances.append(page.evaluate(f"() => {view}.describe().distance"))
    assert all(b < a for a, b in zip([d0["distance"], *distances], distances)), distances
    assert distances[-1] < 0.45 * d0["fitDistance"], distances


def wait_for(predicate, timeout: float = 20.0, what: str = "condition", interval: float = 0.05):
    """Poll `predicate` until it returns something true (returned) or `timeout` seconds pass (AssertionError)."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


def settled_session(preset: str, timeout: float = 120.0):
    """A CPU Session of `preset` (no autosave) once it has settled, closed after: a fixture's body,
    `yield from settled_session("car")`."""
    from somwidget.frontend.model import Session

    s = Session(preset, device="cpu", autosave=False)
    assert s.wait_idle(timeout), f"the {preset} session did not settle within {timeout:g} s"
    yield s
    s.close()


def answers(url: str, any_status: bool = False) -> bool:
    """The server at `url` answers with a success status (with `any_status`, with any HTTP status: it listens)."""
    try:
        with urllib.request.urlopen(url, timeout=5):
            return True
    except urllib.error.HTTPError:
        return any_status
    except OSError:
        return False


def stop(proc: subprocess.Popen, wait: float = 20.0) -> None:
    """Terminate a server process, killed if it has not ended within `wait` seconds."""
    proc.terminate()
    try:
        proc.wait(wait)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)


@contextlib.contextmanager
def server_process(argv: list[str], log_path: Path, ready_url: str, what: str, *, cwd=None, env: dict | None = None,
                   timeout: float = 90.0, any_status: bool = False):
    """Run the server `argv` (its output into `log_path`) until it answers at `ready_url` (`answers`); yields the
    process, stopped (`stop`) after the block. A server that exits before it answers fails with its log's end."""
    with open(log_path, "w") as log:
        proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=log, stderr=subprocess.STDOUT)
        try:
            wait_for(lambda: proc.poll() is not None or answers(ready_url, any_status), timeout=timeout,
                     what=f"{what} to start")
            assert proc.poll() is None, f"{what} exited with {proc.returncode}: {Path(log_path).read_text()[-3000:]}"
            yield proc
        finally:
            stop(proc)


def insecure_context() -> ssl.SSLContext:
    """A client TLS context that accepts the server's self-signed certificate (tests compare fingerprints)."""
    ctx = ssl.create_default_context()
    ctx.check_hostname = False
    ctx.verify_mode = ssl.CERT_NONE
    return ctx


def request(url: str, headers: dict | None = None, timeout: float = 20.0) -> tuple[int, bytes]:
    """GET `url` (any certificate accepted): (status, body), also for error statuses."""
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=timeout, context=insecure_context()) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


class Serve:
    """`python -m somwidget.cli serve --port 0 --device cpu *args`, on the port it announces.

    `base` is scheme://127.0.0.1:port (no trailing slash), `url` the same with "/"; `state()` reads the read-only
    debug route GET /api/state. Each server has a data directory of its own (`data_dir`: autosaves, certificates),
    so that no server recovers another one's session, unless `env` names one."""

    def __init__(self, *args: str, env: dict | None = None, timeout: float = 120.0):
        full_env = dict(os.environ)
        self.data_dir = Path(tempfile.mkdtemp(prefix="somwidget-serve-data-"))
        full_env["SOMWIDGET_DATA_DIR"] = str(self.data_dir)
        full_env["PYTHONPATH"] = os.pathsep.join([str(ROOT), full_env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        full_env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
        full_env.update(env or {})
        self.data_dir = Path(full_env["SOMWIDGET_DATA_DIR"])
        self.log_path = Path(tempfile.mkdtemp(prefix="somwidget-serve-")) / "serve.log"
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen([sys.executable, "-m", "somwidget.cli", "serve", "--port", "0", "--device", "cpu",
                                      *args], cwd=ROOT, env=full_env, stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + timeout
        while True:
            m = ANNOUNCED.search(self.output())
            if m:
                break
            if self.proc.poll() is not None:
                self.log.close()
                raise RuntimeError(f"somwidget serve exited with {self.proc.returncode}:\n{self.output()[-3000:]}")
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"somwidget serve did not come up within {timeout:g} s:\n{self.output()[-3000:]}")
            time.sleep(0.2)
        scheme, _host, port = (m.group(1), m.group(2), m.group(3)) if m.group(1) else (m.group(4), m.group(5),
                                                                                         m.group(6))
        self.scheme, self.port = scheme, int(port)
        self.base = f"{scheme}://127.0.0.1:{self.port}"
        self.url = self.base + "/"

    def output(self) -> str:
        if not self.log.closed:
            self.log.flush()
        return self.log_path.read_text(errors="replace")

    def get(self, path: str, token: str | None = None, headers: dict | None = None) -> tuple[int, bytes]:
        url = self.base + path + (("&" if "?" in path else "?") + f"token={token}" if token else "")
        return request(url, headers)

    def state(self, positions: bool = False, token: str | None = None) -> dict:
        status, body = self.get("/api/state" + ("?positions=1" if positions else ""), token)
        assert status == 200, (status, body[:200])
        return json.loads(body)

    def wait(self, predicate, timeout: float = 20.0, what: str = "condition") -> dict:
        """Poll the state (with positions) until `predicate(state)` holds; returns that state."""
        deadline = time.monotonic() + timeout
        while True:
            st = self.state(positions=True)
            if predicate(st):
                return st
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out waiting for {what}; last state: {json.dumps(st)[:800]}")
            time.sleep(0.1)

    def idle(self, timeout: float = 30.0) -> dict:
        """Wait until training has stopped and every intent is in a published frame."""
        def done(st):
            f = st["session"]["frame"]
            return not f["running"] and st["session"]["pending_intents"] == 0
        return self.wait(done, timeout, "the session to go idle")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        if not self.log.closed:
            self.log.close()
