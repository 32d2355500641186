"""GPU timings of the dense distance table build (N x N uint16 BFS hop counts).

Run from the repo root: `PYTHONPATH=. python3 benchmarks/bench_bfs.py [grid] [sweep] [thin] [lattice]` (no argument:
all). Needs only numpy and warp.

grid:    the 256 x 256 quad grid (65,536 vertices, d_max 510): the old build (a thread per source, a serial queue
         each) and the new one (a block of threads per source, level-synchronous; as `distance_table` runs it), each
         on a fresh Topology; both tables compared on the device (a kernel counting mismatches) and a few rows checked
         against |di| + |dj|; the memset of an 8 GiB uint16 table for reference.
sweep:   the new build on that grid with 32 .. 512 threads per block and fewer or more blocks than fit at once.
thin:    a 4,096 x 16 strip (65,536 vertices, d_max 4,110: few vertices per level), old and new.
lattice: a 40 x 40 x 40 lattice (64,000 vertices, 6 neighbours, d_max 117: many vertices per level), old and new.
Environment: DEV (default cuda:0).
"""

import gc
import os
import sys

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_WARNING
from device_timing import device_timer  # noqa: E402 (beside this script)

from somwidget import Topology  # noqa: E402
from somwidget.backend import topology as topo_mod  # noqa: E402

DEV = os.environ.get("DEV", "cuda:0")
print("warp", wp.__version__, wp.get_device(DEV).name, "SMs", wp.get_device(DEV).sm_count, flush=True)


@wp.kernel(enable_backward=False)
def count_mismatches(a: wp.array2d(dtype=wp.uint16), b: wp.array2d(dtype=wp.uint16), per_row: wp.array(dtype=wp.int32)):
    i, j = wp.tid()
    if a[i, j] != b[i, j]:
        wp.atomic_add(per_row, i, 1)


sync, timed = device_timer(DEV)


def fresh(topo: Topology) -> Topology:
    """The same graph with nothing computed (no table, no d_max)."""
    return Topology(topo.n_vertices, topo.edges, topo.faces)


def grid(nx: int, ny: int) -> Topology:
    idx = np.arange(nx * ny).reshape(ny, nx)
    quads = np.stack([idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()], 1)
    return Topology.from_faces(quads)


def lattice(n: int) -> Topology:
    idx = np.arange(n**3).reshape(n, n, n)
    e = [np.stack([np.moveaxis(idx, a, 0)[:-1].ravel(), np.moveaxis(idx, a, 0)[1:].ravel()], 1) for a in range(3)]
    return Topology.from_edges(np.concatenate(e), n**3)


def mismatches(a: wp.array, b: wp.array) -> int:
    per_row = wp.zeros(a.shape[0], dtype=wp.int32, device=DEV)
    wp.launch(count_mismatches, dim=a.shape, inputs=[a, b, per_row], device=DEV)
    return int(per_row.numpy().astype(np.int64).sum())


def small_graphs() -> dict[str, Topology]:
    path = np.stack([np.arange(299), np.arange(1, 300)], 1)
    torus = [[i * 7 + j, ((i + 1) % 9) * 7 + j, ((i + 1) % 9) * 7 + (j + 1) % 7, i * 7 + (j + 1) % 7]
             for i in range(9) for j in range(7)]
    rng = np.random.default_rng(3)
    return {
        "grid 12 x 9": grid(12, 9),
        "lattice 6^3": lattice(6),
        "torus 9 x 7": Topology.from_faces(torus),
        "mixed faces": Topology.from_faces([[0, 1, 2], [1, 3, 4, 2], [2, 4, 5, 6, 7], [7, 8, 9, 10, 11, 12]]),
        "two components + isolated": Topology.from_faces([[0, 1, 2, 3], [3, 2, 4, 5], [6, 7, 8]], n_vertices=12),
        "single vertex": Topology.from_edges(np.zeros((0, 2), np.int64), 1),
        "no edges": Topology.from_edges(np.zeros((0, 2), np.int64), 7),
        "path 300": Topology.from_edges(path, 300),
        "star 600": Topology.from_edges(np.stack([np.zeros(600, np.int64), np.arange(1, 601)], 1), 601),
        "random 500": Topology.from_edges(rng.integers(0, 500, (700, 2)), 500),
    }


def warm_up() -> bool:
    """Compile everything timed below (both builds, every block size of the sweep) on small graphs, and check the
    new build against the old one on them (edge cases: components, isolated vertices, a path, a star)."""
    ok = True
    for name, small in small_graphs().items():
        old = fresh(small)
        ref = old._bfs_table(DEV, "thread")
        for threads in (None, 32, 64, 128, 256, 512):
            new = fresh(small)
            table = new.distance_table(DEV) if threads is None else new._bfs_table(DEV, "block", threads=threads)
            bad = mismatches(ref, table)
            if bad or new.d_max != old.d_max or not np.array_equal(ref.numpy(), table.numpy()):
                print(f"  {name}, threads {threads}: {bad} entries differ, d_max {new.d_max} vs {old.d_max}")
                ok = False
    sync()
    print("small graphs, new build against old on the device:", "ok" if ok else "FAILED", flush=True)
    return ok


