"""The autosave that a crash cannot take away: each step a session completes goes to disk, and `Session.recover()`
brings back a session that did not close cleanly.

Each live session that autosaves owns two files in data_dir()/autosave: `<id>.npz`, its latest state (a session
file, io.save_session: written to a temporary file, then renamed over the old one, so a kill mid-write leaves the
previous state whole), and `<id>.lock`, locked for as long as its process lives. A clean close deletes both. The
operating system drops the lock of a process that dies however it dies (SIGKILL included), so a state file whose
lock can be taken belongs to a session that did not close cleanly: `crashed()` lists those, newest first. Disk use
is bounded: one state per live session, and at most KEEP_CRASHED states of crashed ones (older ones are deleted).
"""

from __future__ import annotations

import logging
import os
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path

from .storage import autosave_dir

log = logging.getLogger(__name__)

#: States of sessions that did not close cleanly kept for `Session.recover()`; older ones are deleted.
KEEP_CRASHED = 5
_SUFFIX = ".npz"


def _try_lock(handle) -> bool:
    """An exclusive, non-blocking lock on an open file: True if taken (the OS releases it when the process ends)."""
    try:
        import fcntl

        fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except ImportError:  # Windows
        import msvcrt

        try:
            msvcrt.locking(handle.fileno(), msvcrt.LK_NBLCK, 1)
            return True
        except OSError:
            return False
    except OSError:
        return False


class Autosave:
    """The autosave of one live session: `submit(write)` hands over a function that writes the latest state to a
    path; a background thread runs the newest one (older ones not yet written are skipped) and renames the result
    into place. `close(clean=True)` writes what is pending, then deletes the files (a clean exit)."""

    def __init__(self, directory: str | os.PathLike | None = None):
        self.directory = Path(directory) if directory is not None else autosave_dir()
        self.directory.mkdir(parents=True, exist_ok=True)
        self.id = f"{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self.path = self.directory / f"{self.id}{_SUFFIX}"
        self.lock_path = self.directory / f"{self.id}.lock"
        self._lock_file = open(self.lock_path, "a+b")  # noqa: SIM115 (held open for the session's life)
        if not _try_lock(self._lock_file):  # pragma: no cover - a fresh, unique name
            raise RuntimeError(f"autosave: cannot lock {self.lock_path}")
        self._pending = None
        self._writing = False
        self._cond = threading.Condition()
        self._closed = False
        self.saves = 0
        self.error: str | None = None
        self._thread = threading.Thread(target=self._run, name="somwidget-autosave", daemon=True)
        self._thread.start()

    def submit(self, write) -> None:
        """Save soon: `write(path)` writes the state (the latest call wins)."""
        with self._cond:
            if self._closed:
                return
            self._pending = write
            self._cond.notify_all()

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait until nothing is pending; False at the timeout."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._pending is not None or self._writing:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.05))
        return True

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._pending is None and self._closed:
                    return
                write, self._pending = self._pending, None
                self._writing = True
            try:
                write(self.path)  # io.save_session writes a temporary file and renames it over the old one
                self.saves += 1
                self.error = None
            except Exception as exc:  # a full disk must not stop the session
                self.error = f"autosave to {self.path} failed: {exc}"
                log.warning("%s", self.error)
            finally:
                with self._cond:
                    self._writing = False
                    self._cond.notify_all()

    def close(self, clean: bool = True, timeout: float = 10.0) -> None:
        """Stop the writer after what is pending; with `clean`, delete the state and the lock (a clean exit)."""
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout)
        if clean:
            for p in (self.path, self.lock_path):
                try:
                    p.unlink()
                except FileNotFoundError:
                    pass
        self._lock_file.close()


def crashed(directory: str | os.PathLike | None = None) -> list[Path]:
    """State files of sessions that did not close cleanly (their lock is free), newest first; those past
    KEEP_CRASHED are deleted, as are lock files left without a state."""
    folder = Path(directory) if directory is not None else autosave_dir()
    if not folder.is_dir():
        return []
    found = []
    for lock_path in folder.glob("*.lock"):
        state = lock_path.with_suffix(_SUFFIX)
        try:
            with open(lock_path, "a+b") as handle:
                if not _try_lock(handle):
                    continue  # a live session
        except OSError:
            continue
        if state.exists():
            found.append(state)
        else:
            _unlink(lock_path)
    found.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    for old in found[KEEP_CRASHED:]:
        discard(old)
    return found[:KEEP_CRASHED]


def discard(state: Path) -> None:
    """Delete a crashed session's state and lock."""
    _unlink(state)
    _unlink(state.with_suffix(".lock"))


def _unlink(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass


#: While training, the autosave writes at most this often (it always writes when training settles).
AUTOSAVE_SECONDS = 2.0


class SessionAutosave:
    """When a session's state is written: after a change, once training settles or AUTOSAVE_SECONDS have passed
    (the training thread asks after each turn), or at once on `flush`. `state()` reads the state to write (io's
    session dict), `write(path, state)` writes it."""

    def __init__(self, clay, state: Callable[[], dict], write: Callable[[Path, dict], None],
                 settled: Callable[[], bool]):
        self.clay = clay
        self.state = state
        self.write = write
        self.settled = settled
        self.writer = Autosave()
        self._saved_at = 0.0

    @property
    def path(self) -> Path:
        return self.writer.path

    def if_due(self, closed: bool) -> None:
        """Training thread: write the state if something changed since the last save and training has settled (or
        AUTOSAVE_SECONDS have passed)."""
        clay = self.clay
        with clay.lock:
            if not clay.unsaved or closed:
                return
            if not self.settled() and time.monotonic() - self._saved_at < AUTOSAVE_SECONDS:
                return
            clay.unsaved = False
            self._saved_at = time.monotonic()
        self._submit()

    def flush(self, timeout: float) -> bool:
        """Write the current state now and wait until it is on disk; False at the timeout."""
        with self.clay.lock:
            self.clay.unsaved = False
            self._saved_at = time.monotonic()
        self._submit()
        return self.writer.flush(timeout)

    def _submit(self) -> None:
        try:
            state = self.state()
        except Exception:  # pragma: no cover - a state that cannot be read now is saved at the next change
            log.exception("autosave: could not read the session's state")
            return
        self.writer.submit(lambda path: self.write(path, state))

    def close(self) -> None:
        self.writer.close(clean=True)


def recover(session_class, **options):
    """A session of `session_class` brought back from the newest readable crashed autosave (nothing trains until the
    next intent), or None; `options` go to the class (device, start...). An unreadable autosave is discarded with
    the reason in the log. The crashed file goes once the new session has saved its own."""
    from . import files
    from .clay import max_vertices_for

    start = options.pop("start", True)
    max_vertices = options.get("max_vertices") or max_vertices_for(options.get("device"))
    for path in crashed():
        try:
            state = files.read(path, max_vertices)
            preset, weights, iteration = files.preset_of(state)
            saved = path.stat().st_mtime
        except (ValueError, OSError) as exc:
            log.warning("autosave %s cannot be read (%s): discarded", path, exc)
            discard(path)
            continue
        session = session_class(preset, start=False, **options)
        session._restore_into(weights, iteration)
        session.recovered = {"path": str(path), "saved": saved, "preset": state["preset"]}
        session.flush_autosave()
        discard(path)
        if start:
            session.start()
        return session
    return None
