"""The studio under load: rooms with one designer each dragging at 30 moves a second, the engine alone batched, and
Dask actors against the workers' own servers.

Modes:

rooms (default)   A real studio (StudioServer: the front, and the rooms in its process or in --workers worker
                  processes, one a GPU in turn) serves R rooms (--presets car: all the car; mixed: car, sphere, torus,
                  lines in turn). R designers, websocket clients in --client-procs processes of their own, each in a
                  room of its own through the front (/r/<name>/view/ws, its token), grab control 0 and move it every
                  1/30 s on a small circle for --seconds. A move is answered by the first frame that designer
                  receives showing its control where it sent it (a move overtaken before a frame went out counts as
                  superseded). Per R:
                  move -> frame median / p95 / p99 (ms), the share answered, frames a second each designer gets, the
                  server's CPU (cores busy: the front and its workers), memory a room (the server processes' resident
                  memory and, on a GPU, the device memory in use, before and after the rooms were made, over R) and
                  whether p95 <= 50 ms. The largest R that passes is printed last.
engine            The engine alone, as the rooms step it (no server; numpy and warp only): R car rooms' Soms, each
                  round every room's control 0 moved (a local restart), 10 cycles stepped and its weights read back
                  (its frame); `own`: each Som by itself, one after another (the rooms unbatched); `studio`: the
                  studio's rounds (studio/batched.py: the rooms' states held in one BatchSom between rounds, each
                  room's move applied to its Som and its controls and cycle put in, one launch, every weight back in
                  one copy, each frame its row; one room steps alone, as the worker's loop steps it); `kernels`: the
                  batched kernels alone (every state loaded, controls up, one launch, every weight back). Round time
                  median / p95 and whether R rooms keep 30 frames a second (p95 <= 33 ms); `studio host ms`: the
                  studio's round less its launch (the rooms' moves, the per-room work, the frames' rows).
dask              A LocalCluster of two workers (processes): R rooms on its workers reached (a) through the front
                  relaying to the workers' own room servers (what the studio does), (b) as Dask actors (a move is an
                  actor call, frames come back by long-polling calls); move -> frame as in `rooms`.

GPU runs need numpy, warp-lang, aiohttp (and its dependencies: aiohappyeyeballs, aiosignal, attrs, frozenlist,
multidict, propcache, yarl, idna, typing_extensions) and platformdirs; nothing here imports trame, pyvista, trimesh or
vtk (checked at start: --check-imports).

Usage:
    python benchmarks/bench_studio.py --rooms 1,2,4 --device cpu                       # this machine
    python benchmarks/bench_studio.py --rooms 32,64,128,256 --device cuda --workers 4  # one GPU, 4 processes
    CUDA_VISIBLE_DEVICES=0,1 python benchmarks/bench_studio.py --device cuda --workers 2 --rooms 64,128,256,512
    python benchmarks/bench_studio.py --mode engine --rooms 256,1024,2048 --device cuda
    python benchmarks/bench_studio.py --mode dask --rooms 2
    python benchmarks/bench_studio.py --device cuda --gpus 1 --workers-per-gpu 2,4,8 --rooms 128,256,320  # a sweep
    python benchmarks/bench_studio.py --device cuda --gpus 1 --rooms 128 --profile prof  # prof/profile.txt by role
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from studio_load import back_after_cut, drive, loop_lags, summarise  # noqa: E402 (benchmarks/, next to this file)

MOVE_INTERVAL = 1.0 / 30.0  # s: 30 moves a second
TARGET_MS = 50.0
MIXED = ("car", "sphere", "torus", "lines")
HEAVY = ("trame", "pyvista", "trimesh", "vtk", "vtkmodules", "wslink", "ipywidgets", "anywidget")


def check_imports() -> list[str]:
    """The UI packages the GPU mode's imports pulled in (none expected)."""
    import somwidget.frontend.studio.serve  # noqa: F401
    import somwidget.frontend.studio.worker  # noqa: F401
    from somwidget.frontend.transport import messages  # noqa: F401

    return sorted({m.split(".")[0] for m in sys.modules} & set(HEAVY))


# -- the server's processes ------------------------------------------------------------------------------------------
def cpu_seconds(pids: list[int]) -> float:
    total = 0.0
    tick = os.sysconf("SC_CLK_TCK")
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
        except (OSError, IndexError, ValueError):
            pass
    return total


