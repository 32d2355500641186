"""The launch floor on a GPU: the cost of one kernel node in a captured CUDA graph (an empty kernel, and a tiled
kernel with one block reduction), the lower bound of a cycle that needs one kernel; and the cost of one block-wide
reduction inside a kernel (what a cycle that stays in one block would pay per winner search).

Run on the GPU machine from the repo root: `PYTHONPATH=. python3 benchmarks/bench_launch_floor.py`.
"""

import time

import warp as wp

wp.config.log_level = wp.LOG_WARNING
DEVICE = "cuda:0" if wp.get_cuda_device_count() else "cpu"


@wp.kernel(enable_backward=False)
def empty(a: wp.array(dtype=wp.int32)):
    wp.tid()


@wp.kernel(enable_backward=False)
def one_reduction(a: wp.array(dtype=wp.int32)):
    _block, lane = wp.tid()
    wp.tile_sum(wp.tile(lane))


keys8 = wp.types.vector(length=8, dtype=wp.uint64)


@wp.kernel(enable_backward=False)
def reductions(out: wp.array(dtype=wp.uint64), rounds: int, kind: int):
    """`rounds` block reductions in a loop: kind 0 a uint64 tile_min, 1 eight at once (an (8, block) tile reduced
    along its second axis), 2 an int tile_sum (a barrier)."""
    _block, lane = wp.tid()
    acc = wp.uint64(0)
    for r in range(rounds):
        key = wp.uint64(lane * 7 + r) ^ acc
        if kind == 0:
            acc = acc + wp.tile_min(wp.tile(key))[0]
        elif kind == 1:
            k = keys8()
            for g in range(8):
                k[g] = key + wp.uint64(g)
            acc = acc + wp.tile_reduce(wp.min, wp.tile(k), axis=1)[3]
        else:
            acc = acc + wp.uint64(wp.tile_sum(wp.tile(lane))[0])
    if lane == 0:
        out[0] = acc


def per_reduction_us(kind: int, threads: int, rounds: int = 2000) -> float:
    out = wp.zeros(1, dtype=wp.uint64, device=DEVICE)
    wp.launch_tiled(reductions, dim=[1], block_dim=threads, inputs=[out, 10, kind], device=DEVICE)
    wp.synchronize_device(DEVICE)
    t = time.perf_counter()
    wp.launch_tiled(reductions, dim=[1], block_dim=threads, inputs=[out, rounds, kind], device=DEVICE)
    wp.synchronize_device(DEVICE)
    return (time.perf_counter() - t) / rounds * 1e6


def per_node_us(launch, nodes: int = 1000) -> float:
    launch()
    with wp.ScopedCapture(device=DEVICE) as capture:
        for _ in range(nodes):
            launch()
    wp.capture_launch(capture.graph)
    wp.synchronize_device(DEVICE)
    t = time.perf_counter()
    wp.capture_launch(capture.graph)
    wp.synchronize_device(DEVICE)
    return (time.perf_counter() - t) / nodes * 1e6


if __name__ == "__main__":
    a = wp.zeros(1, dtype=wp.int32, device=DEVICE)
    print(f"{wp.get_device(DEVICE).name}: us per graph node")
    print(f"  empty kernel, 4096 threads: {per_node_us(lambda: wp.launch(empty, dim=4096, inputs=[a])):.2f}")
    for threads in (32, 128):
        us = per_node_us(lambda threads=threads:
                         wp.launch_tiled(one_reduction, dim=[128], block_dim=threads, inputs=[a]))
        print(f"  tiled kernel, 128 blocks of {threads}, one tile_sum: {us:.2f}")
    print("us per block reduction inside one kernel (one block):")
    for threads in (256, 1024):
        for kind, what in ((0, "uint64 tile_min"), (1, "8 uint64 mins at once (axis reduce)"), (2, "int tile_sum")):
            print(f"  {threads} threads, {what}: {per_reduction_us(kind, threads):.3f}")
