"""Bringing back a stopped session (`recover`): the newest folder a session left (store.py), read and checked whole
before anything is built (readback.py); else an earlier version's autosave.

What a start does with a stopped session's folder, so that no start can lose work:

- read whole: the session comes back in its folder and goes on saving there; nothing is written into it until the
  person's next step, so a start that fails, or a process that ends before then, leaves it as it was;
- anything in it unreadable: the folder is set aside whole (renamed `<folder>.unreadable-<time>`: nothing in it is
  changed or deleted) and what could be read comes back in a new folder, written at once (`readback`: a damaged undo
  or redo step is left out with those beyond it; a damaged current step gives way to the newest readable undo step);
  when nothing could be read, the next folder is tried;
- nothing is saved into any folder until the session rebuilt from it is whole (SessionStore.writable): a failure
  while rebuilding sets the folder aside whole, the half-built session is dropped unsaved and the start goes on.

Each folder that was not read whole gets one notice: what was wrong, in which file, what came back and where the
folder is kept (the views show the notices; `Session.recover` and `somwidget serve` log or print each as one line).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from pathlib import Path

from .files import preset_of, read
from .readback import Reading, read_folder
from .state import max_vertices_for
from .store import LOCK, SessionStore, autosave_dir, lock, peek, set_aside, stopped

log = logging.getLogger(__name__)

#: An earlier version's autosave: `<id>.npz` (a session file) beside `<id>.lock` in the autosave folder.
LEGACY_SUFFIX = ".npz"
#: How long a start waits for what it brought back from a damaged folder to be on disk in its new one.
REWRITE_SECONDS = 30.0


def recovered_message(saved_at: float | None, preset: str, gesture: bool, undo_steps: int, back: int = 0) -> str:
    """What a view says about a session brought back: when it was saved, and which state it is (`back`: that many
    steps before the last one, which could not be read)."""
    of = "" if saved_at is None else f" of {time.strftime('%Y-%m-%d %H:%M', time.localtime(saved_at))}"
    steps = f"; Undo reaches the {undo_steps} step{'s' if undo_steps != 1 else ''} before it" if undo_steps else ""
    if back:
        last = "its last step" if back == 1 else f"its last {back} steps"
        return (f"Brought back your session{of} ({preset}) as it was {back} step{'s' if back != 1 else ''} before "
                f"its end, because {last} could not be read{steps}.")
    if gesture:
        return (f"Brought back your session{of} ({preset}) as it was during a drag that was not released: "
                "the drag is kept as a step of its own, which Undo removes.")
    return f"Brought back your session{of} ({preset}) as its last completed step{steps}."


def recover(session_class, origin: str | None = None, **options):
    """(the newest stopped session of `origin` (None: any) brought back, or None; notices): the session has its undo
    history and a folder it goes on saving in, and nothing trains until the next intent; `options` go to
    `session_class` (device, start...). See the module's docstring for what happens to a folder that cannot be read
    whole."""
    notices: list[str] = []
    start = options.pop("start", True)
    max_vertices = options.get("max_vertices") or max_vertices_for(options.get("device"))
    session = None
    for folder in stopped(notices):
        manifest = peek(folder)
        if manifest is not None and origin is not None and manifest.get("origin") != origin:
            continue
        session = _from_folder(session_class, folder, origin, max_vertices, options, notices)
        if session is not None:
            break
    if session is None:
        session = _recover_legacy(session_class, origin, notices, max_vertices, options)
    if session is not None:
        session.notices.extend(notices)
        if start:
            session.start()
    return session, notices


def _from_folder(session_class, folder: Path, origin: str | None, max_vertices: int, options: dict,
                 notices: list[str]):
    """The session of one stopped folder brought back (its notice added when it was not read whole), or None."""
    try:
        store = SessionStore.adopt(folder)
    except FileNotFoundError:
        return None  # gone meanwhile: another start set it aside
    except OSError as exc:
        lock_path = folder / LOCK
        why = "its lock is a link" if lock_path.is_symlink() else "its lock is not a file" \
            if lock_path.exists() and not lock_path.is_file() else exc.strerror or str(exc)
        notices.append(f"Your saved session in {folder} cannot be opened ({why}); it is left as it is.")
        return None
    if store is None:
        return None  # live: another process has it
    reading = read_folder(folder, max_vertices)
    if origin is not None and reading.origin is not None and reading.origin != origin:
        store.release()
        return None
    aside = None
    if not reading.whole:
        aside = _set_aside(store, notices, reading)
        if aside is None:
            return None
        if reading.current is None:
            notices.append(f"Your saved session in {folder} could not be brought back: {_problems(reading)}. "
                           f"Nothing in it was changed; it is kept at {aside}.")
            return None
        _moved(reading, aside)
        store = SessionStore.new(reading.origin or origin or "python", writable=False)
    session = None
    try:  # a folder read whole has its current step (a step not read is a problem); should one lack it, it is set aside
        current = reading.current
        if current is None:
            raise ValueError("its current step is missing")
        session = session_class(current.preset, start=False, origin=reading.origin or origin or "python",
                                _store=store, **options)
        session.timeline.bring_back(current, reading.undo, reading.redo)
        if reading.whole:
            store.take_over(reading.files, reading.presets, current.key)
        preset = current.preset
        session.recovered = {"path": str(aside or folder), "saved": reading.saved, "preset": preset.name,
                             "gesture": reading.gesture, "undo": len(reading.undo), "redo": len(reading.redo),
                             "back": reading.back,
                             "message": recovered_message(reading.saved, preset.title or preset.name, reading.gesture,
                                                          len(reading.undo), reading.back)}
        session.autosave.arm(on_disk=reading.whole)
    except Exception as exc:  # the start goes on: nothing of the half-built session is written anywhere
        log.debug("recovery: rebuilding the session of %s failed", folder, exc_info=True)
        if session is not None:
            session.close(timeout=2.0)
        why = _plain(exc)
        if aside is None:
            try:
                aside = store.set_aside()
            except OSError as err:
                store.release()
                notices.append(f"Your saved session in {folder} could not be brought back ({why}) nor set aside "
                               f"({err.strerror or err}); it is left as it is.")
                return None
        notices.append(f"Your saved session in {folder} could not be brought back: {why}. Nothing in it was "
                       f"changed; it is kept at {aside}.")
        return None
    if not reading.whole:
        session.autosave.flush(REWRITE_SECONDS)  # a failure shows as the autosave's error, tried again each second
        notices.append(f"Part of your saved session could not be read: {_problems(reading)}. {_kept(reading)} The "
                       f"folder as it was is kept at {aside}, unchanged; the session now saves in {store.folder}.")
    return session


def _set_aside(store: SessionStore, notices: list[str], reading: Reading) -> Path | None:
    """Rename the folder aside whole (and let go of it); None, with a notice, when that fails."""
    try:
        return store.set_aside()
    except OSError as exc:
        store.release()
        notices.append(f"Your saved session in {reading.folder} could not be read ({_problems(reading)}) nor set "
                       f"aside ({exc.strerror or exc}); it is left as it is.")
        return None


def _moved(reading: Reading, aside: Path) -> None:
    """The steps whose weights stay on disk now read them from the folder's new name."""
    def moved(step):
        return dataclasses.replace(step, weights=aside / step.weights.name) if isinstance(step.weights, Path) else step

    reading.undo = [moved(s) for s in reading.undo]
    reading.redo = [moved(s) for s in reading.redo]


