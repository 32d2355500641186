"""The studio front's relay alone: its CPU a frame, with no rooms and no kernels in the way.

Three processes on this machine: a stand-in room server (answers each move with one frame of --frame-bytes, as a
worker's room does), the front's relay (somwidget/frontend/studio/relay.py, as `RemotePlace.socket` runs it) and the
designers (websocket clients, each moving at --rate moves a second). Prints the relay process's CPU ms a frame (its
own user + system time over the frames it passed), frames a second and move -> frame median / p95. The relay's CPU a
frame is what bounds the designers one front process holds (BENCHMARKS.md, "Studio"); compare before and after a
change by running both in one go on one machine.

    python benchmarks/bench_relay.py --designers 64,128 --seconds 5
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import socket
import time

import numpy as np


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process `pid` (Linux /proc)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _room_server(port: int, frame_bytes: int) -> None:
    from aiohttp import WSMsgType, web

    frame = os.urandom(frame_bytes)

    async def ws(request):
        sock = web.WebSocketResponse(max_msg_size=64 * 1024)
        await sock.prepare(request)
        async for msg in sock:
            if msg.type == WSMsgType.TEXT:  # a move: its number back at the front of one frame
                await sock.send_bytes(msg.data.encode()[:8].ljust(8) + frame[8:])
        return sock

    app = web.Application()
    app.router.add_get("/ws", ws)
    web.run_app(app, host="127.0.0.1", port=port, print=None, handle_signals=True)


def _front(port: int, upstream: str) -> None:
    from aiohttp import web

    from somwidget.frontend.studio import relay

    async def ws(request):
        return await relay.relay(request, await relay.open_upstream(upstream, {}))

    app = web.Application()
    app.router.add_get("/ws", ws)
    web.run_app(app, host="127.0.0.1", port=port, print=None, handle_signals=True)


async def _designers(url: str, count: int, seconds: float, rate: float, front_pid: int, room_pid: int) -> dict:
    import aiohttp

    latencies: list[float] = []
    frames = 0
    measuring = False

    async def designer(session, k: int) -> None:
        nonlocal frames
        async with session.ws_connect(url, max_msg_size=0) as ws:
            sent: dict[bytes, float] = {}

            async def receive() -> None:
                nonlocal frames
                async for msg in ws:
                    t = sent.pop(msg.data[:8], None)
                    if measuring and t is not None:
                        latencies.append(time.perf_counter() - t)
                        frames += 1

            reading = asyncio.ensure_future(receive())
            n, start = 0, time.perf_counter() + (k % 33) / 1000
            while not reading.done():
                n += 1
                key = f"{k % 1000:03d}{n % 100000:05d}".encode()
                sent[key] = time.perf_counter()
                await ws.send_str(key.decode() + '{"type":"move","id":3,"position":[0.123456,-0.5,0.25]}')
                await asyncio.sleep(max(0.0, start + n / rate - time.perf_counter()))

    async with aiohttp.ClientSession() as session:
        tasks = [asyncio.ensure_future(designer(session, k)) for k in range(count)]
        await asyncio.sleep(1.5)  # every designer connected and moving
        measuring = True
        cpu0, room0, t0 = _cpu_seconds(front_pid), _cpu_seconds(room_pid), time.perf_counter()
        await asyncio.sleep(seconds)
        cpu1, room1, t1 = _cpu_seconds(front_pid), _cpu_seconds(room_pid), time.perf_counter()
        measuring = False
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    ms = np.asarray(latencies) * 1e3
    return {"designers": count, "frames_per_s": frames / (t1 - t0),
            "front_cpu_ms_a_frame": 1e3 * (cpu1 - cpu0) / max(frames, 1),
            "room_server_cpu_ms_a_frame": 1e3 * (room1 - room0) / max(frames, 1),
            "front_cores": (cpu1 - cpu0) / (t1 - t0),
            "median_ms": float(np.median(ms)) if ms.size else None,
            "p95_ms": float(np.percentile(ms, 95)) if ms.size else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--designers", default="32,64", help="comma-separated designer counts, one run each")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--rate", type=float, default=30.0, help="moves a second a designer")
    ap.add_argument("--frame-bytes", type=int, default=14_000, help="a frame's size (a car frame: about 14 KB)")
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args()
    ctx = mp.get_context("spawn")
    rows = []
    for count in (int(c) for c in args.designers.split(",")):
        room_port, front_port = _free_port(), _free_port()
        room = ctx.Process(target=_room_server, args=(room_port, args.frame_bytes), daemon=True)
        front = ctx.Process(target=_front, args=(front_port, f"ws://127.0.0.1:{room_port}/ws"), daemon=True)
        room.start()
        front.start()
        try:
            deadline = time.monotonic() + 30
            for port in (room_port, front_port):
                while True:
                    try:
                        socket.create_connection(("127.0.0.1", port), 0.2).close()
                        break
                    except OSError:
                        if time.monotonic() > deadline:
                            raise SystemExit(f"bench_relay: nothing listens on port {port} after 30 s") from None
                        time.sleep(0.1)
            row = asyncio.run(_designers(f"ws://127.0.0.1:{front_port}/ws", count, args.seconds, args.rate,
                                         front.pid, room.pid))
        finally:
            for p in (front, room):
                p.terminate()
                p.join(5)
        rows.append(row)
        print(" ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()), flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
