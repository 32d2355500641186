"""The server's loop never waits on training (issue 35, item 4), over the views' websocket /view/ws of a real server
(XRServer) around a real Session:

- while the training thread is busy for a second and more (S set to 1,000,000: the engine builds its learning table),
  a drag's first move leaves the loop free: another view's ping comes back within 50 ms (it used to wait for the
  whole build, the loop held by the move waiting for the Som's lock);
- in the long training run that follows, a ping sent right behind a drag's first move comes back within 50 ms (a
  view's intents run on the training thread in the order they came, so that pong also says the grab and the first
  move were taken), and two other views' frames keep coming as often as before.

Timings on this 2-core machine are shared with whatever else runs: each figure is the median of several drags (the
first drag of a session pays for compiling the engine's local kernels and is not counted).
"""

from __future__ import annotations

import asyncio
import json
import time

import aiohttp
import numpy as np
import pytest
from helpers import settled_session

from somwidget.frontend.model import Session
from somwidget.frontend.web.standalone import XRServer

#: Round trip of a ping right behind a drag's first move, median over the drags (ms).
MAX_ROUND_TRIP_MS = 50.0
DRAGS = 7


@pytest.fixture(scope="module")
def session():
    yield from settled_session("car")


async def _watch(cs, base: str, arrivals: list, stop: asyncio.Event) -> None:
    """Another view: when each of its frames arrived."""
    async with cs.ws_connect(base + "/view/ws") as ws:
        while not stop.is_set():
            try:
                msg = await ws.receive(timeout=0.2)
            except asyncio.TimeoutError:
                continue
            if msg.type == aiohttp.WSMsgType.BINARY:
                arrivals.append(time.perf_counter())


async def _drags(base: str, session: Session) -> tuple[list[float], list[float], list[list[float]]]:
    async with aiohttp.ClientSession() as cs:
        stop = asyncio.Event()
        watched: list[list[float]] = [[], []]
        watchers = [asyncio.ensure_future(_watch(cs, base, arrivals, stop)) for arrivals in watched]
        async with cs.ws_connect(base + "/view/ws") as ws:
            async def pong(t: int, timeout: float = 60.0) -> None:
                deadline = time.perf_counter() + timeout
                while True:
                    msg = await ws.receive(timeout=deadline - time.perf_counter())
                    if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data) == {"type": "pong", "t": t}:
                        return

            await ws.send_json({"type": "set", "name": "iterations", "value": 1_000_000})
            await ws.send_json({"type": "train"})
            await ws.send_json({"type": "ping", "t": 0})
            await pong(0)
            ids = session.control_ids
            trips, firsts = [], []
            for n in range(DRAGS + 1):
                cid = ids[2 + n % 4]
                start = [float(v) for v in session.controls[ids.index(cid)][:3]]
                await asyncio.sleep(1.0)  # steady training
                await ws.send_json({"type": "grab", "id": cid})
                t = time.perf_counter()
                await ws.send_json({"type": "move", "id": cid, "position": [start[0], start[1], start[2] + 0.1]})
                await ws.send_json({"type": "ping", "t": n + 1})  # right behind the first move
                await pong(n + 1)
                if n:  # the first drag compiles the engine's local kernels: not counted
                    trips.append((time.perf_counter() - t) * 1e3)
                    firsts.append(t)
                for k in range(1, 8):
                    await ws.send_json({"type": "move", "id": cid,
                                        "position": [start[0], start[1], start[2] + 0.1 + 0.01 * k]})
                    await asyncio.sleep(0.03)
                await ws.send_json({"type": "release", "id": cid})
            await asyncio.sleep(1.0)
        stop.set()
        await asyncio.gather(*watchers)
    return trips, firsts, watched


