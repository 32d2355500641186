"""Work is never lost: each step a session completes goes to its folder on disk (store.py) with its undo history, so
that recovery.py can bring back a stopped session, however it stopped.

When a session writes (`SessionAutosave`): at once when a step completes (a drag released, a control added, a
setting, a reset, an undo...); while training goes on, when training settles or about every AUTOSAVE_SECONDS; while
a drag is held, about every AUTOSAVE_SECONDS (its moves settle one after another, a fast engine's every frame); never
what is not whole. "About": each wait is drawn within AUTOSAVE_JITTER of it, so that the sessions of one process (a
studio's rooms, whose drags may all begin at once) do not all write in the same moment, every time.

A save of a drag not yet released is marked as one: brought back, the drag is a step of its own that Undo removes,
and the message says so.

A save that fails (a full disk, a folder that cannot be written) is kept and tried again every RETRY_SECONDS, a newer
state taking its place, until one is on disk; meanwhile `Autosave.error` says what is wrong and where, and the
session's views show it. Nothing is called saved before its manifest is on disk.

A session brought back (recovery.py) saves nothing until it is whole (`SessionAutosave.arm`): a store it took over
stays as it was if the start fails, and a session that never finished starting is not saved at exit.
"""

from __future__ import annotations

import logging
import random
import threading
import time
from collections.abc import Callable

from .operations import Publish
from .state import ModellingState
from .store import Saving, SessionStore
from .timeline import Timeline
from .trainer import Trainer

log = logging.getLogger(__name__)

#: While training or dragging, a session writes at most this often (it writes at once when a step completes, and
#: when training settles with no drag held).
AUTOSAVE_SECONDS = 2.0
#: ...give or take this share of it, drawn afresh after each save.
AUTOSAVE_JITTER = 0.25
#: A failed save is tried again after this many seconds.
RETRY_SECONDS = 1.0


def next_due() -> float:
    """When the next save of a changing session is due (time.monotonic): about AUTOSAVE_SECONDS from now."""
    return time.monotonic() + AUTOSAVE_SECONDS * (1.0 + AUTOSAVE_JITTER * random.uniform(-1.0, 1.0))


class Autosave:
    """The writer of one session's store: `submit(saving)` hands over the latest state; a thread of its own commits
    the newest (older ones not yet written are skipped), and keeps trying a save that failed. `on_status()` is called
    (on that thread) whenever `error` changes."""

    def __init__(self, store: SessionStore, on_status: Callable[[], None] = lambda: None) -> None:
        self.store = store
        self.on_status = on_status
        self.error: str | None = None  # why the latest save failed; None once one is on disk
        self.saves = 0  # saves on disk
        self._pending: Saving | None = None
        self._writing = False
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="somwidget-autosave", daemon=True)
        self._thread.start()

    def submit(self, saving: Saving) -> None:
        """Save `saving` soon (the latest call wins)."""
        with self._cond:
            if self._closed:
                return
            self._pending = saving
            self._cond.notify_all()

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait until what was submitted is on disk; False at the timeout or while saves fail."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._pending is not None or self._writing:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.05))
            return self.error is None

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._pending is None:
                    return
                saving, self._pending = self._pending, None
                self._writing = True
            try:
                self.store.commit(saving)
                error = None
            except (OSError, ValueError) as exc:  # a full disk must not stop the session
                where = getattr(exc, "filename", None) or self.store.folder
                error = (f"autosave failed: cannot write {where}: {getattr(exc, 'strerror', None) or exc}. "
                         f"Trying again every {RETRY_SECONDS:g} s; the steps since the last save are not on disk yet")
            with self._cond:
                self._writing = False
                if error is None:
                    self.saves += 1
                elif self._pending is None:
                    self._pending = saving  # tried again, unless a newer state comes first
                changed, self.error = error != self.error, error
                self._cond.notify_all()
            if changed:
                (log.warning if error else log.info)("%s", error or f"autosave works again: {self.store.folder}")
                try:
                    self.on_status()
                except Exception:  # pragma: no cover - a view's trouble must not stop the saves
                    log.exception("autosave: telling the views failed")
            if error is not None:
                with self._cond:
                    if not self._closed:
                        self._cond.wait(RETRY_SECONDS)
                    elif self._pending is saving:  # closing: give up on a disk that keeps refusing
                        self._pending = None

    def close(self, timeout: float = 10.0) -> bool:
        """Write what is pending (for up to `timeout` seconds), stop the thread and let go of the folder (it stays
        for the next start). False when the latest state could not be written."""
        ok = self.flush(timeout)
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(max(timeout, 1.0))
        self.store.release()
        return ok


