"""bench_studio.py's simulated designers: websocket clients, each in a room of its own, holding control 0 and moving it
thirty times a second; move -> frame as the designer receives it.

Cheap, because they share the host's cores with the studio they measure: the designers of one process are asyncio
tasks of one loop; a move is one preformatted JSON text; a frame is not decoded: its header gives where control 0's
position lies (transport/messages.py HEADER_FORMAT), and a move is answered by the first frame whose 12 bytes there are
the move's position as float32. Each designer is bounded by the run's deadline: one that never connects, or whose
room never answers, is counted as such (its moves unanswered), never waited for. A designer whose websocket closes
(its worker died: 1012) connects again to its room's link, grabs again and goes on; the time from the cut to its
first answered move after it is its room's time back.
"""

from __future__ import annotations

import asyncio
import json
import math
import multiprocessing
import os
import queue as queues
import struct
import sys
import time

import numpy as np

MOVE_INTERVAL = 1.0 / 30.0  # s: 30 moves a second
RECONNECT_PAUSE = 0.2  # s between two tries to reach a room again
SLOW = 0.050  # s: a move answered later than this is slow (its time kept: when the slow ones come)
LAG_NOTED = 0.010  # s: an event loop this late is noted (`loop_lags`)


class _Designer:
    """One designer's counts (what its process sends back)."""

    def __init__(self, index: int) -> None:
        self.index = index
        self.latencies: list[float] = []
        self.slow: list[float] = []  # when each move answered after SLOW was sent (time.time)
        self.sent = 0
        self.frames = 0
        self.seconds = 0.0
        self.connected = False
        self.cuts: list[tuple[float, float | None]] = []  # (when its websocket was cut, when answered again: time.time)
        self.error: str | None = None

    def result(self) -> dict:
        return dict(vars(self))


async def _first_frame(ws, aiohttp, header_size: int):
    """(topology message, the first frame's bytes) of a room's websocket."""
    topology = latest = None
    while topology is None or latest is None:
        msg = await ws.receive()
        if msg.type == aiohttp.WSMsgType.TEXT:
            if topology is None and '"topology"' in msg.data:
                data = json.loads(msg.data)
                topology = data if data.get("type") == "topology" else None
        elif msg.type == aiohttp.WSMsgType.BINARY and topology is not None and len(msg.data) >= header_size:
            latest = msg.data
        elif msg.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.ERROR):
            raise ConnectionError(f"the room closed its websocket ({ws.close_code})")
    return topology, latest


async def designer(url: str, d: _Designer, seconds: float, start_at: float, deadline: float) -> None:
    """Designer `d` in the room at `url` (see the module's docstring) until `seconds` of moving end or the deadline
    (time.time) comes."""
    import aiohttp

    from somwidget.frontend.transport.messages import HEADER_FORMAT, HEADER_SIZE

    header = struct.Struct(HEADER_FORMAT)
    pending: list[tuple[float, float, bytes]] = []  # (sent at: perf_counter, time.time; the position's float32s)
    state = {"t0": None}
    async with aiohttp.ClientSession() as cs:
        while time.time() < deadline:
            try:
                ws = await cs.ws_connect(url, compress=0, max_msg_size=0, autoping=True)
            except (aiohttp.ClientError, OSError, asyncio.TimeoutError) as exc:
                d.error = f"connect: {exc}"
                await asyncio.sleep(RECONNECT_PAUSE)
                continue
            try:
                topology, first = await _first_frame(ws, aiohttp, HEADER_SIZE)
            except (ConnectionError, aiohttp.ClientError, asyncio.TimeoutError) as exc:
                d.error = str(exc)
                await ws.close()
                await asyncio.sleep(RECONNECT_PAUSE)
                continue
            d.connected, d.error = True, None
            cid = topology["control_ids"][0]
            at = HEADER_SIZE + 12 * header.unpack_from(first, 0)[7]  # control 0 in the frame's control positions
            if state["t0"] is None:
                state["home"] = struct.unpack_from("<3f", first, at)
                lo, hi = topology["bounds"]["min"], topology["bounds"]["max"]
                state["radius"] = 0.015 * math.dist(lo, hi)
            ended = await _drag(ws, d, cid, at, pending, state, seconds, start_at, deadline, aiohttp)
            if ended == "done":
                return
            d.cuts.append((time.time(), None))  # cut: its room moves to another worker
            pending.clear()


async def _drag(ws, d: _Designer, cid: int, at: int, pending: list, state: dict, seconds: float, start_at: float,
                deadline: float, aiohttp) -> str:
    """Grab control 0 and move it on a small circle until `seconds` of moving are over ("done") or the websocket is
    cut ("cut")."""
    cut = asyncio.Event()

    async def receive():
        async for msg in ws:
            if msg.type != aiohttp.WSMsgType.BINARY:
                continue
            d.frames += 1
            shown = msg.data[at:at + 12]
            for m, (t, wall, p) in enumerate(pending):
                if p == shown:
                    now = time.perf_counter()
                    d.latencies.append(now - t)
                    if now - t > SLOW:
                        d.slow.append(wall)
                    del pending[:m + 1]
                    if d.cuts and d.cuts[-1][1] is None:
                        d.cuts[-1] = (d.cuts[-1][0], time.time())
                    break
        cut.set()

    receiver = asyncio.ensure_future(receive())
    try:
        if state["t0"] is None:
            await asyncio.sleep(max(0.0, start_at - time.time()))
        # the grab just before the moves: a hand silent for hands.SILENT_SECONDS while it holds lets go
        await ws.send_str(f'{{"type":"grab","id":{cid}}}')
        if state["t0"] is None:
            state["t0"] = time.perf_counter()
        t0, (hx, hy, hz), r = state["t0"], state["home"], state["radius"]
        phase = 2 * math.pi * (d.index % 7) / 7
        tick = time.perf_counter()
        end = min(t0 + seconds, time.perf_counter() + deadline - time.time())
        while time.perf_counter() < end and not cut.is_set():
            a = phase + math.pi * (time.perf_counter() - t0)
            p = (round(hx + r * math.cos(a), 6), round(hy + r * math.sin(a), 6),
                 round(hz + 0.5 * r * math.sin(2 * a), 6))
            await ws.send_str(f'{{"type":"move","id":{cid},"position":[{p[0]!r},{p[1]!r},{p[2]!r}]}}')
            pending.append((time.perf_counter(), time.time(), struct.pack("<3f", *p)))
            d.sent += 1
            tick += MOVE_INTERVAL
            await asyncio.sleep(max(0.0, tick - time.perf_counter()))
        if cut.is_set():
            return "cut"
        await asyncio.sleep(0.5)  # the last moves' frames
        d.seconds = time.perf_counter() - t0
        await ws.send_str(f'{{"type":"release","id":{cid}}}')
        return "done"
    except (ConnectionError, RuntimeError):  # a send on a closing websocket
        return "cut"
    finally:
        receiver.cancel()
        await ws.close()


