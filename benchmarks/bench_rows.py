"""GPU check and timings of distance rows mode.

Run from the repo root: `PYTHONPATH=. python3 benchmarks/bench_rows.py [check] [bfs] [big]`.

check: rows mode against dense mode on cuda:0 (and against the CPU) on small meshes, with the default cache, a
       cache smaller than the winners, smoothing and mirroring; then both modes timed on a 128 x 128 grid.
bfs:   one distance row, 18 and 128 rows on 512 x 512 and 1000 x 1000 grids: a block per row with its visited set and
       frontier in shared memory, a block per row without, a launch per level, a thread per row.
big:   a 1000 x 1000 grid (1,000,000 vertices), 9 controls mirrored (18), S = 1000 in rows mode: us/cycle with
       cache misses amortised (cold cache), the app's step(10) frames, how often winners change, us/cycle without
       misses (a cache holding a whole run), and the cost of one miss (1, 4 and 18 new rows).
Environment: DEV (default cuda:0), SIDE (default 1000).
"""

import os
import sys
import time

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_WARNING
from device_timing import device_timer  # noqa: E402 (beside this script)

from somwidget import Som, Topology  # noqa: E402
from somwidget.backend import row_cache  # noqa: E402
from somwidget.backend.topology import RowSearch  # noqa: E402

DEV = os.environ.get("DEV", "cuda:0")
SIDE = int(os.environ.get("SIDE", "1000"))
print("warp", wp.__version__, wp.get_device(DEV).name, flush=True)


sync, timed = device_timer(DEV)


def grid(nx, ny):
    idx = np.arange(nx * ny).reshape(ny, nx)
    quads = np.stack([idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()], 1)
    t = time.perf_counter()
    topo = Topology.from_faces(quads)
    jj, ii = np.divmod(np.arange(nx * ny), nx)
    W = np.stack([ii / (nx - 1) * 2 - 1, jj / (ny - 1) * 2 - 1, 0.05 * np.sin(ii * 9.0 / nx)], 1).astype(np.float32)
    return topo, W, time.perf_counter() - t


def lattice(n):
    idx = np.arange(n**3).reshape(n, n, n)
    e = [np.stack([np.moveaxis(idx, a, 0)[:-1].ravel(), np.moveaxis(idx, a, 0)[1:].ravel()], 1) for a in range(3)]
    W = (np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3) - (n - 1) / 2).astype(np.float32)
    return Topology.from_edges(np.concatenate(e), n**3), W


def torus(nu, nv):
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    quads = np.stack([i * nv + j, ((i + 1) % nu) * nv + j, ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv],
                     -1).reshape(-1, 4)
    u, v = 2 * np.pi * i.ravel() / nu, 2 * np.pi * j.ravel() / nv
    W = np.stack([(2 + 0.7 * np.cos(v)) * np.cos(u), (2 + 0.7 * np.cos(v)) * np.sin(u), 0.7 * np.sin(v)], 1)
    return Topology.from_faces(quads), W.astype(np.float32)


def check():
    rng = np.random.default_rng(1)
    worst = 0.0
    for name, (topo, W) in {"lattice6": lattice(6), "torus30x17": torus(30, 17)}.items():
        C = rng.uniform(-2.5, 2.5, (4, 3)).astype(np.float32)
        for kw in ({}, {"smoothing": 0.3}, {"mirror": (1,)}, {"mirror": (1,), "smoothing": 0.2}):
            out = {}
            for dev, mode, cache in [(DEV, "dense", None), (DEV, "rows", None), (DEV, "rows", 1), (DEV, "rows", 3),
                                     ("cpu", "rows", None)]:
                som = Som(topo, W, C, iterations=60, device=dev, distances=mode, cache_rows=cache, **kw)
                som.step(7)
                som.step(13)
                som.set_controls(C[::-1] * 0.9)
                som.step(5)
                som.reset()
                som.train()
                out[(dev, mode, cache)] = som.weights
                if mode == "rows" and dev == DEV:
                    info = f"rows {som.parts.model.cache.computed} stalls {som.parts.model.cache.stalls}"
            ref = out[(DEV, "dense", None)]
            diffs = {f"{d}/{m}/{c}": float(np.abs(w - ref).max()) for (d, m, c), w in out.items()}
            worst = max(worst, *(v for k, v in diffs.items() if k.startswith(DEV)))
            print(f"check {name} {kw}: max |w - cuda dense| {diffs} ({info})", flush=True)
    print(f"check: worst cuda rows vs cuda dense {worst:.3g}", flush=True)

    topo, W, _ = grid(128, 128)
    C = rng.uniform(-0.9, 0.9, (9, 3)).astype(np.float32)
    C[:, 2] *= 0.3
    for mode in ("dense", "rows"):
        som = Som(topo, W, C, iterations=1000, mirror=(1,), device=DEV, distances=mode)
        for _ in range(2):  # graphs captured, rows cached
            som.train()
            som.reset()
        dt, _ = timed(som.train)
        cache = som.parts.model.cache
        extra = f" rows {cache.computed} stalls {cache.stalls}" if mode == "rows" else ""
        print(f"grid128 {mode}: train {dt / 1000 * 1e6:.1f} us/cycle (warm){extra}", flush=True)
        if mode == "dense":
            dense_w = som.weights
    print(f"grid128 rows vs dense max |dw| {np.abs(som.weights - dense_w).max():.3g}", flush=True)


