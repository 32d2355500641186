"""A session's undo and redo: which intents make one step, and travelling between steps.

Every completed gesture is one undo step (history.py keeps them): a drag from `begin_gesture()` to `end_gesture()`,
and each other intent call (a control added, removed or recoloured, a parameter set, a reset, a preset, a mesh, a
loaded session); the same parameter set again within PARAMETER_STEP_SECONDS joins its step (a slider's drag). Each
completed step (and each undo or redo) counts in `clay.completed`: the autosave writes it at once.

Drags: each frame of a drag is the local restart from the shape the drag began with (the Som anchors it,
`Som.anchor`), to the hand's latest position; so a drag ends exactly as one move there would, however many frames it
took (restarting from the latest weights at every frame would wear the rest of the shape down).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

from .clay import Clay
from .history import History, Shelf, Step
from .operations import Publish
from .trainer import Trainer

#: Setting the same parameter again within this many seconds joins the previous undo step (a slider's drag).
PARAMETER_STEP_SECONDS = 1.5


class Timeline:
    """The undo history of one session and the gesture in progress.

    rebuild(preset): install another preset's Som (a step of an earlier preset); install_frame(): make and keep a
    frame of the state put back; shelf: where the history's steps go on disk (None: a temporary folder)."""

    def __init__(self, clay: Clay, trainer: Trainer, rebuild: Callable[[object], None],
                 install_frame: Callable[[], None], shelf: Shelf | None = None):
        self.clay = clay
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
        released (caller holds clay.lock)."""
        return self.clay.gesture and self._gesture_step is not None

    @property
    def counts(self) -> tuple[int, int]:
        """(undo steps, redo steps) available (caller holds clay.lock)."""
        return self.history.undo_count, self.history.redo_count

    # -- gestures ----------------------------------------------------------------------------------------------
    def begin_gesture(self) -> None:
        with self.clay.lock:
            self.clay.gesture = True
            self._gesture_step = None
            self.anchor = None

    def end_gesture(self) -> None:
        clay = self.clay
        with clay.wake:
            if not clay.gesture:
                return
            clay.gesture = False
            self.anchor = None
            clay.unsaved = True
            if self._gesture_step is not None:
                clay.completed += 1
            clay.wake.notify_all()

    def drag_anchor(self):
        """The Som a control move should restart from: the drag's anchor inside a gesture, else None."""
        return self.anchor if self.clay.gesture else None

    @contextlib.contextmanager
    def step(self, kind: str):
        """Around one intent: record the state before it as an undo step (unless it belongs to an open gesture that
        has one, or repeats the same parameter within PARAMETER_STEP_SECONDS); a refused intent takes it back."""
        clay = self.clay
        with clay.lock:
            last_kind, last_time = self._last_step
            joins = (clay.gesture and self._gesture_step is not None) or (
                kind.startswith("parameter:") and kind == last_kind
                and time.monotonic() - last_time < PARAMETER_STEP_SECONDS)
        step, anchor = (None, None) if joins else self._record()
        try:
            yield
        except BaseException:
            if step is not None:
                with clay.lock:
                    self.history.drop_last(step)
                    if clay.gesture and self._gesture_step is step:
                        self._gesture_step = self.anchor = None
            raise
        with clay.lock:
            if step is not None and clay.gesture:
                self._gesture_step, self.anchor = step, anchor
            self._last_step = (kind, time.monotonic())
            clay.unsaved = True
            if not clay.gesture:
                clay.completed += 1

    def _record(self) -> tuple[Step, object]:
        """Push the current state (every queued intent applied first) as an undo step. Returns it, and inside a
        gesture the Som that kept its weights (the drag's frames restart from them), else None."""
        clay = self.clay
        with clay.som_lock:
            drained = self.trainer.drain()
            with clay.lock:
                step = clay.capture()
                self.history.push(step)
                anchor = None
                if clay.gesture:
                    anchor = clay.som
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
        clay = self.clay
        with clay.lock:
            clay.gesture = False
        with clay.som_lock:
            self.trainer.drain()
            with clay.lock:
                target = move(clay.capture())
            if target is None:
                return False
            self.put_back(target)
        with clay.lock:
            self._last_step = ("", 0.0)
            clay.unsaved = True
            clay.completed += 1
            self.trainer.enqueue(Publish(), intent=False)
        return True

    def put_back(self, step: Step) -> None:
        """Put a recorded state back exactly and hold (caller holds clay.som_lock, no intent queued)."""
        if step.preset is not self.clay.preset:
            self.rebuild(step.preset)
        with self.clay.lock:
            self.clay.put_back(step)
            self.install_frame()

    def jump(self, controls, changes: dict, weights) -> None:
        """Put a state made elsewhere in place (a design variant: its controls, schedule `changes` and trained
        weights), at the end of its schedule, held (caller records the step)."""
        clay = self.clay
        with clay.som_lock:
            self.trainer.drain()
            with clay.lock:
                params = dict(clay.capture().parameters, **changes)
            self.put_back(Step(preset=clay.preset, controls=controls, parameters=params, weights=weights,
                               iteration=params["iterations"]))
        with clay.lock:
            self.trainer.enqueue(Publish(), intent=False)

    def close(self) -> None:
        self.history.close()
