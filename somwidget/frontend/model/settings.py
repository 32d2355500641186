"""Intents on a session's parameters: a schedule parameter (backend/schedule.py), both learning rates at once,
symmetry, the metric weights. Each is checked in the caller's thread against its declaration (parameters.py),
changes the session's view at once and queues the change for the Som; a schedule change restarts the schedule
locally from the latest weights. Setting the same parameter again within a moment joins its undo step (timeline.py).
"""

from __future__ import annotations

import numpy as np

from ...backend import checks
from ...backend.schedule import MAX_ITERATIONS
from ...backend.som_schedule import MAX_TABLE_ENTRIES as _MAX_TABLE_ENTRIES
from ...backend.symmetry import Symmetry
from .clay import Clay
from .controls import MAX_ABS_VALUE, check_count
from .operations import SetMetricWeights, SetParameter, SetSymmetry
from .parameters import BY_NAME, METRIC_WEIGHT, SYMMETRY
from .timeline import Timeline
from .trainer import Trainer

#: The engine's cap on its learning table, S x (d_max + 1) float32 entries (2 GiB): backend/som.py, _build_table.
MAX_TABLE_ENTRIES = _MAX_TABLE_ENTRIES


class ParameterEdits:
    """The parameter intents of one session (see the module's docstring)."""

    def __init__(self, clay: Clay, timeline: Timeline, trainer: Trainer):
        self.clay = clay
        self.timeline = timeline
        self.trainer = trainer

    @property
    def max_iterations(self) -> int:
        d_max = int(self.clay.preset.topology.d_max)  # the Som's own d_max: sessions keep the dense table
        return min(MAX_ITERATIONS, MAX_TABLE_ENTRIES // (d_max + 1))

    def set(self, name: str, value) -> None:
        name = "iterations" if name == "S" else name
        if name == "symmetry":
            return self.set_symmetry(value)
        if name == "metric_weights":
            return self.set_metric_weights(value)
        if name not in BY_NAME:
            raise ValueError(f"unknown parameter {name!r}; known: {', '.join((*BY_NAME, 'metric_weights'))}")
        x = BY_NAME[name].parse(value)
        with self.timeline.step(f"parameter:{name}"), self.clay.lock:
            if name == "iterations" and x > self.max_iterations:
                d_max = int(self.clay.preset.topology.d_max)
                raise ValueError(f"S (iterations): {x} is more than this mesh allows: at most {self.max_iterations}, "
                                 f"since the learning table S x (d_max + 1) = {x} x {d_max + 1} may hold at most "
                                 f"{MAX_TABLE_ENTRIES} entries")
            self.clay.params[name] = x
            self.trainer.enqueue(SetParameter(name, x))

    def set_learning_rates(self, l_start, l_end) -> None:
        a, b = BY_NAME["l_start"].parse(l_start), BY_NAME["l_end"].parse(l_end)
        with self.timeline.step("parameter:rates"), self.clay.lock:
            self.clay.params["l_start"], self.clay.params["l_end"] = a, b
            self.trainer.enqueue(SetParameter("l_start", a))
            self.trainer.enqueue(SetParameter("l_end", b))

    def set_symmetry(self, value) -> None:
        """A group (a Symmetry, its spec "radial-8-z") or on / off (True: the last group, else the preset's mirror).
        Off, each copy becomes a control of its own; on, controls that are each other's images pair up again; when
        the controls the engine applies stay the same, nothing moves and nothing trains."""
        clay = self.clay
        group = self._group_of(value)
        with self.timeline.step("symmetry"), clay.lock:
            controls, radii, ids, strokes, keep = regroup(clay, group)
            check_count(controls, group)
            clay.controls, clay.radii, clay.control_ids, clay.strokes = controls, radii, ids, strokes
            clay.set_symmetry(group)
            if keep:
                clay.hold = True
            self.trainer.enqueue(SetSymmetry(group, controls.copy(), radii.copy(), strokes, ids, keep))

    def _group_of(self, value) -> Symmetry | None:
        clay = self.clay
        if isinstance(value, Symmetry):
            group = value
        elif isinstance(value, str) and value.strip().lower() not in ("true", "false", "on", "off", "1", "0"):
            group = Symmetry.parse(value)
        else:
            group = clay.default_group if SYMMETRY.parse(value) else None
        if group is None:
            return None
        layout = clay.layout
        group = group.on(layout.position, layout.direction)
        group.maps(layout.n_dims)  # ValueError when it does not fit
        return group

    def set_metric_weights(self, value) -> None:
        clay = self.clay
        with self.timeline.step("parameter:metric_weights"), clay.lock:
            m = checks.finite_vector("metric_weights", value, clay.layout.n_dims, MAX_ABS_VALUE)
            if (m < 0).any():
                raise ValueError(f"metric_weights: weights must be >= 0, got {m.tolist()}")
            if not (m > 0).any():
                raise ValueError("metric_weights: at least one weight must be positive")
            clay.params["metric_weights"] = [float(x) for x in m]
            self.trainer.enqueue(SetMetricWeights(m))

    def set_metric_weight(self, dim: int, value) -> None:
        clay = self.clay
        with clay.lock:
            d = checks.integer_text("feature dimension", dim, 0, clay.layout.n_dims - 1)
            m = list(clay.params["metric_weights"])
            m[d] = METRIC_WEIGHT.check(value, f"{METRIC_WEIGHT.label} of {clay.layout.names[d]}")
        self.set_metric_weights(m)


def expand(controls: np.ndarray, radii: np.ndarray, strokes: tuple, group) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Every control and its copies under `group` (None: the controls as they are): [originals..., first
    copies...], with their radii and strokes."""
    if group is None:
        return controls, radii, strokes
    order = group.order
    return group.images(controls).astype(np.float32), np.tile(radii, order), strokes * order


def regroup(clay, group) -> tuple[np.ndarray, np.ndarray, tuple, tuple, bool]:
    """(controls, radii, ids, strokes, keep) of the clay's controls under a new `group` (caller holds clay.lock):
    the old group's copies become controls of their own, then, under a group, controls (or strokes) that are images
    of an earlier one (within PAIR_TOLERANCE of the size) join it as its copies. keep: the effective controls stay
    the same (every image found), so nothing needs to move."""
    controls, radii, strokes = expand(clay.controls, clay.radii, clay.strokes, clay.symmetry)
    k = len(clay.controls)
    ids = list(clay.control_ids) + list(clay.fresh_ids(len(controls) - k))
    if group is None:
        return controls, radii, tuple(ids), strokes, True
    pos = list(clay.layout.position)
    size = float(np.linalg.norm(np.ptp(controls[:, pos], axis=0))) if len(controls) > 1 else 1.0
    tol = PAIR_TOLERANCE * (size or 1.0)
    maps = group.maps(controls.shape[1])
    starts = np.concatenate([[0], np.cumsum(strokes)]).astype(int)
    runs = [np.arange(starts[r], starts[r + 1]) for r in range(len(strokes))]
    c64 = controls.astype(np.float64)
    taken = np.zeros(len(runs), bool)
    kept, complete = [], True
    for r, run in enumerate(runs):
        if taken[r]:
            continue
        taken[r] = True
        kept.append(r)
        for m in maps[1:]:
            image = c64[run] @ m.T
            match = next((o for o, other in enumerate(runs) if not taken[o] and len(other) == len(run)
                          and np.linalg.norm(c64[other] - image, axis=1).max() <= tol), None)
            if match is None:
                complete = False
            else:
                taken[match] = True
    index = np.concatenate([runs[r] for r in kept])
    return (controls[index], radii[index], tuple(ids[i] for i in index), tuple(len(runs[r]) for r in kept),
            complete)


#: Two controls pair up as a control and its symmetric copy when the copy lies within this share of the controls'
#: spread of the other.
PAIR_TOLERANCE = 1e-4