def memory(studio) -> tuple[float, float]:
    """(resident MB of the server's processes, GPU MB in use on their devices) as the places report them."""
    async def loads():
        return [await p.health() for p in studio.front.alive()]

    reports = [r["load"] for r in studio.call(loads())]
    rss = sum(r.get("rss_mb", 0.0) for r in reports)
    if studio.workers:
        from somwidget.frontend.studio.limits import resident_bytes

        rss += resident_bytes() / 2**20  # the front
    gpus = {}
    for place, r in zip(studio.front.alive(), reports):
        gpus[getattr(place, "label", "").split(" worker")[0]] = r.get("gpu_mb", 0.0)
    return rss, sum(gpus.values())


def round_timings(studio) -> list[dict]:
    """Each worker's latest rounds as it reports them (rounds.py `timings`)."""
    async def loads():
        return [await p.health() for p in studio.front.alive()]

    return [r["load"].get("round", {}) for r in studio.call(loads())]


def timed_checks(front) -> list[tuple[float, float]]:
    """The front's looks at its places from now on, each (began: time.time, seconds it took), in the list returned."""
    looks: list[tuple[float, float]] = []
    check = front.check

    async def timed(place):
        began, t = time.time(), time.perf_counter()
        try:
            await check(place)
        finally:
            looks.append((began, time.perf_counter() - t))

    front.check = timed
    return looks


def tail_causes(views: list, looks: list, rounds: list[dict], window: tuple[float, float]) -> dict:
    """Where the slow moves came from: how periodic they are, the front's looks at its places (p95 and longest
    ms) and the workers' rounds (median, p95, longest of any worker)."""
    slow = np.array([t for v in views for t in v.get("slow", []) if window[0] <= t <= window[1]])
    took = np.array([d for b, d in looks if window[0] <= b <= window[1]] or [0.0])
    timed = [r for r in rounds if r.get("rounds")]
    # how periodic the slow moves are: the mean resultant length of their phases (0: spread evenly, 1: all at one
    # phase) for a period of 1 s (the front's looks) and of 2 s (the rooms' autosaves while a drag is held)
    phase = {f"slow_phase_{p:g}s": float(abs(np.mean(np.exp(2j * np.pi * slow / p)))) if len(slow) else float("nan")
             for p in (1.0, 2.0)}
    return {**phase, "slow_moves": int(len(slow)),
            "look_p95_ms": float(np.percentile(took, 95) * 1e3), "look_max_ms": float(took.max() * 1e3),
            "round_median_ms": max((r["median_ms"] for r in timed), default=float("nan")),
            "round_p95_ms": max((r["p95_ms"] for r in timed), default=float("nan")),
            "round_max_ms": max((r["max_ms"] for r in timed), default=float("nan"))}


def lag_figures(role: str, lags: list, window: tuple[float, float]) -> dict:
    """The event loops' lags of `role` (studio_load.loop_lags) in the moving window: the seconds late in all (summed
    over the role's loops) and the longest."""
    late = [d for t, d in lags if window[0] <= t <= window[1]]
    return {f"{role}_lag_s": float(sum(late)), f"{role}_lag_max_ms": 1e3 * max(late, default=0.0)}


def causes_line(c: dict) -> str:
    return (f"#   slow moves {c['slow_moves']}: their phase at 1 s {c['slow_phase_1s']:.2f}, "
            f"at 2 s {c['slow_phase_2s']:.2f} (0 even, 1 at one phase); the front's look at a place p95 "
            f"{c['look_p95_ms']:.0f} ms, longest {c['look_max_ms']:.0f}; the front's loop late "
            f"{c['front_lag_s']:.2f} s in all, at most {c['front_lag_max_ms']:.0f} ms; the designers' loops "
            f"{c['designers_lag_s']:.2f} s, at most {c['designers_lag_max_ms']:.0f} ms; the slowest worker's rounds "
            f"median {c['round_median_ms']:.1f} ms, p95 {c['round_p95_ms']:.1f}, longest {c['round_max_ms']:.1f}")


def server_pids(studio) -> list[int]:
    pids = [os.getpid()]
    if studio.pool is not None and hasattr(studio.pool, "procs"):
        pids += [p.pid for p in studio.pool.procs.values()]
    return pids


async def _workers_up(front, count: int, timeout: float) -> None:
    """Until `count` workers answer (32 workers starting on one host took longer than the studio's own start: the
    first rooms were refused, "no worker for rooms now")."""
    end = time.time() + timeout
    while len(front.alive()) < count and time.time() < end:
        await asyncio.sleep(0.2)


async def _make_rooms(front, names: list[str], presets: tuple[str, ...], at_once: int) -> None:
    """The rooms, `at_once` made at a time (each on the least loaded place)."""
    gate = asyncio.Semaphore(at_once)

    async def one(i, name):
        async with gate:
            await front.create(name, presets[i % len(presets)])

    await asyncio.gather(*(one(i, n) for i, n in enumerate(names)))