async def _busy(base: str, session: Session) -> tuple[float, float]:
    """S set to 1,000,000, then at once a drag's first move; another view pings meanwhile. (its round trip, how
    long the set took the training thread), in ms."""
    async with aiohttp.ClientSession() as cs:
        async with cs.ws_connect(base + "/view/ws") as ws, cs.ws_connect(base + "/view/ws") as other:
            cid = session.control_ids[2]
            start = [float(v) for v in session.controls[2][:3]]
            t0 = time.perf_counter()
            await ws.send_json({"type": "set", "name": "iterations", "value": 1_000_000})
            await ws.send_json({"type": "grab", "id": cid})
            await ws.send_json({"type": "move", "id": cid, "position": [start[0], start[1], start[2] + 0.1]})
            await ws.send_json({"type": "ping", "t": 1})
            await asyncio.sleep(0.1)
            t = time.perf_counter()
            await other.send_json({"type": "ping", "t": 2})
            while True:
                msg = await other.receive(timeout=60)
                if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data) == {"type": "pong", "t": 2}:
                    trip = (time.perf_counter() - t) * 1e3
                    break
            while True:
                msg = await ws.receive(timeout=60)
                if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data) == {"type": "pong", "t": 1}:
                    busy = (time.perf_counter() - t0) * 1e3
                    break
            await ws.send_json({"type": "release", "id": cid})
    return trip, busy


def test_a_view_is_answered_at_once_while_another_views_first_move_waits_for_a_busy_trainer(session):
    assert session.parameters["iterations"] == 1000
    with XRServer(session) as srv:
        trip, busy = asyncio.run(asyncio.wait_for(_busy(srv.base, session), 120))
    print(f"another view's ping: {trip:.1f} ms, while the set and the first move took {busy:.0f} ms")
    assert busy > 300, "the set did not keep the training thread busy: nothing was shown"
    # at once, not behind the busy trainer: within 50 ms, or a tenth of the time the trainer was busy where a loaded
    # machine delays the one ping (111 ms against 2,137 ms in a CI run); a ping that waits for the trainer takes it all
    assert trip <= max(MAX_ROUND_TRIP_MS, 0.1 * busy), (trip, busy)


def test_a_ping_behind_a_drags_first_move_comes_back_at_once_and_other_views_keep_their_frames(session):
    with XRServer(session) as srv:
        trips, firsts, watched = asyncio.run(asyncio.wait_for(_drags(srv.base, session), 300))
    assert session.frame.iterations == 1_000_000 and session.frame.running  # a long run, all along
    median = float(np.median(trips))
    print(f"ping behind a first move: median {median:.1f} ms, all {[round(x, 1) for x in trips]}")
    assert median <= MAX_ROUND_TRIP_MS, trips
    for arrivals in watched:  # the gaps between frames just after a first move, against the steady ones
        t = np.array(arrivals)
        gaps = np.diff(t)
        after = np.array([any(0.0 <= a - f <= 0.5 for f in firsts) for a in t[1:]])
        steady = np.array([all(not -0.5 <= a - f <= 1.0 for f in firsts) for a in t[1:]])
        worst = [gaps[(t[1:] >= f) & (t[1:] <= f + 0.5)].max() for f in firsts]
        before = [gaps[(t[1:] >= f - 0.5) & (t[1:] < f)].max() for f in firsts]  # the same half second, steady
        print(f"another view: steady gaps median {np.median(gaps[steady]) * 1e3:.1f} ms, p90 "
              f"{np.percentile(gaps[steady], 90) * 1e3:.1f} ms; after a first move median "
              f"{np.median(gaps[after]) * 1e3:.1f} ms, worst per drag {[round(w * 1e3) for w in worst]} ms, in the "
              f"half second before {[round(w * 1e3) for w in before]} ms")
        assert steady.sum() > 30 and after.sum() > 5 * len(firsts), "too few frames to compare"
        # unchanged: the frames just after a first move come as often as the steady ones (medians), and the worst
        # gap in the half second after a first move is within twice the worst in the steady half second before it
        # (medians over the drags: a stall at each first move shows, the machine's load is in both)
        assert np.median(gaps[after]) <= 1.5 * np.median(gaps[steady]) + 0.005
        assert np.median(worst) <= 2.0 * np.median(before) + 0.030, (worst, before)
