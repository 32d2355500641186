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
from dataclasses import dataclass

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

    def __init__(self, state: ModellingState, timeline: Timeline, trainer: Trainer) -> None:
        self.state = state
        self.timeline = timeline
        self.trainer = trainer
        self.notice = ""  # what the latest symmetry change (or revolve) did to the controls, in words
        self.notices = 0  # such news so far: a panel shows `notice` when this moves

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

    def set(self, name: str, value) -> str | None:
        """One setting by name (a schedule setting, "symmetry" or "group", "metric_weights"); a schedule setting
        restarts the schedule locally from the latest weights. For the symmetry: what happened to the controls."""
        name = ALIASES.get(name, name)
        if name in ("symmetry", "group"):
            return self.set_symmetry(value)
        if name == "metric_weights":
            self.set_metric_weights(value)
        else:
            self.update({name: value})
        return None

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

    def set_symmetry(self, value) -> str:
        """A group (a Symmetry, its spec "radial-8-z"), on / off (True: the last group, else the preset's mirror) or
        None (off). Off, each copy becomes a control of its own. On, the controls pair up again as a control and its
        copies only where every control finds all its copies (the copies a group left when it was turned off): then
        nothing moves and nothing trains. Otherwise every control is kept with copies of its own, none merged; the
        clay follows. Returns what happened to the controls, in words (also `notice`, for the panels)."""
        state = self.state
        group = self._group_of(value)
        with self.timeline.step("symmetry"), state.lock:
            done = regroup(state, group)
            check_count(done.controls, group)
            state.controls, state.radii, state.control_ids, state.strokes = (done.controls, done.radii, done.ids,
                                                                              done.strokes)
            state.set_symmetry(group)
            if done.keep:
                state.hold = True
            self.trainer.enqueue(SetSymmetry(group, done.controls.copy(), done.radii.copy(), done.strokes, done.ids,
                                             done.keep))
            self.notice = done.notice(group, state.layout)
            self.notices += 1
            return self.notice

    def _group_of(self, value) -> Symmetry | None:
        state = self.state
        if value is None:
            return None
        group: Symmetry | None
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


@dataclass(frozen=True)
class Regrouped:
    """The controls under a new group (`regroup`): their values, radii, ids and strokes; `keep`: the controls the
    engine applies stay the same, so nothing moves; `images`: (id, id) of controls kept apart although one is an
    image of the other under the group."""

    controls: np.ndarray
    radii: np.ndarray
    ids: tuple
    strokes: tuple
    keep: bool
    merged: int = 0
    images: tuple = ()

    def notice(self, group, layout) -> str:
        """What happened to the controls, in words (numbered by their ids, as the views number them; a stroke counts
        as one, as the table's rows)."""
        k = len(self.controls) - sum(self.strokes) + len(self.strokes)
        if group is None:
            return f"symmetry off: {k} controls, each copy now a control of its own (nothing moves)"
        said = f"{group.describe()}: "
        if self.merged:
            return said + (f"{self.merged} controls paired up again as {k} controls and their copies (nothing "
                           "moves)")
        said += f"{k} control{'s' * (k != 1)} kept, each with {group.order - 1} cop{'ies' if group.order > 2 else 'y'}"
        if self.images:
            shown = [f"{a} and {b}" for a, b in self.images[:4]]
            pairs = (", ".join(shown[:-1]) + " as well as " + shown[-1] if len(shown) > 1 else shown[0]) + (
                " (and more)" if len(self.images) > 4 else "")
            said += (f". Controls {pairs} already sit where each other's copies go, so two controls now pull at each "
                     "of those places: delete one of each pair to leave one there")
        return said


def regroup(state, group) -> Regrouped:
    """The controls under a new `group` (caller holds state.lock): the old group's copies become controls of their
    own; then, under a group, controls (or strokes) pair up as a control and its copies only when every one finds all
    its images (within PAIR_TOLERANCE of the controls' spread): the copies that group left when it was turned off, so
    the effective controls stay the same. Otherwise none merges: every control is kept, with copies of its own."""
    controls, radii, strokes = expand(state.controls, state.radii, state.strokes, state.symmetry)
    ids = list(state.control_ids) + list(state.run_ids(strokes[len(state.strokes):]))
    if group is None:
        return Regrouped(controls, radii, tuple(ids), strokes, True)
    pos = list(state.layout.position)
    size = float(np.linalg.norm(np.ptp(controls[:, pos], axis=0))) if len(controls) > 1 else 1.0
    tol = PAIR_TOLERANCE * (size or 1.0)
    maps = group.maps(controls.shape[1])
    starts = np.concatenate([[0], np.cumsum(strokes)]).astype(int)
    runs = [np.arange(starts[r], starts[r + 1]) for r in range(len(strokes))]
    c64 = controls.astype(np.float64)
    taken = np.zeros(len(runs), bool)
    kept, images, complete = [], [], True
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
                images.append((ids[run[0]], ids[runs[match][0]]))
    if not complete:  # some control lacks a copy: nothing merges
        return Regrouped(controls, radii, tuple(ids), strokes, False, images=tuple(images))
    index = np.concatenate([runs[r] for r in kept])
    return Regrouped(controls[index], radii[index], tuple(ids[i] for i in index), tuple(len(runs[r]) for r in kept),
                     True, merged=len(runs))


#: Two controls pair up as a control and its symmetric copy when the copy lies within this share of the controls'
#: spread of the other.
PAIR_TOLERANCE = 1e-4
