"""The CUDA cycle's fast paths give the weights of the general path, bit for bit.

On CUDA a small mesh's cycle runs in a kernel that spreads the controls over the warps of a block (at most eight
controls, no smoothing) or in the general kernel looking up every control's rate at once; and kernels are launched
dependent (their blocks start while the previous kernel ends) on compute capability 9.0+. The general path is the
kernel of a warp per 32 neurons, eight rates at a time, launched one after the other: each run here is repeated
that way and must give the same float32 weights. The engine tests compare all paths to the float64 reference.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import HAS_CUDA
from reference import lattice_edges

from somwidget import Som, Topology
from somwidget.backend import dependent_launch
from somwidget.backend import som as som_module

pytestmark = pytest.mark.skipif(not HAS_CUDA, reason="warp reports no CUDA device on this machine")

DEVICE = "cuda:0"


def _lattice(nx: int, ny: int, nz: int) -> tuple[Topology, np.ndarray]:
    edges, points = lattice_edges(nx, ny, nz)
    return Topology.from_edges(edges, nx * ny * nz), (points - points.mean(0)) / max(nx, ny, nz)


def _trained(topology, weights, controls, **kw) -> Som:
    som = Som(topology, weights, controls, device=DEVICE, **kw)
    som.train()
    return som


def _general_path(monkeypatch) -> None:
    monkeypatch.setattr(som_module, "SMALL_MESH", 0)
    monkeypatch.setattr(dependent_launch, "available", lambda device: False)


@pytest.mark.parametrize(
    ("n_dims", "k", "mirror", "smoothing", "distances"),
    [
        (3, 8, (), 0.0, None),  # spread over eight warps (case study 1's shape)
        (3, 3, (), 0.0, None),  # spread, most warps past the controls
        (5, 9, (1,), 0.0, None),  # 18 effective controls: every rate at once (case study 2's shape)
        (3, 8, (), 0.2, None),  # smoothing: the general kernel, launched dependent
        (3, 5, (), 0.0, "rows"),  # spread kernel reading distance rows, with stalls on missing rows
    ],
)
def test_fast_paths_equal_general_path(monkeypatch, n_dims, k, mirror, smoothing, distances):
    rng = np.random.default_rng(k + 10 * n_dims)
    topology, points = _lattice(12, 10, 6)
    weights = np.concatenate([points, rng.uniform(-1, 1, (len(points), n_dims - 3))], axis=1)
    controls = rng.uniform(-1, 1, (k, n_dims))
    kw = dict(iterations=120, smoothing=smoothing, mirror=mirror)
    if distances:
        kw.update(distances=distances, cache_rows=8)
    launched = []
    real_launch = dependent_launch.launch_tiled_after_kernel
    monkeypatch.setattr(dependent_launch, "launch_tiled_after_kernel",
                        lambda *a, **kws: launched.append(a[0].key) or real_launch(*a, **kws))
    dependent = dependent_launch.available(DEVICE)  # 9.0+ and a CUDA 12.3+ driver
    fast_som = _trained(topology, weights, controls, **kw)
    fast = fast_som.weights
    if dependent:
        assert launched, "no kernel was launched dependent on a device that allows it"
    if distances:
        assert fast_som._cache.stalls >= 1  # a graph stopped on a missing row and went on
    _general_path(monkeypatch)
    general = _trained(topology, weights, controls, **kw).weights
    assert np.array_equal(fast, general), f"largest difference {np.abs(fast - general).max():.3e}"
    assert not np.array_equal(fast, weights)  # the runs moved the mesh


def test_frames_equal_one_run(monkeypatch):
    """step() in frames replays shorter graphs whose first kernel follows a graph boundary."""
    rng = np.random.default_rng(7)
    topology, points = _lattice(16, 16, 4)
    controls = rng.uniform(-1, 1, (8, 3))
    som = Som(topology, points, controls, iterations=100, device=DEVICE)
    while som.iteration < som.iterations:
        som.step(7)
    _general_path(monkeypatch)
    assert np.array_equal(som.weights, _trained(topology, points, controls, iterations=100).weights)
