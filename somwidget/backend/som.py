"""The self-organizing map as computational clay (Felbrich et al. 2018): `Som`, the engine's public face.

Cycle s of the paper's algorithm (tests/reference.py writes it again in float64), with D[u, v] the hop distance over
the mesh's edges and L[s, d] = alpha(s) theta(d, s) the learning table (schedule.py):
1. every control's winner from the weights before the cycle, u_c = argmin_v sum_j m_j (C_cj - W_vj)^2 (the lowest
   index on a tie);
2. every neuron applies the controls in list order, W_v <- W_v + L[s, D[u_c, v]] (C_c - W_v); a control and its
   mirrored copy act at once, W <- W + (l1 (C - W) + l2 (C' - W)) / max(1, l1 + l2), so a symmetric mesh stays exactly
   symmetric (cycle_kernels.move_pair);
3. with smoothing lambda > 0, one Jacobi step of the uniform Laplacian on smooth_dims (smoothing_kernels.py).
Controls with a radius (handles: bound to the patch of clay a grab takes, handles.py), radial groups and Taubin's
smoothing take the shaping rules (shaping_path.py).

Restarts: moving the controls or changing the schedule goes on from the latest weights at s0 = floor((1 - reach) S)
of the same table, where the neighbourhood is `reach` of its full radius (the clay follows locally; s = 0 would pull
it into a blob and regrow all of it); `reset()` runs the whole schedule from the start weights (with `grow`, as a case
study grows: every control a point until S); `restore()` puts weights and s back (an undo, a loaded session) and
restarts nothing.

The parts, apart as in warp.sim: the model (som_model.py), the state (som_state.py), the controls (som_controls.py),
the schedule (som_schedule.py), and the paths that run the cycles, chosen once: cpu_path.py, cuda_path.py,
rows_path.py (distance rows on CUDA), local_path.py (the CPU past the dense table), and shaping_path.py. batch.py
runs B variants of one mesh at once.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import warp as wp
from numpy.typing import ArrayLike

from . import checks
from .block_boxes import BlockBoxes
from .cpu_cores import CpuCores
from .cpu_path import CpuPath
from .cuda_path import CudaPath
from .cycle_kernels import LONGEST_GRAPH
from .device import resolve, warp_exclusive
from .local_path import LocalPath
from .rows_path import RowsPath
from .schedule import BY_NAME, DEFAULT_REACH, SMOOTHING_RULES, Schedule
from .shaping_path import ShapingPath
from .som_controls import Controls, check_group
from .som_model import SomModel, check_distances, check_metric, check_smooth_dims, check_start
from .som_schedule import SomSchedule
from .som_state import SomState
from .symmetry import Symmetry, mirror_of_dims
from .topology import Topology


class SomParts(NamedTuple):
    """A Som's parts (an internal API, for tests and benchmarks). Every path takes them as
    `path.run(model, state, controls, schedule, cycles)` and `path.winners(model, state, controls, schedule)`;
    `next_path()` is the one the Som runs now. cores: the CPU's (None on CUDA)."""

    model: SomModel
    state: SomState
    controls: Controls
    schedule: SomSchedule
    path: CpuPath | CudaPath | RowsPath | LocalPath
    shaping: ShapingPath
    cores: CpuCores | None

    def next_path(self) -> CpuPath | CudaPath | RowsPath | LocalPath | ShapingPath:
        """The shaping path where the controls or the smoothing rule need it, else the paper's."""
        return self.shaping if self.controls.shaping(len(self.schedule.steps())) else self.path


def _schedule_value(name: str, doc: str) -> property:
    """Som.<name>: a value of the schedule (backend/schedule.py declares it); setting it restarts the schedule from
    the current weights (Som._change_schedule)."""

    def get(som: Som):
        return getattr(som._schedule.values, name)

    @warp_exclusive
    def set_(som: Som, value) -> None:
        som._change_schedule(**{name: value})

    return property(get, set_, doc=f"{doc} Setting it restarts the schedule from the current weights.")