def _problems(reading: Reading) -> str:
    seen: list[str] = []
    for problem in reading.problems:
        if str(problem) not in seen:
            seen.append(str(problem))
    return "; ".join(seen)


def _kept(reading: Reading) -> str:
    """What came back of a folder not read whole, in words."""
    def n(count: int, what: str) -> str:
        return f"{count} {what} step{'s' if count != 1 else ''}"

    stacks = f"{n(len(reading.undo), 'undo')} and {n(len(reading.redo), 'redo')}"
    if reading.back:
        before = "the step before the last one" if reading.back == 1 else \
            f"the step {reading.back} steps before the last"
        came = f"Brought back instead: {before} (the newest that could be read), with {n(len(reading.undo), 'undo')}"
    else:
        came = f"Brought back: the last step, with {stacks}"
    left = reading.left_out
    return came + (f"; left out: {left} step{'s' if left != 1 else ''}." if left else "; nothing was left out.")


def _plain(exc: Exception, path: Path | None = None) -> str:
    """An error met while reading or rebuilding, in words: a check's message (a ValueError) without the file's name
    in front, anything else by its kind only."""
    if not isinstance(exc, ValueError):
        return f"the session could not be rebuilt ({type(exc).__name__})"
    message = str(exc)
    return message[len(str(path)) + 2:] if path is not None and message.startswith(f"{path}: ") else message


def legacy_stopped() -> list[Path]:
    """Autosaves written by somwidget before 2026-11-25 (one session file each, no undo history) of sessions that
    stopped (their lock free or gone), newest first."""
    folder = autosave_dir()
    if not folder.is_dir():
        return []
    found = []
    for path in folder.glob(f"*{LEGACY_SUFFIX}"):
        if path.is_symlink() or not path.is_file():
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
    file then renamed `<id>.npz.brought-back-<time>` so it is taken once and never deleted; or None. One that cannot
    be read, or brought back, is set aside."""
    for path in legacy_stopped():
        session = None
        try:
            state = read(path, max_vertices)
            preset = preset_of(state)[0]
            session = session_class(preset, start=False, origin=origin or "python",
                                    _store=SessionStore.new(origin or "python", writable=False), **options)
            session.files.restore(state)
        except Exception as exc:
            if session is not None:
                session.close(timeout=2.0)
            why = _plain(exc, path)
            try:
                notices.append(f"The earlier version's autosave {path} cannot be brought back ({why}); it is kept at "
                               f"{set_aside(path)}.")
            except OSError as err:
                notices.append(f"The earlier version's autosave {path} cannot be brought back ({why}) nor set aside "
                               f"({err.strerror or err}).")
            continue
        kept = path.with_name(f"{path.name}.brought-back-{time.strftime('%Y%m%d-%H%M%S')}")
        try:
            os.replace(path, kept)
            path.with_suffix(".lock").unlink(missing_ok=True)
        except OSError as exc:
            notices.append(f"The earlier version's autosave {path} was brought back but cannot be renamed: {exc}")
            kept = path
        saved = kept.stat().st_mtime if kept.exists() else time.time()
        when = time.strftime("%Y-%m-%d %H:%M", time.localtime(saved))
        message = (f"Brought back your session of {when} ({preset.title or preset.name}) from an earlier version's "
                   f"autosave, as it was saved; the file is kept at {kept}.")
        session.recovered = {"path": str(kept), "saved": saved, "preset": preset.name, "gesture": False, "undo": 0,
                             "redo": 0, "back": 0, "message": message}
        session.autosave.arm(on_disk=False)
        return session
    return None
