"""A session's home on disk: the folder its autosave keeps under storage.autosave_dir(), one per session, so that
whatever ends the process (a clean stop, a kill, a crash, the power) the next start can bring the session back with
its undo history.

A session's folder holds:

    lock            locked (flock) for as long as a process has the session: a folder whose lock is held is never
                    read, pruned or taken by another process
    manifest.json   the session: its current step, the undo and redo steps (oldest first), each with its preset and
                    settings (a setting a step lacks, declared since it was written, reads as its default);
                    whether the current step is a drag not yet released ("gesture"); when it was saved ("saved")
                    and which program made it ("origin": "serve" for `somwidget serve`)
    s<n>.npz        one step's arrays (weights, controls, radii): written once, never changed
    p<n>.npz        one preset's start (a session file, backend/session_file.py): written once

Every file is written whole under a temporary name, flushed to the disk (fsync) and renamed into place, the manifest
last; so a kill at any moment leaves the previous manifest and every file it names whole. A file that no manifest
names any more is deleted once the next manifest is on disk. A folder taken over from a stopped session is read back
by readback.py and written only once the session rebuilt from it is whole (`SessionStore.writable`).

Stopped sessions are pruned (`prune`): those older than KEEP_DAYS go, and past KEEP_SESSIONS of them or KEEP_BYTES
in all the oldest go first; the newest stopped session of each origin is always kept (a notebook's many sessions
never push out the web app's last one). A folder or file that cannot be read is set
aside under a name ending ".unreadable" (`set_aside`), never deleted. A link in the autosave folder is never
followed (neither read nor written through), and no file is read that is not a plain one (`read_small`).
"""

from __future__ import annotations

import dataclasses
import errno
import json
import logging
import os
import re
import shutil
import stat
import sys
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...backend import session_file
from ...backend.presets import Preset
from ...backend.session_file import write_atomic
from .history import Step
from .storage import autosave_dir

log = logging.getLogger(__name__)

#: The manifest's format; `read` takes this one.
FORMAT = 1
MANIFEST = "manifest.json"
LOCK = "lock"
#: Stopped sessions are kept this many days...
KEEP_DAYS = 30
#: ...at most this many of them...
KEEP_SESSIONS = 50
#: ...and at most this many bytes in all (the newest stopped session of each origin is always kept).
KEEP_BYTES = 4 << 30
#: A folder changed within this many seconds is never pruned (a session being made).
FRESH_SECONDS = 60.0
UNREADABLE = ".unreadable"
#: The names of a folder's step and preset files (ASCII digits, as many as this module writes at most).
STEP_FILE = re.compile(r"s([0-9]{1,12})\.npz")
PRESET_FILE = re.compile(r"p([0-9]{1,12})\.npz")
#: File numbers counted when a folder is taken over (far below the 12 digits a name may have).
COUNTED = 10**9
#: The largest manifest read (200 undo and 200 redo steps of 32 dims take about 1 MiB).
MAX_MANIFEST_BYTES = 16 << 20


class Unreadable(ValueError):
    """A file of a stored session that cannot be read: the message says what is wrong in plain words."""


@dataclass(frozen=True)
class Saving:
    """What one save writes: the current step, the undo and redo stacks (oldest first), and whether the current step
    is a drag not yet released."""

    current: Step
    undo: list
    redo: list
    gesture: bool = False


# -- files --------------------------------------------------------------------------------------------------------
def sync_folder(folder: Path) -> None:
    """Flush a folder's entries (the names just renamed into it) to the disk."""
    if os.name != "posix":  # pragma: no cover - Windows has no directory handles to flush
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def lock(path: Path):
    """The open lock file at `path`, locked exclusively (the OS drops the lock when the process ends, however it
    ends), or None when another process holds it. OSError when it cannot be opened, or is not a plain file (a link
    is never followed: a lock is made only inside the session's folder)."""
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) \
        | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags, 0o644)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(errno.EINVAL, "not a plain file", str(path))
    handle = os.fdopen(fd, "r+b")
    try:
        if sys.platform == "win32":  # pragma: no cover - Windows
            import msvcrt

            msvcrt.locking(handle.fileno(), msvcrt.LK_NBLCK, 1)
        else:
            import fcntl

            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        return handle
    except OSError:
        pass
    handle.close()
    return None


