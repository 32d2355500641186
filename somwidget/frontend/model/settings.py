"""A session's settings (`session.settings`), built from their declaration (backend/schedule.py, SETTINGS): their
values as the session holds them, and the intents that change them: one setting or several as one step, the
symmetry group, the metric weights. Each value is checked in the caller's thread against its declaration, changes
the session's view at once and, for a setting of the engine, is queued for the Som: a schedule change restarts the
schedule locally from the latest weights. Setting the same one again within a moment joins its undo step
(timeline.py).

What the views are told and may send comes from here too: `wire_schema()` is the topology message's list of the
settings a view sets by name, `check_set(name, value)` checks a "set" intent's value.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...backend import checks, schedule
from ...backend.som_schedule import MAX_TABLE_ENTRIES as _MAX_TABLE_ENTRIES
from ...backend.symmetry import Symmetry
from .controls import MAX_ABS_VALUE, check_count
from .operations import Publish, SetMetricWeights, SetParameter, SetSymmetry
from .state import ModellingState
from .timeline import Timeline
from .trainer import Trainer

#: The engine's cap on its learning table, S x (d_max + 1) float32 entries (2 GiB): backend/som.py, _build_table.
MAX_TABLE_ENTRIES = _MAX_TABLE_ENTRIES
#: The settings a view sets by name (Session.set_parameter, the "set" intent: one number or flag), in panel order.
PARAMETERS: tuple[schedule.Setting, ...] = tuple(s for s in schedule.SETTINGS if s.by_name)
BY_NAME: dict[str, schedule.Setting] = {s.name: s for s in PARAMETERS}
#: Names that also reach a setting: the paper's S.
ALIASES = {"S": "iterations"}


def settable() -> tuple[schedule.Setting, ...]:
    """The settings a view sets by name, as declared now."""
    return tuple(s for s in schedule.SETTINGS if s.by_name)


def wire_schema() -> list[dict]:
    """What the topology message declares to the views: each setting a view sets by name, as JSON."""
    return [s.describe() for s in settable()]


def check_set(name, value):
    """A "set" intent's value checked against its declaration: a number (or a flag) within its bounds. ValueError
    naming the setting, the value and what was expected."""
    declared = {s.name: s for s in settable()}
    if not isinstance(name, str) or ALIASES.get(name, name) not in declared:
        raise ValueError(f"unknown parameter {str(name)[:40]!r}; known: {', '.join(declared)}")
    return declared[ALIASES.get(name, name)].check(value)


class SessionSettings:
    """The settings of one session (see the module's docstring): `session.settings["reach"]`,
    `session.settings.set("reach", 0.2)`, `session.settings.update(smoothing=0.1, reach=0.2)`."""

    def __init__(self, state: ModellingState, timeline: Timeline, trainer: Trainer):
        self.state = state
        self.timeline = timeline
        self.trainer = trainer

    def values(self) -> dict:
        """Every setting held by name, with "mirror" (the dims a mirror group negates) and "group" (the symmetry
        group's spec, "none" when off)."""
        with self.state.lock:
            return self.state.parameters()

    def __getitem__(self, name: str):
        return self.values()[ALIASES.get(name, name)]

    @property
    def symmetry(self) -> Symmetry | None:
        """The symmetry group in effect, or None."""
        return self.state.symmetry

    @property
    def max_iterations(self) -> int:
        """The largest S this mesh allows: MAX_ITERATIONS, or fewer where the engine's learning table
        S x (d_max + 1) would pass MAX_TABLE_ENTRIES (a mesh with a long grid diameter)."""
        d_max = int(self.state.preset.topology.d_max)  # the Som's own d_max: sessions keep the dense table
        return min(schedule.MAX_ITERATIONS, MAX_TABLE_ENTRIES // (d_max + 1))

    def set(self, name: str, value) -> None:
        """One setting by name (a schedule setting, "symmetry" or "group", "metric_weights"); a schedule setting
        restarts the schedule locally from the latest weights."""
        name = ALIASES.get(name, name)
        if name in ("symmetry", "group"):
            return self.set_symmetry(value)
        if name == "metric_weights":
            return self.set_metric_weights(value)
        self.update({name: value})

    def update(self, values: Mapping | None = None, **more) -> None:
        """Several settings of one value each as one step (`update(smoothing=0.1, reach=0.2)`): every value is
        checked first, so a refused one changes nothing."""
        values = {ALIASES.get(k, k): v for k, v in {**(values or {}), **more}.items()}
        declared = {s.name: s for s in settable() if s.section != "symmetry"}
        unknown = [name for name in values if name not in declared]
        if unknown or not values:
            raise ValueError(f"unknown parameter {(unknown or [''])[0]!r}; known: "
                             f"{', '.join((*declared, 'symmetry', 'metric_weights'))}")
        checked = {name: declared[name].parse(value) for name, value in values.items()}
        state = self.state
        with self.timeline.step("parameter:" + "+".join(checked)), state.lock:
            if checked.get("iterations", 0) > self.max_iterations:
                d_max, x = int(state.preset.topology.d_max), checked["iterations"]
                raise ValueError(f"S (iterations): {x} is more than this mesh allows: at most {self.max_iterations}, "
                                 f"since the learning table S x (d_max + 1) = {x} x {d_max + 1} may hold at most "
                                 f"{MAX_TABLE_ENTRIES} entries")
            for name, x in checked.items():
                state.params[name] = x
                if declared[name].scope == "engine":
                    self.trainer.enqueue(SetParameter(name, x))
            if all(declared[name].scope != "engine" for name in checked):
                self.trainer.enqueue(Publish())  # nothing for the Som: a frame shows it

    def set_symmetry(self, value) -> None:
        """A group (a Symmetry, its spec "radial-8-z") or on / off (True: the last group, else the preset's mirror).
        Off, each copy becomes a control of its own; on, controls that are each other's images pair up again; when
        the controls the engine applies stay the same, nothing moves and nothing trains."""
        state = self.state
        group = self._group_of(value)
        with self.timeline.step("symmetry"), state.lock:
            controls, radii, ids, strokes, keep = regroup(state, group)
            check_count(controls, group)
            state.controls, state.radii, state.control_ids, state.strokes = controls, radii, ids, strokes
            state.set_symmetry(group)
            if keep:
                state.hold = True
            self.trainer.enqueue(SetSymmetry(group, controls.copy(), radii.copy(), strokes, ids, keep))

    def _group_of(self, value) -> Symmetry | None:
        state = self.state
        if isinstance(value, Symmetry):
            group = value
        elif isinstance(value, str) and value.strip().lower() not in ("true", "false", "on", "off", "1", "0"):
            group = Symmetry.parse(value)
        else:
            group = state.default_group if schedule.BY_NAME["symmetry"].parse(value) else None
        if group is None:
            return None
        layout = state.layout
        group = group.on(layout.position, layout.direction)
        group.maps(layout.n_dims)  # ValueError when it does not fit
        return group

    def set_metric_weights(self, value) -> None:
        """One weight >= 0 per feature dimension (at least one positive) for the winner search."""
        state = self.state
        with self.timeline.step("parameter:metric_weights"), state.lock:
            m = checks.finite_vector("metric_weights", value, state.layout.n_dims, MAX_ABS_VALUE)
            if (m < 0).any():
                raise ValueError(f"metric_weights: weights must be >= 0, got {m.tolist()}")
            if not (m > 0).any():
                raise ValueError("metric_weights: at least one weight must be positive")
            state.params["metric_weights"] = [float(x) for x in m]
            self.trainer.enqueue(SetMetricWeights(m))

    def set_metric_weight(self, dim: int, value) -> None:
        """The metric weight of one feature dimension."""
        state = self.state
        declared = schedule.BY_NAME["metric_weights"]
        with state.lock:
            d = checks.integer_text("feature dimension", dim, 0, state.layout.n_dims - 1)
            m = list(state.params["metric_weights"])
            m[d] = declared.check(value, f"{declared.label} of {state.layout.names[d]}")
        self.set_metric_weights(m)


def expand(controls: np.ndarray, radii: np.ndarray, strokes: tuple, group) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Every control and its copies under `group` (None: the controls as they are): [originals..., first
    copies...], with their radii and strokes."""
    if group is None:
        return controls, radii, strokes
    order = group.order
    return group.images(controls).astype(np.float32), np.tile(radii, order), strokes * order


def regroup(state, group) -> tuple[np.ndarray, np.ndarray, tuple, tuple, bool]:
    """(controls, radii, ids, strokes, keep) of the controls under a new `group` (caller holds state.lock):
    the old group's copies become controls of their own, then, under a group, controls (or strokes) that are images
    of an earlier one (within PAIR_TOLERANCE of the size) join it as its copies. keep: the effective controls stay
    the same (every image found), so nothing needs to move."""
    controls, radii, strokes = expand(state.controls, state.radii, state.strokes, state.symmetry)
    k = len(state.controls)
    ids = list(state.control_ids) + list(state.fresh_ids(len(controls) - k))
    if group is None:
        return controls, radii, tuple(ids), strokes, True
    pos = list(state.layout.position)
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
