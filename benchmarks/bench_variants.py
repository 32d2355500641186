"""Batched variants against single runs, in one run: `PYTHONPATH=. python benchmarks/bench_variants.py [--device cuda]`.

For the car (1,024 variants, S = 1000) and the space grid (256 variants): the batched engine's time (training alone,
and all in: set-up, tables, upload, training, weights back), the same variants run one after another on one `Som`
(reset, then train), the ratio, how far the batch's weights are from the single runs', and the figures' floors: the
arithmetic the cycles must do over the GPU's float32 rate, and the bytes that must cross its memory at least once.
`--shaping N`: N variants of the sphere with its controls' radii (handles, Taubin's smoothing), as
`somwidget sweep --preset sphere` runs them: single Soms, each its controls' typed move (variants.run_plan; the
batched kernel runs the paper's rule only). A count of 0 skips a case.
numpy and warp-lang only.
"""

import argparse
import os
import sys
import time

import numpy as np

if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import warp as wp  # noqa: E402

from somwidget.backend import batch, presets  # noqa: E402
from somwidget.backend.device import resolve  # noqa: E402
from somwidget.backend.schedule import Schedule  # noqa: E402
from somwidget.backend.som import Som  # noqa: E402
from somwidget.backend.variants import plan_variants, run_plan  # noqa: E402

#: float32 rate (non-tensor) and memory bandwidth of the GPUs these figures are taken on (their data sheets).
PEAKS = {"H200": (67e12, 4.8e12), "H100": (67e12, 3.35e12)}


def plan_for(name: str, n: int, seed: int = 0, radii: bool = False):
    """n variants of a preset, as `somwidget sweep` draws them; with `radii` its controls' radii and smoothing rule
    (a general shape's), else point controls (the batched kernel of the paper's rule)."""
    p = presets.get_preset(name)
    base = Schedule.of(p).as_dict()
    shaping = {"radii": p.control_radii(), "smoothing_rule": p.smoothing_rule} if radii else {}
    return p, plan_variants(p.topology, p.weights, p.controls, base, n, jitter=0.05, seed=seed, mirror=p.mirror,
                            smooth_dims=p.smooth_dims, metric_weights=p.metric_weights,
                            position_dims=p.layout.position, **shaping)


def make_batch(p, plan, device):
    s = plan.schedules
    return batch.BatchSom(p.topology, plan.start, plan.controls, smooth_dims=plan.smooth_dims,
                          metric_weights=plan.metric_weights, mirror=plan.mirror, device=device, **s)


def bench_shaping(name: str, n: int, device: str) -> None:
    """Variants whose controls have radii: run_plan's single Soms, one after another (the first two compile)."""
    p, plan = plan_for(name, n, radii=True)
    run_plan(plan.part(0, 2), device=device)  # compile and capture
    print(f"\n{name} with radii {float(plan.radii.max()):.3f} ({plan.smoothing_rule} smoothing {p.smoothing}): {n} "
          f"variants of N = {p.n_vertices}, S = {p.iterations}, {len(p.controls)} controls on {device} "
          f"({wp.get_device(device).name}), each a typed move as a single Som")
    t0 = time.perf_counter()
    run_plan(plan, device=device)
    took = time.perf_counter() - t0
    print(f"  run_plan, all in: {took * 1e3:.1f} ms ({took / n * 1e3:.2f} ms a variant)")


def floors(p, plan, device) -> tuple[float, float, float]:
    """(flops, bytes, seconds at the floor): winner search 3n flops per neuron and control, a move 3n per neuron
    and control (a pair 8n for two), smoothing 3n per neuron and edge end; bytes: weights in and out once, the
    distance table and the learning tables read once."""
    n_dims, N, k = plan.start.shape[1], p.n_vertices, len(p.controls)
    k_eff = k * (2 if p.mirror else 1)
    S = plan.schedules["iterations"].astype(np.float64)
    per_cycle = N * k_eff * 3 * n_dims + (N * k * 8 * n_dims if p.mirror else N * k_eff * 3 * n_dims)
    smooth = (plan.schedules["smoothing"] > 0) * (len(p.topology.neighbors) * 3 * n_dims + N * 4 * n_dims)
    flops = float(((per_cycle + smooth) * S).sum())
    nbytes = 2.0 * plan.n_variants * N * n_dims * 4 + N * N * 2 + S.sum() * (p.topology.d_max + 1) * 4
    name = wp.get_device(device).name if device != "cpu" else ""
    peak = next((v for key, v in PEAKS.items() if key in name), None)
    floor = max(flops / peak[0], nbytes / peak[1]) if peak else float("nan")
    return flops, nbytes, floor


