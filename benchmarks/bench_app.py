"""Measure the web app as a person sees it: frames drawn by the browser's clay view, and mouse move -> changed mesh.

Starts `python -m somwidget.cli serve` on a free loopback port for each preset and drives Debian's Chromium with
Playwright (no `playwright install`). For each preset it reports:

  training  frames applied to the page's scene per second while the map trains a long run (S set to 1,000,000 in
            the panel's field, as a person would; 50,000 for a wave, whose table has 511 rates a cycle), next to
            the session's own frames/s and the changed meshes the page drew per second
  drag      frames applied per second while the mouse drags a control round a circle (a real Playwright press,
            then pointer moves at 60 a second dispatched in the page), and changed meshes drawn per second
  latency   from a mouse move of a held control (the view sends it; page clock) to the first paint of a frame that
            shows the control there with a changed mesh: median and 90th percentile over every move of the drag
            (and, apart, to that frame's arrival)

Usage:
    python benchmarks/bench_app.py [--presets car,space-grid] [--waves 256] [--seconds 5] [--device cpu]
                                   [--viewport 1200x800] [--json results.json]

car has 602 nodes (case study 2), space-grid 4096 (case study 1); --waves 256 adds an uploaded mesh, a 256 x 256
wave sheet (65,536 vertices: the views draw its decimated display mesh), served with `--mesh`. The figures depend
on the CPU (the page draws with a software rasteriser when there is no GPU, on the same cores that train) and on the
view's pixel count.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
VIEW = "document.getElementById('clay-view')?.somview"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wave(side: int, folder: str) -> str:
    """A side x side wave sheet written as a binary PLY in `folder` (what a person uploads)."""
    import trimesh

    xs = np.linspace(-1.0, 1.0, side)
    x, y = np.meshgrid(xs, xs, indexing="xy")
    pts = np.stack([x.ravel(), y.ravel(), 0.2 * np.sin(3 * x.ravel()) * np.cos(2 * y.ravel())], 1)
    v = np.arange(side * side).reshape(side, side)
    quads = np.stack([v[:-1, :-1], v[:-1, 1:], v[1:, 1:], v[1:, :-1]], -1).reshape(-1, 4)
    path = str(Path(folder) / f"wave-{side}.ply")
    trimesh.Trimesh(pts, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]), process=False).export(path)
    return path


class Server:
    def __init__(self, preset: str, device: str):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}/"
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        self.data = tempfile.TemporaryDirectory(prefix="bench-app-")
        env["SOMWIDGET_DATA_DIR"] = self.data.name
        self.log = open(Path(self.data.name) / "serve.log", "w")
        start = ["--mesh", preset] if Path(preset).suffix else ["--preset", preset]
        self.proc = subprocess.Popen([sys.executable, "-m", "somwidget.cli", "serve", "--port", str(self.port),
                                      *start, "--device", device, "--fresh"], cwd=ROOT, env=env,
                                     stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 120
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"somwidget serve exited ({self.proc.returncode}); see {self.log.name}")
            try:
                self.state()
                return
            except OSError:
                if time.monotonic() > deadline:
                    raise RuntimeError("somwidget serve did not come up") from None
                time.sleep(0.25)

    def state(self) -> dict:
        with urllib.request.urlopen(self.url + "api/state", timeout=10) as r:
            return json.loads(r.read())

    def idle(self, timeout: float = 60.0) -> dict:
        deadline = time.monotonic() + timeout
        while True:
            st = self.state()
            f = st["session"]["frame"]
            if not f["running"] and st["session"]["pending_intents"] == 0:
                return st
            if time.monotonic() > deadline:
                raise RuntimeError("the session did not go idle")
            time.sleep(0.05)

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.log.close()
        self.data.cleanup()


def view(page) -> dict:
    return page.evaluate(f"{VIEW}.describe()")


def open_page(browser, url: str, viewport):
    page = browser.new_page(viewport=viewport)
    page.goto(url)
    page.wait_for_function(f"() => {{ const v = {VIEW}; return v && v.describe().frames > 0; }}", timeout=60000)
    return page


def pick_control(page, margin: float = 110.0) -> int:
    """An original control well inside the view, clear of the others and not hidden by the clay (a press there
    would not grab it)."""
    box = page.locator("#clay-view").bounding_box()
    time.sleep(0.35)  # the view has looked again which controls the clay hides
    state = view(page)
    behind = set(state.get("behind", []))
    spots = [page.evaluate(f"{VIEW}.controlScreen({j})") for j in range(state["kEff"])]
    best, best_score = 0, -1.0
    for i in range(state["k"]):
        if i in behind:
            continue
        x, y = spots[i]
        inside = box["x"] + margin < x < box["x"] + box["width"] - margin and \
            box["y"] + margin < y < box["y"] + box["height"] - margin
        clear = min([np.hypot(x - u, y - v) for j, (u, v) in enumerate(spots) if j != i] or [1e9])
        if inside and clear > best_score:
            best, best_score = i, clear
    return best


def set_iterations(page, value: int) -> None:
    field = page.locator("#field-iterations")
    field.fill(str(value))
    field.press("Enter")


def measure_training(page, server: Server, seconds: float, iterations: int) -> dict:
    set_iterations(page, iterations)
    time.sleep(1.0)
    v0, t0, s0 = view(page), time.monotonic(), server.state()["session"]["frame"]
    time.sleep(seconds)
    v1, t1, s1 = view(page), time.monotonic(), server.state()["session"]["frame"]
    page.locator("#train-button").click()  # pause
    time.sleep(0.3)
    set_iterations(page, 1000)
    page.locator("#train-button").click()  # train again: the run goes on to the new S
    server.idle()
    return {"frames_per_s": (v1["frames"] - v0["frames"]) / (t1 - t0),
            "drawn_per_s": (v1["painted"] - v0["painted"]) / (t1 - t0),
            "session_frames_per_s": (s1["seq"] - s0["seq"]) / (t1 - t0), "cycle_ms": s1["cycle_time"] * 1e3}


DRAG_JS = """
([x0, y0, ms]) => new Promise((done) => {
  const canvas = document.querySelector('#clay-view canvas');
  const t0 = performance.now();
  let n = 0;
  const timer = setInterval(() => {
    const a = (performance.now() - t0) / 500.0;
    canvas.dispatchEvent(new PointerEvent('pointermove', { clientX: x0 + 40 * Math.sin(a),
      clientY: y0 - 40 + 40 * Math.cos(a), pointerId: 1, pointerType: 'mouse', buttons: 1, bubbles: true }));
    n += 1;
    if (performance.now() - t0 >= ms) { clearInterval(timer); done(n); }
  }, 1000 / 60);
})
"""


def measure_drag(page, server: Server, seconds: float) -> dict:
    server.idle()
    i = pick_control(page)
    x0, y0 = page.evaluate(f"{VIEW}.controlScreen({i})")
    page.evaluate(f"() => {{ const v = {VIEW}; v.grabs.latencyLog.length = 0; v.grabs.latencies.length = 0; }}")
    page.mouse.move(x0, y0)
    page.mouse.down()  # a real press grabs the control
    v0, t0 = view(page), time.monotonic()
    # the drag's pointer moves at 60 events/s, as a mouse reports (Playwright's driver manages about 20/s on two
    # loaded cores): the page dispatches them to the view's canvas from its own timer
    moves = page.evaluate(DRAG_JS, [x0, y0, seconds * 1000.0])
    v1, t1 = view(page), time.monotonic()
    page.mouse.up()
    time.sleep(0.5)
    paint = np.array(page.evaluate(f"{VIEW}.moveToPaint()"))
    arrive = np.array(view(page)["latencies"])
    server.idle()
    out = {"frames_per_s": (v1["frames"] - v0["frames"]) / (t1 - t0),
           "drawn_per_s": (v1["painted"] - v0["painted"]) / (t1 - t0), "mouse_moves_per_s": moves / (t1 - t0),
           "control": i,
           "answered_moves": int(len(paint))}
    for name, a in (("paint", paint), ("arrive", arrive)):
        out[f"{name}_median_ms"] = float(np.median(a)) if len(a) else None
        out[f"{name}_p90_ms"] = float(np.percentile(a, 90)) if len(a) else None
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--presets", default="car,space-grid")
    ap.add_argument("--waves", default="", help="sides of wave sheets to upload, e.g. 256 (65,536 vertices)")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--viewport", default="1200x800")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    w, h = (int(v) for v in args.viewport.split("x"))
    results = {"machine": f"{platform.node()} ({os.cpu_count()} cores)", "date": time.strftime("%Y-%m-%d"),
               "viewport": args.viewport, "device": args.device, "presets": {}}
    meshes = tempfile.TemporaryDirectory(prefix="bench-app-meshes-")
    runs = [p for p in args.presets.split(",") if p] + [wave(int(n), meshes.name) for n in args.waves.split(",") if n]
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            for preset in runs:
                server = Server(preset, args.device)
                try:
                    page = open_page(browser, server.url, {"width": w, "height": h})
                    server.idle()
                    long_run = 1_000_000 if preset in args.presets.split(",") else 50_000  # a wave's table:
                    r = {"training": measure_training(page, server, args.seconds, long_run),  # 511 rates a cycle
                         "drag": measure_drag(page, server, args.seconds)}
                    page.close()
                finally:
                    server.stop()
                preset = Path(preset).stem
                results["presets"][preset] = r
                t, d = r["training"], r["drag"]
                print(f"{preset}: training {t['frames_per_s']:.1f} frames/s in the page (session "
                      f"{t['session_frames_per_s']:.1f}, drawn {t['drawn_per_s']:.1f}); drag {d['frames_per_s']:.1f} "
                      f"frames/s (drawn {d['drawn_per_s']:.1f}, pointer moves {d['mouse_moves_per_s']:.1f}); "
                      f"move -> changed mesh painted {d['paint_median_ms']:.0f} ms median, "
                      f"{d['paint_p90_ms']:.0f} ms p90 (arrived "
                      f"{d['arrive_median_ms']:.0f} / {d['arrive_p90_ms']:.0f}) over {d['answered_moves']} moves",
                      flush=True)
        finally:
            browser.close()
            meshes.cleanup()
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