def bfs():
    for side in (512, SIDE):
        topo, _, t_build = grid(side, side)
        t_d, d_max = timed(lambda topo=topo: topo.diameter(DEV))
        search = RowSearch(topo, DEV)
        rows = wp.empty((search.batch, topo.n_vertices), dtype=wp.int32, device=DEV)
        rng = np.random.default_rng(0)
        print(f"grid {side}^2: build {t_build:.2f} s, diameter {d_max} in {t_d * 1e3:.0f} ms, batch {search.batch}, "
              f"method {search.method(d_max)}", flush=True)
        chosen = search.method
        for label in ("shared", "block", "levels", "thread"):
            search.method = lambda levels, label=label: label
            search.run([[0]], [0], rows, d_max)  # compile, capture
            sync()
            for k in ((1, 18, 128) if label in ("shared", "block") else (1, 18)):
                src = [[int(v)] for v in rng.integers(0, topo.n_vertices, k)]
                dt, _ = timed(lambda src=src, search=search, rows=rows, d_max=d_max:
                              search.run(src, list(range(len(src))), rows, d_max))
                print(f"  {label}: {k} rows {dt * 1e3:.2f} ms", flush=True)
        search.method = chosen
        # check one row against the Manhattan distance
        search.run([[side * (side // 2) + 7]], [0], rows, d_max)
        jj, ii = np.divmod(np.arange(side * side), side)
        u = side * (side // 2) + 7
        ok = np.array_equal(rows.numpy()[0], np.abs(ii - ii[u]) + np.abs(jj - jj[u]))
        print(f"  row equals |di| + |dj|: {ok}", flush=True)


def big():
    topo, W, t_build = grid(SIDE, SIDE)
    t_d, d_max = timed(lambda: topo.diameter(DEV))
    rng = np.random.default_rng(7)
    C = np.concatenate([rng.uniform(-0.9, 0.9, (9, 2)), rng.uniform(-0.3, 0.3, (9, 1))], 1).astype(np.float32)
    C[:, 1] = np.abs(C[:, 1]) + 0.05  # originals at y > 0, copies at y < 0: 18 distinct winners
    small, w_small, _ = grid(40, 40)
    Som(small, w_small, C, iterations=50, mirror=(1,), device=DEV, distances="rows").train()  # compile for 3 dims

    def make(S=1000, **kw):
        return Som(topo, W, C, iterations=S, mirror=(1,), device=DEV, distances="rows", **kw)

    t_som, som = timed(make)
    cache = som.parts.model.cache
    print(f"{SIDE}^2 grid: build {t_build:.2f} s, d_max {d_max} in {t_d:.2f} s, Som {t_som:.2f} s, cache {cache.size} "
          f"rows, search {cache._search.method(d_max)}", flush=True)
    dt, _ = timed(som.train)
    print(f"  cold train (S=1000): {dt:.2f} s = {dt / 1000 * 1e6:.1f} us/cycle with misses amortised; rows "
          f"searched {cache.computed} (+{cache.prefetched} around the winners), stalls {cache.stalls}", flush=True)
    # the app: step(10) and a weights copy per frame, from a reset (the cache keeps the last rows)
    som.reset()
    c0, s0 = cache.computed, cache.stalls

    each = []

    def frames():
        for _ in range(30):
            t = time.perf_counter()
            som.step(10)
            _ = som.weights  # the view's read back
            each.append(time.perf_counter() - t)

    dt, _ = timed(frames)
    each = np.array(each) * 1e3
    print(f"  app frames from reset, step(10) + weights copy: {dt / 30 * 1e3:.1f} ms/frame (median "
          f"{np.median(each):.1f}, 90th percentile {np.percentile(each, 90):.1f}, slowest {each.max():.1f}); "
          f"rows searched {cache.computed - c0}, stalls {cache.stalls - s0}", flush=True)
    # how far do the winners move from one cycle to the next? (hops on the grid)
    jj, ii = np.divmod(np.arange(topo.n_vertices), SIDE)
    som.reset()
    prev, drift, new = som.winners(), [], []
    for _ in range(100):
        som.step(1)
        now = som.winners()
        drift.append(np.abs(ii[now] - ii[prev]) + np.abs(jj[now] - jj[prev]))
        new.append(len(set(now.tolist()) - set(prev.tolist())))
        prev = now
    drift = np.array(drift)
    print(f"  winners per cycle (first 100): new distinct winners mean {np.mean(new):.2f}, cycles with one or more "
          f"{np.mean(np.array(new) > 0):.2f}; hops moved mean {drift.mean():.2f}, <= 1 hop {np.mean(drift <= 1):.2f}",
          flush=True)
    # without misses: a cache that holds a whole run's winner rows (none searched ahead), run again from reset
    rings, row_cache._PREFETCH_RINGS = row_cache._PREFETCH_RINGS, 0
    som = make(S=200, cache_rows=8000)
    cache = som.parts.model.cache
    som.train()
    som.reset()
    c0, s0 = cache.computed, cache.stalls
    dt, _ = timed(som.train)
    row_cache._PREFETCH_RINGS = rings
    print(f"  no misses (S=200, cache 8000 rows, second run): {dt / 200 * 1e6:.1f} us/cycle; rows searched "
          f"{cache.computed - c0}, stalls {cache.stalls - s0}", flush=True)
    # one miss: rows for neurons not cached
    fresh = [v for v in rng.integers(0, topo.n_vertices, 64).tolist() if v not in cache._lru]
    for k in (1, 4, 18):
        dt, _ = timed(lambda k=k, fresh=fresh: cache.fetch(fresh[:k], d_max))
        fresh = fresh[k:]
        print(f"  miss cost: {k} new rows (and rows around them, {cache.prefetched} so far) {dt * 1e3:.2f} ms",
              flush=True)


if __name__ == "__main__":
    for part in sys.argv[1:] or ["check", "bfs", "big"]:
        print(f"== {part} on {DEV}", flush=True)
        {"check": check, "bfs": bfs, "big": big}[part]()