def check_plain(path: Path, limit: int) -> None:
    """Unreadable (in plain words) unless `path` is a plain file of at most `limit` bytes: a link (never followed),
    a folder, a named pipe or a file too large for what it should hold."""
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        raise Unreadable("missing") from None
    except OSError as exc:
        raise Unreadable(f"cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISLNK(info.st_mode):
        raise Unreadable("a link to somewhere else, not a file of this folder")
    if stat.S_ISDIR(info.st_mode):
        raise Unreadable("a folder where a file should be")
    if not stat.S_ISREG(info.st_mode):
        raise Unreadable("not a plain file")
    if info.st_size > limit:
        raise Unreadable(f"{info.st_size:,} bytes, more than such a file holds ({limit:,} at most)")


def read_small(path: Path, limit: int) -> bytes:
    """The bytes of the plain file at `path` (`check_plain`), of at most `limit` bytes; Unreadable otherwise, or when
    it cannot be read. Nothing blocks and no link is followed."""
    check_plain(path, limit)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise Unreadable("not a plain file")
            data = f.read(limit + 1)
    except OSError as exc:
        raise Unreadable(f"cannot be read ({exc.strerror or exc})") from None
    if len(data) > limit:
        raise Unreadable(f"more than such a file holds ({limit:,} bytes at most)")
    return data


def set_aside(path: Path) -> Path:
    """Rename `path` (a file or a folder that cannot be read) to a free name ending ".unreadable", beside it; the new
    path. Nothing is deleted."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for i in range(1000):
        target = path.with_name(f"{path.name}{UNREADABLE}-{stamp}" + (f"-{i}" if i else ""))
        if not target.exists():
            os.replace(path, target)
            return target
    raise OSError(f"no free name to set {path} aside")  # pragma: no cover


def sessions_folder(notices: list[str] | None = None) -> Path:
    """The folder of every session's folder (storage.autosave_dir()). Something else at its path (a file) is set aside
    and a notice says where; OSError when it cannot be made."""
    folder = autosave_dir()
    if folder.exists() and not folder.is_dir():
        aside = set_aside(folder)
        message = f"the autosave folder {folder} was a file, not a folder: it is kept at {aside}"
        log.warning("%s", message)
        if notices is not None:
            notices.append(message)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _session_folders(folder: Path) -> list[tuple[float, Path]]:
    """(when it was last saved, folder) of each session folder under `folder`, newest first."""
    found = []
    for entry in folder.iterdir():
        if UNREADABLE in entry.name or entry.is_symlink() or not entry.is_dir():
            continue  # set aside, not a folder, or a link to one elsewhere (never read, never written)
        manifest, lock_path = entry / MANIFEST, entry / LOCK
        try:
            when = (manifest if manifest.exists() else lock_path).stat().st_mtime
        except OSError:
            continue  # neither: not a session's folder
        found.append((when, entry))
    found.sort(key=lambda item: item[0], reverse=True)
    return found


def stopped(notices: list[str] | None = None) -> list[Path]:
    """The folders of saved sessions, newest first (a live one among them is skipped by `SessionStore.adopt`)."""
    try:
        folder = sessions_folder(notices)
        return [p for _, p in _session_folders(folder) if (p / MANIFEST).exists()]
    except OSError as exc:
        message = f"cannot read the autosave folder {autosave_dir()}: {exc.strerror or exc}"
        log.warning("%s", message)
        if notices is not None:
            notices.append(message)
        return []


def peek(folder: Path) -> dict | None:
    """A session folder's manifest as it is (nothing checked: readback.py checks), or None when it cannot be read."""
    try:
        data = json.loads(read_small(folder / MANIFEST, MAX_MANIFEST_BYTES).decode("utf-8"))
        return data if isinstance(data, dict) else None
    except (ValueError, RecursionError):  # Unreadable, not UTF-8, not JSON
        return None


def _size(folder: Path) -> int:
    total = 0
    for entry in os.scandir(folder):
        try:
            total += entry.stat(follow_symlinks=False).st_size
        except OSError:
            pass
    return total


def prune(keep_days: float = KEEP_DAYS, keep_sessions: int = KEEP_SESSIONS, keep_bytes: int = KEEP_BYTES) -> list[Path]:
    """Delete stopped sessions by age, count and size (the module's docstring says the rule); returns what went.
    Live sessions, folders changed within FRESH_SECONDS and unreadable ones set aside are left alone."""
    try:
        folder = autosave_dir()
        if not folder.is_dir():
            return []
        entries = _session_folders(folder)
    except OSError:
        return []
    now, kept, kept_bytes, gone, origins = time.time(), 0, 0, [], set()
    for when, entry in entries:
        if now - when < FRESH_SECONDS:
            continue
        try:
            handle = lock(entry / LOCK)
        except OSError:
            continue
        if handle is None:
            continue  # live
        try:
            size = _size(entry)
            manifest = peek(entry)
            origin = None if manifest is None else manifest.get("origin")
            newest_of_its_origin = manifest is not None and origin not in origins
            if manifest is not None and (newest_of_its_origin or (now - when <= keep_days * 86400
                                                                   and kept < keep_sessions
                                                                   and kept_bytes + size <= keep_bytes)):
                kept, kept_bytes = kept + 1, kept_bytes + size
                origins.add(origin)
                continue
            shutil.rmtree(entry, ignore_errors=True)
            gone.append(entry)
        finally:
            handle.close()
    return gone


# -- one session's folder ------------------------------------------------------------------------------------------
def _jsonable(value):
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    if isinstance(value, (np.ndarray, tuple)):
        return list(value)
    raise TypeError(f"cannot write {type(value).__name__} to a manifest")


class SessionStore:
    """One session's folder (see the module's docstring). `put` and `drop` make it the shelf of the session's
    History; `commit` writes a save. Made with `new` (the folder and its lock come with the first write) or `adopt`
    (a stopped session's folder, locked at once, read by readback.py).

    `writable`: a store taken over from a stopped session (or made for one being brought back) writes nothing until
    the rebuilt session is whole (`allow_writes`): a start that fails half way leaves the folder as it found it."""

    def __init__(self, folder: Path, origin: str, handle=None, writable: bool = True) -> None:
        self.folder = Path(folder)
        self.origin = origin
        self.writable = writable
        self._handle = handle  # the lock file, open and locked
        self._lock = threading.Lock()
        self._files: dict[int, str] = {}  # step key -> its file's name
        self._presets: dict[int, tuple[Preset, str]] = {}  # id(preset) -> (the preset, its file's name)
        self._current: int | None = None  # the key of the current step the manifest on disk names
        self._counter = 0

    @classmethod
    def new(cls, origin: str, writable: bool = True) -> SessionStore:
        """A store for a new session (nothing on disk until its first write)."""
        name = f"{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        return cls(autosave_dir() / name, origin, writable=writable)

    @classmethod
    def adopt(cls, folder: Path) -> SessionStore | None:
        """The store of a stopped session's folder, locked for this process and not writable yet; None when it is
        live (another process holds it). OSError when its lock cannot be opened (or is not a plain file)."""
        handle = lock(Path(folder) / LOCK)
        if handle is None:
            return None
        origin = (peek(folder) or {}).get("origin", "python")
        store = cls(folder, origin if isinstance(origin, str) else "python", handle, writable=False)
        store._count_files()
        return store

    def take_over(self, files: dict[int, str], presets: dict[str, Preset], current: int) -> None:
        """The files of the steps and presets read back from this folder (step key -> name, name -> preset), and the
        key of its current step: the next saves name them again instead of writing them anew."""
        with self._lock:
            self._files.update(files)
            self._presets.update({id(preset): (preset, name) for name, preset in presets.items()})
            self._current = current

    def allow_writes(self) -> None:
        """The session is whole: saves may go to the folder from now on."""
        self.writable = True

    def _check_writable(self) -> None:
        if not self.writable:
            raise OSError(errno.EPERM, "nothing is written here until the session brought back is whole",
                          str(self.folder))

    def open(self, notices: list[str] | None = None) -> None:
        """Make the folder and take its lock (once); OSError when the disk refuses."""
        if self._handle is not None:
            return
        sessions_folder(notices)
        self.folder.mkdir(exist_ok=True)
        handle = lock(self.folder / LOCK)
        if handle is None:  # pragma: no cover - a fresh, unique name
            raise OSError(f"{self.folder / LOCK} is locked by another process")
        self._handle = handle
        self._count_files()

    def release(self) -> None:
        """Let go of the folder (it stays on disk for the next start)."""
        with self._lock:
            if self._handle is not None:
                self._handle.close()
                self._handle = None

    def set_aside(self) -> Path:
        """Rename this (unreadable) folder aside and let go of it; the new path."""
        aside = set_aside(self.folder)
        self.release()
        return aside

    def _count_files(self) -> None:
        """Number the next files past those in the folder (a stray one numbered near the names' limit, which no
        session reaches, is not counted: the names written stay names the reader takes)."""
        for entry in os.listdir(self.folder):
            m = STEP_FILE.fullmatch(entry) or PRESET_FILE.fullmatch(entry)
            if m and int(m.group(1)) < COUNTED:
                self._counter = max(self._counter, int(m.group(1)))

    def _next(self) -> int:
        self._counter += 1
        return self._counter

    # -- the history's shelf ------------------------------------------------------------------------------------
    def put(self, step: Step) -> Path:
        """Write `step`'s arrays (once) and return its file."""
        with self._lock:
            return self.folder / self._put(step)

    def drop(self, step: Step) -> None:
        """The history forgot `step`: its file goes once a manifest without it is on disk."""
        with self._lock:
            self._files.pop(step.key, None)

    def close(self) -> None:
        """The history closed: the files stay (the autosave lets go of the folder)."""

    def _put(self, step: Step) -> str:
        name = self._files.get(step.key)
        if name is not None:
            return name
        self._check_writable()
        self.open()
        weights = step.loaded().weights
        controls = np.asarray(step.controls, np.float32)
        radii = np.zeros(len(controls), np.float32) if step.radii is None else np.asarray(step.radii, np.float32)
        name = f"s{self._next()}.npz"
        write_atomic(self.folder / name, lambda f: np.savez(f, weights=np.asarray(weights, np.float32),
                                                             controls=controls, radii=radii))
        self._files[step.key] = name
        return name

    def _preset(self, preset: Preset) -> str:
        known = self._presets.get(id(preset))
        if known is not None and known[0] is preset:
            return known[1]
        name = f"p{self._next()}.npz"
        session_file.save_session(self.folder / name, session_file.session_state(preset))  # flushed, renamed
        self._presets[id(preset)] = (preset, name)
        return name

    # -- saves --------------------------------------------------------------------------------------------------
    def commit(self, saving: Saving) -> None:
        """Write a save: the files of its steps and presets not yet on disk, then the manifest that names them, then
        delete the files no manifest names any more. OSError (a full disk, a folder that cannot be written) or
        ValueError leaves the previous manifest and its files as they were."""
        with self._lock:
            self._check_writable()
            self.open()
            presets: dict[str, dict] = {}

            def record(step: Step) -> dict:
                preset = step.preset
                name = self._preset(preset)
                presets[name] = {"name": preset.name, "title": preset.title, "description": preset.description,
                                 "grow": bool(preset.grow), "radius": float(preset.radius), "meta": preset.meta}
                group = step.symmetry
                return {"file": self._put(step), "preset": name, "iteration": int(step.iteration),
                        "parameters": step.parameters,
                        "symmetry": None if group is None else dataclasses.asdict(group),
                        "strokes": None if step.strokes is None else [int(n) for n in step.strokes]}

            manifest = {"format": FORMAT, "origin": self.origin, "saved": time.time(), "gesture": bool(saving.gesture),
                        "current": record(saving.current), "undo": [record(s) for s in saving.undo],
                        "redo": [record(s) for s in saving.redo]}
            manifest["presets"] = presets
            text = json.dumps(manifest, default=_jsonable, allow_nan=False).encode("utf-8")
            sync_folder(self.folder)  # the new files' names, before the manifest that names them
            write_atomic(self.folder / MANIFEST, lambda f: f.write(text))
            sync_folder(self.folder)
            self._presets = {k: v for k, v in self._presets.items() if v[1] in presets}
            if self._current not in (None, saving.current.key):  # the previous current step: no history has it
                self._files.pop(self._current, None)
            self._current = saving.current.key
            self._collect(manifest)

    def _collect(self, manifest: dict) -> None:
        """Delete the files that neither `manifest` nor the history names (and temporaries a kill left behind)."""
        named = {LOCK, MANIFEST, *manifest["presets"], *self._files.values()}
        for r in [manifest["current"], *manifest["undo"], *manifest["redo"]]:
            named.add(r["file"])
        for entry in os.listdir(self.folder):
            if entry not in named and (STEP_FILE.fullmatch(entry) or PRESET_FILE.fullmatch(entry)
                                       or entry.startswith(".tmp-")):
                try:
                    os.unlink(self.folder / entry)
                except OSError:
                    pass
