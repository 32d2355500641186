"""Gestures per hand: which open gesture an intent belongs to, and what each completed step changed and whose it was.

A session is shared by several hands at once (hands.py: each view, and Python). Each hand's gesture is its own: a
view's drag (its grab of a control to the release, keyed by the hand and the control) or a script's
`with session.gesture():` (keyed by Python's hand alone). An intent joins the open gesture of the hand acting it
(`acting`), never another hand's: two drags at once are two undo steps, a setting made meanwhile a third.

The undo history (history.py) keeps whole states, one before each step, in the order the steps complete. While
gestures are open their changes build on one state, the *boundary*: the state at the last completion, taken at the
first change (timeline.py). A gesture that completes makes the boundary its step, and where other gestures are still
open the state now becomes the next boundary; a step outside any gesture does the same. So undo from Python travels
the whole history exactly. A view's undo takes back its own latest step (`Change`): exactly where it is the newest,
else by putting back on the state now what that step changed (the controls it moved, their radii, the settings it
made, the controls it added), as a step of its own (hands.py).
"""

from __future__ import annotations

import contextlib
from contextvars import ContextVar
from dataclasses import dataclass, field

import numpy as np

from ...backend.schedule import KEYS as SCHEDULE_KEYS
from .history import Step

#: Python's hand (hands.py): the scripts, the panels.
PYTHON = 0
#: The settings a view's undo can put back alone (a group change regroups the controls: not alone).
REVERTIBLE = (*SCHEDULE_KEYS, "metric_weights")

#: (hand id, control id or None): the hand whose intent runs now, and the control it names.
_ACTING: ContextVar[tuple[int, int | None]] = ContextVar("somwidget_acting", default=(PYTHON, None))
#: A step is open on this thread: the steps inside it join it (a view's undo puts back several things as one).
_IN_STEP: ContextVar[bool] = ContextVar("somwidget_in_step", default=False)


@contextlib.contextmanager
def acting(hand: int, control_id: int | None = None):
    """The intents inside are `hand`'s (on `control_id`, for a drag's moves)."""
    token = _ACTING.set((hand, control_id))
    try:
        yield
    finally:
        _ACTING.reset(token)


def actor() -> tuple[int, int | None]:
    """(hand id, control id or None) of the intent running now (Python's by default)."""
    return _ACTING.get()


@contextlib.contextmanager
def one_step():
    """Mark a step open on this thread; yields whether one was open already (then the new one joins it)."""
    inside = _IN_STEP.get()
    token = _IN_STEP.set(True)
    try:
        yield inside
    finally:
        _IN_STEP.reset(token)


@dataclass
class Gesture:
    """One open gesture: whether it changed anything yet, (a drag) its controls as they were before its first
    change (control id -> (values, radius)), and the key of the boundary its first change built on."""

    changed: bool = False
    before: dict[int, tuple[np.ndarray, float]] = field(default_factory=dict)
    start: int | None = None


@dataclass(frozen=True)
class Change:
    """What one completed step changed, for its hand to take it back later on a state that moved on: the controls it
    changed (id -> values and radius before), the settings (name -> value before), the controls it added; `whole`:
    it replaced what the controls are (a preset, a mesh, a group, a removal), which cannot be put back alone.
    `exact`: the state recorded before it is the state before all of it (a drag that another step's completion cut
    is not: its state before has part of the drag). `reverts`: the key of the step this one took back (a view's
    undo of an older step)."""

    hand: int
    kind: str
    controls: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    added: tuple = ()
    whole: bool = False
    exact: bool = True
    reverts: int | None = None

    @property
    def empty(self) -> bool:
        return not (self.controls or self.parameters or self.added or self.whole)


def change_since(hand: int, kind: str, before: Step, before_ids: tuple, state, skip=frozenset()) -> Change:
    """What changed from `before` (a captured state and its control ids) to the clay's view now (caller holds
    clay.lock); controls in `skip` (held in other open gestures) are left out."""
    index = {cid: j for j, cid in enumerate(before_ids)}
    radii = before.radii if before.radii is not None else np.zeros(len(before.controls), np.float32)
    controls = {}
    for i, cid in enumerate(state.control_ids):
        j = index.get(cid)
        if j is None or cid in skip:
            continue
        if not np.array_equal(before.controls[j], state.controls[i]) or radii[j] != state.radii[i]:
            controls[cid] = (before.controls[j].copy(), float(radii[j]))
    now = set(state.control_ids)
    added = tuple(cid for cid in state.control_ids if cid not in index)
    removed = any(cid not in now for cid in before_ids)
    parameters = {name: before.parameters[name] for name in REVERTIBLE
                  if before.parameters.get(name) != state.params.get(name)}
    whole = removed or before.preset is not state.preset or before.symmetry != state.symmetry
    return Change(hand, kind, controls, parameters, added, whole)


class OpenGestures:
    """The gestures open now (key -> Gesture), the boundary their changes build on (a captured state and its control
    ids, None until the first change), the Som anchored there (a drag's frames restart from it), and the `Change` of
    each step in the history by its key (caller holds clay.lock for all of it)."""

    def __init__(self):
        self.open: dict[tuple[int, int | None], Gesture] = {}
        self.boundary: Step | None = None
        self.boundary_ids: tuple = ()
        self.anchor = None
        self.changes: dict[int, Change] = {}
        self.taken_back: set[int] = set()  # keys of steps a view's undo took back on a later state

    def key_for(self, hand: int, control_id: int | None) -> tuple[int, int | None] | None:
        """The open gesture an intent of `hand` on `control_id` joins: its drag of that control, else its script's
        gesture; None when it has neither (the intent is a step of its own)."""
        for key in ((hand, control_id), (hand, None)):
            if key in self.open:
                return key
        return None

    def changed(self, but=None) -> list[tuple[tuple[int, int | None], Gesture]]:
        """The open gestures that changed something (all but `but`)."""
        return [(k, g) for k, g in self.open.items() if g.changed and k != but]

    def held_ids(self, but=None) -> frozenset:
        """The controls the open drags (all but `but`) hold."""
        return frozenset(k[1] for k in self.open if k[1] is not None and k != but)

    def settle(self) -> None:
        """Every open gesture starts over (an undo put another state in place): unchanged, no boundary, no anchor."""
        for g in self.open.values():
            g.changed, g.before, g.start = False, {}, None
        self.boundary, self.boundary_ids, self.anchor = None, (), None

    def note(self, step: Step, change: Change, kept) -> None:
        """`change` is what the history's `step` did; changes of steps no longer kept (`kept`: the keys in the
        history, read when the table grows) are forgotten."""
        self.changes[step.key] = change
        if len(self.changes) > 4 * 200:
            alive = set(kept())
            self.changes = {k: c for k, c in self.changes.items() if k in alive}
            self.taken_back &= alive

    def latest_of(self, hand: int, undo: list[Step]) -> Step | None:
        """The newest step of `hand` among `undo` (oldest first) not taken back yet (its own undo steps aside)."""
        for step in reversed(undo):
            change = self.changes.get(step.key)
            if (change is not None and change.hand == hand and change.reverts is None
                    and step.key not in self.taken_back):
                return step
        return None
