"""The self-organizing map as computational clay: device state and the training cycle (DESIGN.md, the algorithm).

Restarts. A run is S cycles of the learning table L[s, d], whose neighbourhood starts as wide as the whole mesh and
narrows to nothing. Restarting at s = 0 when a control moves (the paper's retraining) would pull the clay into a
blob and regrow all of it, so a restart begins later in the same table: at s0 = floor((1 - reach) S), where `reach`
in (0, 1] is the neighbourhood radius the restart begins with, as a share of the full one; reach 1 is s = 0. Moving,
adding or removing controls and changing S, l_start, l_end, smoothing, smooth_dims or metric weights restart so
from the latest weights; `reset()` runs the whole schedule from the start weights; `restore()` puts weights and s
back as they were (an undo, a loaded session) and restarts nothing.

Mirrored pairs. With mirroring each control has a copy with the `mirror` dims negated, and the two act together
at the pair's place in the list: both rates from the same weights, l1 = L[s, D[u_c, v]] and l2 = L[s, D[u_c', v]],
W <- W + (l1 (C - W) + l2 (C' - W)) / max(1, l1 + l2) (`cycle_kernels.move_pair`), so a symmetric mesh stays exactly
symmetric. The device holds each original next to its copy.
"""

from __future__ import annotations

import functools
import os
from collections import OrderedDict
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp
from numpy.typing import ArrayLike

try:  # Warp's internals, for `_copy` (warp-lang is pinned to 1.19.x in pyproject.toml)
    from warp._src import context as _warp_context
except ImportError:  # pragma: no cover - another Warp layout: wp.copy then
    _warp_context = None

from . import checks, dependent_launch
from .device import resolve, warp_exclusive
from .halos import block_halos
from .cycle_kernels import CUDA_BLOCK, PAIRS, SCALED_PAIRS, SINGLES, cycle_kernels
from .distance_kernels import assign_slots
from .primitives import barrier, sched_yield_address
from .spread_kernels import (SHARED_TABLE_WORDS, spread_cycle_inputs, spread_cycle_kernel,
                             spread_smoothing_cycle_inputs, spread_smoothing_cycle_kernel)
from .schedule import learning_table
from .topology import MAX_DENSE_NEURONS, RowSearch, Topology

MAX_DIMS = 32
MAX_CONTROLS = 256  # counts the effective list: originals plus mirrored copies
_KEY_NONE = np.uint64(0xFFFFFFFFFFFFFFFF)
#: Cycles in the longest captured graph; runs are split into powers of two.
_LONGEST_GRAPH = 512
#: Meshes up to this many neurons have latency-bound cycles on CUDA (a block per 32 neurons leaves most of the GPU
#: idle). With at most 32 controls a block spreads the controls over up to eight warps (`spread_cycle_kernel`; with
#: smoothing, and the dense table, `spread_smoothing_cycle_kernel`, where each block also moves the neighbours of
#: its neurons that other blocks own: at most _SPREAD_MOST_WARPS chunks of 32, neurons of at most
#: _SMOOTHING_MOST_NEIGHBOURS neighbours); otherwise the move kernel looks up the rates of all controls at once, up
#: to 32 (measured on an H200, BENCHMARKS.md).
SMALL_MESH = 16384
_SPREAD_MOST_WARPS = 8
_SPREAD_MOST_CONTROLS = 32
_SMOOTHING_MOST_NEIGHBOURS = 16
_YIELD = sched_yield_address()
#: Neuron-control pairs a cycle must have per core before the CPU cycle is split (about 1 ms of work each).
_PAIRS_PER_EXTRA_CORE = 1 << 18
#: Distance rows mode: the cache's default size in bytes (int32 rows of N), at least 2 x MAX_CONTROLS rows: on the
#: CPU 1 GiB, on a GPU a sixteenth of its memory up to 8 GiB.
_CACHE_BYTES = {"cpu": 1 << 30, "cuda": 8 << 30}
_CACHE_MOST_ROWS = 4096
#: Distance rows mode on CUDA: rings of neurons around the winners whose rows a search brings along (see _around).
_PREFETCH_RINGS = 8
#: Learning table entries (S x (d_max + 1) float32) a Som may hold: 2 GiB.
_MAX_TABLE_ENTRIES = 1 << 29
#: The neighbourhood radius a restart begins with, as a share of the full radius sigma (Restarts, above). Chosen
#: by measurement on the car (BENCHMARKS.md, "Local restarts"): a control moved by 5% of the size is followed to
#: within 1% while the far half of the mesh stays within 2% and nothing collapses, with the least spike at the moved
#: control among the values that do (a smaller reach pulls a narrower, pointier bump; a larger one wears down the
#: neighbourhoods of the other controls).
DEFAULT_REACH = 0.08


def restart_iteration(reach: float, iterations: int) -> int:
    """s0 = floor((1 - reach) S), at most S - 1: where a local restart begins in the unchanged schedule."""
    return min(int(np.floor((1.0 - reach) * iterations)), iterations - 1)