@contextlib.contextmanager
def started(studio, timeout: float):
    """The studio started (given `timeout` seconds: its workers start slower under the profiler), stopped after."""
    try:
        yield studio.start(timeout)
    finally:
        studio.stop()


def _kill_one(studio) -> tuple[object, int]:
    """SIGKILL the worker process with the most rooms; (its place, its room count)."""
    import signal

    procs = studio.pool.procs
    place = max(procs, key=lambda p: p.load.get("rooms", 0))
    os.kill(procs[place].pid, signal.SIGKILL)
    return place, int(place.load.get("rooms", 0))


def run_rooms(count: int, presets: tuple[str, ...], seconds: float, device: str, workers: int, procs: int,
              deadline: float, kill: bool = False) -> dict:
    """R rooms with a designer each (the module's docstring); `kill`: a worker killed halfway through the moving,
    its rooms' time back measured. Whatever happens, it ends by `deadline` (time.time)."""
    from somwidget.frontend.studio.limits import StudioLimits
    from somwidget.frontend.studio.serve import StudioServer

    limits = StudioLimits(rooms=max(64, count + 1), park_after=0)
    made = float("nan")
    with started(StudioServer(tempfile.mkdtemp(prefix="bench-studio-"), device=device, workers=workers,
                              limits=limits), max(180.0, deadline - time.time() - 60.0)) as studio:
        left = lambda: max(1.0, deadline - time.time())  # noqa: E731
        studio.call(_workers_up(studio.front, max(1, workers), left() - 30.0), timeout=left())
        looks = timed_checks(studio.front)
        front_lags: list = []
        # a room on each place first: what the first room loads is not a room's
        studio.call(_make_rooms(studio.front, [f"warm{p}" for p in range(max(1, workers))], presets, 64),
                    timeout=left())
        time.sleep(2.0)
        rss0, gpu0 = memory(studio)
        names = [f"d{i}" for i in range(count)]
        t0 = time.perf_counter()
        studio.call(_make_rooms(studio.front, names, presets, 4 * max(1, workers)), timeout=left())
        made = time.perf_counter() - t0
        urls = [studio.room_url(n).replace("http", "ws", 1).replace("/?token=", "/view/ws?token=") for n in names]
        time.sleep(min(20.0, 2.0 + 0.02 * count))  # the rooms grow their shapes (the car) meanwhile
        rss1, gpu1 = memory(studio)
        front, workers_pids = [os.getpid()], server_pids(studio)[1:]
        lead = 5.0 + 0.02 * count
        c0, w0 = cpu_seconds(front), cpu_seconds(workers_pids)
        t0 = time.perf_counter()
        killed = None
        if kill:
            import threading

            def killer():
                time.sleep(lead + seconds / 2)
                killed_place, rooms_there = _kill_one(studio)
                killed.update(at=time.time(), label=killed_place.label, rooms=rooms_there)

            killed = {}
            threading.Thread(target=killer, daemon=True).start()
        moving_end = time.time() + lead + seconds + 1.0
        asyncio.run_coroutine_threadsafe(loop_lags(front_lags, moving_end), studio._loop)
        views, designer_cpu, designer_lags = drive(urls, seconds, procs, lead, min(deadline - 20.0, moving_end + 30.0))
        wall = time.perf_counter() - t0
        rounds = round_timings(studio) if not kill else []
        front_cores = (cpu_seconds(front) - c0) / wall
        worker_cores = (cpu_seconds(workers_pids) - w0) / wall if kill is False else float("nan")
    out = summarise(views, seconds)
    frames = max(1, out["frames"])
    out.update(rooms=count, presets="+".join(presets), made_s=made, rss_mb_room=(rss1 - rss0) / count,
               gpu_mb_room=(gpu1 - gpu0) / count, front_cores=front_cores, worker_cores=worker_cores,
               designer_cores=designer_cpu / wall, server_cores=front_cores + worker_cores,
               front_ms_frame=1e3 * front_cores * wall / frames, worker_ms_frame=1e3 * worker_cores * wall / frames,
               designer_ms_frame=1e3 * designer_cpu / frames,
               ok=out["p95_ms"] <= TARGET_MS and out["answered"] >= 0.9 and not out["silent"])
    out["cpu_ms_frame"] = out["front_ms_frame"] + out["worker_ms_frame"]
    window = (moving_end - seconds - 1.0, moving_end)
    out.update(tail_causes(views, looks, rounds, window))
    out.update(lag_figures("front", front_lags, window), **lag_figures("designers", designer_lags, window))
    if killed is not None:
        out.update(killed=killed, **back_after_cut(views, killed.get("at", float("nan"))))
    return out


