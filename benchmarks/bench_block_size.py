"""Threads a block of the CUDA cycle kernel (CUDA_BLOCK): us a cycle for a whole run at 32 to 128.

Run from the repo root on a GPU machine: `PYTHONPATH=. python3 benchmarks/bench_block_size.py`. Each size rebuilds
the kernels (the size is a compile-time constant: a thread per control scans the block's neurons, unrolled).
"""

import time

import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_WARNING
from somwidget.backend import cuda_path, cycle_kernels, rows_path, som_model  # noqa: E402
from somwidget.cli import load_bench_harness  # noqa: E402

benchmark = load_bench_harness()

DEV = "cuda:0"


def per_cycle(engine) -> float:
    engine.train()
    times = []
    for _ in range(5):
        engine.reset()
        wp.synchronize_device(DEV)
        t = time.perf_counter()
        engine.train()
        wp.synchronize_device(DEV)
        times.append(time.perf_counter() - t)
    return float(np.median(times)) / engine.iterations * 1e6


for size in (32, 64, 128):  # whole warps: the tile primitives of the winner search need them
    cycle_kernels.CUDA_BLOCK = som_model.CUDA_BLOCK = cuda_path.CUDA_BLOCK = rows_path.CUDA_BLOCK = wp.constant(size)
    cycle_kernels.cycle_kernels.cache_clear()
    row = []
    for case in ("space-grid", "space-grid-smooth", "car", "big"):
        engine, _ = benchmark._make(case, DEV, 1000)
        row.append(f"{case} {per_cycle(engine):.2f}")
    print(f"CUDA_BLOCK {size}: " + ", ".join(row) + " us/cycle", flush=True)