class SessionAutosave:
    """When a session's state is written (the module's docstring): its modelling state with the undo history of its
    timeline, between the training thread's turns."""

    def __init__(self, state: ModellingState, store: SessionStore, timeline: Timeline, trainer: Trainer) -> None:
        self.state = state
        self.timeline = timeline
        self.trainer = trainer
        self.writer = Autosave(store, self._publish)
        self._due_at = 0.0
        self._completed = -1  # state.completed at the latest save (-1: a new session's first state is due)
        self._timer: threading.Timer | None = None  # a held drag settled: the turn that saves it, when it is due

    def snapshot(self) -> Saving:
        """What a save writes now (caller holds the Som's lock and the state lock, no intent queued)."""
        undo, redo = self.timeline.steps()  # open gestures that changed something: their state before, the newest
        return Saving(self.state.capture(), undo, redo, gesture=self.timeline.gesture_recorded)

    def quiet(self) -> bool:
        """No intent is queued."""
        return not self.trainer.ops

    def settled(self) -> bool:
        """Training has nothing to do."""
        return not self.trainer.should_step() and not self.trainer.ops

    def drain(self) -> None:
        """Apply the queued intents now (caller holds the Som's lock)."""
        self.trainer.drain()

    def _publish(self) -> None:
        """A frame for every view now (the autosave's status changed: the views show it)."""
        with self.state.lock:
            if not self.trainer.closed:
                self.trainer.enqueue(Publish(), intent=False)

    @property
    def path(self):
        """The session's folder."""
        return self.writer.store.folder

    @property
    def error(self) -> str | None:
        return self.writer.error

    def _due(self) -> bool:
        state = self.state
        if state.completed != self._completed:
            return True
        return state.unsaved and ((self.settled() and not state.gesture)
                                  or time.monotonic() >= self._due_at)

    @property
    def armed(self) -> bool:
        """The session is whole: its saves go to its store (`arm`)."""
        return self.writer.store.writable

    def arm(self, on_disk: bool) -> None:
        """The session brought back is whole: from now on it saves. `on_disk`: its folder holds exactly this state
        (it came back from there whole), so nothing is written until it changes."""
        state = self.state
        with state.lock:
            if on_disk:
                state.unsaved = False
                self._completed = state.completed
                self._due_at = next_due()
            self.writer.store.allow_writes()

    def if_due(self) -> None:
        """Training thread, after each turn: write the state if a step completed since the last save, or if it
        changed and training has settled (or AUTOSAVE_SECONDS have passed)."""
        state = self.state
        if not self.armed:
            return
        with state.lock:
            if not self._due():
                self._save_later()
                return
        with self._som_for_save(), state.lock:
            if not self._due() or not self.quiet():
                return  # an intent is on its way: the next turn saves with it
            saving = self._take()
        self.writer.submit(saving)

    def _som_for_save(self):
        """The Som's lock as a save takes it: a studio room's held by a batch stays lent (the save reads its weights
        from the batch's last round: ModellingState.capture), else the Som's lock."""
        lent = self.state.lent
        return self.state.som_lock if lent is None else lent.for_save()

    def _save_later(self) -> None:
        """A held drag whose training settled is written when its next save is due (`next_due`): a turn then (a posted
        call, nothing else) asks again, since a settled session has no turns of its own (caller holds the state
        lock)."""
        state = self.state
        if not (state.unsaved and state.gesture and self.settled()) or self._timer is not None or self.trainer.closed:
            return

        def turn() -> None:
            with state.lock:
                self._timer = None
            if not self.trainer.closed:
                self.trainer.post(lambda: None, quick=True)  # the training thread's turn after it saves (`if_due`)

        delay = max(0.0, self._due_at - time.monotonic()) + 0.01
        self._timer = threading.Timer(delay, turn)
        self._timer.daemon = True
        self._timer.start()

    def _take(self) -> Saving:
        """The state to save now (caller holds both locks), marked as saved."""
        saving = self.snapshot()
        self.state.unsaved = False
        self._completed = self.state.completed
        self._due_at = next_due()
        return saving

    def flush(self, timeout: float = 10.0) -> bool:
        """Write the current state now (the queued intents applied first) and wait until it is on disk; False at the
        timeout or while saves fail (or before the session is armed)."""
        state = self.state
        if not self.armed:
            return False
        with state.som_lock:
            self.drain()
            with state.lock:
                saving = self._take()
        self.writer.submit(saving)
        return self.writer.flush(timeout)

    def close(self, timeout: float) -> bool:
        """Write what changed since the last save and let go of the folder; False when it could not be written. A
        session that never finished starting (never armed) writes nothing."""
        state = self.state
        with state.lock:
            due = self.armed and (state.unsaved or state.completed != self._completed)
            timer, self._timer = self._timer, None
        if timer is not None:
            timer.cancel()
        try:
            if due:
                with state.som_lock:
                    self.drain()
                    with state.lock:
                        saving = self._take()
                self.writer.submit(saving)
        except Exception:  # pragma: no cover - closing must go on
            log.exception("autosave: could not read the session's last state")
        ok = self.writer.close(timeout)
        if not ok:
            log.error("somwidget: the session's last steps could not be saved to %s: %s", self.path, self.error)
        return ok
