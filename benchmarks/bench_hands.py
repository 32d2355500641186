"""Many hands on one session: move -> frame latency with 1, 6 and 30 views dragging at once.

A real Session (the car, 602 nodes, mirrored: each control has a copy) is served on the views' websocket /view/ws by
XRServer; the views are websocket clients in a second process (so their work does not share the server's GIL). Each
view grabs a control of its own (the session gets controls added up to the number of views) and moves it about 45
times a second (every 22 ms, as the browser client does), each move somewhere new, for `--seconds`. A move is
answered by the first frame that view receives showing its control at the position it sent (frames are the latest
state, so a move overtaken by the view's next one before a frame went out is never shown on its own: it counts as
superseded, not answered).

Reported per number of views: the latency from a move's send to the frame that answers it (median, p90, p99, ms), the
share of moves answered, the frames each view received per second, and the session's frames per second and cycles
per frame while they drag. Every view lets go at the end; the undo steps made (one per drag) are checked.

Usage:
    python benchmarks/bench_hands.py [--views 1,6,30] [--seconds 6] [--device cpu] [--json results.json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import multiprocessing
import os
import platform
import struct
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MOVE_INTERVAL = 0.022  # s: the browser client's pace (client/src/grabs.js)


# -- the views (a process of their own) ----------------------------------------------------------------------------
async def _view(base: str, index: int, seconds: float, start_at: float, out: list) -> None:
    import aiohttp

    from somwidget.frontend.transport.messages import HEADER_FORMAT, HEADER_SIZE

    header = struct.Struct(HEADER_FORMAT)
    async with aiohttp.ClientSession() as cs, cs.ws_connect(base + "/view/ws", compress=0, max_msg_size=0) as ws:
        topology = None
        latest = None
        while topology is None or latest is None:
            msg = await ws.receive(timeout=60)
            if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data)["type"] == "topology":
                topology = json.loads(msg.data)
            elif msg.type == aiohttp.WSMsgType.BINARY:
                latest = msg.data
        cid = topology["control_ids"][index]
        fields = header.unpack_from(latest, 0)
        n = fields[7]
        at = HEADER_SIZE + 12 * n + 12 * index  # this view's control in the frame's control positions
        home = np.array(struct.unpack_from("<3f", latest, at), np.float64)
        await ws.send_json({"type": "grab", "id": cid})
        pending: list[tuple[float, tuple]] = []  # (sent, position as float32) not answered yet
        latencies, sent, frames = [], 0, 0
        done = asyncio.Event()

        async def receive():
            nonlocal frames
            while not done.is_set():
                try:
                    msg = await ws.receive(timeout=0.5)
                except asyncio.TimeoutError:
                    continue
                if msg.type != aiohttp.WSMsgType.BINARY:
                    if msg.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                        return
                    continue
                now = time.perf_counter()
                frames += 1
                shown = struct.unpack_from("<3f", msg.data, at)
                for m, (t, p) in enumerate(pending):
                    if p == shown:
                        latencies.append(now - t)
                        del pending[:m + 1]  # this one, and the ones it overtook
                        break

        receiver = asyncio.ensure_future(receive())
        await asyncio.sleep(max(0.0, start_at - time.time()))  # every view starts moving at once
        t0 = time.perf_counter()
        phase = 2 * math.pi * index / 7
        while time.perf_counter() - t0 < seconds:
            a = phase + 2 * math.pi * (time.perf_counter() - t0) / 2.0  # a small circle every 2 s
            p = home + 0.06 * np.array([math.cos(a), math.sin(a), 0.5 * math.sin(2 * a)])
            p32 = tuple(float(v) for v in np.float32(np.round(p, 6)))
            await ws.send_json({"type": "move", "id": cid, "position": [round(float(v), 6) for v in p]})
            pending.append((time.perf_counter(), p32))
            sent += 1
            await asyncio.sleep(MOVE_INTERVAL)
        await asyncio.sleep(0.5)  # the last answers
        done.set()
        await receiver
        await ws.send_json({"type": "release", "id": cid})
        await ws.send_json({"type": "ping", "t": 1})
        while True:  # the release taken
            msg = await ws.receive(timeout=60)
            if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data) == {"type": "pong", "t": 1}:
                break
        out.append({"latencies": latencies, "sent": sent, "frames": frames, "seconds": time.perf_counter() - t0})


def _views(base: str, count: int, seconds: float, start_at: float, queue) -> None:
    async def main():
        out: list = []
        await asyncio.gather(*(_view(base, i, seconds, start_at, out) for i in range(count)))
        return out

    queue.put(asyncio.run(main()))


# -- the server ------------------------------------------------------------------------------------------------------
def run(count: int, seconds: float, device: str) -> dict:
    from somwidget.frontend.model import Session
    from somwidget.frontend.web.standalone import XRServer

    session = Session("car", device=device, autosave=False)
    try:
        assert session.wait_idle(120)
        rng = np.random.default_rng(count)
        while session.n_controls < count:  # a control for each view, on the clay
            node = session.frame.positions[rng.integers(len(session.frame.positions))]
            session.add_control(list(map(float, node)))
        with session.gesture():  # a drag first: the engine compiles what a drag runs (seconds, once a process)
            session.move_control(0, session.controls[0][:3] + np.float32([0.0, 0.0, 0.05]))
        assert session.wait_idle(60)
        steps = session.history[0]
        published, cycles = [], []

        def count_frame(frame):
            published.append(time.perf_counter())
            cycles.append(frame.step_cycles)

        with XRServer(session) as srv:
            queue = multiprocessing.get_context("spawn").Queue()
            start_at = time.time() + 8.0  # the views' process starts and connects meanwhile
            proc = multiprocessing.get_context("spawn").Process(target=_views,
                                                                args=(srv.base, count, seconds, start_at, queue))
            proc.start()
            time.sleep(max(0.0, start_at - time.time()))
            session.add_listener(count_frame, replay=False)
            t0 = time.perf_counter()
            time.sleep(seconds)
            session.remove_listener(count_frame)
            views = queue.get(timeout=300)
            proc.join(60)
        assert session.wait_idle(120)
        made = session.history[0] - steps
    finally:
        session.close()
    lat = np.array([x for v in views for x in v["latencies"]]) * 1e3
    sent = sum(v["sent"] for v in views)
    window = [c for t, c in zip(published, cycles) if t - t0 <= seconds]
    return {"views": count, "moves": sent, "answered": len(lat) / max(sent, 1),
            "median_ms": float(np.median(lat)), "p90_ms": float(np.percentile(lat, 90)),
            "p99_ms": float(np.percentile(lat, 99)),
            "view_fps": float(np.mean([v["frames"] / v["seconds"] for v in views])),
            "session_fps": len(window) / seconds, "cycles_per_frame": float(np.mean(window)) if window else 0.0,
            "undo_steps": made}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", default="1,6,30")
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    print(f"# bench_hands: {platform.node()}, {os.cpu_count()} CPUs, device {args.device}, {args.seconds:g} s of "
          "dragging each")
    print(f"{'views':>5} {'moves':>6} {'answered':>8} {'median ms':>9} {'p90 ms':>7} {'p99 ms':>7} "
          f"{'view fps':>8} {'session fps':>11} {'cycles/frame':>12} {'steps':>5}")
    results = []
    for count in (int(v) for v in args.views.split(",")):
        r = run(count, args.seconds, args.device)
        results.append(r)
        print(f"{r['views']:>5} {r['moves']:>6} {r['answered']:>8.0%} {r['median_ms']:>9.1f} {r['p90_ms']:>7.1f} "
              f"{r['p99_ms']:>7.1f} {r['view_fps']:>8.1f} {r['session_fps']:>11.1f} {r['cycles_per_frame']:>12.1f} "
              f"{r['undo_steps']:>5}", flush=True)
        assert r["undo_steps"] == count, f"{count} drags made {r['undo_steps']} undo steps"
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
