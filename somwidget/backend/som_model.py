"""What a Som trains and how it measures (warp.sim's Model): the mesh's topology and start weights W(0), the n feature
dims, the metric weights m_j of the winner criterion u_c = argmin_v sum_j m_j (C_cj - W_vj)^2, the position dims and
the dims step 3 smooths, and where the hop distances D[u, v] come from: the topology's dense N x N table, or distance
rows of recent winners computed on demand (row_cache.RowCache).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import checks
from .cycle_kernels import CUDA_BLOCK, cycle_kernels
from .row_cache import RowCache
from .topology import MAX_DENSE_NEURONS, Topology

MAX_DIMS = 32
#: On the CPU the dense table is the default up to this many neurons (512 MiB, built by the CPU's cores); past it,
#: distance rows (the local cycle, local_path.py).
CPU_DENSE_NEURONS = 16384


def check_start(topology: Topology, weights) -> np.ndarray:
    """W(0) as (N, n) float32: one row per vertex, 1..MAX_DIMS feature dims."""
    start = checks.finite_array("weights", weights, 2)
    if start.shape[0] != topology.n_vertices:
        raise ValueError(f"weights: expected {topology.n_vertices} rows (one per vertex), got {start.shape[0]}")
    if not 1 <= start.shape[1] <= MAX_DIMS:
        raise ValueError(f"weights: expected 1 to {MAX_DIMS} feature dimensions, got {start.shape[1]}")
    return start


def check_smooth_dims(smooth_dims, n_dims: int) -> tuple[int, ...]:
    if smooth_dims is None:
        return tuple(range(min(3, n_dims)))
    return checks.dims("smooth_dims", smooth_dims, n_dims)


def check_metric(metric, n_dims: int) -> np.ndarray:
    if metric is None:
        return np.ones(n_dims, np.float32)
    m = checks.finite_array("metric_weights", metric, 1)
    if m.shape[0] != n_dims:
        raise ValueError(f"metric_weights: expected {n_dims} weights (one per dimension), got {m.shape[0]}")
    if (m < 0).any():
        raise ValueError(f"metric_weights: weights must be >= 0, got {m.tolist()}")
    if not (m > 0).any():
        raise ValueError("metric_weights: at least one weight must be positive, all are zero")
    return m


def check_distances(distances, n_neurons: int, device: str) -> bool:
    """True for distance rows on demand, False for the dense table (None: dense up to CPU_DENSE_NEURONS on the CPU,
    MAX_DENSE_NEURONS on a GPU)."""
    if distances is None:
        return n_neurons > (CPU_DENSE_NEURONS if device == "cpu" else MAX_DENSE_NEURONS)
    if distances not in ("dense", "rows"):
        raise ValueError(f"distances: expected 'dense', 'rows' or None, got {distances!r}")
    if distances == "dense" and n_neurons > MAX_DENSE_NEURONS:
        raise ValueError(f"distances: the dense table holds at most {MAX_DENSE_NEURONS:,} neurons, this mesh has "
                         f"{n_neurons:,}; use distances='rows' (distance rows computed on demand)")
    return distances == "rows"


def mask_of(dims: tuple[int, ...], n_dims: int) -> np.ndarray:
    """(n,) float32: 1 on `dims`, else 0."""
    mask = np.zeros(n_dims, np.float32)
    mask[list(dims)] = 1
    return mask


class SomModel:
    """The model's arrays on `device`: start (N, n) float32 on the host; offsets, neighbors (the topology's CSR
    lists); m (1,) the metric weights and mask (1,) the smoothing dims as vectors; distances and slot_of, read by the
    cycle kernels as D[u, v] (rows: the cache's rows, found through slot_of; dense: the table, slot_of unread);
    kernels: cycle_kernels(n) (vec: a row of weights). `metric` and `smooth_dims` may change (`set_metric`,
    `set_smooth_dims`); the rest is fixed."""

    def __init__(self, topology: Topology, start: np.ndarray, device: str, smooth_dims: tuple[int, ...],
                 metric: np.ndarray, rows: bool, cache_rows: int | None) -> None:
        self.topology = topology
        self.device = device
        self.start = start
        self.n_neurons, self.n_dims = start.shape
        self.position_dims = list(range(min(3, self.n_dims)))
        self.rows = rows
        self.kernels = cycle_kernels(self.n_dims)
        self.vec = self.kernels.vec
        self.blocks = (self.n_neurons + int(CUDA_BLOCK) - 1) // int(CUDA_BLOCK)  # CUDA blocks of a thread per neuron
        self.cache: RowCache | None = None
        if rows:
            self.cache = RowCache(topology, device, cache_rows)
            self.distances, self.slot_of = self.cache.rows, self.cache.slot_of
        else:
            self.distances = topology.distance_table(device)
            self.slot_of = wp.full(1, -1, dtype=wp.int32, device=device)  # unread: the dense table has every row
        self.no_near = wp.zeros((1, 1), dtype=wp.int32, device=device)  # unread: the shaping path's dense table
        self.offsets = wp.array(topology.offsets, dtype=wp.int32, device=device)
        neighbors = topology.neighbors if len(topology.neighbors) else np.zeros(1, np.int32)
        self.neighbors = wp.array(neighbors, dtype=wp.int32, device=device)
        self.metric = metric
        self.m = wp.array(metric[None, :], dtype=self.vec, device=device)
        self.smooth_dims = smooth_dims
        self.mask = wp.array(mask_of(smooth_dims, self.n_dims)[None, :], dtype=self.vec, device=device)

    def set_metric(self, metric: np.ndarray) -> None:
        self.metric = metric
        self.m.assign(metric[None, :])

    def set_smooth_dims(self, dims: tuple[int, ...]) -> None:
        self.smooth_dims = dims
        self.mask.assign(mask_of(dims, self.n_dims)[None, :])

    def kernels_for(self, pairs: int):
        """The cycle kernels whose step 2 applies the controls by `pairs` (Controls.pairs)."""
        return cycle_kernels(self.n_dims, 8, pairs)

    def row_cache(self) -> RowCache:
        """The cache of distance rows (distance rows mode); RuntimeError with the dense table, which needs none."""
        if self.cache is None:
            raise RuntimeError("SomModel: no distance rows' cache: this Som reads the dense table")
        return self.cache

    def d_max(self) -> int:
        """The largest finite hop distance: the learning table's last column."""
        return self.topology.diameter(self.device) if self.rows else self.topology.d_max
