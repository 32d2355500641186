"""Variants over several GPUs through Dask: `PYTHONPATH=. python benchmarks/bench_variants_dask.py [--car 16384]
[--grid 4096] [--gpus 1,2,all] [--cpu-workers 1,2]`.

For each GPU count G it starts a Dask cluster on this machine with one worker per GPU (a Nanny whose worker sees
only its GPU through CUDA_VISIBLE_DEVICES, one thread; NCCL's NVLink multicast off, though nothing here uses
NCCL), compiles the kernels on every worker, then sweeps the car and the space grid (`run_plan`, four batches a
worker) and prints variants per second, all in (training, figures on the workers, weights back to the client), and
the scaling from one GPU. Without a GPU, --cpu-workers gives the same on CPU workers (one core each).
"""

import argparse
import os
import sys
import time

if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
from bench_variants import plan_for  # noqa: E402 (beside this script: the same variants)

from somwidget.backend.variants import run_batch, run_plan  # noqa: E402


def cluster(workers: int, gpus: bool):
    from distributed import Client, Nanny, Scheduler, SpecCluster

    env = {"NCCL_NVLS_ENABLE": "0", "OMP_NUM_THREADS": "1"}
    spec = {i: {"cls": Nanny, "options": {"nthreads": 1, "env": dict(env, **({"CUDA_VISIBLE_DEVICES": str(i)}
                                                                             if gpus else {}))}}
            for i in range(workers)}
    c = SpecCluster(workers=spec, scheduler={"cls": Scheduler, "options": {"dashboard_address": None,
                                                                           "host": "127.0.0.1"}})
    return c, Client(c)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--car", type=int, default=16384)
    parser.add_argument("--grid", type=int, default=4096)
    parser.add_argument("--gpus", default="1,2,all", help="GPU counts to run (all: every GPU of the machine)")
    parser.add_argument("--cpu-workers", default="", help="CPU worker counts to run instead of GPUs")
    args = parser.parse_args(argv)
    gpus = not args.cpu_workers
    if gpus:
        import warp as wp

        wp.config.log_level = wp.LOG_WARNING
        total = wp.get_cuda_device_count()
        names = {wp.get_device(f"cuda:{i}").name for i in range(total)}
        counts = sorted({total if x == "all" else int(x) for x in args.gpus.split(",") if x})
        counts = [g for g in counts if 1 <= g <= total]
        print(f"{total} GPU(s): {', '.join(sorted(names))}")
    else:
        counts = [int(x) for x in args.cpu_workers.split(",") if x]
        print(f"CPU workers, one core each ({os.cpu_count()} cores here)")
    plans = {"car": plan_for("car", args.car)[1], "space-grid": plan_for("space-grid", args.grid)[1]}
    rates: dict = {}
    for workers in counts:
        c, client = cluster(workers, gpus)
        try:
            client.wait_for_workers(workers, timeout=120)
            device = None if gpus else "cpu"
            for plan in plans.values():  # compile on every worker
                client.run(run_batch, plan.part(0, 2), device)
            for name, plan in plans.items():
                t0 = time.perf_counter()
                weights, figs = run_plan(plan, device=device, client=client)
                seconds = time.perf_counter() - t0
                assert np.isfinite(weights).all() and len(figs["gap"]) == plan.n_variants
                rate = plan.n_variants / seconds
                rates[(name, workers)] = rate
                base = rates.get((name, counts[0]))
                scale = f", x {rate / base:.2f} from {counts[0]} ({rate / base / (workers / counts[0]):.2f} of " \
                        f"linear)" if workers != counts[0] else ""
                print(f"  {workers} {'GPU' if gpus else 'CPU worker'}(s), {name}: {plan.n_variants} variants in "
                      f"{seconds:.2f} s = {rate:,.0f} variants/s{scale}")
        finally:
            client.close()
            c.close()


if __name__ == "__main__":
    main()