class Som:
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

    radii (k,): each control's radius of influence in model units (None: all 0, the paper's point controls). A
    control with a radius is a handle (handles.py; DESIGN.md "Handles"): `grab(i)` binds the patch of clay within
    its radius of its winner, while held the patch goes where the control goes (`set_controls`, then cycles) and
    `release(i)` lets go; moved while no hand holds it (a typed position), it is grabbed at its old place and
    released at once; unbound, it does nothing. symmetry: a `Symmetry` group whose copies of each control act
    together with it (`mirror` is the shorthand for a mirror of any dims). strokes: the lengths of consecutive runs
    of controls that a hand takes as one (the samples of a polyline; None: every control alone). smoothing_rule:
    "laplacian" (the paper's) or "taubin" (lambda capped at 0.7, then mu, smoothing the nodes no handle holds, the
    volume of every closed part put back).
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
    ) -> None:
        if not isinstance(topology, Topology):
            raise ValueError(f"topology: expected a Topology, got {type(topology).__name__}")
        self.device = resolve(device)
        self.topology = topology
        start = check_start(topology, weights)
        self.n_neurons, self.n_dims = start.shape
        values = Schedule(iterations=iterations, l_start=l_start, l_end=l_end, smoothing=smoothing, reach=reach)
        group = check_group(symmetry, mirror, self.n_dims)
        rule = checks.choice("smoothing_rule", smoothing_rule, SMOOTHING_RULES)
        smooth = check_smooth_dims(smooth_dims, self.n_dims)
        metric = check_metric(metric_weights, self.n_dims)
        self._controls = Controls.make(controls, radii, strokes, group, self.n_dims)
        requested = None if cpu_cores is None else checks.integer("cpu_cores", cpu_cores, 1, 64)
        rows = check_distances(distances, self.n_neurons, self.device)
        size = None if cache_rows is None else checks.integer("cache_rows", cache_rows, 1)

        self._model = SomModel(topology, start, self.device, smooth, metric, rows, size)
        self._cores = CpuCores(requested) if self.device == "cpu" else None
        boxes = None if self._cores is None else BlockBoxes(self.n_neurons, self.n_dims, self._cores)
        self._state = SomState(self._model, boxes)
        self._schedule = SomSchedule(values, rule, self.device)
        self._path: CpuPath | CudaPath | RowsPath | LocalPath
        if self._cores is not None:
            self._path = LocalPath(self._cores) if rows else CpuPath(self._cores)
        else:
            cuda = CudaPath(self._model)
            self._path = RowsPath(cuda) if rows else cuda
        self._shaping = ShapingPath(self._model)
        self._growing: Controls | None = None  # after a reset: the controls as points, until S or a restart
        self._build_table(values)
        self._upload_controls()

    @property
    def parts(self) -> SomParts:
        """The engine's parts (an internal API: tests and benchmarks drive a path with them)."""
        return SomParts(self._model, self._state, self._running(), self._schedule, self._path, self._shaping,
                        self._cores)

    # -- configuration ------------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        """s: the schedule's current cycle (a local restart begins past 0, at `restart_iteration`)."""
        return self._state.s

    @property
    def reach(self) -> float:
        """The neighbourhood radius a restart begins with, as a share of the full radius: s0 = floor((1 - reach) S).
        1 restarts at s = 0 (the paper's restart). Setting it changes the next restart, not the run under way."""
        return self._schedule.values.reach

    @reach.setter
    def reach(self, value: float) -> None:
        self._schedule.values = Schedule.of(self._schedule.values, reach=value)

    @property
    def restart_iteration(self) -> int:
        """s0, where the next local restart begins."""
        return self._schedule.restart_iteration()

    iterations = _schedule_value("iterations", "S: cycles in a run.")
    l_start = _schedule_value("l_start", "The learning rate at s = 0.")
    l_end = _schedule_value("l_end", "The learning rate at s = S.")
    smoothing = _schedule_value("smoothing", "lambda of the smoothing step after each cycle; 0 switches it off.")

    @property
    def smooth_dims(self) -> tuple[int, ...]:
        return self._model.smooth_dims

    @smooth_dims.setter
    @warp_exclusive
    def smooth_dims(self, value: Sequence[int] | None) -> None:
        self._model.set_smooth_dims(check_smooth_dims(value, self.n_dims))
        self._restart()

    @property
    def metric_weights(self) -> np.ndarray:
        return self._model.metric.copy()

    @metric_weights.setter
    @warp_exclusive
    def metric_weights(self, value: ArrayLike) -> None:
        self._model.set_metric(check_metric(value, self.n_dims))
        self._restart()

    @property
    def mirror(self) -> tuple[int, ...]:
        """Dims negated in each control's mirrored copy; () = no symmetry."""
        return self._controls.mirror

    @mirror.setter
    @warp_exclusive
    def mirror(self, value: Sequence[int]) -> None:
        self._regroup(self._controls.regrouped((None, checks.dims("mirror", value, self.n_dims))))

    @property
    def symmetry(self) -> Symmetry | None:
        """The symmetry group of the controls: a radial `Symmetry`, a mirror one (the same as `mirror` of its dims),
        or None (also for mirror dims that are no axis's)."""
        controls, position = self._controls, self._model.position_dims
        if controls.symmetry is not None or not controls.mirror or len(position) < 3:
            return controls.symmetry
        return mirror_of_dims(controls.mirror, position)

    @symmetry.setter
    @warp_exclusive
    def symmetry(self, value: Symmetry | None) -> None:
        self._regroup(self._controls.regrouped(check_group(value, (), self.n_dims)))

    @property
    def radii(self) -> np.ndarray:
        """(k,) each control's radius of influence in model units (0: the paper's point control)."""
        return self._controls.radii.copy()

    @radii.setter
    @warp_exclusive
    def radii(self, value: ArrayLike) -> None:
        self._regroup(self._controls.with_radii(value))

    strokes = property(lambda self: self._controls.strokes, doc="The lengths of the runs of controls that act as one "
                       "(a stroke's samples); 1 for a control alone.")

    @property
    def smoothing_rule(self) -> str:
        """"laplacian" (the paper's step) or "taubin" (the step, then one that undoes its shrinking)."""
        return self._schedule.rule

    @smoothing_rule.setter
    @warp_exclusive
    def smoothing_rule(self, value: str) -> None:
        self._schedule.rule = checks.choice("smoothing_rule", value, SMOOTHING_RULES)
        self._regroup(self._controls)

    @property
    def controls(self) -> np.ndarray:
        """(k, n) the controls as given, without mirrored copies."""
        return self._controls.values.copy()

    @property
    def effective_controls(self) -> np.ndarray:
        """[originals..., their first copies..., their second copies...]: every control and its symmetric copies
        (with a mirror: [originals..., mirrored copies...]); copy j is of control j mod k."""
        return self._controls.effective()

    @property
    @warp_exclusive
    def weights(self) -> np.ndarray:
        """(N, n) float32 host copy of the current weights."""
        self._state.settle_anchor()
        w = self._state.w.numpy().reshape(self.n_neurons, self.n_dims)
        return w.copy() if self.device == "cpu" else w  # from a GPU numpy() is a copy already

    @property
    def distances(self) -> str:
        """"dense" (the N x N table) or "rows" (distance rows of the winners, computed on demand and cached)."""
        return "rows" if self._model.rows else "dense"

    start_weights = property(lambda self: self._model.start.copy(), doc="(N, n) the start mesh's weights (a copy).")

    def learning_table(self) -> np.ndarray:
        """L[s, d] (S, d_max + 1) float32 (a copy)."""
        return self._schedule.host_table()

    # -- intents ------------------------------------------------------------------------------------------
    @warp_exclusive
    def set_controls(self, controls: ArrayLike, radii: ArrayLike | None = None, *, strokes: Sequence[int] | None = None,
                     from_anchor: bool = False, reach: float | None = None) -> None:
        """New controls (any count k), their radii (None: kept where the count stays, else all 0) and strokes (None:
        kept where the count stays, else every control alone); the schedule restarts at s0 from the latest weights
        (local follow), or with `from_anchor` from the weights `anchor()` kept (a drag's frames restart from its start
        shape; on CUDA the copy back is a node of the run's first graph). `reach`: this restart's (None: the Som's;
        a long move of a point control takes a wider one, schedule.reach_for_move)."""
        state = self._state
        if from_anchor and state.w_anchor is None:
            raise ValueError("set_controls: from_anchor needs anchor() first (no weights are kept)")
        reach = None if reach is None else BY_NAME["reach"].check(reach)
        new = self._controls.moved(controls, radii, strokes)
        self._end_growth()
        state.from_anchor(from_anchor)
        self._shaping.handles.moved(state, new)  # (the released bindings end: the restart's part)
        self._controls = new
        self._upload_controls()
        state.restart(self._schedule.restart_iteration(reach))

    @warp_exclusive
    def regroup(self, controls: ArrayLike, radii: ArrayLike | None, symmetry: Symmetry | None = None,
                mirror: Sequence[int] = (), keep_shape: bool = False, strokes: Sequence[int] | None = None) -> None:
        """New controls, radii and symmetry at once (a group turned on or off: the controls change with it); with
        `keep_shape` the weights and s stay as they are and nothing trains until the next change, else a local
        restart. ValueError (nothing changed) if they do not fit together."""
        self._controls = Controls.make(controls, radii, strokes, check_group(symmetry, mirror, self.n_dims),
                                       self.n_dims)
        self._shaping.handles.end_all(self._state)
        self._upload_controls()
        if keep_shape:
            self._state.settle_anchor()
            self._restart(self._state.s)
        else:
            self._state.anchor_pending = False
            self._restart()

    @warp_exclusive
    def anchor(self) -> None:
        """Keep a copy of the current weights on the device, for `set_controls(..., from_anchor=True)`."""
        self._state.anchor()

    @warp_exclusive
    def set_weights(self, weights: ArrayLike) -> None:
        """Replace the current weights (same shape); the schedule restarts at s0 from them."""
        self._let_go(self._checked_weights(weights))
        self._restart()

    @warp_exclusive
    def restart(self) -> None:
        """Restart the schedule at s0 from the latest weights, as a control move does."""
        self._restart()

    @warp_exclusive
    def reset(self, grow: bool = False) -> None:
        """Back to the start weights and s = 0 (the whole schedule); the controls stay. With `grow` (a start mesh the
        controls grow into a form: the paper's case studies), every control acts as the paper's point control until
        the run reaches S or anything restarts it (a move, a grab, a change of a value), so the clay grows to where
        the controls are, whatever their radii; then the controls with a radius are handles again. (A handle binds
        only the clay a grab takes: from the car's ellipsoid, handles alone would grow nothing.)"""
        self._let_go(self._model.start)
        self._restart(0)
        if grow and self._controls.radii.any():
            self._growing = self._controls.with_radii(np.zeros(len(self._controls.values), np.float32))

    @warp_exclusive
    def restore(self, weights: ArrayLike, iteration: int) -> None:
        """Put saved weights and s back exactly (a loaded session, an undo): nothing trains, nothing restarts."""
        s = checks.integer("iteration", iteration, 0, self.iterations)
        self._let_go(self._checked_weights(weights))
        self._restart(s)

    @warp_exclusive
    def winners(self) -> np.ndarray:
        """(k_eff,) the nearest neuron (metric-weighted) of each effective control for the current weights, in the
        order of `effective_controls`."""
        parts = self.parts
        return parts.next_path().winners(parts.model, parts.state, parts.controls, parts.schedule)

    @warp_exclusive
    def grab(self, i: int) -> None:
        """A hand takes control i (with the rest of its stroke): each member of a control with a radius binds the
        patch of clay around its winner (handles.py). Nothing moves and nothing restarts; a point control binds
        nothing, and a control held already stays as it is. A grab ends a reset's growth (`reset`)."""
        self._end_growth()
        self._shaping.handles.grab(self._state, self._controls.stroke_of(i))

    @warp_exclusive
    def release(self, i: int) -> None:
        """The hand lets go of control i (with the rest of its stroke): its bindings carry the clay to where the hand
        left it until the run reaches S or the next restart. Nothing trains."""
        self._shaping.handles.release(self._controls.stroke_of(i))

    @property
    def held(self) -> tuple[int, ...]:
        """The controls a hand holds (`grab`), in order."""
        return tuple(sorted(self._shaping.handles.held))

    def _checked_weights(self, weights: ArrayLike) -> np.ndarray:
        w = checks.finite_array("weights", weights, 2)
        if w.shape != (self.n_neurons, self.n_dims):
            raise ValueError(f"weights: expected shape {(self.n_neurons, self.n_dims)}, got {w.shape}")
        return w

    # -- training -----------------------------------------------------------------------------------------
    @warp_exclusive
    def step(self, n: int = 1) -> int:
        """Run up to n cycles (stopping at S); returns how many ran."""
        n = min(checks.integer("n", n, 0), self.iterations - self._state.s)
        parts = self.parts
        path = parts.next_path()
        done = 0
        most = path.most_cycles(parts.controls, parts.schedule) if path is parts.shaping else LONGEST_GRAPH
        while done < n:
            chunk = n - done if most is None else min(most, 1 << ((n - done).bit_length() - 1))
            path.run(parts.model, parts.state, parts.controls, parts.schedule, chunk)
            done += chunk
        if n and self._state.s >= self.iterations:
            self._end_growth()
            self._shaping.handles.end_released(self._state)  # the run is over: released bindings end
        return n

    def train(self) -> int:
        """Run the rest of the schedule (to s = S); returns the cycles run."""
        return self.step(self.iterations - self._state.s)

    @warp_exclusive
    def synchronize(self) -> None:
        wp.synchronize_device(self.device)

    # -- changes ------------------------------------------------------------------------------------------
    def _change_schedule(self, **change) -> None:
        """A schedule value changed: a new learning table (but for lambda, which the paths take as it is), then a
        local restart."""
        values = Schedule.of(self._schedule.values, **change)
        if set(change) == {"smoothing"}:
            self._schedule.values = values
        else:
            self._build_table(values)
        self._restart()

    def _build_table(self, values: Schedule) -> None:
        def drop() -> None:
            self._path.forget()
            self._shaping.forget()

        self._schedule.rebuild(values, self._model.d_max(), self._model.rows, drop=drop)

    def _regroup(self, controls: Controls) -> None:
        """New controls (checked), on the device, and a local restart (bindings kept where the controls' count,
        group and which have a radius stay)."""
        self._controls = controls
        self._upload_controls()
        self._restart()

    def _let_go(self, weights: np.ndarray) -> None:
        """New weights: every binding ends, every hold is let go, and the clamp's box takes them."""
        handles = self._shaping.handles
        handles.end_all(self._state)
        handles.grow(weights)
        self._state.assign(weights)

    def _running(self) -> Controls:
        """The controls the cycles take: after a reset, until S or a restart, every control as a point (`reset`)."""
        return self._controls if self._growing is None else self._growing

    def _end_growth(self) -> None:
        """A reset's growth ends: the controls with a radius are handles again."""
        if self._growing is not None:
            self._growing = None
            self._shaping.handles.adopt(self._controls)

    def _upload_controls(self) -> None:
        self._state.upload(self._controls)
        self._shaping.handles.adopt(self._controls)

    def _restart(self, s: int | None = None) -> None:
        """Continue the schedule from cycle s (default: s0, a local restart) with the winners found afresh; the
        bindings no hand holds end, and so does a reset's growth."""
        self._end_growth()
        self._shaping.handles.end_released(self._state)
        self._state.restart(self._schedule.restart_iteration() if s is None else s)
