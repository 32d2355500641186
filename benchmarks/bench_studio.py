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
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

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


# -- designers (processes of their own) -----------------------------------------------------------------------------
async def _designer(url: str, index: int, seconds: float, start_at: float, out: list) -> None:
    import aiohttp

    from somwidget.frontend.transport.messages import HEADER_FORMAT, HEADER_SIZE

    header = struct.Struct(HEADER_FORMAT)
    async with aiohttp.ClientSession() as cs, cs.ws_connect(url, compress=0, max_msg_size=0) as ws:
        topology, latest = None, None
        while topology is None or latest is None:
            msg = await ws.receive(timeout=300)
            if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data)["type"] == "topology":
                topology = json.loads(msg.data)
            elif msg.type == aiohttp.WSMsgType.BINARY and topology is not None:
                latest = msg.data
            elif msg.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                raise RuntimeError(f"designer {index}: the room closed its websocket")
        cid = topology["control_ids"][0]
        n = header.unpack_from(latest, 0)[7]
        at = HEADER_SIZE + 12 * n  # control 0 in the frame's control positions
        home = np.array(struct.unpack_from("<3f", latest, at), np.float64)
        size = float(np.linalg.norm(np.subtract(topology["bounds"]["max"], topology["bounds"]["min"])))
        pending: list[tuple[float, tuple]] = []
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
                if len(msg.data) < at + 12:
                    continue
                shown = struct.unpack_from("<3f", msg.data, at)
                for m, (t, p) in enumerate(pending):
                    if p == shown:
                        latencies.append(now - t)
                        del pending[:m + 1]
                        break

        receiver = asyncio.ensure_future(receive())
        await asyncio.sleep(max(0.0, start_at - time.time()))
        # the grab just before the moves: a hand silent for hands.SILENT_SECONDS while it holds lets go
        await ws.send_json({"type": "grab", "id": cid})
        t0 = time.perf_counter()
        phase = 2 * math.pi * (index % 7) / 7
        tick = t0
        while time.perf_counter() - t0 < seconds:
            a = phase + 2 * math.pi * (time.perf_counter() - t0) / 2.0
            p = home + 0.015 * size * np.array([math.cos(a), math.sin(a), 0.5 * math.sin(2 * a)])
            p = np.round(p, 6)
            await ws.send_json({"type": "move", "id": cid, "position": [float(v) for v in p]})
            pending.append((time.perf_counter(), tuple(float(v) for v in np.float32(p))))
            sent += 1
            tick += MOVE_INTERVAL
            await asyncio.sleep(max(0.0, tick - time.perf_counter()))
        await asyncio.sleep(0.5)
        done.set()
        await receiver
        await ws.send_json({"type": "release", "id": cid})
        out.append({"latencies": latencies, "sent": sent, "frames": frames, "seconds": time.perf_counter() - t0})


def _designers(urls: list[str], first: int, seconds: float, start_at: float, queue) -> None:
    async def main():
        out: list = []
        results = await asyncio.gather(*(_designer(u, first + i, seconds, start_at, out) for i, u in enumerate(urls)),
                                       return_exceptions=True)
        failed = [str(r) for r in results if isinstance(r, BaseException)]
        return out, failed

    result = asyncio.run(main())
    if os.environ.get("SOMWIDGET_PROFILE_DIR") and "sitecustomize" in sys.modules:  # benchmarks/profile_hook
        getattr(sys.modules["sitecustomize"], "dump", lambda role: None)("designers")
    queue.put(result)


def drive(urls: list[str], seconds: float, procs: int, lead: float) -> tuple[list, list]:
    """Run the designers in `procs` processes; their results and failures."""
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    start_at = time.time() + lead
    chunks = [urls[i::procs] for i in range(procs)]
    workers = [ctx.Process(target=_designers, args=(chunk, i * 1000, seconds, start_at, queue))
               for i, chunk in enumerate(chunks) if chunk]
    for w in workers:
        w.start()
    views, failed = [], []
    for _ in workers:
        out, bad = queue.get(timeout=seconds + lead + 600)
        views += out
        failed += bad
    for w in workers:
        w.join(60)
    return views, failed


def summarise(views: list, seconds: float) -> dict:
    lat = np.array([x for v in views for x in v["latencies"]]) * 1e3
    sent = sum(v["sent"] for v in views)
    pct = (lambda q: float(np.percentile(lat, q))) if len(lat) else (lambda q: float("nan"))
    return {"moves": sent, "answered": len(lat) / max(sent, 1), "median_ms": pct(50), "p95_ms": pct(95),
            "p99_ms": pct(99), "designer_fps": float(np.mean([v["frames"] / v["seconds"] for v in views]))
            if views else 0.0}


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


def server_pids(studio) -> list[int]:
    pids = [os.getpid()]
    if studio.pool is not None and hasattr(studio.pool, "procs"):
        pids += [p.pid for p in studio.pool.procs.values()]
    return pids


