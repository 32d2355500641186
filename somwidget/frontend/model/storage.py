"""Where somwidget keeps its files, and the autosave that a crash cannot take away.

`data_dir()` is $SOMWIDGET_DATA_DIR, else the platform's data directory for somwidget (~/.local/share/somwidget on
Linux, ~/Library/Application Support/somwidget on macOS, %LOCALAPPDATA%\\somwidget on Windows).

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
from pathlib import Path

log = logging.getLogger(__name__)

#: States of sessions that did not close cleanly kept for `Session.recover()`; older ones are deleted.
KEEP_CRASHED = 5
_SUFFIX = ".npz"


def data_dir() -> Path:
    """$SOMWIDGET_DATA_DIR, else the platform's user data directory for somwidget."""
    if os.environ.get("SOMWIDGET_DATA_DIR"):
        return Path(os.environ["SOMWIDGET_DATA_DIR"]).expanduser()
    import platformdirs

    return Path(platformdirs.user_data_dir("somwidget", appauthor=False))


def autosave_dir() -> Path:
    return data_dir() / "autosave"


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
