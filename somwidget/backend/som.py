"""The self-organizing map as computational clay: device state and the training cycle.

The cycle (the paper's algorithm; tests/reference.py writes it again in float64). D is the BFS hop distance between
neurons over the mesh's edges, d_max the largest finite one; sigma = d_max / sqrt(2 ln 2), c(s) = sigma (1 - s / S),
theta(d, s) = exp(-d^2 / (2 c(s)^2)) (1 at d = 0, 0 across components), alpha(s) = l_start l_end / (l_end +
(l_start - l_end) s / S), and the learning table L[s, d] = alpha(s) theta(d, s) in float32 (schedule.py). Cycle s:
1. every control's winner from the weights before the cycle, u_c = argmin_v sum_j m_j (C_cj - W_vj)^2 (the lowest
   index on an exact tie); 2. every neuron applies the controls in list order, W_v <- W_v + L[s, D[u_c, v]] (C_c -
   W_v); 3. with smoothing lambda > 0, one Jacobi step of the uniform Laplacian on smooth_dims, W_v <- W_v + lambda
(mean of its neighbours' W - W_v), all from the same weights (a neuron with no neighbour stays). Controls with a
radius, radial groups and strokes take the shaping rules instead (shaping_path.py).

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

Execution paths. `Som` holds the state (weights, controls, counters, learning table, on its device) and the public
API; how a run of cycles executes lives beside it, one module a path: cpu_path.py (each core replays its share),
cuda_path.py (captured graphs of one kernel a cycle, spread kernels for small meshes), rows_path.py (distance rows
past the dense table). batch.py runs B variants of one mesh at once.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp
from numpy.typing import ArrayLike

try:  # Warp's internals, for `_copy` (warp-lang is pinned to 1.19.x in pyproject.toml)
    from warp._src import context as _warp_context
except ImportError:  # pragma: no cover - another Warp layout: wp.copy then
    _warp_context = None

from . import checks
from .device import resolve, warp_exclusive
from .cpu_path import CpuPath
from .cuda_path import CudaPath
from .cycle_kernels import CUDA_BLOCK, LONGEST_GRAPH, MAX_CONTROLS, PAIRS, SCALED_PAIRS, SINGLES, cycle_kernels
from .local_path import LocalPath
from .rows_path import RowCache, RowsPath
from .schedule import BY_NAME, DEFAULT_REACH, NEIGHBOURHOOD_CUT, SMOOTHING_RULES, learning_table
from .shaping_path import ShapingPath, taubin_mu
from .symmetry import Symmetry, images, mirror_dims_of, mirror_of_dims
from .topology import MAX_DENSE_NEURONS, Topology

MAX_DIMS = 32
#: On the CPU the dense table is the default up to this many neurons (512 MiB, built by the CPU's cores); past it,
#: distance rows (the local cycle, local_path.py).
CPU_DENSE_NEURONS = 16384
_KEY_NONE = np.uint64(0xFFFFFFFFFFFFFFFF)
#: Learning table entries (S x (d_max + 1) float32) a Som may hold: 2 GiB.
_MAX_TABLE_ENTRIES = 1 << 29


def restart_iteration(reach: float, iterations: int) -> int:
    """s0 = floor((1 - reach) S), at most S - 1: where a local restart begins in the unchanged schedule."""
    return min(int(np.floor((1.0 - reach) * iterations)), iterations - 1)


#: How a Som smooths: "laplacian" (the paper's uniform step, the case studies) or "taubin" (the same step, then a
#: negative one that undoes its shrinking: the volume stays).
#: Largest radius of influence a control may have (model units).
MAX_RADIUS = 1e6


def check_radii(radii, k: int) -> np.ndarray:
    """(k,) float32 radii of influence, each in [0, MAX_RADIUS] model units (None: k point controls, 0)."""
    if radii is None:
        return np.zeros(k, np.float32)
    r = checks.finite_array("radii", [radii] if np.isscalar(radii) else radii, 1)
    if r.shape[0] != k:
        raise ValueError(f"radii: expected one radius per control ({k}), got {r.shape[0]}")
    if (r < 0).any() or (r > MAX_RADIUS).any():
        raise ValueError(f"radii: each radius must lie in [0, {MAX_RADIUS:g}] (model units; 0 = a point "
                         f"control), got {r.tolist()}")
    return r


class Som(CpuPath, CudaPath, RowsPath, ShapingPath, LocalPath):
    """A SOM whose neurons are the vertices of `topology`, trained towards `controls`.

    weights (N, n) and controls (k, n) share the n feature dimensions (1..32). State stays on `device`
    ("cpu", "cuda:N", None = best available); `weights` returns a host copy. On the CPU the cycle is split over
    `cpu_cores` cores (None: one for small meshes, else the cores this process may use, at most 8).

    distances: "dense" reads D[u, v] from the topology's dense N x N table (N <= 65,536); "rows" computes the
    distance rows of the current winners on demand and keeps the `cache_rows` most recently used on the device
    (None: as many as fit in 256 MiB on the CPU, on a GPU in a sixteenth of its memory up to 8 GiB; at least 64 on
    the CPU, 512 on a GPU, at most 4096; 2 at the least); None picks dense up to 65,536 neurons on a GPU and 16,384 on
    the CPU, else rows.
    Past the dense table the neighbourhood is cut where theta < 2^-24 (schedule.NEIGHBOURHOOD_CUT).
    Both give the same weights, but for that cut.

    reach (0, 1]: the neighbourhood radius a restart begins with, as a share of the full radius (Restarts, in the
    module's docstring). Moving controls and changing S, l_start, l_end, smoothing or metric weights restart at
    s0 = floor((1 - reach) S) from the latest weights (the clay follows locally); `reset()` runs the whole schedule
    from the start weights; `restore()` puts saved weights and s back without training.

    radii (k,): each control's radius of influence in model units (None: all 0, the paper's point controls); a
    control with a radius carries the clay around its winner with a smooth falloff (shaping_kernels.py). symmetry: a
    `Symmetry` group whose copies of each control act together with it (`mirror` is the shorthand for a mirror of
    any dims). strokes: the lengths of consecutive runs of controls that act together as one (the samples of a
    polyline; None: every control alone). smoothing_rule: "laplacian" (the paper's) or "taubin" (keeps the volume).
    """

    @warp_exclusive
    def __init__(
        self,
        topology: Topology,
        weights: ArrayLike,
        controls: ArrayLike,
        iterations: int = BY_NAME["iterations"].default,
        l_start: float = BY_NAME["l_start"].default,
        l_end: float = BY_NAME["l_end"].default,
        smoothing: float = BY_NAME["smoothing"].default,
        smooth_dims: Sequence[int] | None = None,
        metric_weights: ArrayLike | None = None,
        mirror: Sequence[int] = (),
        device: str | None = None,
        reach: float = DEFAULT_REACH,
        radii: ArrayLike | None = None,
        symmetry: Symmetry | None = None,
        strokes: Sequence[int] | None = None,
        *,
        smoothing_rule: str = "laplacian",
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
        self._iterations = BY_NAME["iterations"].check(iterations, "iterations")
        self._l_start = BY_NAME["l_start"].check(l_start, "l_start")
        self._l_end = BY_NAME["l_end"].check(l_end, "l_end")
        self._smoothing = BY_NAME["smoothing"].check(smoothing, "smoothing")
        self._reach = BY_NAME["reach"].check(reach, "reach")
        self._position_dims = list(range(min(3, self.n_dims)))
        self._symmetry, self._mirror = self._check_symmetry(symmetry, mirror)
        self._smoothing_rule = self._check_smoothing_rule(smoothing_rule)
        self._smooth_dims = self._check_smooth_dims(smooth_dims)
        self._metric = self._check_metric(metric_weights)
        self._controls = self._check_controls(controls, self._mirror)
        self._radii = check_radii(radii, len(self._controls))
        self._strokes = self._check_strokes(strokes, len(self._controls))
        self._edge: float | None = None  # the start mesh's median edge length, once the shaping path needs it
        self._sh_rest = None  # the shaping path's weights where the latest restart began
        self._sh_rest_pending = True  # taken when the first cycle runs
        self._anchor_version = 0  # counts `anchor()` calls
        self._rest_source = self._rest_taken = None  # the anchor a restart begins from, and the one the rest holds

        dev = self.device
        self._blocks = (self.n_neurons + int(CUDA_BLOCK) - 1) // int(CUDA_BLOCK)
        self._cpu_cores = None if cpu_cores is None else checks.integer("cpu_cores", cpu_cores, 1, 64)
        self._cores = 1
        self._pool: ThreadPoolExecutor | None = None
        self._rows_mode = self._check_distances(distances)
        size = None if cache_rows is None else checks.integer("cache_rows", cache_rows, 1)
        self._cache: RowCache | None = None
        # the cycle kernels read D[u_c, v] from the dense table or from the cache's rows (through slot_of)
        if self._rows_mode:
            self._cache = RowCache(topology, dev, size)
            self._distances, self._slot_of = self._cache.rows, self._cache.slot_of
        else:
            self._distances = topology.distance_table(dev)
            self._slot_of = wp.full(1, -1, dtype=wp.int32, device=dev)  # unread: the dense table has every row
        self._no_near = wp.zeros((1, 1), dtype=wp.int32, device=dev)  # unread: the shaping path's dense table
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
        self._box_anchor = None  # the anchored weights' block boxes (CPU)
        if dev == "cpu":
            self._local_setup()
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
            return self.n_neurons > (CPU_DENSE_NEURONS if self.device == "cpu" else MAX_DENSE_NEURONS)
        if distances not in ("dense", "rows"):
            raise ValueError(f"distances: expected 'dense', 'rows' or None, got {distances!r}")
        if distances == "dense" and self.n_neurons > MAX_DENSE_NEURONS:
            raise ValueError(f"distances: the dense table holds at most {MAX_DENSE_NEURONS:,} neurons, this mesh has "
                             f"{self.n_neurons:,}; use distances='rows' (distance rows computed on demand)")
        return distances == "rows"

    def _check_symmetry(self, symmetry, mirror) -> tuple[Symmetry | None, tuple[int, ...]]:
        """(the group, the mirror dims): a mirror group is the engine's mirrored pairs of its position dim."""
        dims = checks.dims("mirror", mirror, self.n_dims)
        if symmetry is None:
            return None, dims
        if not isinstance(symmetry, Symmetry):
            raise ValueError(f"symmetry: expected a Symmetry (Symmetry.mirror(axis), Symmetry.radial(n, axis)) or "
                             f"None, got {type(symmetry).__name__}")
        if dims:
            raise ValueError("give either symmetry or mirror, not both (mirror is the shorthand for a mirror group)")
        symmetry.maps(self.n_dims)  # ValueError when its dims do not fit the weights
        if symmetry.kind == "mirror":
            return None, mirror_dims_of(symmetry)
        return symmetry, ()

    def _check_strokes(self, strokes, k: int) -> tuple[int, ...]:
        return (1,) * k if strokes is None else checks.runs("strokes", strokes, k)

    def _check_smoothing_rule(self, rule) -> str:
        return checks.choice("smoothing_rule", rule, SMOOTHING_RULES)

    @property
    def _order(self) -> int:
        """Each control's group: the control and its copies."""
        if self._symmetry is not None:
            return self._symmetry.order
        return 2 if self._mirror else 1

    def _group_maps(self) -> np.ndarray:
        """(order, n, n) the group's maps of a control, the identity first."""
        if self._symmetry is not None:
            return self._symmetry.maps(self.n_dims)
        maps = np.repeat(np.eye(self.n_dims)[None], self._order, axis=0)
        if self._mirror:
            maps[1][list(self._mirror), list(self._mirror)] = -1.0
        return maps

    @property
    def _shaping(self) -> bool:
        """The shaping path runs the cycles: radii, a radial group or Taubin's smoothing in use."""
        return bool(self._radii.any()) or self._symmetry is not None or len(self._strokes) < len(self._controls) or (
            self._smoothing_rule == "taubin" and self._smoothing > 0.0)

    def _smoothing_steps(self) -> list[float]:
        """The strengths of the smoothing steps a cycle runs: none, lambda, or Taubin's lambda and mu."""
        if self._smoothing <= 0.0:
            return []
        if self._smoothing_rule == "taubin":
            return [self._smoothing, taubin_mu(self._smoothing)]
        return [self._smoothing]

    def _check_controls(self, controls, mirror) -> np.ndarray:
        c = np.asarray(controls) if not isinstance(controls, np.ndarray) else controls
        if c.ndim == 1:
            c = c[None, :]
        c = checks.finite_array("controls", c, 2)
        if c.shape[1] != self.n_dims:
            raise ValueError(f"controls: expected {self.n_dims} feature dimensions like the weights, got {c.shape[1]}")
        order = self._symmetry.order if getattr(self, "_symmetry", None) is not None else (2 if mirror else 1)
        k_eff = c.shape[0] * order
        if c.shape[0] < 1 or k_eff > MAX_CONTROLS:
            raise ValueError(f"controls: expected 1 to {MAX_CONTROLS} controls counting symmetric copies, "
                             f"got {c.shape[0]} ({k_eff} with their copies)")
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
        self._reach = BY_NAME["reach"].check(value, "reach")

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
        old, self._iterations = self._iterations, BY_NAME["iterations"].check(value, "iterations")
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
        self._l_start = BY_NAME["l_start"].check(value, "l_start")
        self._build_table()
        self._restart()

    @property
    def l_end(self) -> float:
        return self._l_end

    @l_end.setter
    @warp_exclusive
    def l_end(self, value: float) -> None:
        self._l_end = BY_NAME["l_end"].check(value, "l_end")
        self._build_table()
        self._restart()

    @property
    def smoothing(self) -> float:
        """lambda of the Laplacian step after each cycle; 0 switches smoothing off."""
        return self._smoothing

    @smoothing.setter
    @warp_exclusive
    def smoothing(self, value: float) -> None:
        self._smoothing = BY_NAME["smoothing"].check(value, "smoothing")
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
        symmetry, self._symmetry = self._symmetry, None
        try:
            self._check_controls(self._controls, mirror)
        except ValueError:
            self._symmetry = symmetry
            raise
        self._mirror = mirror
        self._upload_controls()
        self._restart()

    @property
    def symmetry(self) -> Symmetry | None:
        """The symmetry group of the controls: a radial `Symmetry`, a mirror one (the same as `mirror` of its dims),
        or None (also for mirror dims that are no axis's)."""
        if self._symmetry is not None or not self._mirror or len(self._position_dims) < 3:
            return self._symmetry
        return mirror_of_dims(self._mirror, self._position_dims)

    @symmetry.setter
    @warp_exclusive
    def symmetry(self, value: Symmetry | None) -> None:
        old = self._symmetry, self._mirror
        self._symmetry, self._mirror = None, ()
        try:
            self._symmetry, self._mirror = self._check_symmetry(value, ())
            self._check_controls(self._controls, self._mirror)
        except ValueError:
            self._symmetry, self._mirror = old
            raise
        self._upload_controls()
        self._restart()

    @property
    def radii(self) -> np.ndarray:
        """(k,) each control's radius of influence in model units (0: the paper's point control)."""
        return self._radii.copy()

    @radii.setter
    @warp_exclusive
    def radii(self, value: ArrayLike) -> None:
        self._radii = check_radii(value, len(self._controls))
        self._upload_controls()
        self._restart()

    @property
    def strokes(self) -> tuple[int, ...]:
        """The lengths of the runs of controls that act as one (a stroke's samples); 1 for a control alone."""
        return self._strokes

    @property
    def smoothing_rule(self) -> str:
        """"laplacian" (the paper's step) or "taubin" (the step, then one that undoes its shrinking)."""
        return self._smoothing_rule

    @smoothing_rule.setter
    @warp_exclusive
    def smoothing_rule(self, value: str) -> None:
        self._smoothing_rule = self._check_smoothing_rule(value)
        self._upload_controls()
        self._restart()

    @property
    def controls(self) -> np.ndarray:
        """(k, n) the controls as given, without mirrored copies."""
        return self._controls.copy()

    @property
    def effective_controls(self) -> np.ndarray:
        """[originals..., their first copies..., their second copies...]: every control and its symmetric copies
        (with a mirror: [originals..., mirrored copies...]); copy j is of control j mod k."""
        if self._order == 1:
            return self._controls.copy()
        return images(self._controls, self._group_maps()).astype(np.float32)

    @property
    @warp_exclusive
    def weights(self) -> np.ndarray:
        """(N, n) float32 host copy of the current weights."""
        self._settle_anchor()
        w = self._w.numpy().reshape(self.n_neurons, self.n_dims)
        return w.copy() if self.device == "cpu" else w  # from a GPU numpy() is a copy already

    @property
    def distances(self) -> str:
        """"dense" (the N x N table) or "rows" (distance rows of the winners, computed on demand and cached)."""
        return "rows" if self._rows_mode else "dense"

    @property
    def start_weights(self) -> np.ndarray:
        return self._start.copy()

    def learning_table(self) -> np.ndarray:
        """L[s, d] (S, d_max + 1) float32 (a copy)."""
        return self._table_host.copy() if self._table_host is not None else self._table.numpy()

    # -- intents ------------------------------------------------------------------------------------------
    @warp_exclusive
    def set_controls(self, controls: ArrayLike, radii: ArrayLike | None = None, *, strokes: Sequence[int] | None = None,
                     from_anchor: bool = False) -> None:
        """New controls (any count k), their radii (None: kept where the count stays, else all 0) and strokes (None:
        kept where the count stays, else every control alone); the schedule
        restarts at s0 from the latest weights (local follow), or with `from_anchor` from the weights `anchor()` kept
        (each frame of a drag restarts from the shape the drag began with: on CUDA the copy back is a node of the
        run's first graph, not a call of its own)."""
        if from_anchor and self._w_anchor is None:
            raise ValueError("set_controls: from_anchor needs anchor() first (no weights are kept)")
        controls = self._check_controls(controls, self._mirror)
        if radii is not None or len(controls) != len(self._controls):
            self._radii = check_radii(radii, len(controls))
        if strokes is not None or len(controls) != len(self._controls):
            self._strokes = self._check_strokes(strokes, len(controls))
        self._controls = controls
        self._anchor_pending = from_anchor
        if from_anchor and self.device == "cpu":
            self._settle_anchor()
        self._upload_controls()
        self._restart()
        self._rest_source = self._anchor_version if from_anchor else None

    @warp_exclusive
    def regroup(self, controls: ArrayLike, radii: ArrayLike | None, symmetry: Symmetry | None = None,
                mirror: Sequence[int] = (), keep_shape: bool = False, strokes: Sequence[int] | None = None) -> None:
        """New controls, radii and symmetry at once (a group turned on or off: the controls change with it); with
        `keep_shape` the weights and s stay as they are and nothing trains until the next change, else a local
        restart. ValueError (nothing changed) if they do not fit together."""
        old = self._symmetry, self._mirror, self._controls, self._radii, self._strokes
        try:
            self._symmetry, self._mirror = None, ()
            self._symmetry, self._mirror = self._check_symmetry(symmetry, mirror)
            self._controls = self._check_controls(controls, self._mirror)
            self._radii = check_radii(radii, len(self._controls))
            self._strokes = self._check_strokes(strokes, len(self._controls))
        except ValueError:
            self._symmetry, self._mirror, self._controls, self._radii, self._strokes = old
            raise
        self._upload_controls()
        if keep_shape:
            self._settle_anchor()
            self._restart(self._s)
        else:
            self._anchor_pending = False
            self._restart()

    @warp_exclusive
    def anchor(self) -> None:
        """Keep a copy of the current weights on the device, for `set_controls(..., from_anchor=True)`."""
        self._settle_anchor()
        self._anchor_version += 1
        if self._w_anchor is None:
            self._w_anchor = wp.empty_like(self._w)
        wp.copy(self._w_anchor, self._w)
        if self.device == "cpu":  # the local cycle's boxes go with them
            self._anchor_boxes()

    @warp_exclusive
    def set_weights(self, weights: ArrayLike) -> None:
        """Replace the current weights (same shape); the schedule restarts at s0 from them."""
        self._anchor_pending = False
        self._w.assign(self._checked_weights(weights))
        self._weights_replaced()
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
        self._weights_replaced()
        self._restart(0)

    @warp_exclusive
    def restore(self, weights: ArrayLike, iteration: int) -> None:
        """Put saved weights and s back exactly (a loaded session, an undo): nothing trains, nothing restarts."""
        s = checks.integer("iteration", iteration, 0, self._iterations)
        w = self._checked_weights(weights)
        self._anchor_pending = False
        self._w.assign(w)
        self._weights_replaced()
        self._restart(s)

    @warp_exclusive
    def winners(self) -> np.ndarray:
        """(k_eff,) the nearest neuron (metric-weighted) of each effective control for the current weights, in the
        order of `effective_controls`."""
        if self._shaping:
            return self._shaping_winners()
        self._find_winners_now()
        found = self._current_winners()
        if not self._mirror:
            return found
        return np.concatenate([found[0::2], found[1::2]])

    def _settle_anchor(self) -> None:
        """The anchored weights into the current ones now, if a restart from the anchor still waits for its run."""
        if self._anchor_pending:
            self._anchor_pending = False
            if self._box_anchor is not None:  # the CPU: only the blocks moved since (with their boxes)
                self._back_to_anchor()
            else:
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
            chunk = min(LONGEST_GRAPH, 1 << ((n - done).bit_length() - 1))
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
        cut = NEIGHBOURHOOD_CUT if self._rows_mode else 0.0  # past the dense table: the cut neighbourhood
        # one table at a time: the old one (and the graphs that hold it) goes before the new one is made, and on the
        # CPU the device array is the host array itself, so an S change costs at most one table's bytes
        self._graphs.clear()
        self._table = self._table_host = None
        host = learning_table(self._iterations, d_max, self._l_start, self._l_end, cut)
        self._table_max = float(host.max())
        self._d_max = d_max
        self._table_host = host
        self._table = wp.array(host, dtype=wp.float32, device=self.device, copy=self.device != "cpu")
        if self.device == "cpu":  # the local cycle's reach per cycle (the CPU's only)
            self._local_table()
        else:  # the device holds it; `learning_table()` reads it back
            self._table_host = None

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
        self._sh_controls = None  # the shaping path's grouped controls: uploaded when it next runs

    @property
    def _pairs(self) -> int:
        """How step 2 applies the controls (cycle_kernels.SINGLES, PAIRS, SCALED_PAIRS): in mirrored pairs with
        mirroring, scaled only where the table has a rate above 0.5 (two rates may then sum past 1)."""
        if not self._mirror:
            return SINGLES
        return SCALED_PAIRS if self._table_max > 0.5 else PAIRS


    def _restart(self, s: int | None = None) -> None:
        """Continue the schedule from cycle s (default: s0, a local restart) with the winners found afresh."""
        self._s = restart_iteration(self._reach, self._iterations) if s is None else s
        self._winners_valid = False
        self._sh_rest_pending = True  # the shaping path's falloffs measure from the shape a restart begins with
        self._rest_source = None

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
        if self._shaping:
            self._run_shaping(cycles)
            self._winners_valid = False
            return
        if self._rows_mode:
            if self.device == "cpu":
                self._run_local(cycles)
                return
            self._settle_anchor()
            self._run_rows(cycles)
            return
        fresh = not self._winners_valid
        if fresh:
            self._set_cycle()
        smoothing = self._smoothing > 0.0
        if self.device == "cpu":
            self._run_cpu(cycles, fresh, smoothing)
            self._weights_replaced()
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