def old_and_new(name: str, topo: Topology, expect_d_max: int | None = None, rows_check=None):
    """Times the old build and the new one (the default path of distance_table) on fresh copies; compares."""
    n = topo.n_vertices
    old_topo, new_topo = fresh(topo), fresh(topo)
    t_old, old = timed(lambda: old_topo._bfs_table(DEV, "thread"))
    threads = new_topo._block_threads()
    blocks = topo_mod._block_count(n, threads, DEV)
    t_new, new = timed(lambda: new_topo.distance_table(DEV))
    bad = mismatches(old, new)
    print(f"{name}: N {n:,}, d_max old {old_topo.d_max} new {new_topo.d_max}"
          + (f" (expected {expect_d_max})" if expect_d_max is not None else ""), flush=True)
    print(f"  old (thread per source):        {t_old:8.3f} s", flush=True)
    print(f"  new (block per source, auto):   {t_new:8.3f} s   threads/block {threads}, blocks {blocks}", flush=True)
    print(f"  speed-up {t_old / t_new:.1f}x; tables differ in {bad:,} of {n * n:,} entries", flush=True)
    ok = bad == 0 and old_topo.d_max == new_topo.d_max and (expect_d_max is None or new_topo.d_max == expect_d_max)
    if rows_check is not None:
        ok = rows_check(new) and ok
    print("  CHECK", "ok" if ok else "FAILED", flush=True)
    del old, new
    old_topo._tables.clear()
    new_topo._tables.clear()
    gc.collect()
    sync()
    return ok


def grid_rows_ok(table: wp.array, nx: int = 256) -> bool:
    """A few rows against the closed form |di| + |dj|."""
    n = table.shape[0]
    i, j = np.arange(n) % nx, np.arange(n) // nx
    for src in (0, 255, 32896, 65535, 12345):
        row = table[src].numpy()
        if not np.array_equal(row, np.abs(i - i[src]) + np.abs(j - j[src])):
            print(f"  row {src} differs from |di| + |dj|", flush=True)
            return False
    return True


def memset_reference(n: int = 65536):
    """fill_ of an existing (n, n) uint16 array, and wp.full (allocation and fill)."""
    table = wp.empty((n, n), dtype=wp.uint16, device=DEV)
    times = [timed(lambda: table.fill_(65535))[0] for _ in range(3)]
    t_full, _ = timed(lambda: wp.full((n, n), 65535, dtype=wp.uint16, device=DEV))
    gib = n * n * 2 / 2**30
    print(f"memset {gib:.0f} GiB uint16: fill_ {min(times) * 1e3:.2f} ms (best of 3, {gib / min(times):.0f} GiB/s); "
          f"wp.full (alloc + fill) {t_full * 1e3:.2f} ms", flush=True)


def sweep(topo: Topology):
    n = topo.n_vertices
    reference = fresh(topo)
    base = reference.distance_table(DEV)
    print(f"sweep on the {topo.n_vertices:,}-vertex grid (seconds; blocks: resident at once = auto, and x0.5 / x2):",
          flush=True)
    ok = True
    for threads in (32, 64, 128, 256, 512):
        auto = topo_mod._block_count(n, threads, DEV)
        cells = []
        for blocks in (max(1, auto // 2), auto, min(n, 2 * auto)):
            t = fresh(topo)
            secs, table = timed(lambda t=t, blocks=blocks, threads=threads:
                                t._bfs_table(DEV, "block", threads=threads, blocks=blocks))
            bad = mismatches(base, table)
            ok = ok and bad == 0
            cells.append(f"{blocks:5d} blocks {secs:7.3f}" + ("" if bad == 0 else f" ({bad} WRONG)"))
            del table
            gc.collect()
        print(f"  {threads:3d} threads/block: " + " | ".join(cells), flush=True)
    print("  CHECK", "ok" if ok else "FAILED", flush=True)
    del base
    reference._tables.clear()
    gc.collect()
    return ok


def main(args):
    todo = set(args) or {"grid", "sweep", "thin", "lattice"}
    t, ok = timed(warm_up)
    print(f"warm-up (compiles, small-graph checks) {t:.1f} s", flush=True)
    if "grid" in todo or "sweep" in todo:
        g = grid(256, 256)
    if "grid" in todo:
        memset_reference()
        gc.collect()
        ok = old_and_new("grid 256 x 256", g, 510, grid_rows_ok) and ok
    if "sweep" in todo:
        ok = sweep(g) and ok
    if "thin" in todo:
        ok = old_and_new("strip 4096 x 16", grid(4096, 16), 4095 + 15) and ok
    if "lattice" in todo:
        ok = old_and_new("lattice 40 x 40 x 40", lattice(40), 3 * 39) and ok
    print("ALL CHECKS", "ok" if ok else "FAILED", flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