ROOMS_HEAD = (f"{'GPUs':>4} {'workers':>7} {'rooms':>5} {'moves':>6} {'answered':>8} {'median':>7} {'p95':>7} "
              f"{'p99':>7} {'fps':>5} {'front':>6} {'workers':>7} {'designers':>9} {'server ms/frame':>15} "
              f"{'MB/room':>7} {'GPU MB/room':>11} {'ok':>3}")


def rooms_line(r: dict, gpus, workers: int) -> str:
    """One row of ROOMS_HEAD: cores busy by role, server CPU a frame (front + workers)."""
    return (f"{gpus!s:>4} {workers:>7} {r['rooms']:>5} {r['moves']:>6} {r['answered']:>8.0%} {r['median_ms']:>7.1f} "
            f"{r['p95_ms']:>7.1f} {r['p99_ms']:>7.1f} {r['designer_fps']:>5.1f} {r['front_cores']:>6.2f} "
            f"{r['worker_cores']:>7.2f} {r['designer_cores']:>9.2f} {r['cpu_ms_frame']:>15.2f} "
            f"{r['rss_mb_room']:>7.1f} {r['gpu_mb_room']:>11.1f} {'yes' if r['ok'] else 'no':>3}"
            + (f"  ({r['silent']} rooms never answered: {r['errors']})" if r["silent"] else ""))


# -- the engine alone -----------------------------------------------------------------------------------------------
def run_engine(count: int, device: str, rounds: int, own_rooms: bool = True) -> dict:
    """R car rooms' Soms (as the studio's rooms hold them), each round every room's control 0 moved (its local
    restart), 10 cycles stepped and its weights read back (its frame); three ways: each Som alone (`own`), the
    studio's rounds (BatchedRooms: the states held in one BatchSom, each room's move applied to its Som and its
    controls and cycle put in, one launch, one read-back of every weight, each frame its row: `studio`), and the
    batched kernels alone (every state loaded, one launch, one read-back of every weight: `kernels`)."""
    import warp as wp

    from somwidget.backend import presets as _presets
    from somwidget.backend.batch import BatchSom
    from somwidget.frontend.studio.batched import BatchedRooms

    preset = _presets.get_preset("car")
    som = preset.make_som(device=device)
    som.train()
    settled = som.weights
    base = np.asarray(preset.controls, np.float32)

    def moved(r: int) -> np.ndarray:
        c = np.repeat(base[None], count, axis=0).copy()
        c[:, 0, :3] += 0.05 * np.stack([np.cos(r + np.arange(count)), np.sin(r + np.arange(count)),
                                        np.zeros(count)], axis=1).astype(np.float32)
        return c

    def rooms() -> list:
        made = []
        for _ in range(count):
            s = preset.make_som(device=device)  # one preset: its topology (and distance table) shared
            s.restore(settled, s.iterations)
            made.append(s)
        return made

    def timed(one_round) -> np.ndarray:
        times = []
        for r in range(rounds):
            controls = moved(r)
            t = time.perf_counter()
            one_round(controls)
            if device != "cpu":
                wp.synchronize_device(device)
            times.append(time.perf_counter() - t)
        skip = min(2, rounds - 1)  # the first rounds compile and warm up
        return np.array(times[skip:]) * 1e3

    soms = rooms()

    def own(controls):
        for b, s in enumerate(soms):
            s.set_controls(controls[b])
            s.step(10)
            _ = s.weights

    own_ms = timed(own) if own_rooms else np.full(1, np.nan)
    for s in soms:
        s.restore(settled, s.iterations)
    batches = BatchedRooms()
    key = batches.key(soms[0])

    def studio(controls):
        for b, s in enumerate(soms):
            s.set_controls(controls[b])
            if count > 1:
                batches.hold(b, s, key)
        if count == 1:  # a room alone steps by itself (rounds.py)
            soms[0].step(10)
            _ = soms[0].weights
            return
        got = batches.step([(b, 10) for b in range(count)])
        launched.append(got[0][1])  # the launch and the one copy of every weight out
        for b in range(count):
            _ = batches.host(b)

    launched: list[float] = []
    studio_ms = timed(studio)
    assert count == 1 or (batches.launches == rounds and batches.widest == count)  # all in each round's launch
    soms.clear()  # their memory goes before the batch is made
    batch = BatchSom(preset.topology, settled, moved(0), iterations=preset.iterations, l_start=preset.l_start,
                     l_end=preset.l_end, smoothing=preset.smoothing, reach=preset.reach,
                     smooth_dims=preset.smooth_dims, metric_weights=preset.metric_weights, mirror=preset.mirror,
                     device=device)
    state = {"w": np.repeat(settled[None], count, axis=0)}

    def kernels(controls):
        batch.load(state["w"], np.full(count, preset.iterations, np.int64), controls)
        batch.restart()
        batch.step(10)
        state["w"] = batch.weights

    kernels_ms = timed(kernels)
    frame = 1e3 / 30

    def figures(name, ms):
        return {f"{name}_median_ms": float(np.median(ms)), f"{name}_p95_ms": float(np.percentile(ms, 95)),
                f"{name}_30fps": float(np.percentile(ms, 95)) <= frame}

    # the round's host work: the studio's round less its launch (the kernels and the one copy of every weight out)
    launch_ms = np.array(launched[min(2, rounds - 1):]) * 1e3 if count > 1 else np.zeros(1)
    host_ms = studio_ms - launch_ms
    return {"rooms": count, **figures("own", own_ms), **figures("studio", studio_ms), **figures("kernels", kernels_ms),
            "host_median_ms": float(np.median(host_ms))}


