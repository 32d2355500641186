"""A session's undo and redo: which intents make one step, and travelling between steps.

Every completed gesture is one undo step (history.py keeps them): a drag from `begin_gesture()` to `end_gesture()`,
and each other intent call (a control added, removed or recoloured, a parameter set, a reset, a preset, a mesh, a
loaded session); the same parameter set again within PARAMETER_STEP_SECONDS joins its step (a slider's drag). Each
completed step (and each undo or redo) counts in `state.completed`: the autosave writes it at once.

Drags: each frame of a drag is the local restart from the shape the drag began with (the Som anchors it,
`Som.anchor`), to the hand's latest position; so a drag ends exactly as one move there would, however many frames it
took (restarting from the latest weights at every frame would wear the rest of the shape down).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

from .state import ModellingState
from .history import History, Shelf, Step
from .operations import Publish
from .trainer import Trainer

#: Setting the same parameter again within this many seconds joins the previous undo step (a slider's drag).
PARAMETER_STEP_SECONDS = 1.5


class Timeline:
    """The undo history of one session and the gesture in progress.

    rebuild(preset): install another preset's Som (a step of an earlier preset); install_frame(): make and keep a
    frame of the state put back; shelf: where the history's steps go on disk (None: a temporary folder)."""

    def __init__(self, state: ModellingState, trainer: Trainer, rebuild: Callable[[object], None],
                 install_frame: Callable[[], None], shelf: Shelf | None = None):
        self.state = state
        self.trainer = trainer
        self.rebuild = rebuild
        self.install_frame = install_frame
        self.history = History(shelf=shelf)
        self._gesture_step: Step | None = None  # the step the open gesture recorded, once it changed something
        self.anchor = None  # in a drag: the Som that anchored its weights (where each frame restarts)
        self._last_step: tuple[str, float] = ("", 0.0)  # kind and time of the latest recorded step

    @property
    def gesture_recorded(self) -> bool:
        """A gesture is open and has changed something (its step is recorded): the state now is a drag not yet
        released (caller holds state.lock)."""
        return self.state.gesture and self._gesture_step is not None

    @property
    def counts(self) -> tuple[int, int]:
        """(undo steps, redo steps) available (caller holds state.lock)."""
        return self.history.undo_count, self.history.redo_count

    # -- gestures ----------------------------------------------------------------------------------------------
    def begin_gesture(self) -> None:
        with self.state.lock:
            self.state.gesture = True
            self._gesture_step = None
            self.anchor = None

    def end_gesture(self) -> None:
        state = self.state
        with state.wake:
            if not state.gesture:
                return
            state.gesture = False
            self.anchor = None
            state.unsaved = True
            if self._gesture_step is not None:
                state.completed += 1
            state.wake.notify_all()

    def drag_anchor(self):
        """The Som a control move should restart from: the drag's anchor inside a gesture, else None."""
        return self.anchor if self.state.gesture else None

    @contextlib.contextmanager
    def step(self, kind: str):
        """Around one intent: record the state before it as an undo step (unless it belongs to an open gesture that
        has one, or repeats the same parameter within PARAMETER_STEP_SECONDS); a refused intent takes it back."""
        state = self.state
        with state.lock:
            last_kind, last_time = self._last_step
            joins = (state.gesture and self._gesture_step is not None) or (
                kind.startswith("parameter:") and kind == last_kind
                and time.monotonic() - last_time < PARAMETER_STEP_SECONDS)
        step, anchor = (None, None) if joins else self._record()
        try:
            yield
        except BaseException:
            if step is not None:
                with state.lock:
                    self.history.drop_last(step)
                    if state.gesture and self._gesture_step is step:
                        self._gesture_step = self.anchor = None
            raise
        with state.lock:
            if step is not None and state.gesture:
                self._gesture_step, self.anchor = step, anchor
            self._last_step = (kind, time.monotonic())
            state.unsaved = True
            if not state.gesture:
                state.completed += 1

    def _record(self) -> tuple[Step, object]:
        """Push the current state (every queued intent applied first) as an undo step. Returns it, and inside a
        gesture the Som that kept its weights (the drag's frames restart from them), else None."""
        state = self.state
        with state.som_lock:
            drained = self.trainer.drain()
            with state.lock:
                step = state.capture()
                self.history.push(step)
                anchor = None
                if state.gesture:
                    anchor = state.som
                    anchor.anchor()
                if drained:
                    self.trainer.enqueue(Publish(), intent=False)  # a frame that shows the drained intents
        return step, anchor

    # -- travel ------------------------------------------------------------------------------------------------
    def undo(self) -> bool:
        return self._travel(self.history.undo)

    def redo(self) -> bool:
        return self._travel(self.history.redo)

    def _travel(self, move) -> bool:
        state = self.state
        with state.lock:
            state.gesture = False
        with state.som_lock:
            self.trainer.drain()
            with state.lock:
                target = move(state.capture())
            if target is None:
                return False
            self.put_back(target)
        with state.lock:
            self._last_step = ("", 0.0)
            state.unsaved = True
            state.completed += 1
            self.trainer.enqueue(Publish(), intent=False)
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
