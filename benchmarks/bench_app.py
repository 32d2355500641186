"""Measure the web app as a person sees it: images per second reaching the browser, and drag-to-changed-mesh latency.

Starts `python -m somwidget.cli serve` on a free loopback port for each preset and drives Debian's Chromium with
Playwright (no `playwright install`). For each preset it reports:

  training  images/s reaching the page (the view's <img> getting a new image) while the map trains a long run,
            and the session's own frames/s (GET /api/state)
  drag      images/s while the mouse drags a control round a circle (a real Playwright mouse drag)
  latency   from one mouse move of a held control (page clock) to the first image in the page whose pixels
            changed away from the dragged sphere (the clay or a mirrored copy moved), median over repeats;
            the mesh is converged and idle before each move

Usage:
    python benchmarks/bench_app.py [--presets car,space-grid] [--seconds 5] [--repeats 7] [--device cpu]
                                   [--viewport 1200x800] [--json results.json]

car has 602 nodes (case study 2), space-grid 4096 (case study 1). The numbers depend on the CPU, on the view's
pixel count (the server renders with Mesa llvmpipe when there is no GPU) and on what else runs on the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import statistics
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

# Page-side instrumentation: count the view's images, and compare each new one with a reference outside a mask.
PAGE_JS = """
() => {
  const img = document.querySelector('#view-container img');
  const canvas = document.createElement('canvas');
  const ctx = canvas.getContext('2d', {willReadFrequently: true});
  const bench = window.__bench = {count: 0, times: [], ref: null, mask: null, watchFrom: null, hit: null,
                                   changed: 0};
  function pixels() {
    canvas.width = img.naturalWidth; canvas.height = img.naturalHeight;
    ctx.drawImage(img, 0, 0);
    return ctx.getImageData(0, 0, canvas.width, canvas.height);
  }
  bench.setReference = () => { bench.ref = pixels(); bench.hit = null; };
  img.addEventListener('load', () => {
    const t = performance.now();
    bench.count += 1;
    bench.times.push(t);
    if (bench.watchFrom !== null && bench.hit === null && t >= bench.watchFrom && bench.ref) {
      const now = pixels();
      if (now.width !== bench.ref.width || now.height !== bench.ref.height) return;
      const sx = now.width / img.clientWidth, sy = now.height / img.clientHeight;
      const [mx0, my0, mx1, my1, mr] = bench.mask;
      let changed = 0;
      const a = now.data, b = bench.ref.data;
      for (let y = 0; y < now.height; y += 2) {
        for (let x = 0; x < now.width; x += 2) {
          const cx = x / sx, cy = y / sy;
          if (Math.hypot(cx - mx0, cy - my0) < mr || Math.hypot(cx - mx1, cy - my1) < mr) continue;
          const i = 4 * (y * now.width + x);
          if (Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > 90) {
            changed += 1;
          }
        }
      }
      bench.changed = changed;
      if (changed > 40) bench.hit = t;
    }
  });
  return true;
}
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    def __init__(self, preset: str, device: str):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}/"
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
        self.log = tempfile.NamedTemporaryFile("w", prefix="bench-app-", suffix=".log", delete=False)
        self.proc = subprocess.Popen([sys.executable, "-m", "somwidget.cli", "serve", "--port", str(self.port),
                                      "--preset", preset, "--device", device], cwd=ROOT, env=env,
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
            if not f["running"] and st["session"]["pending_intents"] == 0 and st["view"]["frame_seq"] == f["seq"] \
                    and not st["animating"]:
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
        os.unlink(self.log.name)


def open_page(browser, url: str, viewport):
    page = browser.new_page(viewport=viewport)
    page.goto(url)
    page.wait_for_function("() => { const i = document.querySelector('#view-container img');"
                           " return i && i.src.startsWith('blob:') && i.naturalWidth > 0; }", timeout=60000)
    page.evaluate(PAGE_JS)
    return page


def screen_of(page, st: dict) -> list[tuple[float, float]]:
    box = page.locator("#view-container img").bounding_box()
    w, h = st["view"]["window_size"]
    return [(box["x"] + x * box["width"] / w, box["y"] + y * box["height"] / h) for x, y in st["view"]["widget_screen"]]


def pick_control(page, st: dict, margin: float = 110.0) -> int:
    box = page.locator("#view-container img").bounding_box()
    spots = screen_of(page, st)
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    best, best_score = None, -1.0
    for i, (x, y) in enumerate(spots):
        inside = box["x"] + margin < x < box["x"] + box["width"] - margin and \
            box["y"] + margin < y < box["y"] + box["height"] - margin
        clear = min([np.hypot(x - u, y - v) for j, (u, v) in enumerate(spots) if j != i] or [1e9])
        if inside and clear > best_score:
            best, best_score = i, clear
    if best is None:
        best = int(np.argmin([np.hypot(x - cx, y - cy) for x, y in spots]))
    return best


def set_iterations(page, value: int) -> None:
    field = page.locator("#field-iterations")
    field.fill(str(value))
    field.press("Enter")


def measure_training(page, server: Server, seconds: float) -> dict:
    set_iterations(page, 1_000_000)
    time.sleep(1.0)
    n0, t0 = page.evaluate("window.__bench.count"), time.monotonic()
    s0 = server.state()["session"]["frame"]
    time.sleep(seconds)
    n1, t1 = page.evaluate("window.__bench.count"), time.monotonic()
    s1 = server.state()["session"]["frame"]
    page.locator("#train-button").click()  # pause
    time.sleep(0.3)
    set_iterations(page, 1000)
    page.locator("#train-button").click()  # train again (the run restarts from the latest weights)
    server.idle()
    return {"images_per_s": (n1 - n0) / (t1 - t0), "session_frames_per_s": (s1["seq"] - s0["seq"]) / (t1 - t0),
            "cycles_per_s": (s1["iteration"] - s0["iteration"]) / (t1 - t0), "cycle_ms": s1["cycle_time"] * 1e3}


def measure_drag(page, server: Server, seconds: float) -> dict:
    st = server.idle()
    i = pick_control(page, st)
    x0, y0 = screen_of(page, st)[i]
    page.mouse.move(x0, y0)
    page.mouse.down()
    n0, t0 = page.evaluate("window.__bench.count"), time.monotonic()
    moves = 0
    while time.monotonic() - t0 < seconds:
        a = (time.monotonic() - t0) * 2.0
        page.mouse.move(x0 + 40 * np.sin(a), y0 - 40 + 40 * np.cos(a))
        moves += 1
        time.sleep(0.02)
    n1, t1 = page.evaluate("window.__bench.count"), time.monotonic()
    page.mouse.up()
    st1 = server.idle()
    return {"images_per_s": (n1 - n0) / (t1 - t0), "mouse_moves_per_s": moves / (t1 - t0),
            "drag_events": st1["view"]["drag_moves"] - st["view"]["drag_moves"], "control": i}


def measure_latency(page, server: Server, repeats: int) -> dict:
    lat, misses = [], 0
    step = 36.0
    for r in range(repeats):
        st = server.idle()
        i = pick_control(page, st)
        x0, y0 = screen_of(page, st)[i]
        page.mouse.move(x0, y0)
        page.mouse.down()
        time.sleep(0.6)  # the press alone changes nothing; let its images settle
        page.evaluate("window.__bench.setReference()")
        dx, dy = (step, -step * 0.5) if r % 2 == 0 else (-step, step * 0.5)
        page.evaluate(f"window.__bench.mask = [{x0} - document.querySelector('#view-container img')"
                      f".getBoundingClientRect().x, {y0} - document.querySelector('#view-container img')"
                      f".getBoundingClientRect().y, {x0 + dx} - document.querySelector('#view-container img')"
                      f".getBoundingClientRect().x, {y0 + dy} - document.querySelector('#view-container img')"
                      f".getBoundingClientRect().y, 48]")
        # vtk.js turns the first pointer move after 200 ms of stillness into a StartMouseMove that its remote
        # style does not send: wake it with a 1-pixel move (inside the sphere's mask), then time the real one
        page.mouse.move(x0 + 1, y0)
        time.sleep(0.03)
        t_move = page.evaluate("window.__bench.watchFrom = performance.now()")
        page.mouse.move(x0 + dx, y0 + dy)
        deadline = time.monotonic() + 5.0
        hit = None
        while time.monotonic() < deadline:
            hit = page.evaluate("window.__bench.hit")
            if hit is not None:
                break
            time.sleep(0.01)
        page.evaluate("window.__bench.watchFrom = null")
        page.mouse.up()
        if hit is None:
            misses += 1
        else:
            lat.append(hit - t_move)
    return {"median_ms": statistics.median(lat) if lat else None, "min_ms": min(lat) if lat else None,
            "max_ms": max(lat) if lat else None, "samples": len(lat), "misses": misses}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--presets", default="car,space-grid", help="comma-separated presets (default: %(default)s)")
    ap.add_argument("--seconds", type=float, default=5.0, help="length of each rate measurement")
    ap.add_argument("--repeats", type=int, default=7, help="latency samples per preset")
    ap.add_argument("--device", default="cpu", choices=("auto", "cpu", "cuda"))
    ap.add_argument("--viewport", default="1200x800", help="browser viewport WxH (the 3-D view is the part right "
                    "of the 390-pixel panel)")
    ap.add_argument("--json", help="write the results here too")
    args = ap.parse_args(argv)
    from playwright.sync_api import sync_playwright

    w, h = (int(v) for v in args.viewport.lower().split("x"))
    results = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                           "viewport": [w, h], "device": args.device}, "presets": {}}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            for preset in [s.strip() for s in args.presets.split(",") if s.strip()]:
                server = Server(preset, args.device)
                try:
                    page = open_page(browser, server.url, {"width": w, "height": h})
                    st = server.idle()
                    view = st["view"]["window_size"]
                    res = {"nodes": st["session"]["n_vertices"], "view_pixels": view,
                           "training": measure_training(page, server, args.seconds),
                           "drag": measure_drag(page, server, args.seconds),
                           "latency": measure_latency(page, server, args.repeats)}
                    results["presets"][preset] = res
                    page.close()
                finally:
                    server.stop()
                tr, dr, la = res["training"], res["drag"], res["latency"]
                print(f"{preset:>11} {res['nodes']:>5} nodes, view {view[0]}x{view[1]}: "
                      f"training {tr['images_per_s']:.1f} images/s in the browser "
                      f"(session {tr['session_frames_per_s']:.1f} frames/s, cycle {tr['cycle_ms']:.3f} ms); "
                      f"drag {dr['images_per_s']:.1f} images/s; drag-to-changed-mesh latency median "
                      f"{la['median_ms'] if la['median_ms'] is None else round(la['median_ms'])} ms "
                      f"(min {la['min_ms'] and round(la['min_ms'])}, max {la['max_ms'] and round(la['max_ms'])}, "
                      f"{la['samples']} samples, {la['misses']} misses)", flush=True)
        finally:
            browser.close()
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
