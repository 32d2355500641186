"""The CUDA cycle's fast paths give the weights of the general path, bit for bit.

On CUDA a small mesh's cycle runs in a kernel that spreads the controls over the warps of a block (at most 32
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
from somwidget.backend import cuda_path, dependent_launch
from somwidget.backend.spread_kernels import SHARED_TABLE_WORDS

pytestmark = [pytest.mark.gpu, pytest.mark.skipif(not HAS_CUDA, reason="warp reports no CUDA device on this machine")]

DEVICE = "cuda:0"


def _lattice(nx: int, ny: int, nz: int) -> tuple[Topology, np.ndarray]:
    edges, points = lattice_edges(nx, ny, nz)
    return Topology.from_edges(edges, nx * ny * nz), (points - points.mean(0)) / max(nx, ny, nz)


def _trained(topology, weights, controls, **kw) -> Som:
    som = Som(topology, weights, controls, device=DEVICE, **kw)
    som.train()
    return som


def _general_path(monkeypatch) -> None:
    monkeypatch.setattr(cuda_path, "SMALL_MESH", 0)
    monkeypatch.setattr(dependent_launch, "available", lambda device: False)


@pytest.mark.parametrize(
    ("n_dims", "k", "mirror", "smoothing", "distances", "spread"),
    [
        (3, 8, (), 0.0, None, True),  # eight warps, a control each (case study 1's shape)
        (3, 3, (), 0.0, None, True),  # three warps
        (5, 9, (1,), 0.0, None, True),  # 18 effective controls: six warps of three (case study 2's shape)
        (4, 16, (1,), 0.0, None, True),  # 32: eight warps of four, the most a spread kernel takes
        (3, 20, (1,), 0.0, None, False),  # 40: the general kernel, every rate at once
        (3, 8, (), 0.2, None, True),  # smoothing in the same kernel, each block moving its halo too
        (5, 9, (1,), 0.3, None, True),  # the same with 18 controls, smoothing the position dims only
        (3, 5, (), 0.0, "rows", True),  # spread kernel reading distance rows, with stalls on missing rows
        (5, 9, (1,), 0.0, "rows", True),  # the same with 18 controls
    ],
)
def test_fast_paths_equal_general_path(monkeypatch, n_dims, k, mirror, smoothing, distances, spread):
    rng = np.random.default_rng(k + 10 * n_dims)
    topology, points = _lattice(12, 10, 6)
    weights = np.concatenate([points, rng.uniform(-1, 1, (len(points), n_dims - 3))], axis=1)
    controls = rng.uniform(-1, 1, (k, n_dims))
    kw = dict(iterations=120, smoothing=smoothing, mirror=mirror)
    if distances:
        kw.update(distances=distances, cache_rows=k * (2 if mirror else 1) + 3)
    launched = _record_dependent_launches(monkeypatch)
    dependent = dependent_launch.available(DEVICE)  # 9.0+ and a CUDA 12.3+ driver
    fast_som = _trained(topology, weights, controls, **kw)
    fast = fast_som.weights
    if dependent:
        assert launched, "no kernel was launched dependent on a device that allows it"
        assert any(_spread(key) for key in launched) == spread, launched
    if distances:
        assert fast_som.parts.model.cache.stalls >= 1  # a graph stopped on a missing row and went on
    _general_path(monkeypatch)
    general = _trained(topology, weights, controls, **kw).weights
    assert np.array_equal(fast, general), f"largest difference {np.abs(fast - general).max():.3e}"
    assert not np.array_equal(fast, weights)  # the runs moved the mesh


def test_spread_kernel_with_a_long_table_row(monkeypatch):
    """A chain of 1,500 neurons has 1,500 hop counts, more than the spread kernel copies into shared memory: it
    reads the table from global memory instead."""
    n = 1500
    topology = Topology.from_edges(np.stack([np.arange(n - 1), np.arange(1, n)], axis=1), n)
    rng = np.random.default_rng(3)
    points = np.stack([np.linspace(-1, 1, n), np.zeros(n), np.zeros(n)], axis=1)
    controls = rng.uniform(-1, 1, (6, 3))
    launched = _record_dependent_launches(monkeypatch)
    som = _trained(topology, points, controls, iterations=80)
    assert som.learning_table().shape[1] > SHARED_TABLE_WORDS
    if dependent_launch.available(DEVICE):
        assert any(_spread(key) for key in launched), launched
    _general_path(monkeypatch)
    assert np.array_equal(som.weights, _trained(topology, points, controls, iterations=80).weights)


@pytest.mark.parametrize(
    ("case", "spread"),
    [
        ("paths", True),  # 300 separate 3-vertex paths: halos that wrap around block boundaries, no winner nearby
        ("hub", False),  # a vertex of 40 neighbours: smoothing in its own kernel
    ],
)
def test_smoothing_in_one_kernel_equals_general_path(monkeypatch, case, spread):
    if case == "paths":
        n = 900
        starts = np.arange(0, n, 3)
        edges = np.concatenate([np.stack([starts, starts + 1], 1), np.stack([starts + 1, starts + 2], 1)])
    else:
        n = 600
        edges = np.concatenate([np.stack([np.zeros(40, int), np.arange(1, 41)], 1),
                                np.stack([np.arange(40, n - 1), np.arange(41, n)], 1)])
    topology = Topology.from_edges(edges, n)
    rng = np.random.default_rng(5)
    points = rng.uniform(-1, 1, (n, 3))
    controls = rng.uniform(-1, 1, (7, 3))
    launched = _record_dependent_launches(monkeypatch)
    som = _trained(topology, points, controls, iterations=90, smoothing=0.25)
    if dependent_launch.available(DEVICE):
        assert any(_spread(key) for key in launched) == spread, launched
    _general_path(monkeypatch)
    general = _trained(topology, points, controls, iterations=90, smoothing=0.25).weights
    assert np.array_equal(som.weights, general), f"largest difference {np.abs(som.weights - general).max():.3e}"


def _spread(kernel_key: str) -> bool:
    return "move_spread" in kernel_key or "move_smooth_spread" in kernel_key


def _record_dependent_launches(monkeypatch) -> list[str]:
    launched = []
    real_launch = dependent_launch.launch_tiled_after_kernel
    monkeypatch.setattr(dependent_launch, "launch_tiled_after_kernel",
                        lambda *a, **kws: launched.append(a[0].key) or real_launch(*a, **kws))
    return launched


@pytest.mark.parametrize("smoothing", [0.0, 0.2])
def test_frames_equal_one_run(monkeypatch, smoothing):
    """step() in frames replays shorter graphs whose first kernel follows a graph boundary (and, with smoothing in
    one kernel, graphs of an odd number of cycles, which end with the weights in the other array)."""
    rng = np.random.default_rng(7)
    topology, points = _lattice(16, 16, 4)
    controls = rng.uniform(-1, 1, (8, 3))
    som = Som(topology, points, controls, iterations=100, smoothing=smoothing, device=DEVICE)
    while som.iteration < som.iterations:
        som.step(7)
    _general_path(monkeypatch)
    one_run = _trained(topology, points, controls, iterations=100, smoothing=smoothing).weights
    assert np.array_equal(som.weights, one_run)
