"""Step 3 of the cycle, written once: one Jacobi step of the uniform Laplacian, W_v <- W_v + lambda (mean of its
neighbours' W - W_v) on the masked dims, all from the weights before the step (a neuron with no neighbour stays);
and Taubin's lambda / mu pair, the same step twice, the second with mu < 0, which keeps the volume (Taubin 1995).

Every path calls these: the CPU's and CUDA's cycles (cycle_kernels.py), the distance rows and local cycles, the
shaping cycle (`smooth_kernel`), the spread kernels (spread_kernels.py, the neighbours' sum from shared memory) and
the batched kernels (batch_kernels.py, a variant's row of the weights).
"""

import functools
from typing import Any

import warp as wp

#: Taubin's pass band: with lambda > 0 the second step's mu = 1 / (PASS_BAND - 1 / lambda) < -lambda undoes the
#: first step's shrinking of the shape's broad curves and keeps damping the fine ripples. Chosen by measurement on
#: the sphere preset (BENCHMARKS.md, "Smoothing that keeps the volume"): the usual 0.1 grew it by up to 20% over a
#: whole run at lambda 0.3, 0 shrank it by 2.7%; 0.015 keeps it within 0.1% for lambda 0.05 to 0.3.
PASS_BAND = 0.015


def taubin_mu(strength: float) -> float:
    """The negative second step of Taubin's lambda / mu pair for lambda = strength."""
    return 1.0 / (PASS_BAND - 1.0 / strength)


def smoothing_steps(strength: float, rule: str) -> list[float]:
    """The strengths of the steps a cycle takes: none (strength 0), lambda ("laplacian"), or lambda and mu
    ("taubin")."""
    if strength <= 0.0:
        return []
    if rule == "taubin":
        return [strength, taubin_mu(strength)]
    return [strength]


@wp.func
def laplacian_step(w: Any, total: Any, count: int, pull: Any):
    """W + pull (total / count - W): the step for a neuron of weights w whose `count` neighbours' weights sum to
    `total` (count > 0); pull = lambda * mask."""
    return w + wp.cw_mul(pull, total / wp.float32(count) - w)


@wp.func
def smoothed(weights: wp.array(dtype=Any), v: int, offsets: wp.array(dtype=wp.int32),
             neighbors: wp.array(dtype=wp.int32), pull: Any):
    """Neuron v after one step from `weights` (the topology's CSR lists: neighbours offsets[v] .. offsets[v + 1]),
    its neighbours summed in the topology's order; a neuron without neighbours stays."""
    w = weights[v]
    lo = offsets[v]
    hi = offsets[v + 1]
    if hi > lo:
        total = type(w)()
        for e in range(lo, hi):
            total += weights[neighbors[e]]
        w = laplacian_step(w, total, hi - lo, pull)
    return w


@functools.cache
def smooth_kernel(n_dims: int) -> wp.Kernel:
    """One step for weights of n_dims features, a thread per neuron, from weights_in into weights_out."""
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)

    @wp.kernel(enable_backward=False, module="unique", module_options={"max_unroll": 32})
    def smooth(weights_in: wp.array(dtype=vec), weights_out: wp.array(dtype=vec), offsets: wp.array(dtype=wp.int32),
               neighbors: wp.array(dtype=wp.int32), pull: vec):
        v = wp.tid()
        weights_out[v] = smoothed(weights_in, v, offsets, neighbors, pull)

    return smooth
