"""The clay view in a browser, fed a big clay's frame stream: what the page does with it (no engine involved).

A GPU machine trains a 1,000,000-vertex grid and streams it decimated (wire_display.DECIMATED_NODES display
vertices, 0.12 MB a frame; bench_big_view.py measures that side). This script replays such a stream on this machine: the
same grid's display mesh, its nodes moving as a wave, sent by a small aiohttp server at a chosen rate to the page's
clay view (dist/somview.js, mounted as the web app mounts it) in headless Chromium. It reports the frames the page
applied and painted per second, and the time from a frame's arrival to its paint.

Usage:
    .venv/bin/python benchmarks/bench_view_stream.py [--side 1000] [--fps 30] [--seconds 5] [--viewport 1200x800]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import socket
import statistics
import sys
import threading
import time
from pathlib import Path

import numpy as np
from aiohttp import web

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from somwidget.backend.presets import open_grid  # noqa: E402
from somwidget.frontend.client import DIST  # noqa: E402
from somwidget.frontend.transport import display as wire_display  # noqa: E402
from somwidget.frontend.transport import frames as wire_frames  # noqa: E402
from somwidget.frontend.transport import messages as wire  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
PAGE = """<!doctype html><meta charset="utf-8"><title>stream</title>
<style>html,body{margin:0;height:100%}#v{width:100%;height:100%}</style><div id="v"></div>
<script type="module">
import { mountWebView } from './somview.js';
const view = mountWebView(document.getElementById('v'), `ws://${location.host}/ws`);
window.arrivals = [];
const apply = view.applyFrame.bind(view);
window.applyMs = [];
view.applyFrame = (f) => { const t = performance.now(); window.arrivals.push(t); const r = apply(f);
  window.applyMs.push(performance.now() - t); return r; };
window.view = view;
</script>"""


def stream(side: int):
    faces, pts = open_grid(side, side)
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 3]],
                                              faces[:, [3, 0]]]), axis=1), axis=0)
    tris = np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
    nodes, t, e = wire_display.decimate_display(pts, tris, edges)
    p = pts[nodes].astype(np.float32)
    controls = p[np.linspace(0, len(p) - 1, 6).astype(int)]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    topology = {"type": "topology", "protocol": wire.PROTOCOL_VERSION, "generation": 1, "preset": "grid",
                "title": f"Grid {side} x {side} (replayed)", "display": "surface", "n_vertices": len(nodes),
                "n_nodes": side * side, "triangles": t.ravel().tolist(), "segments": e.ravel().tolist(),
                "points": False, "n_controls": 6, "n_effective": 6, "mirror_axes": [False, False, False],
                "up_axis": 2, "bounds": {"min": lo.tolist(), "max": (hi + [0, 0, 0.3]).tolist()},
                "control_radius": 0.03, "colour_space": "none", "feature_names": ["x", "y", "z"]}
    colours = np.full((len(p), 3), 180, np.uint8)

    def frame(k: int) -> bytes:
        q = p.copy()
        q[:, 2] = 0.15 * np.sin(3.0 * q[:, 0] + 0.2 * k) * np.cos(2.0 * q[:, 1])
        header = wire_frames.HEADER.pack(wire.MAGIC, wire.PROTOCOL_VERSION, wire.FLAGS["running"], k, 1,
                                      k % 1000, 1000, len(q), 6, 6)
        body = b"".join([header, q.tobytes(), controls.tobytes(), colours.tobytes(),
                         np.full((6, 3), 220, np.uint8).tobytes()])
        return body + b"\0" * (-len(body) % 4)

    return topology, frame


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve(port: int, topology: dict, frame, fps: float, ready: threading.Event, stop: threading.Event) -> None:
    async def page(_):
        return web.Response(text=PAGE, content_type="text/html")

    async def module(_):
        return web.FileResponse(DIST / "somview.js", headers={"Content-Type": "text/javascript"})

    async def ws_handler(request):
        ws = web.WebSocketResponse(compress=False)
        await ws.prepare(request)
        await ws.send_str(json.dumps(topology))
        k = 0
        t0 = time.perf_counter()
        while not stop.is_set() and not ws.closed:
            await ws.send_bytes(frame(k))
            k += 1
            await asyncio.sleep(max(0.0, t0 + k / fps - time.perf_counter()))
        return ws

    async def main():
        app = web.Application()
        app.router.add_get("/", page)
        app.router.add_get("/somview.js", module)
        app.router.add_get("/ws", ws_handler)
        runner = web.AppRunner(app)
        await runner.setup()
        await web.TCPSite(runner, "127.0.0.1", port).start()
        ready.set()
        while not stop.is_set():
            await asyncio.sleep(0.1)
        await runner.cleanup()

    asyncio.run(main())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--side", type=int, default=1000)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--viewport", default="1200x800")
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    t = time.perf_counter()
    topology, frame = stream(args.side)
    made = time.perf_counter() - t
    size = len(frame(0))
    port = free_port()
    ready, stop = threading.Event(), threading.Event()
    server = threading.Thread(target=serve, args=(port, topology, frame, args.fps, ready, stop), daemon=True)
    server.start()
    ready.wait(30)
    w, h = (int(v) for v in args.viewport.split("x"))
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": w, "height": h})
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function("() => window.view && window.view.describe().painted > 2", timeout=60000)
            d0, t0 = page.evaluate("() => window.view.describe()"), time.monotonic()
            time.sleep(args.seconds)
            d1, t1 = page.evaluate("() => window.view.describe()"), time.monotonic()
            delays = page.evaluate("""() => { const out = []; const paints = window.view.paints;
                for (const a of window.arrivals.slice(-200)) { const p = paints.find((x) => x.t >= a);
                  if (p) out.push(p.t - a); } return out; }""")
            apply_ms = page.evaluate("() => window.applyMs.slice(-200)")
            browser.close()
    finally:
        stop.set()
    applied = (d1["frames"] - d0["frames"]) / (t1 - t0)
    painted = (d1["painted"] - d0["painted"]) / (t1 - t0)
    print(f"{args.side * args.side:,}-vertex grid replayed as {topology['n_vertices']:,} display vertices, "
          f"{size / 1e6:.2f} MB a frame, sent at {args.fps:g}/s ({len(json.dumps(topology)) / 1e6:.1f} MB topology, "
          f"made in {made:.1f} s): the page applied {applied:.1f} and painted {painted:.1f} frames/s; arrival -> "
          f"paint {statistics.median(delays):.0f} ms median, {np.percentile(delays, 90):.0f} ms p90; applying a frame "
          f"{statistics.median(apply_ms):.1f} ms median "
          f"({platform.node()}, {os.cpu_count()} cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