# -- Dask: actors against the workers' own servers ---------------------------------------------------------------------
class RoomActor:
    """A room as a Dask actor (for the comparison only): a Session on the worker; `move` queues a drag's move,
    `frame_after(seq)` waits for a newer frame and returns (seq, encoded frame)."""

    def __init__(self, preset: str):
        from somwidget.frontend.model import Session

        self.session = Session(preset, device="cpu", autosave=False, frame_rate=30.0)
        self.session.wait_idle(300)
        self.session.begin_gesture()
        self._event = None

    def control(self) -> list:
        return [float(v) for v in self.session.controls[0][:3]]

    async def move(self, position) -> None:
        self.session.move_control(0, position)

    async def frame_after(self, seq: int):
        from somwidget.frontend.transport.frames import encode_frame

        loop = asyncio.get_running_loop()
        while self.session.frame.seq <= seq:
            event = asyncio.Event()

            def wake(_frame, event=event):
                loop.call_soon_threadsafe(event.set)

            self.session.add_listener(wake, replay=False)
            try:
                if self.session.frame.seq <= seq:
                    await asyncio.wait_for(event.wait(), 5.0)
            except asyncio.TimeoutError:
                pass
            finally:
                self.session.remove_listener(wake)
        frame = self.session.frame
        return frame.seq, encode_frame(frame, self.session)


async def _actor_designer(actor, seconds: float, index: int) -> dict:
    from somwidget.frontend.transport.frames import decode_frame

    home = np.array(await actor.control(), np.float64)
    pending, latencies, sent, frames = [], [], 0, 0
    done = asyncio.Event()

    async def poll():
        nonlocal frames
        seq = -1
        while not done.is_set():
            seq, data = await actor.frame_after(seq)
            now = time.perf_counter()
            frames += 1
            shown = tuple(float(v) for v in decode_frame(data)["control_positions"][0])
            for m, (t, p) in enumerate(pending):
                if p == shown:
                    latencies.append(now - t)
                    del pending[:m + 1]
                    break

    poller = asyncio.ensure_future(poll())
    t0 = time.perf_counter()
    tick = t0
    phase = 2 * math.pi * index / 7
    while time.perf_counter() - t0 < seconds:
        a = phase + 2 * math.pi * (time.perf_counter() - t0) / 2.0
        p = np.round(home + 0.06 * np.array([math.cos(a), math.sin(a), 0.5 * math.sin(2 * a)]), 6)
        sent_at = time.perf_counter()
        await actor.move([float(v) for v in p])
        pending.append((sent_at, tuple(float(v) for v in np.float32(p))))
        sent += 1
        tick += MOVE_INTERVAL
        await asyncio.sleep(max(0.0, tick - time.perf_counter()))
    await asyncio.sleep(0.5)
    done.set()
    poller.cancel()
    return {"latencies": latencies, "sent": sent, "frames": frames, "seconds": time.perf_counter() - t0,
            "connected": True, "error": None, "cuts": []}


