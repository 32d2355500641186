"""The operations a session queues for its training thread: one small class each, applied to the Som in order
between two steps.

An intent changes the session's own view at once (its controls, its parameters: what `session.controls` and
`session.parameters` show) and queues an operation that brings the Som along. Should the engine refuse it, the
operation's `roll_back` puts the session's view back to what the Som holds, unless a later operation with the same
`key` is already on its way (it will set that view again).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ...backend.symmetry import Symmetry
from .state import engine_symmetry, som_group

if TYPE_CHECKING:
    from ...backend.som import Som


class Operation:
    """What the training thread does to the Som for one intent."""

    @property
    def key(self) -> str | None:
        """Operations of the same key supersede each other's view (None: nothing to roll back)."""
        return None

    @property
    def acts(self) -> bool:
        """The person acted: a held session (after an undo, a load) trains again."""
        return True

    def apply(self, som) -> None:
        raise NotImplementedError

    def applied(self, state) -> None:
        """After `apply` succeeded (caller holds state.lock)."""

    def roll_back(self, state, som) -> None:
        """After `apply` failed: the session's view back to what `som` holds (caller holds state.lock)."""


def _controls_back(state, som) -> None:
    """The session's controls, radii, strokes and ids back to what the Som holds."""
    state.controls = np.array(som.controls, dtype=np.float32)
    state.radii = np.array(som.radii, dtype=np.float32)
    state.strokes = tuple(som.strokes)
    state.control_ids = state.applied_ids


@dataclass(frozen=True)
class SetControls(Operation):
    """New controls and their radii. In a drag, `anchor` is the Som that anchored the shape the drag began with: each
    frame of a point control's drag restarts from it (Som.set_controls(from_anchor=True)), so a long drag ends as one
    move would; while a hand holds a control with a radius (a handle, bound at its grab: `Grab`) the frames go on
    from the latest weights, as the handle carries its patch step by step.
    With `keep` (a control placed: it moves nothing until it is dragged) the weights and s stay and nothing trains;
    `group` is then the symmetry group the Som keeps. With `rest` (the weights and the controls before a control's
    last move) the move is made again from there: the shape and the controls go back (nothing trains), then the
    controls move as the move did, so a radius changed after a move re-does the move with the new radius (a handle
    binds at the old place, as a typed move does)."""

    controls: np.ndarray
    radii: np.ndarray
    strokes: tuple
    anchor: Som | None
    ids: tuple
    keep: bool = False
    group: Symmetry | None = None
    rest: tuple[np.ndarray, np.ndarray] | None = None
    reach: float | None = None  # the restart's own reach (a long move of a point control), None: the Som's
    key = "controls"

    @property
    def acts(self) -> bool:
        return not self.keep

    def after(self, earlier: SetControls) -> SetControls:
        """This operation in place of `earlier`, still queued (several within one frame: only the latest counts):
        a restart the earlier one asked for still happens, as wide as the wider of the two asked."""
        reach = max((r for r in (self.reach, earlier.reach) if r is not None), default=None)
        if self.keep <= earlier.keep and reach == self.reach:
            return self
        return dataclasses.replace(self, keep=self.keep and earlier.keep, reach=reach)

    def apply(self, som) -> None:
        if self.keep:
            som.regroup(self.controls, self.radii, *engine_symmetry(self.group), keep_shape=True,
                        strokes=self.strokes)
        else:
            if self.rest is not None and self.anchor is not som:
                weights, controls = self.rest
                som.restore(weights, som.iterations)
                som.regroup(controls, self.radii, *engine_symmetry(self.group), keep_shape=True, strokes=self.strokes)
            from_anchor = self.anchor is not None and self.anchor is som and not som.held
            som.set_controls(self.controls, self.radii, strokes=self.strokes, from_anchor=from_anchor, reach=self.reach)

    def applied(self, state) -> None:
        state.applied_ids = self.ids  # the ids of the controls the Som now holds

    def roll_back(self, state, som) -> None:
        _controls_back(state, som)


@dataclass(frozen=True)
class Grab(Operation):
    """A hand took these controls (indices now): each with a radius binds the clay it grabs (Som.grab). Nothing
    moves, nothing trains."""

    indices: tuple
    acts = False

    def apply(self, som) -> None:
        for i in self.indices:
            if i < len(som.controls):
                som.grab(i)


@dataclass(frozen=True)
class Release(Operation):
    """A hand let go of these controls (indices now): their bindings carry the clay to where the hand left it until
    the run ends (Som.release). Nothing trains that was not training."""

    indices: tuple
    acts = False

    def apply(self, som) -> None:
        for i in self.indices:
            if i < len(som.controls):
                som.release(i)


@dataclass(frozen=True)
class SetParameter(Operation):
    """One setting of the engine (backend/schedule.py, scope "engine"): a local restart."""

    name: str
    value: float

    @property
    def key(self) -> str:
        return self.name

    def apply(self, som) -> None:
        setattr(som, self.name, self.value)
        if self.name == "reach":  # the Som takes it at its next restart: this change is one
            som.restart()

    def roll_back(self, state, som) -> None:
        state.params[self.name] = type(state.params[self.name])(getattr(som, self.name))


@dataclass(frozen=True)
class SetSymmetry(Operation):
    """A symmetry group on (`group`: a Symmetry) or off (None), with the controls it leaves: turned off, each copy
    becomes a control of its own; turned on, controls that are each other's images pair up again. With `keep`, the
    effective controls are the same as before: weights and s stay and nothing trains."""

    group: Symmetry | None
    controls: np.ndarray
    radii: np.ndarray
    strokes: tuple
    ids: tuple
    keep: bool
    key = "controls"

    @property
    def acts(self) -> bool:
        return not self.keep

    def apply(self, som) -> None:
        som.regroup(self.controls, self.radii, *engine_symmetry(self.group), keep_shape=self.keep,
                    strokes=self.strokes)

    def applied(self, state) -> None:
        state.applied_ids = self.ids

    def roll_back(self, state, som) -> None:
        _controls_back(state, som)
        state.set_symmetry(som_group(som, state.layout))


@dataclass(frozen=True)
class SetMetricWeights(Operation):
    weights: np.ndarray
    key = "metric_weights"

    def apply(self, som) -> None:
        som.metric_weights = self.weights

    def roll_back(self, state, som) -> None:
        state.params["metric_weights"] = [float(x) for x in som.metric_weights]


@dataclass(frozen=True)
class Reset(Operation):
    """Back to the start mesh and s = 0: the whole schedule runs again; `grow`: a preset that grows (the case
    studies) grows again to where the controls are, whatever their radii (Som.reset)."""

    grow: bool = False

    def apply(self, som) -> None:
        som.reset(grow=self.grow)


@dataclass(frozen=True)
class Restart(Operation):
    """A local restart from the latest weights (Train on a settled map)."""

    def apply(self, som) -> None:
        som.restart()


@dataclass(frozen=True)
class Publish(Operation):
    """Nothing for the Som: a frame that shows what changed (paused, a step put back)."""

    acts = False

    def apply(self, som) -> None:
        pass
