"""Side by side in one run: the somwidget engine, a vectorised CuPy SOM of the same cycles, and SOM libraries.

The task every contender can do: a 64 x 64 grid of neurons with 3-D weights, 8 training vectors, S = 1000.

- somwidget: the engine on the chosen device (the GPU where there is one); a cycle = the 8 vectors applied in
  order (som.py, The cycle), grid distances = BFS hops on the grid's quads.
- cupy: the same cycles written as we would write them in CuPy (broadcast winner search, a gather of the learning
  rates through the same distance table, the 8 updates in order), each cycle captured once as a CUDA graph and
  replayed, so Python launches no kernels inside the timed loop. Same winners as the engine are checked.
- minisom (CPU): the nearest task it can do, labelled as such: MiniSom's 64 x 64 rectangular map, Gaussian
  neighbourhood on grid coordinates (Euclidean, not hops), one vector per iteration, trained for 8 x 1000
  iterations in order (the same number of vector updates).
- torchsom (GPU), when it imports: also the nearest task (batch training on grid coordinates), 1000 epochs over
  the 8 vectors.

Prints per-cycle times (a cycle = 8 vector updates) and ratios to the engine. Run on the GPU machine with the
warp wheel on PYTHONPATH: `PYTHONPATH=. python3 benchmarks/bench_peers.py --json peers.json`.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import warp as wp

from somwidget.backend.device import resolve
from somwidget.backend.som import Som
from somwidget.backend.topology import Topology

SIDE = 64
CYCLES = 1000
VECTORS = np.array([
    [0.8, 0.6, 0.5], [-0.7, 0.5, -0.4], [0.6, -0.8, 0.3], [-0.5, -0.6, 0.6],
    [0.1, 0.9, -0.5], [0.9, 0.1, 0.7], [-0.9, -0.1, -0.6], [0.2, -0.3, 0.9],
], np.float32)


def grid() -> tuple[Topology, np.ndarray]:
    idx = np.arange(SIDE * SIDE).reshape(SIDE, SIDE)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], axis=-1).reshape(-1, 4)
    u = np.linspace(-1.0, 1.0, SIDE, dtype=np.float32)
    gy, gx = np.meshgrid(u, u, indexing="ij")
    return Topology.from_faces(quads), np.stack([gx.ravel(), gy.ravel(), np.zeros(SIDE * SIDE, np.float32)], 1)


def time_engine(device: str, repeats: int) -> tuple[float, Som]:
    topo, start = grid()
    som = Som(topo, start, VECTORS, iterations=CYCLES, device=device)
    som.train()
    best = float("inf")
    for _ in range(repeats):
        som.reset()
        wp.synchronize_device(device)
        t = time.perf_counter()
        som.train()
        wp.synchronize_device(device)
        best = min(best, time.perf_counter() - t)
    return best / CYCLES * 1e6, som


def time_cupy(som: Som, repeats: int) -> tuple[float, float]:
    """Returns (us per cycle, max |W_cupy - W_engine|) after a whole run."""
    import cupy as cp

    d = cp.asarray(som.topology.grid_distances())
    table = cp.asarray(som.learning_table())
    unreachable = cp.asarray(np.uint16(65535))
    c = cp.asarray(VECTORS)
    w = cp.asarray(som.start_weights)
    s = cp.zeros((), cp.int32)
    rows = cp.empty((len(VECTORS), w.shape[0]), cp.float32)

    def cycle():
        dist = ((c[:, None, :] - w[None, :, :]) ** 2).sum(-1)  # (k, N)
        u = dist.argmin(axis=1)
        hops = d[u]  # (k, N) uint16
        rate_row = table[s]
        cp.take(rate_row, cp.minimum(hops, table.shape[1] - 1).astype(cp.int32), out=rows)
        cp.copyto(rows, cp.float32(0.0), where=hops == unreachable)  # no boolean indexing: it syncs with the host
        for i in range(len(VECTORS)):
            w[...] += rows[i][:, None] * (c[i] - w)
        s[...] += 1

    stream = cp.cuda.Stream(non_blocking=True)
    with stream:
        cycle()  # compile the elementwise kernels outside the capture
        stream.begin_capture()
        cycle()
        graph = stream.end_capture()
    best = float("inf")
    for _ in range(repeats):
        w[...] = cp.asarray(som.start_weights)
        s[...] = 0
        stream.synchronize()
        t = time.perf_counter()
        for _ in range(CYCLES):
            graph.launch(stream)
        stream.synchronize()
        best = min(best, time.perf_counter() - t)
    som.reset()
    som.train()
    return best / CYCLES * 1e6, float(np.abs(cp.asnumpy(w) - som.weights).max())


def time_minisom(repeats: int) -> float:
    from minisom import MiniSom

    best = float("inf")
    for _ in range(repeats):
        m = MiniSom(SIDE, SIDE, 3, sigma=SIDE / 2, learning_rate=0.25, neighborhood_function="gaussian", random_seed=1)
        t = time.perf_counter()
        m.train(VECTORS, len(VECTORS) * CYCLES, random_order=False)
        best = min(best, time.perf_counter() - t)
    return best / CYCLES * 1e6


def time_torchsom(repeats: int) -> float:
    import torch
    from torchsom import SOM

    data = torch.tensor(VECTORS, device="cuda")
    best = float("inf")
    for _ in range(repeats):
        m = SOM(x=SIDE, y=SIDE, num_features=3, epochs=CYCLES, batch_size=len(VECTORS), device="cuda")
        torch.cuda.synchronize()
        t = time.perf_counter()
        m.fit(data)
        torch.cuda.synchronize()
        best = min(best, time.perf_counter() - t)
    return best / CYCLES * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="auto", help="device for the engine (auto, cpu, cuda)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs of each; the best is reported")
    parser.add_argument("--json", help="also write the results as JSON here")
    args = parser.parse_args()
    device = resolve(args.device)
    rows: list[tuple[str, str, str, float | None, str]] = []
    engine_us, som = time_engine(device, args.repeats)
    rows.append(("somwidget", device, "same cycles", engine_us, ""))
    contenders = [
        ("cupy", "cuda", "same cycles (CUDA graph a cycle)", lambda: time_cupy(som, args.repeats)),
        ("minisom", "cpu", "nearest task: Euclidean grid neighbourhood, 8 x S single updates",
         lambda: (time_minisom(args.repeats), None)),
        ("torchsom", "cuda", "nearest task: batch SOM on grid coordinates, S epochs of 8",
         lambda: (time_torchsom(args.repeats), None)),
    ]
    for name, where, task, run in contenders:
        try:
            us, diff = run()
            note = "" if diff is None else f"max |dW| vs engine {diff:.1e}"
            rows.append((name, where, task, us, note))
        except Exception as exc:  # a peer that does not install or run here is reported, not fatal
            rows.append((name, where, task, None, f"not run: {type(exc).__name__}: {exc}"[:160]))
    print(f"64 x 64 grid, 8 vectors, S = {CYCLES}; us per cycle (8 vector updates); ratio = peer / somwidget")
    print("| contender | device | task | us/cycle | ratio | note |")
    print("|---|---|---|---|---|---|")
    for name, where, task, us, note in rows:
        ratio = "" if us is None else f"{us / engine_us:.1f}"
        print(f"| {name} | {where} | {task} | {'' if us is None else f'{us:.1f}'} | {ratio} | {note} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump([dict(zip(("name", "device", "task", "us_per_cycle", "note"), r)) for r in rows], f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