def run_rooms(count: int, presets: tuple[str, ...], seconds: float, device: str, workers: int, procs: int) -> dict:
    from somwidget.frontend.studio.limits import StudioLimits
    from somwidget.frontend.studio.serve import StudioServer

    limits = StudioLimits(rooms=max(64, count + 1), park_after=0)
    with StudioServer(tempfile.mkdtemp(prefix="bench-studio-"), device=device, workers=workers,
                      limits=limits) as studio:
        for place in range(max(1, workers)):  # a room on each place first: what the first room loads is not a room's
            studio.call(studio.front.create(f"warm{place}", presets[0]), timeout=600)
        time.sleep(3.0)
        rss0, gpu0 = memory(studio)
        names = [f"d{i}" for i in range(count)]
        t0 = time.perf_counter()
        for i, name in enumerate(names):
            studio.call(studio.front.create(name, presets[i % len(presets)]), timeout=600)
        made = time.perf_counter() - t0
        urls = [studio.room_url(n).replace("http", "ws", 1).replace("/?token=", "/view/ws?token=") for n in names]
        time.sleep(min(30.0, 2.0 + 0.05 * count))  # the rooms grow their shapes (the car) meanwhile
        rss1, gpu1 = memory(studio)
        pids = server_pids(studio)
        lead = 10.0 + 0.05 * count
        c0 = cpu_seconds(pids)
        w0 = time.perf_counter()
        views, failed = drive(urls, seconds, procs, lead)
        busy = (cpu_seconds(pids) - c0) / (time.perf_counter() - w0)
    out = summarise(views, seconds)
    out.update(rooms=count, presets="+".join(presets), failed=len(failed), errors=failed[:3],
               made_s=made, rss_mb_room=(rss1 - rss0) / count, gpu_mb_room=(gpu1 - gpu0) / count,
               server_cores=busy, cpu_ms_frame=1e3 * busy / max(1e-9, count * out["designer_fps"]),
               ok=out["p95_ms"] <= TARGET_MS and not failed)
    return out


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
    return {"latencies": latencies, "sent": sent, "frames": frames, "seconds": time.perf_counter() - t0}


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
            views, failed = drive(urls, seconds, 1, 10.0)
            out.append(dict(summarise(views, seconds), path="front -> workers' own servers", rooms=count,
                            failed=len(failed)))

        async def actors():
            async with Client(cluster.scheduler_address, asynchronous=True) as client:
                handles = [await client.submit(RoomActor, "car", actor=True, pure=False) for _ in range(count)]
                return await asyncio.gather(*(_actor_designer(h, seconds, i) for i, h in enumerate(handles)))

        views = asyncio.run(actors())
        out.append(dict(summarise(views, seconds), path="Dask actors (calls, long-polled frames)", rooms=count,
                        failed=0))
    return out


# -- the command -----------------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=("rooms", "engine", "dask"), default="rooms")
    parser.add_argument("--rooms", default="1,2,4", help="room counts to try, comma-separated")
    parser.add_argument("--presets", choices=("car", "mixed"), default="car")
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--workers", type=int, default=0, help="worker processes (0: the rooms in the server's own)")
    parser.add_argument("--client-procs", type=int, default=0, help="designer processes (0: one per 64 designers)")
    parser.add_argument("--rounds", type=int, default=20, help="engine mode: rounds timed")
    parser.add_argument("--no-own", action="store_true", help="engine mode: leave out the rooms stepped one by one")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    # the rooms' sessions keep their folders under the rooms folder; anything else goes to a folder of this run
    os.environ.setdefault("SOMWIDGET_DATA_DIR", tempfile.mkdtemp(prefix="bench-studio-data-"))
    heavy = check_imports() if args.mode != "engine" else []  # the engine alone needs numpy and warp only
    if heavy:
        print(f"# warning: the studio's imports pulled in {heavy}", flush=True)
    counts = [int(v) for v in args.rooms.split(",") if v.strip()]
    gpus = os.environ.get("CUDA_VISIBLE_DEVICES", "all")
    print(f"# bench_studio {args.mode}: {platform.node()}, {os.cpu_count()} CPUs, device {args.device} "
          f"(CUDA_VISIBLE_DEVICES={gpus}), workers {args.workers}, {time.strftime('%Y-%m-%d %H:%M')}", flush=True)
    results = []
    if args.mode == "rooms":
        presets = ("car",) if args.presets == "car" else MIXED
        print(f"{'rooms':>5} {'moves':>6} {'answered':>8} {'median':>7} {'p95':>7} {'p99':>7} {'fps':>5} "
              f"{'cores':>5} {'CPU ms/frame':>12} {'MB/room':>7} {'GPU MB/room':>11} {'ok':>3}", flush=True)
        for count in counts:
            procs = args.client_procs or max(1, math.ceil(count / 64))
            r = run_rooms(count, presets, args.seconds, args.device, args.workers, procs)
            results.append(r)
            print(f"{r['rooms']:>5} {r['moves']:>6} {r['answered']:>8.0%} {r['median_ms']:>7.1f} {r['p95_ms']:>7.1f} "
                  f"{r['p99_ms']:>7.1f} {r['designer_fps']:>5.1f} {r['server_cores']:>5.2f} {r['cpu_ms_frame']:>12.2f} "
                  f"{r['rss_mb_room']:>7.1f} "
                  f"{r['gpu_mb_room']:>11.1f} {'yes' if r['ok'] else 'no':>3}"
                  + (f"  ({r['failed']} designers failed: {r['errors']})" if r["failed"] else ""), flush=True)
        passing = [r["rooms"] for r in results if r["ok"]]
        print(f"# most rooms with p95 <= {TARGET_MS:g} ms: {max(passing) if passing else 'none'} "
              f"(of {', '.join(map(str, counts))}; presets {args.presets})", flush=True)
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