async def loop_lags(lags: list, until: float, tick: float = 0.005) -> None:
    """Until `until` (time.time): how late this loop wakes from a `tick` sleep, each lag over LAG_NOTED kept in `lags`
    as (when: time.time, seconds late)."""
    while time.time() < until:
        t = time.perf_counter()
        await asyncio.sleep(tick)
        late = time.perf_counter() - t - tick
        if late > LAG_NOTED:
            lags.append((time.time(), late))


def run_designers(urls: list[str], first: int, seconds: float, start_at: float, deadline: float, out) -> None:
    """A process of designers (one asyncio loop): their results, this process's CPU seconds and its loop's lags into
    `out`."""
    cpu0 = time.process_time()
    ds = [_Designer(first + i) for i in range(len(urls))]
    lags: list = []

    async def main():
        asyncio.ensure_future(loop_lags(lags, start_at + seconds + 1.0))
        tasks = [asyncio.ensure_future(designer(u, d, seconds, start_at, deadline)) for u, d in zip(urls, ds)]
        done, pending = await asyncio.wait(tasks, timeout=max(1.0, deadline - time.time()))
        for t in pending:
            t.cancel()
        for t, d in zip(tasks, ds):
            if t in done and t.exception() is not None:
                d.error = repr(t.exception())
            elif t in pending:
                d.error = d.error or "the deadline came"

    asyncio.run(main())
    if os.environ.get("SOMWIDGET_PROFILE_DIR") and "sitecustomize" in sys.modules:  # benchmarks/profile_hook
        getattr(sys.modules["sitecustomize"], "dump", lambda role: None)("designers")
    out.put(([d.result() for d in ds], time.process_time() - cpu0, lags))


def drive(urls: list[str], seconds: float, procs: int, lead: float, deadline: float) -> tuple[list, float, list]:
    """The designers of `urls` in `procs` processes, moving from `lead` seconds on for `seconds`; (their results, the
    designers' CPU seconds, their loops' lags: `loop_lags`). Processes that do not report by `deadline` (time.time)
    are ended, their designers counted as never answered."""
    ctx = multiprocessing.get_context("spawn")
    out = ctx.Queue()
    start_at = time.time() + lead
    chunks = [(i, urls[i::procs]) for i in range(procs) if urls[i::procs]]
    workers = [ctx.Process(target=run_designers, args=(chunk, i * 100000, seconds, start_at, deadline, out),
                           daemon=True) for i, chunk in chunks]
    for w in workers:
        w.start()
    results, cpu, lags = [], 0.0, []
    for _ in workers:
        try:
            got, used, late = out.get(timeout=max(1.0, deadline + 15.0 - time.time()))
        except queues.Empty:
            break
        results += got
        cpu += used
        lags += late
    for w in workers:
        w.join(5)
        if w.is_alive():
            w.kill()
    missing = len(urls) - len(results)
    results += [dict(vars(_Designer(-1)), error="its process did not report by the deadline")] * missing
    return results, cpu, lags


def summarise(views: list, seconds: float) -> dict:
    """Move -> frame over every designer; a designer that never connected counts its moves as unanswered."""
    lat = np.array([x for v in views for x in v["latencies"]]) * 1e3
    sent = sum(v["sent"] if v["connected"] else int(seconds / MOVE_INTERVAL) for v in views)
    pct = (lambda q: float(np.percentile(lat, q))) if len(lat) else (lambda q: float("nan"))
    moving = [v for v in views if v["seconds"] > 0]
    return {"moves": sent, "answered": len(lat) / max(sent, 1), "median_ms": pct(50), "p95_ms": pct(95),
            "p99_ms": pct(99), "frames": sum(v["frames"] for v in views),
            "designer_fps": float(np.mean([v["frames"] / v["seconds"] for v in moving])) if moving else 0.0,
            "silent": sum(not v["connected"] or not v["latencies"] for v in views),
            "errors": sorted({v["error"] for v in views if v["error"]})[:3]}


def back_after_cut(views: list, killed_at: float) -> dict:
    """The rooms cut when a worker was killed at `killed_at` (time.time): how many, and the seconds from the kill to
    each one's first answered move after it (None where none came)."""
    backs = [c[1] - killed_at if c[1] is not None else None for v in views for c in v["cuts"][:1]]
    got = [b for b in backs if b is not None]
    return {"cut": len(backs), "back": len(got), "back_max_s": max(got) if got else float("nan"),
            "back_median_s": float(np.median(got)) if got else float("nan")}