def bench(name: str, n: int, device: str, singles: int, configs: list[tuple]) -> None:
    p, plan = plan_for(name, n)
    sync = (lambda: wp.synchronize_device(device)) if device != "cpu" else (lambda: None)
    make_batch(p, plan.part(0, 2), device).train()  # compile
    print(f"\n{name}: {n} variants of N = {p.n_vertices}, S = {p.iterations}, {len(p.controls)} controls"
          f"{' (mirrored)' if p.mirror else ''}, smoothing {p.smoothing} on {device} ({wp.get_device(device).name})")
    best = None
    shapes = [batch.cuda_shape(p.n_vertices)] + [dict(zip(("threads", "min_blocks", "gather", "searched"), c))
                                                   for c in configs] if device != "cpu" else [{"threads": 1}]
    default_shape = batch.cuda_shape
    for shape in shapes:
        batch.cuda_shape = lambda n_neurons, shape=shape: shape
        make_batch(p, plan.part(0, 2), device).train()  # compile this shape
        som = make_batch(p, plan, device)
        sync()
        t0 = time.perf_counter()
        som.train()
        sync()
        train = time.perf_counter() - t0
        print(f"  batched, {shape}: training {train * 1e3:8.2f} ms")
        if best is None or train < best[1]:
            best = (shape, train)
    batch.cuda_shape = lambda n_neurons, shape=best[0]: shape
    sync()
    t0 = time.perf_counter()
    som = make_batch(p, plan, device)
    som.train()
    weights = som.weights
    whole = time.perf_counter() - t0
    print(f"  batched, all in (set-up, upload, training, weights back; {best[0]}): {whole * 1e3:.2f} ms")

    count = min(singles, n)
    single = Som(p.topology, p.weights, plan.controls[0], smooth_dims=p.smooth_dims, metric_weights=p.metric_weights,
                 mirror=p.mirror, device=device, **Schedule.of(p).as_dict())
    single.train()  # compile and capture
    diff = 0.0
    sync()
    t0 = time.perf_counter()
    for i in range(count):
        single.set_controls(plan.controls[i])
        single.reset()
        single.train()
        if i < 8:
            diff = max(diff, float(np.abs(single.weights - weights[i]).max()))
    sync()
    singles_time = time.perf_counter() - t0
    scaled = singles_time * n / count
    print(f"  {count} single runs one after another: {singles_time * 1e3:.1f} ms"
          + (f" (x {n / count:.0f}: {scaled * 1e3:.0f} ms for {n})" if count < n else ""))
    print(f"  batched / single runs: {scaled / best[1]:.1f} x faster (training); largest weight difference "
          f"from the single runs (first 8): {diff:.2e}")
    batch.cuda_shape = default_shape
    flops, nbytes, floor = floors(p, plan, device)
    if np.isnan(floor):
        print(f"  floors: {flops / 1e9:.1f} GFLOP, {nbytes / 1e6:.1f} MB once through memory (no data-sheet peaks "
              f"for this device)")
    else:
        print(f"  floors: {flops / 1e9:.1f} GFLOP, {nbytes / 1e6:.1f} MB once through memory -> {floor * 1e3:.2f} "
              f"ms at the data-sheet peaks; training runs at {floor / best[1] * 100:.1f}% of that floor")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--car", type=int, default=1024, help="car variants (default 1024)")
    parser.add_argument("--grid", type=int, default=256, help="space-grid variants (default 256)")
    parser.add_argument("--shaping", type=int, default=0,
                        help="sphere variants with their controls' radii, run as single Soms (default 0: none)")
    parser.add_argument("--singles", type=int, default=None, help="single runs to time (default: all)")
    parser.add_argument("--shapes", default="",
                        help="CUDA kernel shapes to try beside the default: threads:min_blocks:gather:searched,...")
    args = parser.parse_args(argv)
    device = resolve(args.device)
    configs = [tuple(int(v) for v in x.split(":")) for x in args.shapes.split(",") if x]
    if args.car:
        bench("car", args.car, device, args.singles or args.car, configs)
    if args.grid:
        bench("space-grid", args.grid, device, args.singles or args.grid, configs)
    if args.shaping:
        bench_shaping("sphere", args.shaping, device)


if __name__ == "__main__":
    main()