def run_dask(count: int, seconds: float) -> list[dict]:
    from distributed import Client, LocalCluster

    from somwidget.frontend.studio.limits import StudioLimits
    from somwidget.frontend.studio.serve import StudioServer

    env = {"PYTHONPATH": str(ROOT), "SOMWIDGET_DATA_DIR": tempfile.mkdtemp(prefix="bench-studio-data-")}
    out = []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, env=env) as cluster:
        with StudioServer(tempfile.mkdtemp(prefix="bench-studio-"), device="cpu", scheduler=cluster.scheduler_address,
                          limits=StudioLimits(park_after=0)) as studio:
            names = [f"d{i}" for i in range(count)]
            for name in names:
                studio.call(studio.front.create(name, "car"), timeout=600)
            time.sleep(15)
            urls = [studio.room_url(n).replace("http", "ws", 1).replace("/?token=", "/view/ws?token=") for n in names]
            views, _, _ = drive(urls, seconds, 1, 10.0, time.time() + seconds + 120)
            out.append(dict(summarise(views, seconds), path="front -> workers' own servers", rooms=count))

        async def actors():
            async with Client(cluster.scheduler_address, asynchronous=True) as client:
                handles = [await client.submit(RoomActor, "car", actor=True, pure=False) for _ in range(count)]
                return await asyncio.gather(*(_actor_designer(h, seconds, i) for i, h in enumerate(handles)))

        views = asyncio.run(actors())
        out.append(dict(summarise(views, seconds), path="Dask actors (calls, long-polled frames)", rooms=count))
    return out


