"""A session's undo and redo: which intents make one step, and travelling between steps.

Every completed gesture is one undo step (history.py keeps them): a drag from `begin_gesture(key)` to
`end_gesture(key)`, and each other intent call (a control added, removed or recoloured, a parameter set, a reset, a
preset, a mesh, a loaded session); the same parameter set again within PARAMETER_STEP_SECONDS joins its step (a
slider's drag). Gestures are per hand (gestures.py): several may be open at once, each its own step, recorded in the
order they complete. Each completed step (and each undo or redo) counts in `state.completed`: the autosave writes it
at once.

Drags: each frame of a drag is the local restart from the shape the drag began with (the Som anchors it,
`Som.anchor`), to the hand's latest position; so a drag ends exactly as one move there would, however many frames it
took (restarting from the latest weights at every frame would wear the rest of the shape down).
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable

from ...backend.presets import Preset
from .gestures import PYTHON, Change, Gesture, OpenGestures, actor, change_since, one_step
from .history import History, Shelf, Step
from .operations import Publish
from .state import ModellingState
from .trainer import Trainer

#: Setting the same parameter again within this many seconds joins the previous undo step (a slider's drag).
PARAMETER_STEP_SECONDS = 1.5
#: The gesture of a script (`with session.gesture():`): Python's hand, no control.
SCRIPT = (PYTHON, None)


class Timeline:
    """The undo history of one session and the gesture in progress.

    rebuild(preset): install another preset's Som (a step of an earlier preset); install_frame(): make and keep a
    frame of the state put back; shelf: where the history's steps go on disk (None: a temporary folder)."""

    def __init__(self, state: ModellingState, trainer: Trainer, rebuild: Callable[[Preset], None],
                 install_frame: Callable[[], None], shelf: Shelf | None = None) -> None:
        self.state = state
        self.trainer = trainer
        self.rebuild = rebuild
        self.install_frame = install_frame
        self.history = History(shelf=shelf)
        self.gestures = OpenGestures()  # the open gestures, their boundary and anchor, whose each step is
        self._last_step: tuple[str, float] = ("", 0.0)  # kind and time of the latest recorded step

    @property
    def anchor(self):
        """In a drag: the Som that anchored its weights (where each frame restarts)."""
        return self.gestures.anchor

    @property
    def gesture_recorded(self) -> bool:
        """A gesture is open and has changed something (its state before is kept): the state now is a drag not yet
        released (caller holds state.lock)."""
        return self.gestures.boundary is not None

    @property
    def counts(self) -> tuple[int, int]:
        """(undo steps, redo steps) available (caller holds state.lock); open gestures that changed something count
        as one step."""
        return self.history.undo_count + int(self.gesture_recorded), self.history.redo_count

    def steps(self) -> tuple[list[Step], list[Step]]:
        """(undo steps, redo steps), oldest first, the open gestures' state before as the newest undo step (what the
        autosave writes; caller holds state.lock)."""
        undo, redo = self.history.steps()
        if self.gestures.boundary is not None:
            undo.append(self.gestures.boundary)
        return undo, redo

    # -- gestures ----------------------------------------------------------------------------------------------
    def begin_gesture(self, key=SCRIPT) -> None:
        """Gesture `key` opens: (hand, control id) for a drag, (hand, None) for a script's. One of the same key left
        open (a tab closed mid-drag) ends first."""
        self.end_gesture(key)
        with self.state.lock:
            self.gestures.open[key] = Gesture()
            self.state.gesture = True

    def end_gesture(self, key=SCRIPT) -> None:
        """Gesture `key` completes: if it changed something, it is a step of its hand."""
        state = self.state
        with state.lock:
            gesture = self.gestures.open.get(key)
            if gesture is None:
                return
        with state.som_lock if gesture.changed else contextlib.nullcontext(), state.wake:
            gesture = self.gestures.open.pop(key, None)
            if gesture is None:
                return
            state.gesture = bool(self.gestures.open)
            if gesture.changed and self.gestures.boundary is not None:
                self._complete(Change(key[0], "drag" if key[1] is not None else "gesture", dict(gesture.before),
                                      exact=gesture.start == self.gestures.boundary.key))
            if not self.gestures.open:
                self.gestures.settle()
            state.unsaved = True
            state.wake.notify_all()

    def drag_anchor(self):
        """The Som a control move should restart from: the drags' anchor while one is open, else None."""
        return self.gestures.anchor if self.state.gesture else None

    @contextlib.contextmanager
    def step(self, kind: str):
        """Around one intent: record the state before it as an undo step, or join the open gesture of the hand acting
        it (gestures.py), or the same parameter set within PARAMETER_STEP_SECONDS; a refused intent takes it back.
        A step inside a step joins it."""
        with one_step() as inside:
            if inside:
                yield
                return
            hand, control_id = actor()
            with self.state.lock:
                key = self.gestures.key_for(hand, control_id)
            with self._in_gesture(key, kind) if key is not None else self._alone(hand, kind):
                yield

    @contextlib.contextmanager
    def _in_gesture(self, key, kind: str):
        """An intent inside gesture `key`: the boundary is taken at the first change of any open gesture; a drag
        keeps its controls as they were before its first change."""
        state = self.state
        with state.lock:
            gesture = self.gestures.open.get(key) or Gesture()
            before = self._values(key[1]) if key[1] is not None and not gesture.changed else {}
            fresh = self.gestures.boundary is None
        recorded = self._record_boundary() if fresh else None
        with state.lock:
            start = self.gestures.boundary.key if self.gestures.boundary is not None else None
        try:
            yield
        except BaseException:
            with state.lock:
                if recorded is not None and self.gestures.boundary is recorded and not self.gestures.changed():
                    self.gestures.settle()
            raise
        with state.lock:
            for cid, was in before.items():
                gesture.before.setdefault(cid, was)
            if not gesture.changed:
                gesture.start = start
            gesture.changed = True
            self._last_step = (kind, time.monotonic())
            state.unsaved = True

    @contextlib.contextmanager
    def _alone(self, hand: int, kind: str):
        """An intent outside any gesture of its hand: a step of its own, completed at once."""
        state = self.state
        with state.lock:
            last_kind, last_time = self._last_step
            pending = self.gestures.boundary is not None
            joins = not pending and kind.startswith("parameter:") and kind == last_kind and (
                time.monotonic() - last_time < PARAMETER_STEP_SECONDS)
        if pending:  # open gestures changed things: this step completes first, on their boundary
            yield
            with state.som_lock, state.lock:
                if self.gestures.boundary is not None:
                    held = self.gestures.held_ids()
                    self._complete(change_since(hand, kind, self.gestures.boundary, self.gestures.boundary_ids, state,
                                                held))
                self._last_step = (kind, time.monotonic())
            return
        step, ids = (None, ()) if joins else self._record()
        try:
            yield
        except BaseException:
            if step is not None:
                with state.lock:
                    self.history.drop_last(step)
            raise
        with state.lock:
            if step is not None:
                self.gestures.note(step, change_since(hand, kind, step, ids, state), self._kept)
            self._last_step = (kind, time.monotonic())
            state.unsaved = True
            state.completed += 1

    def _values(self, control_id) -> dict:
        """control id -> (values, radius) of a control and the other samples of its stroke (caller holds
        state.lock)."""
        state = self.state
        if control_id not in state.control_ids:
            return {}
        run = state.run_of(state.control_ids.index(control_id))
        return {state.control_ids[i]: (state.controls[i].copy(), float(state.radii[i])) for i in run}

    def _record(self) -> tuple[Step, tuple]:
        """Push the current state (every queued intent applied first) as an undo step; returns it with its control
        ids."""
        state = self.state
        with state.som_lock:
            drained = self.trainer.drain()
            with state.lock:
                step, ids = state.capture(), tuple(state.control_ids)
                self.history.push(step)
                if drained:
                    self.trainer.enqueue(Publish(), intent=False)  # a frame that shows the drained intents
        return step, ids

    def _record_boundary(self) -> Step | None:
        """Keep the current state as the open gestures' boundary and anchor the Som there, unless one is kept
        already; returns the state kept (None: there was one)."""
        state = self.state
        with state.som_lock:
            with state.lock:
                if self.gestures.boundary is not None:
                    return None
            drained = self.trainer.drain()
            with state.lock:
                step = self.gestures.boundary = state.capture()
                self.gestures.boundary_ids = tuple(state.control_ids)
                self.gestures.anchor = state.som
                state.som.anchor()
                if drained:
                    self.trainer.enqueue(Publish(), intent=False)
        return step

    def _complete(self, change: Change, again: bool = True) -> None:
        """The boundary becomes the step `change` describes; with `again`, where other open gestures changed things,
        the state now is their next boundary (caller holds clay.lock, and som_lock when others may have changed
        things)."""
        state = self.state
        step = self.gestures.boundary
        assert step is not None, "a step completes on its boundary: every caller checks there is one"
        self.history.push(step)
        self.gestures.note(step, change, self._kept)
        state.completed += 1
        state.unsaved = True
        self.gestures.boundary, self.gestures.boundary_ids = None, ()
        if again and self.gestures.changed():
            if self.trainer.drain():
                self.trainer.enqueue(Publish(), intent=False)
            self.gestures.boundary, self.gestures.boundary_ids = state.capture(), tuple(state.control_ids)

    def _kept(self) -> list[int]:
        undo, redo = self.history.steps()
        return [s.key for s in undo + redo]

    # -- travel ------------------------------------------------------------------------------------------------
    def undo(self) -> bool:
        return self._travel(self.history.undo)

    def redo(self) -> bool:
        return self._travel(self.history.redo)

    def _travel(self, move) -> bool:
        """Undo or redo, exactly. Open gestures that changed something are a step first (so an undo takes them back);
        they stay open and start over from the state put back."""
        state = self.state
        with state.som_lock:
            self.trainer.drain()
            with state.lock:
                changed = self.gestures.changed()
                if changed and self.gestures.boundary is not None:
                    key, gesture = changed[0]
                    self._complete(Change(key[0], "drag", dict(gesture.before), exact=False), again=False)
                self.gestures.settle()
                current = state.capture()
                target = move(current)
                if target is not None:  # whose the step was travels with it
                    change = self.gestures.changes.pop(target.key, None)
                    if change is not None:
                        self.gestures.changes[current.key] = change
            if target is None:
                return False
            self.put_back(target)
        with state.lock:
            self._last_step = ("", 0.0)
            state.unsaved = True
            state.completed += 1
            self.trainer.enqueue(Publish(), intent=False)
        return True

    # -- a view's own steps (hands.py) --------------------------------------------------------------------------
    def own_step(self, hand: int) -> tuple[Step | None, bool]:
        """The newest step of `hand` not taken back yet, and whether it is the newest of all (nothing after it, no
        open gesture changed anything since): then a plain undo takes it back exactly."""
        with self.state.lock:
            undo, _ = self.history.steps()
            step = self.gestures.latest_of(hand, undo)
            if step is None:
                return None, False
            newest = undo[-1] is step and self.gestures.boundary is None
            return step, newest and self.gestures.changes[step.key].exact

    def change_of(self, step: Step) -> Change | None:
        with self.state.lock:
            return self.gestures.changes.get(step.key)

    def taken_back(self, step: Step) -> None:
        """The step just completed took `step` back (its hand's undo of an older step): it says so."""
        with self.state.lock:
            undo, _ = self.history.steps()
            change = self.gestures.changes.get(undo[-1].key) if undo else None
            if change is not None:
                self.gestures.changes[undo[-1].key] = dataclasses.replace(change, reverts=step.key)
            self.gestures.taken_back.add(step.key)

    def redo_own(self, hand: int) -> bool | None:
        """`hand`'s redo right after its undo of an older step: that undo is taken back exactly, and nothing is left
        to redo. None when the newest step is not such an undo."""
        with self.state.lock:
            undo, _ = self.history.steps()
            change = self.gestures.changes.get(undo[-1].key) if undo else None
            if change is None or change.hand != hand or change.reverts is None or self.gestures.boundary is not None:
                return None
        if not self._travel(self.history.undo):
            return False
        with self.state.lock:
            self.gestures.taken_back.discard(change.reverts)
            self.history.drop_redo()
        return True

    def put_back(self, step: Step) -> None:
        """Put a recorded state back exactly and hold (caller holds state.som_lock, no intent queued)."""
        if step.preset is not self.state.preset:
            self.rebuild(step.preset)
        with self.state.lock:
            self.state.put_back(step)
            self.install_frame()

    def bring_back(self, current: Step, undo: list[Step], redo: list[Step]) -> None:
        """A session read back from its folder (its preset the installed one): the current step exactly, held, and its
        undo and redo steps."""
        state = self.state
        with state.som_lock:
            self.put_back(current)
            with state.lock:
                self.history.restore(undo, redo)
                state.unsaved = True
                self.install_frame()

    def jump(self, controls, changes: dict, weights) -> None:
        """Put a state made elsewhere in place (a design variant: its controls, schedule `changes` and trained
        weights), at the end of its schedule, held (caller records the step)."""
        state = self.state
        with state.som_lock:
            self.trainer.drain()
            with state.lock:
                params = dict(state.capture().parameters, **changes)
            self.put_back(Step(preset=state.preset, controls=controls, parameters=params, weights=weights,
                               iteration=params["iterations"]))
        with state.lock:
            self.trainer.enqueue(Publish(), intent=False)

    def close(self) -> None:
        self.history.close()


