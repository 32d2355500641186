"""Work is never lost: each step a session completes goes to its folder on disk (store.py) with its undo history, and
`recover` brings back a stopped session, however it stopped.

When a session writes (`SessionAutosave`): at once when a step completes (a drag released, a control added, a
setting, a reset, an undo...), and while training goes on or a drag is held, when training settles or every
AUTOSAVE_SECONDS; never what is not whole. A save of a drag not yet released is marked as one: brought back, the drag
is a step of its own that Undo removes, and the message says so.

A save that fails (a full disk, a folder that cannot be written) is kept and tried again every RETRY_SECONDS, a newer
state taking its place, until one is on disk; meanwhile `Autosave.error` says what is wrong and where, and the
session's views show it. Nothing is called saved before its manifest is on disk.

An autosave of an earlier version (one session file per session, `<id>.npz` beside `<id>.lock`) is brought back by
`recover` when no saved session of this version is waiting, then renamed so that it is taken once.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

from .files import preset_of, read
from .operations import Publish
from .state import ModellingState, max_vertices_for
from .store import Saving, SessionStore, Unreadable, autosave_dir, lock, peek, set_aside, stopped
from .timeline import Timeline
from .trainer import Trainer

log = logging.getLogger(__name__)

#: While training or dragging, a session writes at most this often (it writes at once when a step completes, and
#: when training settles).
AUTOSAVE_SECONDS = 2.0
#: A failed save is tried again after this many seconds.
RETRY_SECONDS = 1.0


class Autosave:
    """The writer of one session's store: `submit(saving)` hands over the latest state; a thread of its own commits
    the newest (older ones not yet written are skipped), and keeps trying a save that failed. `on_status()` is called
    (on that thread) whenever `error` changes."""

    def __init__(self, store: SessionStore, on_status: Callable[[], None] = lambda: None):
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

    def __init__(self, state: ModellingState, store: SessionStore, timeline: Timeline, trainer: Trainer):
        self.state = state
        self.timeline = timeline
        self.trainer = trainer
        self.writer = Autosave(store, self._publish)
        self._saved_at = 0.0
        self._completed = -1  # state.completed at the latest save (-1: a new session's first state is due)

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
        return state.unsaved and (self.settled() or time.monotonic() - self._saved_at >= AUTOSAVE_SECONDS)

    def if_due(self) -> None:
        """Training thread, after each turn: write the state if a step completed since the last save, or if it
        changed and training has settled (or AUTOSAVE_SECONDS have passed)."""
        state = self.state
        with state.lock:
            if not self._due():
                return
        with state.som_lock, state.lock:
            if not self._due() or not self.quiet():
                return  # an intent is on its way: the next turn saves with it
            saving = self._take()
        self.writer.submit(saving)

    def _take(self) -> Saving:
        """The state to save now (caller holds both locks), marked as saved."""
        saving = self.snapshot()
        self.state.unsaved = False
        self._completed = self.state.completed
        self._saved_at = time.monotonic()
        return saving

    def flush(self, timeout: float = 10.0) -> bool:
        """Write the current state now (the queued intents applied first) and wait until it is on disk; False at the
        timeout or while saves fail."""
        state = self.state
        with state.som_lock:
            self.drain()
            with state.lock:
                saving = self._take()
        self.writer.submit(saving)
        return self.writer.flush(timeout)

    def close(self, timeout: float) -> bool:
        """Write what changed since the last save and let go of the folder; False when it could not be written."""
        state = self.state
        with state.lock:
            due = state.unsaved or state.completed != self._completed
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


def recovered_message(saved_at: float, preset: str, gesture: bool, undo_steps: int) -> str:
    """What a view says about a session brought back: when it was saved, and which state it is."""
    when = time.strftime("%Y-%m-%d %H:%M", time.localtime(saved_at))
    if gesture:
        return (f"Brought back your session of {when} ({preset}) as it was during a drag that was not released: "
                "the drag is kept as a step of its own, which Undo removes.")
    steps = f"; Undo reaches the {undo_steps} step{'s' if undo_steps != 1 else ''} before it" if undo_steps else ""
    return f"Brought back your session of {when} ({preset}) as its last completed step{steps}."


def recover(session_class, origin: str | None = None, **options):
    """(the newest stopped session of `origin` (None: any) brought back, or None; notices): the session has its undo
    history and its folder (it goes on saving there), and nothing trains until the next intent; `options` go to
    `session_class` (device, start...). A folder that cannot be read is set aside (renamed, never deleted) and the next
    one tried; each notice says what was wrong and where."""
    notices: list[str] = []
    start = options.pop("start", True)
    max_vertices = options.get("max_vertices") or max_vertices_for(options.get("device"))
    for folder in stopped(notices):
        manifest = peek(folder)
        if manifest is not None and origin is not None and manifest.get("origin") != origin:
            continue
        try:
            store = SessionStore.adopt(folder)
        except OSError as exc:
            notices.append(f"cannot open the saved session {folder}: {exc.strerror or exc}")
            continue
        if store is None:
            continue  # live: another process has it
        try:
            saved = store.read(max_vertices)
        except Unreadable as exc:
            try:
                aside = store.set_aside()
                notices.append(f"the saved session in {folder} cannot be read ({exc}); it is kept at {aside}")
            except OSError as err:
                store.release()
                notices.append(f"the saved session in {folder} cannot be read ({exc}) nor set aside ({err})")
            continue
        if origin is not None and saved.origin != origin:
            store.release()
            continue
        try:
            session = session_class(saved.current.preset, start=False, origin=saved.origin, _store=store, **options)
        except ValueError as exc:  # it does not fit this device
            store.release()
            notices.append(f"the saved session in {folder} cannot be brought back here: {exc}")
            continue
        session.timeline.bring_back(saved.current, saved.undo, saved.redo)
        session.recovered = {"path": str(folder), "saved": saved.saved, "preset": saved.current.preset.name,
                             "gesture": saved.gesture, "undo": len(saved.undo), "redo": len(saved.redo),
                             "message": recovered_message(saved.saved, saved.current.preset.title or
                                                          saved.current.preset.name, saved.gesture, len(saved.undo))}
        session.notices.extend(notices)
        if start:
            session.start()
        return session, notices
    session = _recover_legacy(session_class, origin, notices, max_vertices, options)
    if session is not None and start:
        session.start()
    return session, notices


#: An earlier version's autosave: `<id>.npz` (a session file) beside `<id>.lock` in the autosave folder.
LEGACY_SUFFIX = ".npz"


def legacy_stopped() -> list[Path]:
    """Autosaves written by somwidget before 2026-11-25 (one session file each, no undo history) of sessions that
    stopped (their lock free or gone), newest first."""
    folder = autosave_dir()
    if not folder.is_dir():
        return []
    found = []
    for path in folder.glob(f"*{LEGACY_SUFFIX}"):
        if not path.is_file():
            continue
        lock_path = path.with_suffix(".lock")
        if lock_path.exists():
            try:
                handle = lock(lock_path)
            except OSError:
                continue
            if handle is None:
                continue  # its process is alive
            handle.close()
        found.append((path.stat().st_mtime, path))
    return [p for _, p in sorted(found, reverse=True)]


def _recover_legacy(session_class, origin, notices: list[str], max_vertices: int, options: dict):
    """The newest earlier-version autosave brought back (as a loaded session file: its step, no undo history), the
    file then renamed `<id>.npz.brought-back-<time>` so it is taken once and never deleted; or None."""
    for path in legacy_stopped():
        try:
            state = read(path, max_vertices)
            preset = preset_of(state)[0]
        except ValueError as exc:
            try:
                notices.append(f"the earlier version's autosave {path} cannot be read ({exc}); it is kept at "
                               f"{set_aside(path)}")
            except OSError as err:
                notices.append(f"the earlier version's autosave {path} cannot be read ({exc}) nor set aside ({err})")
            continue
        try:
            session = session_class(preset, start=False, origin=origin or "python", **options)
        except ValueError as exc:  # it does not fit this device
            notices.append(f"the earlier version's autosave {path} cannot be brought back here: {exc}")
            continue
        session.files.restore(state)
        kept = path.with_name(f"{path.name}.brought-back-{time.strftime('%Y%m%d-%H%M%S')}")
        try:
            os.replace(path, kept)
            path.with_suffix(".lock").unlink(missing_ok=True)
        except OSError as exc:
            notices.append(f"the earlier version's autosave {path} was brought back but cannot be renamed: {exc}")
            kept = path
        saved = kept.stat().st_mtime if kept.exists() else time.time()
        when = time.strftime("%Y-%m-%d %H:%M", time.localtime(saved))
        message = (f"Brought back your session of {when} ({preset.title or preset.name}) from an earlier version's "
                   f"autosave, as it was saved; the file is kept at {kept}.")
        session.recovered = {"path": str(kept), "saved": saved, "preset": preset.name, "gesture": False, "undo": 0,
                             "redo": 0, "message": message}
        session.notices.extend(notices)
        return session
    return None