# -- GPU counts, the deadline --------------------------------------------------------------------------------------
def default_procs(count: int) -> int:
    """Designer processes: one per 24 designers, at most a quarter of the cores (the studio has the rest). At 48 a
    process, 512 designers on a 64-core host answered 86% of their moves where 22 processes answered 99%
    (BENCHMARKS.md, "The tail at four GPUs")."""
    return max(1, min(math.ceil(count / 24), (os.cpu_count() or 4) // 4))


def trial_seconds(count: int, seconds: float) -> float:
    """About how long one room count takes here: workers starting, rooms made, their shapes grown, the moving,
    the studio closed."""
    return 30.0 + seconds + 0.12 * count


def workers_of(g: int, per_gpu: int) -> int:
    """Worker processes for g GPUs: per_gpu each (0: cores / (2 GPUs), at most 8 a GPU)."""
    return g * (per_gpu or max(1, min(8, (os.cpu_count() or 2) // (2 * g))))


def run_gpu_counts(args, gpu_counts: list[int], per_gpu: list[int], presets: tuple[str, ...]) -> list[dict]:
    """For each GPU count g (the first g GPUs, rooms on the least loaded GPU) and each --workers-per-gpu w in turn:
    g x --rooms designers in turn, up to the first count that misses p95 <= 50 ms, within --budget seconds a (g, w);
    then the most designers that passed for each and the ratio to one GPU (same w); with --kill-worker a run more
    that kills a worker (the largest g, the w that passed the most designers there)."""
    from somwidget.frontend.studio.workers import gpu_ids

    visible = gpu_ids() if args.device != "cpu" else [str(i) for i in range(max(gpu_counts))]
    before = os.environ.get("CUDA_VISIBLE_DEVICES")
    results, best = [], {}
    for g in gpu_counts:
        if g > len(visible):
            print(f"# {g} GPUs: this host has {len(visible)}; skipped", flush=True)
            continue
        if args.device != "cpu":
            os.environ["CUDA_VISIBLE_DEVICES"] = ",".join(visible[:g])
        for w in args.workers_per_gpu:
            workers = workers_of(g, w)
            end = time.time() + args.budget
            best[g, w] = 0
            for per in per_gpu:
                count = per * g
                need = trial_seconds(count, args.seconds)
                if time.time() + need > end:
                    print(f"# {g} GPUs, {workers} workers, {count} rooms: not started (about {need:.0f} s; "
                          f"{end - time.time():.0f} s of the budget left)", flush=True)
                    break
                r = run_rooms(count, presets, args.seconds, args.device, workers,
                              args.client_procs or default_procs(count), end)
                r.update(gpus=g, workers=workers)
                results.append(r)
                print(rooms_line(r, g, workers), flush=True)
                print(causes_line(r), flush=True)
                if not r["ok"]:
                    break
                best[g, w] = count
    if before is None:
        os.environ.pop("CUDA_VISIBLE_DEVICES", None)
    else:
        os.environ["CUDA_VISIBLE_DEVICES"] = before

    def shown(g, w, n):
        one = best.get((1, w))
        return (f"{g} GPU{'s' if g > 1 else ''} x {workers_of(g, w) // g} workers: {n}"
                + (f" ({n / one:.2f}x one GPU)" if one and g > 1 else ""))

    print(f"# most designers at p95 <= {TARGET_MS:g} ms ({args.presets} rooms, one a designer): "
          + "; ".join(shown(g, w, n) for (g, w), n in best.items()), flush=True)
    if args.kill_worker and best:
        g = max(g for g, _ in best)
        w = max((w for gg, w in best if gg == g), key=lambda w: best[g, w])
        count = max(best[g, w], per_gpu[0] * g)
        if args.device != "cpu":
            os.environ["CUDA_VISIBLE_DEVICES"] = ",".join(visible[:g])
        workers = workers_of(g, w)
        r = run_rooms(count, presets, args.seconds, args.device, workers, args.client_procs or default_procs(count),
                      time.time() + args.budget, kill=True)
        r.update(gpus=g, workers=workers)
        results.append(r)
        k = r.get("killed", {})
        print(f"# a worker killed halfway ({g} GPUs, {workers} workers, {count} rooms): {k.get('label', '?')} held "
              f"{k.get('rooms', '?')} rooms; {r['back']} of the {r['cut']} designers cut answered again, the last "
              f"{r['back_max_s']:.1f} s after the kill (median {r['back_median_s']:.1f} s); all moves: answered "
              f"{r['answered']:.0%}, p95 {r['p95_ms']:.1f} ms", flush=True)
    return results


def watchdog(seconds: float) -> None:
    """Past `seconds` from now: say so, end this run's child processes (the studio's workers, the designers) and exit;
    what was measured is printed already."""
    if seconds <= 0:
        return
    import signal
    import threading

    def fire():
        print(f"# deadline: the run passed its {seconds:.0f} s and ends here (the figures above stand)", flush=True)
        me = str(os.getpid())
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                if stat.read_text().rsplit(")", 1)[1].split()[1] == me:
                    os.kill(int(stat.parent.name), signal.SIGKILL)
            except (OSError, IndexError, ValueError):
                pass
        os._exit(3)

    timer = threading.Timer(seconds, fire)
    timer.daemon = True
    timer.start()


# -- profiling every process (benchmarks/profile_hook) -------------------------------------------------------------
HOOK = Path(__file__).resolve().parent / "profile_hook"


def profiling(folder: str) -> bool:
    """Whether this process runs under the hook, profiling into `folder`."""
    hook = sys.modules.get("sitecustomize")
    return (getattr(hook, "_DIR", None) == str(Path(folder).resolve())
            and Path(getattr(hook, "__file__", "")).resolve().parent == HOOK)


def profiled_again(folder: str, argv, clock: str = "wall") -> int:
    """This command again under the hook (its folder first on PYTHONPATH, SOMWIDGET_PROFILE_DIR set): every process
    it starts (the studio's workers, the designers) is profiled from its first line (`clock`: wall or each thread's
    CPU time); its exit status."""
    import subprocess

    out = Path(folder).resolve()
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.prof"):
        old.unlink()
    path = os.pathsep.join(p for p in (str(HOOK), str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    env = dict(os.environ, PYTHONPATH=path, SOMWIDGET_PROFILE_DIR=str(out), SOMWIDGET_PROFILE_CLOCK=clock)
    args = sys.argv[1:] if argv is None else list(argv)
    return subprocess.call([sys.executable, str(Path(__file__).resolve()), *args], env=env)


def summarise_profiles(folder: str) -> Path:
    """This process's profile written (the studio's workers wrote theirs as they stopped), then DIR/profile.txt."""
    from profile_summary import write_summary

    sys.modules["sitecustomize"].dump("front")
    return write_summary(folder)


# -- the command -----------------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=("rooms", "engine", "dask"), default="rooms")
    parser.add_argument("--rooms", default="1,2,4", help="room counts to try, comma-separated")
    parser.add_argument("--presets", choices=("car", "mixed"), default="car")
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--workers", type=int, default=0, help="worker processes (0: the rooms in the server's own)")
    parser.add_argument("--client-procs", type=int, default=0,
                        help="designer processes (0: one per 24 designers, at most a quarter of the cores)")
    parser.add_argument("--gpus", default="", help="rooms mode: GPU counts to run in turn (e.g. 1,2,4): --rooms per "
                        "GPU, --workers-per-gpu workers a GPU; the most designers at p95 <= 50 ms each and the ratio")
    parser.add_argument("--workers-per-gpu", default="0", help="with --gpus: worker processes a GPU, or several to "
                        "run in turn, comma-separated (e.g. 2,4,8; 0: cores / (2 GPUs), at most 8)")
    parser.add_argument("--profile", default=None, metavar="DIR", help="profile every process of the run "
                        "(benchmarks/profile_hook: cProfile, one file a process) and summarise them by role in "
                        "DIR/profile.txt (the top functions of the front, the workers, the designers)")
    parser.add_argument("--profile-clock", choices=("wall", "cpu"), default="wall", help="with --profile: what a "
                        "profile counts: wall time, or each thread's CPU time (Python 3.11 and older; a machine shared "
                        "with other work then compares by the work done)")
    parser.add_argument("--budget", type=float, default=300.0, help="rooms mode: seconds for each GPU count (or "
                        "room count without --gpus); a room count that would not fit what is left is not started")
    parser.add_argument("--deadline", type=float, default=0.0, help="rooms mode: seconds for the whole run (0: the "
                        "budgets and 2 minutes); past it, what was measured stays printed and the run ends")
    parser.add_argument("--kill-worker", action="store_true", help="with --gpus: after each GPU count's largest "
                        "room count, one run more killing a worker halfway: seconds until its rooms answer again")
    parser.add_argument("--rounds", type=int, default=20, help="engine mode: rounds timed")
    parser.add_argument("--no-own", action="store_true", help="engine mode: leave out the rooms stepped one by one")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    if args.profile and not profiling(args.profile):
        return profiled_again(args.profile, argv, args.profile_clock)
    args.workers_per_gpu = [int(v) for v in str(args.workers_per_gpu).split(",") if v.strip()] or [0]
    # the rooms' sessions keep their folders under the rooms folder; anything else goes to a folder of this run
    os.environ.setdefault("SOMWIDGET_DATA_DIR", tempfile.mkdtemp(prefix="bench-studio-data-"))
    heavy = check_imports() if args.mode != "engine" else []  # the engine alone needs numpy and warp only
    if heavy:
        print(f"# warning: the studio's imports pulled in {heavy}", flush=True)
    counts = [int(v) for v in args.rooms.split(",") if v.strip()]
    gpu_counts = [int(v) for v in args.gpus.split(",") if v.strip()]
    gpus = os.environ.get("CUDA_VISIBLE_DEVICES", "all")
    print(f"# bench_studio {args.mode}: {platform.node()}, {os.cpu_count()} CPUs, device {args.device} "
          f"(CUDA_VISIBLE_DEVICES={gpus}), workers {args.workers}, {time.strftime('%Y-%m-%d %H:%M')}", flush=True)
    results = []
    if args.mode == "rooms":
        watchdog(args.deadline or (args.budget * len(gpu_counts) + 120 if gpu_counts else 0))
        presets = ("car",) if args.presets == "car" else MIXED
        print(ROOMS_HEAD, flush=True)
        if not gpu_counts:  # the rooms as given, the workers as given
            for count in counts:
                procs = args.client_procs or default_procs(count)
                r = run_rooms(count, presets, args.seconds, args.device, args.workers, procs, time.time() + args.budget)
                results.append(r)
                print(rooms_line(r, "-", args.workers), flush=True)
                print(causes_line(r), flush=True)
            passing = [r["rooms"] for r in results if r["ok"]]
            print(f"# most rooms with p95 <= {TARGET_MS:g} ms: {max(passing) if passing else 'none'} "
                  f"(of {', '.join(map(str, counts))}; presets {args.presets})", flush=True)
        else:
            results = run_gpu_counts(args, gpu_counts, counts, presets)
    elif args.mode == "engine":
        print(f"{'rooms':>6} " + " ".join(f"{w + ' median':>15} {w + ' p95':>12} {w + ' 30/s':>12}"
                                           for w in ("own", "studio", "kernels"))
              + f" {'studio host ms':>15}", flush=True)
        for count in counts:
            r = run_engine(count, args.device, args.rounds, not args.no_own)
            results.append(r)
            print(f"{r['rooms']:>6} " + " ".join(
                f"{r[w + '_median_ms']:>15.2f} {r[w + '_p95_ms']:>12.2f} {'yes' if r[w + '_30fps'] else 'no':>12}"
                for w in ("own", "studio", "kernels")) + f" {r['host_median_ms']:>15.2f}", flush=True)
    else:
        for count in counts:
            for r in run_dask(count, args.seconds):
                results.append(r)
                print(f"{r['path']:<42} rooms {r['rooms']}: moves {r['moves']}, answered {r['answered']:.0%}, "
                      f"median {r['median_ms']:.1f} ms, p95 {r['p95_ms']:.1f} ms, p99 {r['p99_ms']:.1f} ms, "
                      f"{r['designer_fps']:.1f} frames/s", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    if args.profile:
        print(f"# profiles by role: {summarise_profiles(args.profile)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