class SessionHistory(tuple):
    """A session's undo history and gestures (`session.history`). It reads as the tuple (undo steps, redo steps) it
    was when read (`undo, redo = session.history`); its methods act on the session now."""

    _timeline: Timeline

    def __new__(cls, timeline: Timeline):
        with timeline.state.lock:
            counts = timeline.counts
        history = super().__new__(cls, counts)
        history._timeline = timeline
        return history

    @property
    def counts(self) -> tuple[int, int]:
        """(undo steps, redo steps) available now."""
        return tuple(SessionHistory(self._timeline))

    def undo(self) -> bool:
        """Go back one step: controls, settings, weights and s exactly as before it, nothing trains. False if there
        is no step to undo."""
        return self._timeline.undo()

    def redo(self) -> bool:
        """Go forward again after an undo, exactly; False if there is nothing to redo."""
        return self._timeline.redo()

    def begin_gesture(self) -> None:
        """A gesture starts (a drag's press): the intents until `end_gesture()` make one undo step, recorded with
        the state before the first of them. A gesture left open (a tab closed mid-drag) ends at the next one."""
        self._timeline.begin_gesture()

    def end_gesture(self) -> None:
        """The gesture ends (a drag's release): the step is complete and goes to the autosave."""
        self._timeline.end_gesture()

    @contextlib.contextmanager
    def gesture(self):
        """`with session.history.gesture(): ...`: the intents inside make one undo step."""
        self.begin_gesture()
        try:
            yield self
        finally:
            self.end_gesture()