class Som:
    """A SOM whose neurons are the vertices of `topology`, trained towards `controls`.

    weights (N, n) and controls (k, n) share the n feature dimensions (1..32). State stays on `device`
    ("cpu", "cuda:N", None = best available); `weights` returns a host copy. On the CPU the cycle is split over
    `cpu_cores` cores (None: one for small meshes, else the cores this process may use, at most 8).

    distances: "dense" reads D[u, v] from the topology's dense N x N table (N <= 65,536); "rows" computes the
    distance rows of the current winners on demand and keeps the `cache_rows` most recently used on the device
    (None: as many as fit in 1 GiB on the CPU, on a GPU in a sixteenth of its memory up to 8 GiB; at least 512 and at
    most 4096; 2 at the least); None picks dense up to 65,536 neurons, else rows.
    Both give the same weights.

    reach (0, 1]: the neighbourhood radius a restart begins with, as a share of the full radius (Restarts, in the
    module's docstring). Moving controls and changing S, l_start, l_end, smoothing or metric weights restart at
    s0 = floor((1 - reach) S) from the latest weights (the clay follows locally); `reset()` runs the whole schedule
    from the start weights; `restore()` puts saved weights and s back without training.
    """

    @warp_exclusive
    def __init__(
        self,
        topology: Topology,
        weights: ArrayLike,
        controls: ArrayLike,
        iterations: int = 1000,
        l_start: float = 0.25,
        l_end: float = 0.03,
        smoothing: float = 0.0,
        smooth_dims: Sequence[int] | None = None,
        metric_weights: ArrayLike | None = None,
        mirror: Sequence[int] = (),
        device: str | None = None,
        reach: float = DEFAULT_REACH,
        *,
        cpu_cores: int | None = None,
        distances: str | None = None,
        cache_rows: int | None = None,
    ):
        if not isinstance(topology, Topology):
            raise ValueError(f"topology: expected a Topology, got {type(topology).__name__}")
        self.device = resolve(device)
        self.topology = topology
        start = checks.finite_array("weights", weights, 2)
        if start.shape[0] != topology.n_vertices:
            raise ValueError(f"weights: expected {topology.n_vertices} rows (one per vertex), got {start.shape[0]}")
        if not 1 <= start.shape[1] <= MAX_DIMS:
            raise ValueError(f"weights: expected 1 to {MAX_DIMS} feature dimensions, got {start.shape[1]}")
        self.n_neurons, self.n_dims = start.shape
        self._start = start
        self._iterations = checks.integer("iterations", iterations, 1)
        self._l_start = checks.real("l_start", l_start, 0.0, 1.0, low_open=True)
        self._l_end = checks.real("l_end", l_end, 0.0, 1.0, low_open=True)
        self._smoothing = checks.real("smoothing", smoothing, 0.0, 1.0)
        self._reach = checks.real("reach", reach, 0.0, 1.0, low_open=True)
        self._mirror = checks.dims("mirror", mirror, self.n_dims)
        self._smooth_dims = self._check_smooth_dims(smooth_dims)
        self._metric = self._check_metric(metric_weights)
        self._controls = self._check_controls(controls, self._mirror)

        dev = self.device
        self._blocks = (self.n_neurons + int(CUDA_BLOCK) - 1) // int(CUDA_BLOCK)
        self._cpu_cores = None if cpu_cores is None else checks.integer("cpu_cores", cpu_cores, 1, 64)
        self._cores = 1
        self._pool: ThreadPoolExecutor | None = None
        self._rows_mode = self._check_distances(distances)
        size = None if cache_rows is None else checks.integer("cache_rows", cache_rows, 1)
        self._cache: _RowCache | None = None
        # the cycle kernels read D[u_c, v] from the dense table or from the cache's rows (through slot_of)
        if self._rows_mode:
            self._cache = _RowCache(topology, dev, size)
            self._distances, self._slot_of = self._cache.rows, self._cache.slot_of
        else:
            self._distances = topology.distance_table(dev)
            self._slot_of = wp.full(1, -1, dtype=wp.int32, device=dev)  # unread: the dense table has every row
        self._stalled = wp.zeros(1, dtype=wp.int32, device=dev)  # set only by a distance-rows cycle that stalls
        self._offsets = wp.array(topology.offsets, dtype=wp.int32, device=dev)
        neighbors = topology.neighbors if len(topology.neighbors) else np.zeros(1, np.int32)
        self._neighbors = wp.array(neighbors, dtype=wp.int32, device=dev)
        self._kernels = cycle_kernels(self.n_dims)
        vec = self._kernels.vec
        self._w = wp.array(start, dtype=vec, device=dev)
        self._w_moved = wp.empty_like(self._w)
        # The effective controls (a fixed-size buffer: captured graphs keep its pointer) and the cycle counters (CUDA:
        # two that the kernels pass on, ping-pong; CPU: one per core; a 64-byte line each, no false sharing between
        # cores), in one device block. The host writes them into `_staging`: on the CPU that is the block itself;
        # on CUDA pinned memory, which goes up in one asynchronous copy when a run starts afresh (`_set_cycle`), so
        # that a drag frame costs one copy more than a plain one, not a wait.
        counters = 64 if dev == "cpu" else 2
        control_bytes = MAX_CONTROLS * self.n_dims * 4
        self._block = wp.zeros(control_bytes + counters * 64, dtype=wp.uint8, device=dev)
        self._c = wp.array(ptr=self._block.ptr, dtype=vec, shape=(MAX_CONTROLS,), device=dev)
        self._counters = wp.array(ptr=self._block.ptr + control_bytes, dtype=wp.int32, shape=(counters * 16,),
                                  device=dev)
        self._cycle = [self._counters[i * 16: i * 16 + 1] for i in range(counters)]
        self._staging = None if dev == "cpu" else wp.zeros_like(self._block, device="cpu", pinned=True)
        self._uploaded = None if dev == "cpu" else wp.Event(dev)
        self._staging_busy = False  # an upload from `_staging` may still be under way
        self._w_anchor = None  # weights kept by `anchor()`
        self._anchor_pending = False  # the next run starts by copying them back (set_controls(from_anchor=True))
        words = (self._block if self._staging is None else self._staging).numpy().view(np.float32)
        self._c_rows = words[: control_bytes // 4].reshape(MAX_CONTROLS, self.n_dims)
        self._counter_words = words[control_bytes // 4:].view(np.int32)
        self._m = wp.array(self._metric[None, :], dtype=vec, device=dev)
        self._mask = wp.array(self._mask_of(self._smooth_dims)[None, :], dtype=vec, device=dev)
        self._keys = wp.full((3, MAX_CONTROLS), _KEY_NONE, dtype=wp.uint64, device=dev)
        self._meet = wp.zeros(1, dtype=wp.int64, device=dev)
        self._meet_failed = wp.zeros(1, dtype=wp.int32, device=dev)
        self._graphs: dict[tuple, tuple] = {}  # key -> (graph, the packed arguments of its dependent launches)
        self._graph_controls: tuple[int, int] | None = None  # (k_eff, pairs) the graphs were recorded for
        self._table = None
        self._build_table()
        self._upload_controls()
        self._s = 0
        self._parity = 0
        self._halos = self._block_halos()

    # -- validation ---------------------------------------------------------------------------------------
    def _check_distances(self, distances) -> bool:
        """True for distance rows on demand, False for the dense table."""
        if distances is None:
            return self.n_neurons > MAX_DENSE_NEURONS
        if distances not in ("dense", "rows"):
            raise ValueError(f"distances: expected 'dense', 'rows' or None, got {distances!r}")
        if distances == "dense" and self.n_neurons > MAX_DENSE_NEURONS:
            raise ValueError(f"distances: the dense table holds at most {MAX_DENSE_NEURONS:,} neurons, this mesh has "
                             f"{self.n_neurons:,}; use distances='rows' (distance rows computed on demand)")
        return distances == "rows"

    def _check_controls(self, controls, mirror) -> np.ndarray:
        c = np.asarray(controls) if not isinstance(controls, np.ndarray) else controls
        if c.ndim == 1:
            c = c[None, :]
        c = checks.finite_array("controls", c, 2)
        if c.shape[1] != self.n_dims:
            raise ValueError(f"controls: expected {self.n_dims} feature dimensions like the weights, got {c.shape[1]}")
        k_eff = c.shape[0] * (2 if mirror else 1)
        if c.shape[0] < 1 or k_eff > MAX_CONTROLS:
            raise ValueError(f"controls: expected 1 to {MAX_CONTROLS} controls counting mirrored copies, "
                             f"got {c.shape[0]} ({k_eff} with mirroring)")
        return c

    def _check_metric(self, metric) -> np.ndarray:
        if metric is None:
            return np.ones(self.n_dims, np.float32)
        m = checks.finite_array("metric_weights", metric, 1)
        if m.shape[0] != self.n_dims:
            raise ValueError(f"metric_weights: expected {self.n_dims} weights (one per dimension), got {m.shape[0]}")
        if (m < 0).any():
            raise ValueError(f"metric_weights: weights must be >= 0, got {m.tolist()}")
        if not (m > 0).any():
            raise ValueError("metric_weights: at least one weight must be positive, all are zero")
        return m

    def _check_smooth_dims(self, smooth_dims) -> tuple[int, ...]:
        if smooth_dims is None:
            return tuple(range(min(3, self.n_dims)))
        return checks.dims("smooth_dims", smooth_dims, self.n_dims)

    def _mask_of(self, dims: tuple[int, ...]) -> np.ndarray:
        mask = np.zeros(self.n_dims, np.float32)
        mask[list(dims)] = 1
        return mask

    # -- configuration ------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        """s: the schedule's current cycle (a local restart begins past 0, at `restart_iteration`)."""
        return self._s

    @property
    def reach(self) -> float:
        """The neighbourhood radius a restart begins with, as a share of the full radius: s0 = floor((1 - reach) S).
        1 restarts at s = 0 (the paper's restart). Setting it changes the next restart, not the run under way."""
        return self._reach

    @reach.setter
    def reach(self, value: float) -> None:
        self._reach = checks.real("reach", value, 0.0, 1.0, low_open=True)

    @property
    def restart_iteration(self) -> int:
        """s0, where the next local restart begins."""
        return restart_iteration(self._reach, self._iterations)

    @property
    def iterations(self) -> int:
        """S: cycles in a run. Setting it restarts the schedule from the current weights."""
        return self._iterations

    @iterations.setter
    @warp_exclusive
    def iterations(self, value: int) -> None:
        old, self._iterations = self._iterations, checks.integer("iterations", value, 1)
        try:
            self._build_table()
        except ValueError:
            self._iterations = old
            raise
        self._restart()

    @property
    def l_start(self) -> float:
        return self._l_start

    @l_start.setter
    @warp_exclusive
    def l_start(self, value: float) -> None:
        self._l_start = checks.real("l_start", value, 0.0, 1.0, low_open=True)
        self._build_table()
        self._restart()

    @property
    def l_end(self) -> float:
        return self._l_end

    @l_end.setter
    @warp_exclusive
    def l_end(self, value: float) -> None:
        self._l_end = checks.real("l_end", value, 0.0, 1.0, low_open=True)
        self._build_table()
        self._restart()

    @property
    def smoothing(self) -> float:
        """lambda of the Laplacian step after each cycle; 0 switches smoothing off."""
        return self._smoothing

    @smoothing.setter
    @warp_exclusive
    def smoothing(self, value: float) -> None:
        self._smoothing = checks.real("smoothing", value, 0.0, 1.0)
        self._graphs.clear()  # the graphs hold lambda
        self._restart()

    @property
    def smooth_dims(self) -> tuple[int, ...]:
        return self._smooth_dims

    @smooth_dims.setter
    @warp_exclusive
    def smooth_dims(self, value: Sequence[int] | None) -> None:
        self._smooth_dims = self._check_smooth_dims(value)
        self._mask.assign(self._mask_of(self._smooth_dims)[None, :])
        self._restart()

    @property
    def metric_weights(self) -> np.ndarray:
        return self._metric.copy()

    @metric_weights.setter
    @warp_exclusive
    def metric_weights(self, value: ArrayLike) -> None:
        self._metric = self._check_metric(value)
        self._m.assign(self._metric[None, :])
        self._restart()

    @property
    def mirror(self) -> tuple[int, ...]:
        """Dims negated in each control's mirrored copy; () = no symmetry."""
        return self._mirror

    @mirror.setter
    @warp_exclusive
    def mirror(self, value: Sequence[int]) -> None:
        mirror = checks.dims("mirror", value, self.n_dims)
        self._check_controls(self._controls, mirror)
        self._mirror = mirror
        self._upload_controls()
        self._restart()

    @property
    def controls(self) -> np.ndarray:
        """(k, n) the controls as given, without mirrored copies."""
        return self._controls.copy()

    @property
    def effective_controls(self) -> np.ndarray:
        """[originals..., mirrored copies...]: the list the cycle applies in order."""
        if not self._mirror:
            return self._controls.copy()
        copies = self._controls.copy()
        copies[:, list(self._mirror)] *= -1.0
        return np.concatenate([self._controls, copies])

    @property
    @warp_exclusive
    def weights(self) -> np.ndarray:
        """(N, n) float32 host copy of the current weights."""
        self._settle_anchor()
        return self._w.numpy().reshape(self.n_neurons, self.n_dims).copy()

    @property
    def distances(self) -> str:
        """"dense" (the N x N table) or "rows" (distance rows of the winners, computed on demand and cached)."""
        return "rows" if self._rows_mode else "dense"

    @property
    def start_weights(self) -> np.ndarray:
        return self._start.copy()

    def learning_table(self) -> np.ndarray:
        """L[s, d] (S, d_max + 1) float32."""
        return self._table_host.copy()

    # -- intents ------------------------------------------------------------------------------------------
    @warp_exclusive
    def set_controls(self, controls: ArrayLike, from_anchor: bool = False) -> None:
        """New controls (any count k); the schedule restarts at s0 from the latest weights (local follow), or with
        `from_anchor` from the weights `anchor()` kept (each frame of a drag restarts from the shape the drag began
        with: on CUDA the copy back is a node of the run's first graph, not a call of its own)."""
        if from_anchor and self._w_anchor is None:
            raise ValueError("set_controls: from_anchor needs anchor() first (no weights are kept)")
        self._controls = self._check_controls(controls, self._mirror)
        self._anchor_pending = from_anchor
        if from_anchor and self.device == "cpu":
            self._settle_anchor()
        self._upload_controls()
        self._restart()

    @warp_exclusive
    def anchor(self) -> None:
        """Keep a copy of the current weights on the device, for `set_controls(..., from_anchor=True)`."""
        self._settle_anchor()
        if self._w_anchor is None:
            self._w_anchor = wp.empty_like(self._w)
        wp.copy(self._w_anchor, self._w)

    @warp_exclusive
    def set_weights(self, weights: ArrayLike) -> None:
        """Replace the current weights (same shape); the schedule restarts at s0 from them."""
        self._anchor_pending = False
        self._w.assign(self._checked_weights(weights))
        self._restart()

    @warp_exclusive
    def restart(self) -> None:
        """Restart the schedule at s0 from the latest weights, as a control move does."""
        self._restart()

    @warp_exclusive
    def reset(self) -> None:
        """Back to the start weights and s = 0 (the whole schedule); the controls stay."""
        self._anchor_pending = False
        self._w.assign(self._start)
        self._restart(0)

    @warp_exclusive
    def restore(self, weights: ArrayLike, iteration: int) -> None:
        """Put saved weights and s back exactly (a loaded session, an undo): nothing trains, nothing restarts."""
        s = checks.integer("iteration", iteration, 0, self._iterations)
        w = self._checked_weights(weights)
        self._anchor_pending = False
        self._w.assign(w)
        self._restart(s)

    @warp_exclusive
    def winners(self) -> np.ndarray:
        """(k_eff,) the nearest neuron (metric-weighted) of each effective control for the current weights, in the
        order of `effective_controls`."""
        self._find_winners_now()
        found = self._current_winners()
        if not self._mirror:
            return found
        return np.concatenate([found[0::2], found[1::2]])

    def _settle_anchor(self) -> None:
        """The anchored weights into the current ones now, if a restart from the anchor still waits for its run."""
        if self._anchor_pending:
            self._anchor_pending = False
            _copy(self._w, self._w_anchor)

    def _checked_weights(self, weights: ArrayLike) -> np.ndarray:
        w = checks.finite_array("weights", weights, 2)
        if w.shape != (self.n_neurons, self.n_dims):
            raise ValueError(f"weights: expected shape {(self.n_neurons, self.n_dims)}, got {w.shape}")
        return w

    # -- training -----------------------------------------------------------------------------------------
    @warp_exclusive
    def step(self, n: int = 1) -> int:
        """Run up to n cycles (stopping at S); returns how many ran."""
        n = checks.integer("n", n, 0)
        n = min(n, self._iterations - self._s)
        done = 0
        while done < n:
            chunk = min(_LONGEST_GRAPH, 1 << ((n - done).bit_length() - 1))
            self._run(chunk)
            done += chunk
        return n

    def train(self) -> int:
        """Run the rest of the schedule (to s = S); returns the cycles run."""
        return self.step(self._iterations - self._s)

    @warp_exclusive
    def synchronize(self) -> None:
        wp.synchronize_device(self.device)

    # -- internals ----------------------------------------------------------------------------------------
    def _build_table(self) -> None:
        d_max = self.topology.diameter(self.device) if self._rows_mode else self.topology.d_max
        if self._iterations * (d_max + 1) > _MAX_TABLE_ENTRIES:
            raise ValueError(f"iterations: the learning table S x (d_max + 1) = {self._iterations:,} x {d_max + 1:,} "
                             f"exceeds {_MAX_TABLE_ENTRIES:,} entries (2 GiB); use fewer iterations")
        self._table_host = learning_table(self._iterations, d_max, self._l_start, self._l_end)
        self._table_max = float(self._table_host.max())
        self._d_max = d_max
        self._table = wp.array(self._table_host, dtype=wp.float32, device=self.device)
        self._graphs.clear()

    def _upload_controls(self) -> None:
        """The effective controls into the fixed-size device buffer, so that the captured graphs stay valid while
        only their values change (a drag); with mirroring in pairs, each original next to its copy (slots 2i and
        2i + 1), the order in which step 2 applies them. On CUDA they go up with the next `_set_cycle`."""
        self._staging_ready()
        rows = self._c_rows
        k = len(self._controls)
        k_eff = 2 * k if self._mirror else k
        if self._mirror:
            rows[0:k_eff:2] = self._controls
            rows[1:k_eff:2] = self._controls
            for d in self._mirror:
                rows[1:k_eff:2, d] *= -1.0
        else:
            rows[:k] = self._controls
        rows[k_eff:] = 0.0
        self._k_eff = k_eff
        if self._graph_controls != (self._k_eff, self._pairs):  # the graphs hold the count and the pairing
            self._graphs.clear()
            self._graph_controls = (self._k_eff, self._pairs)
            if self.device == "cpu":
                self._plan_cores()
        self._winners_valid = False

    @property
    def _pairs(self) -> int:
        """How step 2 applies the controls (cycle_kernels.SINGLES, PAIRS, SCALED_PAIRS): in mirrored pairs with
        mirroring, scaled only where the table has a rate above 0.5 (two rates may then sum past 1)."""
        if not self._mirror:
            return SINGLES
        return SCALED_PAIRS if self._table_max > 0.5 else PAIRS

    def _plan_cores(self) -> None:
        """Split the CPU cycle: neuron ranges for the move and smoothing, a thread per extra core."""
        cores = min(self._cpu_cores or _cpu_cores(self.n_neurons, self._k_eff), self.n_neurons)
        bounds = np.linspace(0, self.n_neurons, cores + 1).astype(int)
        self._ranges = list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))
        if cores > 1 and self._pool is None:
            self._pool = ThreadPoolExecutor(63, thread_name_prefix="som-core")
        if cores != self._cores:
            self._meet.zero_()  # barrier generations count in multiples of the core count
        self._cores = cores

    def _restart(self, s: int | None = None) -> None:
        """Continue the schedule from cycle s (default: s0, a local restart) with the winners found afresh."""
        self._s = restart_iteration(self._reach, self._iterations) if s is None else s
        self._winners_valid = False

    def _set_cycle(self) -> None:
        """Every cycle counter to s; on CUDA the staged controls go up with them, in one asynchronous copy."""
        self._staging_ready()
        self._counter_words[:] = self._s
        if self._staging is not None:
            _copy(self._block, self._staging)
            wp.record_event(self._uploaded)
            self._staging_busy = True

    def _staging_ready(self) -> None:
        """On CUDA, wait until the last upload has left the staging buffer (so that it can be written again)."""
        if self._staging_busy:
            wp.synchronize_event(self._uploaded)
            self._staging_busy = False

    def _find_winners_now(self) -> None:
        if self._winners_valid:
            return
        self._settle_anchor()
        self._set_cycle()
        self._launch_find()
        self._winners_valid = True

    def _current_winners(self) -> np.ndarray:
        keys = self._keys.numpy()[self._s % 3, : self._k_eff]
        return (keys & np.uint64(0xFFFFFFFF)).astype(np.int64)

    def _launch_find(self) -> None:
        if self.device == "cpu":
            wp.launch(self._kernels.find_part, dim=1, device="cpu", inputs=[self._w, self._c, self._k_eff, self._m,
                                                                     self._keys, self._cycle[0], 0, 1, 0,
                                                                     self._stalled])
            return
        self._keys.fill_(_KEY_NONE)
        wp.launch_tiled(self._kernels.find_winners, dim=[self._blocks], block_dim=int(CUDA_BLOCK), device=self.device,
                        inputs=[self._w, self._c, self._k_eff, self._m, self._keys, self._cycle[0]])

    def _run(self, cycles: int) -> None:
        """`cycles` cycles from s, replayed from captured graphs (one per CPU core)."""
        if self._rows_mode:
            self._settle_anchor()
            self._run_rows(cycles)
            return
        fresh = not self._winners_valid
        if fresh:
            self._set_cycle()
        smoothing = self._smoothing > 0.0
        if self.device == "cpu":
            self._run_cpu(cycles, fresh, smoothing)
        else:
            parity = 0 if fresh else self._parity
            two_kernels = smoothing and self._smoothing_in_one_kernel() is None
            anchored, self._anchor_pending = self._anchor_pending, False  # the graph copies the anchor back first
            graph = self._graph((cycles, fresh, parity, smoothing, anchored),
                                lambda: self._record_cuda(cycles, fresh, parity, smoothing, anchored))
            wp.capture_launch(graph)
            self._parity = parity if two_kernels else (parity + cycles) % 2  # a kernel a cycle passes the counter on
        self._s += cycles
        self._winners_valid = True

    def _graph(self, key: tuple, record) -> object:
        held = self._graphs.get(key)
        if held is None:
            with wp.ScopedCapture(device=self.device) as capture:
                records = record()
            held = self._graphs[key] = (capture.graph, records)
        return held[0]

    def _run_cpu(self, cycles: int, fresh: bool, smoothing: bool) -> None:
        graphs = [self._graph((cycles, fresh, smoothing, core), lambda core=core: self._record_cpu(core, cycles, fresh,
                                                                                                smoothing))
                  for core in range(self._cores)]
        self._replay_cpu(graphs)

    def _replay_cpu(self, graphs: list) -> None:
        """Each core's graph on its own thread (the first on this one)."""
        others = [self._pool.submit(wp.capture_launch, g) for g in graphs[1:]] if self._pool else []
        wp.capture_launch(graphs[0])
        for job in others:
            job.result()
        if self._cores > 1 and self._meet_failed.numpy()[0]:
            self._meet_failed.zero_()
            self._meet.zero_()
            raise RuntimeError("Som: a CPU core did not reach the cycle barrier (was a worker thread stopped?)")

    def _record_cpu(self, core: int, cycles: int, fresh: bool, smoothing: bool) -> None:
        """One core's share: move and smooth its neurons, find the winners of its controls, meet between phases.
        Without `fresh` the winners of the first cycle are known (always so in distance rows mode)."""
        kern, cores, (lo, hi), counter = self._kernels, self._cores, self._ranges[core], self._cycle[core]
        move_part = self._movers().move_part
        stalled = self._stalled

        def meet():
            if cores > 1:
                wp.launch(barrier, dim=1, device="cpu", inputs=[self._meet, cores, _YIELD, self._meet_failed])

        find = [self._w, self._c, self._k_eff, self._m, self._keys, counter, core, cores]
        if fresh:
            wp.launch(kern.find_part, dim=1, device="cpu", inputs=[*find, 0, stalled])
            meet()
        moved = self._w_moved if smoothing else self._w
        for _ in range(cycles):
            wp.launch(move_part, dim=1, device="cpu",
                      inputs=[self._w, moved, self._c, 0, self._k_eff, self._table, self._distances, self._slot_of,
                              self._keys, counter, lo, hi, stalled])
            meet()
            if smoothing:
                wp.launch(kern.smooth_part, dim=1, device="cpu", inputs=[moved, self._w, self._offsets, self._neighbors,
                                                                      self._mask, self._smoothing, lo, hi, stalled])
                meet()
            wp.launch(kern.find_part, dim=1, device="cpu", inputs=[*find, 1, stalled])
            meet()

    def _record_cuda(self, cycles: int, fresh: bool, parity: int, smoothing: bool, anchored: bool = False) -> list:
        """A kernel a cycle (move + next winners), or two with smoothing (move; smooth + next winners). Without
        `fresh` the winners of the first cycle are known (always so in distance rows mode); `anchored` starts with
        the anchored weights copied back (`set_controls(..., from_anchor=True)`). Returns the packed arguments of
        the dependent launches, which the graph needs as long as it lives."""
        dev, threads, k = self.device, int(CUDA_BLOCK), self._k_eff
        dependent = dependent_launch.available(dev)
        after_kernel = False
        records = []

        def launch(kernel, inputs, threads=threads):
            nonlocal after_kernel
            if dependent and after_kernel:
                records.append(dependent_launch.launch_tiled_after_kernel(kernel, self._blocks, threads, inputs, dev))
            else:
                wp.launch_tiled(kernel, dim=[self._blocks], block_dim=threads, device=dev, inputs=inputs)
            after_kernel = True

        pairs = self._pairs
        move, move_threads, spread = self._movers().move, threads, False
        shared_table = self._table.shape[1] <= SHARED_TABLE_WORDS
        halos = self._smoothing_in_one_kernel() if smoothing else None
        if self.n_neurons <= SMALL_MESH:
            if k <= _SPREAD_MOST_CONTROLS and not smoothing:
                warps, per_warp = _spread_shape(k, 1, pairs != SINGLES)
                move = spread_cycle_kernel(self.n_dims, warps, per_warp, shared_table, self._rows_mode, pairs)
                move_threads, spread = 32 * warps, True
            else:
                move = cycle_kernels(self.n_dims, min(32, 8 * ((k + 7) // 8)), pairs).move

        if anchored:
            wp.copy(self._w, self._w_anchor)
        if fresh:
            self._launch_find()
            after_kernel = True
        if halos is not None:  # a kernel a cycle from one weights array to the other, then back in self._w
            warps, per_warp = _spread_shape(k, halos.chunks, pairs != SINGLES)
            kernel = spread_smoothing_cycle_kernel(self.n_dims, warps, per_warp, shared_table, halos.chunks,
                                                   halos.width, pairs)
            pair = (self._w, self._w_moved)
            for i in range(cycles):
                p = (parity + i) % 2
                launch(kernel, spread_smoothing_cycle_inputs(
                    pair[i % 2], pair[1 - i % 2], self._c, k, self._m, self._table, self._distances, self._keys,
                    self._cycle[p], self._cycle[1 - p], halos.neurons, halos.local, self._offsets, self._mask,
                    self._smoothing), 32 * warps)
            if cycles % 2:
                wp.copy(self._w, self._w_moved)
            return records
        p = parity
        for _ in range(cycles):
            c_in, c_out = self._cycle[p], self._cycle[1 - p]
            moved = self._w_moved if smoothing else self._w
            if spread:
                launch(move, spread_cycle_inputs(self._w, moved, self._c, k, self._m, self._table, self._distances,
                                                 self._slot_of, self._keys, c_in, c_out, self._stalled),
                       move_threads)
            else:
                launch(move, [self._w, moved, self._c, 0, k, k, self._m, self._table, self._distances,
                              self._slot_of, self._keys, c_in, c_out, int(not smoothing), self._stalled], move_threads)
            if smoothing:
                launch(self._kernels.smooth, [self._w_moved, self._w, self._offsets, self._neighbors, self._mask,
                                              self._smoothing, self._c, k, self._m, self._keys, c_out, c_in,
                                              self._stalled])
            else:
                p = 1 - p
        return records

    def _movers(self):
        """The kernels of step 2 for the current controls: pair by pair when mirrored."""
        return cycle_kernels(self.n_dims, 8, self._pairs)

    def _block_halos(self) -> _DeviceHalos | None:
        """The block halos of the one-kernel smoothing cycle on CUDA (dense table, small mesh), uploaded once here,
        never inside a graph capture; None where it does not apply or they do not fit."""
        if self.device == "cpu" or self._rows_mode or self.n_neurons > SMALL_MESH:
            return None
        found = block_halos(self.topology.offsets, self.topology.neighbors, self.n_neurons)
        if found.chunks > _SPREAD_MOST_WARPS or found.width > _SMOOTHING_MOST_NEIGHBOURS:
            return None
        return _DeviceHalos(found, self.device)

    def _smoothing_in_one_kernel(self) -> _DeviceHalos | None:
        """The block halos where a smoothing cycle runs as one kernel (at most 32 controls), else None."""
        return self._halos if self._k_eff <= _SPREAD_MOST_CONTROLS else None

    # -- distance rows mode -------------------------------------------------------------------------------
    def _run_rows(self, cycles: int) -> None:
        """`cycles` cycles reading distance rows: the winners' rows are fetched, then a graph runs until done or a
        cycle stalls on a winner without a row (it then leaves everything as it was); the host fetches that cycle's
        rows and goes on from it. A cycle whose distinct winners outnumber the cache rows runs in parts."""
        target = self._s + cycles
        smoothing = self._smoothing > 0.0
        while self._s < target:
            self._find_winners_now()
            winners = self._current_winners()
            distinct = list(dict.fromkeys(winners.tolist()))
            if len(distinct) > self._cache.size:
                self._cycle_in_parts(winners, smoothing)
                continue
            self._cache.fetch(distinct, self._d_max)
            left = target - self._s
            chunk = min(self._cache.span, 1 << (left.bit_length() - 1))
            if self.device == "cpu":
                self._replay_cpu([self._graph(("rows", chunk, smoothing, core),
                                              lambda core=core: self._record_cpu(core, chunk, False, smoothing))
                                  for core in range(self._cores)])
                reached = int(self._cycle[0].numpy()[0])
            else:  # every graph starts from counter 0 (one graph per length), which then gets the last one's count
                wp.capture_launch(self._graph(("rows", chunk, smoothing),
                                              lambda: self._record_cuda(chunk, False, 0, smoothing)))
                last = 0 if smoothing else chunk % 2
                reached = int(self._cycle[last].numpy()[0])
                if last:
                    self._cycle[0].fill_(reached)
            if reached < self._s + chunk:  # stalled: the graph's later cycles did nothing, try shorter ones
                self._stalled.zero_()
                self._cache.stalls += 1
                self._cache.span = max(1, self._cache.span // 4)
            else:
                self._cache.span = min(_LONGEST_GRAPH, self._cache.span * 2)
            self._s = reached
            self._winners_valid = True

    def _cycle_in_parts(self, winners: np.ndarray, smoothing: bool) -> None:
        """One cycle in consecutive runs of controls whose winners fit in the cache (each neuron still applies the
        controls in list order)."""
        parts, lo, seen = [], 0, set()
        unit = 2 if self._mirror else 1  # a mirrored pair moves together: never split between parts
        for c in range(0, len(winners), unit):
            group = set(winners[c:c + unit].tolist())
            if len(seen | group) > self._cache.size:
                parts.append((lo, c))
                lo, seen = c, set()
            seen |= group
        parts.append((lo, len(winners)))
        kern, dev, cache = self._kernels, self.device, self._cache
        movers = self._movers()
        moved = self._w_moved if smoothing else self._w
        source = self._w
        c_in, c_out = self._cycle[0], self._cycle[1]
        for i, (lo, hi) in enumerate(parts):
            cache.fetch(list(dict.fromkeys(winners[lo:hi].tolist())), self._d_max)
            if dev == "cpu":
                wp.launch(movers.move_part, dim=1, device=dev,
                          inputs=[source, moved, self._c, lo, hi, self._table, self._distances, self._slot_of,
                                  self._keys, c_in, 0, self.n_neurons, self._stalled])
            else:
                find_next = int(not smoothing and i == len(parts) - 1)
                wp.launch_tiled(movers.move, dim=[self._blocks], block_dim=int(CUDA_BLOCK), device=dev,
                                inputs=[source, moved, self._c, lo, hi, self._k_eff, self._m, self._table,
                                        self._distances, self._slot_of, self._keys, c_in, c_out, find_next,
                                        self._stalled])
            source = moved
        if dev == "cpu":
            if smoothing:
                wp.launch(kern.smooth_part, dim=1, device=dev,
                          inputs=[moved, self._w, self._offsets, self._neighbors, self._mask, self._smoothing, 0,
                                  self.n_neurons, self._stalled])
            wp.launch(kern.find_part, dim=1, device=dev,
                      inputs=[self._w, self._c, self._k_eff, self._m, self._keys, c_in, 0, 1, 1, self._stalled])
        elif smoothing:
            wp.launch_tiled(kern.smooth, dim=[self._blocks], block_dim=int(CUDA_BLOCK), device=dev,
                            inputs=[moved, self._w, self._offsets, self._neighbors, self._mask, self._smoothing,
                                    self._c, self._k_eff, self._m, self._keys, c_out, c_in, self._stalled])
        self._s += 1
        self._set_cycle()
        self._winners_valid = True


@functools.cache
def _memcpy(name: str):
    """Warp's memcpy entry point `name` (wp_memcpy_h2d, wp_memcpy_d2d), None where there is none."""
    core = getattr(getattr(_warp_context, "runtime", None), "core", None)
    return getattr(core, name, None)


def _copy(dest: wp.array, src: wp.array) -> None:
    """`src` into `dest`, of the same size. Into a CUDA array from a pinned host array or one on the same device:
    asynchronous, on the device's stream, through Warp's own memcpy entry points without wp.copy's checks (a sixth
    of its time; this runs every drag frame). wp.copy on the CPU, and where those entry points are missing."""
    copy = None if dest.device.is_cpu else _memcpy("wp_memcpy_h2d" if src.device.is_cpu else "wp_memcpy_d2d")
    if copy is None:
        wp.copy(dest, src)
        return
    device = dest.device
    if not copy(device.context, dest.ptr, src.ptr, dest.capacity, device.stream.cuda_stream):
        raise RuntimeError(f"Som: a copy to {device} failed")


def _spread_shape(controls: int, least_warps: int, paired: bool = False) -> tuple[int, int]:
    """(warps, controls a warp) of a spread cycle kernel: at most _SPREAD_MOST_WARPS warps, at least least_warps;
    with `paired` an even number of slots (warps x per_warp), so that no pair lacks its second slot."""
    per_warp = -(-controls // _SPREAD_MOST_WARPS)
    warps = max(-(-controls // per_warp), least_warps)
    per_warp = -(-controls // warps)
    if paired and (warps * per_warp) % 2:
        warps += 1  # odd x odd: warps < _SPREAD_MOST_WARPS (8 is even), so one more warp still fits
    return warps, per_warp


class _DeviceHalos:
    """BlockHalos (halos.py) on a device."""

    def __init__(self, halos, device: str):
        self.chunks, self.width = halos.chunks, halos.width
        self.neurons = wp.array(halos.neurons, dtype=wp.int32, device=device)
        self.local = wp.array(halos.local, dtype=wp.int32, device=device)


class _RowCache:
    """Distance rows (int32 hops, -1 = unreachable) from recent winners, kept on the Som's device; the least
    recently used row makes way for a new one. slot_of[v] is the row of neuron v, -1 when it has none."""

    def __init__(self, topology: Topology, device: str, size: int | None):
        n = topology.n_vertices
        if size is None:
            budget = _CACHE_BYTES["cpu"] if device == "cpu" else min(_CACHE_BYTES["cuda"],
                                                                     wp.get_device(device).total_memory // 16)
            size = max(2 * MAX_CONTROLS, min(_CACHE_MOST_ROWS, budget // (4 * n)))
        self.size = min(max(size, 2), n)  # two at least: a mirrored pair's winners move in the same part
        self.device = device
        self.rows = wp.empty((self.size, n), dtype=wp.int32, device=device)
        self.slot_of = wp.full(n, -1, dtype=wp.int32, device=device)
        self._search = RowSearch(topology, device)
        self._offsets, self._neighbors = topology.offsets, topology.neighbors
        self._lru: OrderedDict[int, int] = OrderedDict()  # neuron -> row, least recently used first
        self._free = list(range(self.size - 1, -1, -1))
        self.computed = 0  # rows searched so far for winners
        self.prefetched = 0  # rows searched ahead for their neighbours
        self.stalls = 0  # graphs that stopped on a missing row
        self.span = _LONGEST_GRAPH  # cycles in the next graph: fewer while winners keep lacking rows

    def fetch(self, neurons: list[int], levels: int) -> None:
        """Rows for `neurons` (distinct, at most `size`), searching those not kept; levels: the deepest search."""
        missing = []
        for u in neurons:
            if u in self._lru:
                self._lru.move_to_end(u)
            else:
                missing.append(u)
        if not missing:
            return
        asked = len(missing)
        missing = self._around(missing, neurons) + missing  # least recent first: asked-for rows stay longest
        slots, evicted = [], []
        for u in missing:  # the neurons asked for are the most recent: the oldest row is never one of them
            if self._free:
                slot = self._free.pop()
            else:
                old, slot = self._lru.popitem(last=False)
                evicted.append(old)
            self._lru[u] = slot
            slots.append(slot)
        self._search.run([[u] for u in missing], slots, self.rows, levels)
        neurons_changed = wp.array(np.array(evicted + missing, dtype=np.int32), device=self.device)
        values = wp.array(np.array([-1] * len(evicted) + slots, dtype=np.int32), device=self.device)
        wp.launch(assign_slots, dim=len(neurons_changed), device=self.device,
                  inputs=[self.slot_of, neurons_changed, values])
        self.computed += asked
        self.prefetched += len(missing) - asked

    def _around(self, missing: list[int], neurons: list[int]) -> list[int]:
        """On CUDA, uncached neurons around the winners, ring by ring (one hop from each winner, those lacking rows
        first, then two hops...), as many as the search runs alongside the missing rows at little extra time and
        at most a sixteenth of the cache (so that rows still in use stay). A winner moves one hop or less in most
        cycles and keeps drifting the same way, so rows searched ahead spare later searches."""
        room = min(self._search.alongside - len(missing), self.size // 16, self.size - len(neurons))
        if self.device == "cpu" or room <= 0:
            return []
        centres = missing + [u for u in neurons if u not in missing]
        taken = dict.fromkeys(centres)
        rings = [[u] for u in centres]
        extra: list[int] = []
        for _ in range(_PREFETCH_RINGS):
            if len(extra) >= room or not any(rings):
                break
            for i, ring in enumerate(rings):
                following = []
                for u in ring:
                    for w in self._neighbors[self._offsets[u]: self._offsets[u + 1]].tolist():
                        if w not in taken:
                            taken[w] = None
                            following.append(w)
                rings[i] = following
                extra += [w for w in following if w not in self._lru]
        return extra[:room][::-1]  # the farthest least recent


def _cpu_cores(n_neurons: int, n_controls: int) -> int:
    """Cores for a CPU Som: one for small cycles (a barrier costs more than it saves on a busy machine), else
    those this process may use, at most 8."""
    if n_neurons * n_controls < _PAIRS_PER_EXTRA_CORE:
        return 1
    try:
        available = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        available = os.cpu_count() or 1
    return max(1, min(available, 8, n_neurons * n_controls // _PAIRS_PER_EXTRA_CORE))
