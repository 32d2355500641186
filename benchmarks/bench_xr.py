"""Measure the WebXR client's websocket: what it carries, and how soon a grab-move shows in the mesh.

For each case (car: 602 nodes, case study 2; space-grid: 4096 nodes, case study 1) it reports:

  stream    frames/s and bytes/s reaching one websocket client (Python, aiohttp) while the map trains a long
            run, the session's own frames/s, the frame size, and the server's encode time per frame
  protocol  latency, Python client: from sending a move (the control held, the mesh converged and idle) to the
            first frame that shows the control there with a changed mesh; median / p90 over repeats
  emulator  the same in Chromium on an emulated Quest 3 (iwer, /xr/emulator.html): the controller holds a control
            and moves a little; from the new controller pose to the first frame in the page showing the control
            there with a changed mesh (page clock), and from the page's move message to that frame;
            then while gliding continuously during training (moves about 45/s)

The server is the XR route on a small aiohttp server (XRServer) around a real Session on one machine (loopback),
so network time is nil; the numbers are the pipeline's: intent -> session thread -> step -> frame -> encode ->
websocket -> parse -> draw.

Usage:
    python benchmarks/bench_xr.py [--cases car,space-grid] [--seconds 5] [--repeats 9] [--device cpu]
                                  [--no-browser] [--json results.json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from somwidget.frontend.client import DIST  # noqa: E402
from somwidget.frontend.model import Session  # noqa: E402
from somwidget.frontend.transport import frames as wire_frames  # noqa: E402
from somwidget.frontend.web.standalone import XRServer  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
CASES = {"car": "car", "space-grid": "space-grid"}


def pct(values, q):
    return float(np.percentile(values, q)) if values else float("nan")


def stream(session: Session, srv: XRServer, seconds: float) -> dict:
    import aiohttp

    session.set_iterations(1_000_000)  # a long run: frames flow the whole time
    published = [0]

    def count(_frame):
        published[0] += 1

    session.add_listener(count, replay=False)
    session.train()

    async def main():
        async with aiohttp.ClientSession() as cs:
            async with cs.ws_connect(srv.base + "/view/ws", compress=0) as ws:
                frames = nbytes = text = 0
                sizes = []
                t0 = None
                published0 = 0
                loop = asyncio.get_running_loop()
                while True:
                    msg = await ws.receive(timeout=30)
                    now = loop.time()
                    if t0 is None and msg.type == aiohttp.WSMsgType.BINARY:
                        t0, published0 = now, published[0]  # count from the first frame
                        continue
                    if t0 is None:
                        continue
                    if msg.type == aiohttp.WSMsgType.BINARY:
                        frames += 1
                        nbytes += len(msg.data)
                        sizes.append(len(msg.data))
                    elif msg.type == aiohttp.WSMsgType.TEXT:
                        text += len(msg.data)
                    if now - t0 >= seconds:
                        break
                elapsed = now - t0
                return frames, nbytes, text, sizes, elapsed, published[0] - published0

    frames, nbytes, text, sizes, elapsed, published = asyncio.run(main())
    session.remove_listener(count)
    session.pause()
    frame = session.frame
    reps = 200
    t = time.perf_counter()
    for _ in range(reps):
        wire_frames.encode_frame(frame, session)
    encode_ms = (time.perf_counter() - t) / reps * 1e3
    return {"frames_per_s": frames / elapsed, "bytes_per_s": (nbytes + text) / elapsed,
            "frame_bytes": int(np.median(sizes)) if sizes else 0, "session_frames_per_s": published / elapsed,
            "encode_ms": encode_ms, "seconds": elapsed, "iteration": frame.iteration}


def protocol_latency(session: Session, srv: XRServer, repeats: int) -> dict:
    import aiohttp

    session.set_iterations(session.preset.iterations)
    session.train()
    session.wait_idle(300)
    index = 0
    base = session.controls[index, :3].astype(float)

    async def main():
        out = []
        async with aiohttp.ClientSession() as cs:
            async with cs.ws_connect(srv.base + "/view/ws") as ws:
                last = None

                async def next_frame(timeout=30):
                    nonlocal last
                    while True:
                        msg = await ws.receive(timeout=timeout)
                        if msg.type == aiohttp.WSMsgType.BINARY:
                            last = wire_frames.decode_frame(msg.data)
                            return last

                await next_frame()
                await ws.send_str(json.dumps({"type": "grab", "index": index}))
                for r in range(repeats):
                    await asyncio.get_running_loop().run_in_executor(None, session.wait_idle, 120)
                    while True:  # drain: the last frame before the move
                        try:
                            await next_frame(timeout=0.2)
                        except asyncio.TimeoutError:
                            break
                    before = last["positions"].copy()
                    target = (base + np.array([0.0, 0.0, 0.05 * (1 + r % 2)])).tolist()
                    t0 = time.perf_counter()
                    await ws.send_str(json.dumps({"type": "move", "index": index, "position": target}))
                    while True:
                        f = await next_frame()
                        if np.allclose(f["control_positions"][index], np.float32(target)) and not np.array_equal(
                                f["positions"], before):
                            out.append((time.perf_counter() - t0) * 1e3)
                            break
                await ws.send_str(json.dumps({"type": "release", "index": index, "position": base.tolist()}))
                await asyncio.sleep(0.2)
        return out

    lat = asyncio.run(main())
    session.wait_idle(300)
    return {"median_ms": statistics.median(lat), "p90_ms": pct(lat, 90), "n": len(lat)}


def emulator_latency(session: Session, srv: XRServer, repeats: int, seconds: float) -> dict:
    from playwright.sync_api import sync_playwright

    session.set_iterations(session.preset.iterations)
    session.train()
    session.wait_idle(300)
    index = 2
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        page = browser.new_page(viewport={"width": 480, "height": 360})
        page.goto(srv.base + "/xr/emulator.html")
        page.wait_for_function("window.somxr && somxr.state().frames > 0", timeout=60000)
        page.wait_for_selector("#enter-ar:not([hidden])")
        box = page.locator("#enter-ar").bounding_box()
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.wait_for_function("somxr.state().presenting", timeout=30000)
        dev = "iwerDevice.controllers.right"

        def frames(n=2):
            start = page.evaluate("somxr.state().xrFrames")
            page.wait_for_function(f"somxr.state().xrFrames >= {start + n}", timeout=30000)

        def pos():
            return np.array(page.evaluate(f"(() => {{ const p = {dev}.position; return [p.x, p.y, p.z]; }})()"))

        def set_pos(q):
            # returns the page clock when the pose changed
            return page.evaluate(f"([x, y, z]) => {{ {dev}.position.set(x, y, z); return performance.now(); }}",
                                 [float(v) for v in q])

        frames(3)
        target = np.array(page.evaluate(f"somxr.controlWorld({index})"))
        for _ in range(3):
            pt = next(i["point"] for i in page.evaluate("somxr.inputs()") if i["handedness"] == "right")
            set_pos(target - (np.array(pt) - pos()))
            frames(2)
        page.evaluate(f"{dev}.updateButtonValue('trigger', 1)")
        page.wait_for_function(f"somxr.state().held.includes({index})", timeout=10000)
        gesture, message = [], []
        for r in range(repeats):
            session.wait_idle(120)
            frames(4)
            n0 = len(page.evaluate("somxr.latencyLog()"))
            t_pose = set_pos(pos() + np.array([0.0, 0.01 * (1 if r % 2 == 0 else -1), 0.0]))
            page.wait_for_function(f"somxr.latencyLog().length > {n0}", timeout=30000)
            e = page.evaluate("somxr.latencyLog()")[-1]
            gesture.append(e["arrived"] - t_pose)
            message.append(e["arrived"] - e["sent"])
        # gliding while the map trains: a circle of 3 cm radius, one step per XR frame
        session.set_iterations(1_000_000)
        session.train()
        n0 = len(page.evaluate("somxr.state().latencies"))
        sent0 = page.evaluate("somxr.state().moves")
        centre = pos()
        t0 = time.perf_counter()
        steps = 0
        while time.perf_counter() - t0 < seconds:
            a = steps * 0.25
            set_pos(centre + 0.03 * np.array([np.cos(a), np.sin(a), 0.0]))
            frames(1)
            steps += 1
        elapsed = time.perf_counter() - t0
        st = page.evaluate("somxr.state()")
        glide = st["latencies"][n0:]
        moves = st["moves"] - sent0
        fps = st["fps"]
        page.evaluate(f"{dev}.updateButtonValue('trigger', 0)")
        frames(3)
        session.pause()
        browser.close()
    session.set_iterations(session.preset.iterations)
    return {"gesture_median_ms": statistics.median(gesture), "gesture_p90_ms": pct(gesture, 90),
            "message_median_ms": statistics.median(message), "message_p90_ms": pct(message, 90), "n": len(gesture),
            "glide_median_ms": statistics.median(glide) if glide else float("nan"),
            "glide_p90_ms": pct(glide, 90), "glide_matched": len(glide), "glide_moves_per_s": moves / elapsed,
            "page_frames_per_s": fps}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default="car,space-grid")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--no-browser", action="store_true")
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    browser = not args.no_browser and os.path.exists(CHROMIUM) and (DIST / "emulator.html").is_file()
    results = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "device": args.device},
               "cases": {}}
    for name in [c.strip() for c in args.cases.split(",") if c.strip()]:
        t = time.perf_counter()
        session = Session(CASES.get(name, name), device=args.device, paused=True)
        build = time.perf_counter() - t
        with session, XRServer(session) as srv:
            r = {"nodes": int(session.topology.n_vertices), "session_build_s": build}
            r["stream"] = stream(session, srv, args.seconds)
            r["protocol"] = protocol_latency(session, srv, args.repeats)
            if browser:
                r["emulator"] = emulator_latency(session, srv, args.repeats, args.seconds)
        results["cases"][name] = r
        s, pl = r["stream"], r["protocol"]
        print(f"{name} ({r['nodes']} nodes): stream {s['frames_per_s']:.1f} frames/s, "
              f"{s['bytes_per_s'] / 1e3:.0f} kB/s, "
              f"{s['frame_bytes']} B/frame (session {s['session_frames_per_s']:.1f} frames/s, encode "
              f"{s['encode_ms']:.3f} ms); protocol move->mesh median {pl['median_ms']:.1f} ms, p90 {pl['p90_ms']:.1f}",
              flush=True)
        if "emulator" in r:
            e = r["emulator"]
            print(f"  emulator: pose->mesh median {e['gesture_median_ms']:.1f} ms (p90 {e['gesture_p90_ms']:.1f}), "
                  f"message->mesh {e['message_median_ms']:.1f} ms; gliding while training: "
                  f"{e['glide_median_ms']:.1f} ms median (p90 {e['glide_p90_ms']:.1f}, {e['glide_matched']} matched, "
                  f"{e['glide_moves_per_s']:.0f} moves/s, page {e['page_frames_per_s']:.0f} frames/s)", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
