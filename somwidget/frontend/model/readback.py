"""Reading a session's folder back (store.py writes it): every value a restart uses is checked before anything is
built, with the checks `Session.load` applies to a session file (session_file.check_state: shapes, float32, finite
values with |x| <= 1e18, each setting within its declared range, s within 0..S, the controls within the engine's
limit), so that nothing read can fail later while the session is rebuilt.

`read_folder` never writes and never raises for what is on the disk: each thing it cannot read is a `Problem` that
names the file and says what is wrong in plain words (never a library's own), and it brings back the most it can:

- the manifest unreadable (missing, not a manifest, another format), or a current step with settings this somwidget
  does not know (a newer one wrote it): nothing;
- an undo or redo step unreadable (its entry in the manifest, its file, or the file of its mesh's start): the
  session without that step and those beyond it;
- the current step unreadable: the newest readable undo step in its place, with the undo steps before it (the redo
  steps, which went on from the step that cannot be read, are left out).

Only files inside the folder are read, by the names the store gives them (s<n>.npz, p<n>.npz, manifest.json): never
through a link, never a folder or a named pipe, never more bytes than such a file holds.
"""

from __future__ import annotations

import dataclasses
import io
import json
import logging
import math
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...backend import checks, schedule, session_file
from ...backend.presets import MAX_CONTROLS, Preset
from ...backend.symmetry import Symmetry
from .history import MAX_STEPS, Step
from .state import engine_symmetry, held_settings
from .store import FORMAT, MANIFEST, MAX_MANIFEST_BYTES, PRESET_FILE, STEP_FILE, Unreadable, check_plain, read_small

log = logging.getLogger(__name__)

#: A manifest's `saved` past this (the year 3000) is not a time this reads.
LAST_TIME = 32_503_680_000.0
#: Bytes a step file holds beyond its arrays' values (zip entries and .npy headers).
STEP_FILE_SLACK = 65536
_STEP_ARRAYS = ("controls.npy", "radii.npy", "weights.npy")
_CURRENT = "the current step"
_WHAT = {"weights": "weights (the clay's shape)", "controls": "controls", "radii": "radii (each control's reach)"}


@dataclass(frozen=True)
class Problem:
    """One thing that cannot be read: the file, the part of the session it holds, and what is wrong."""

    path: Path
    part: str
    reason: str

    def __str__(self) -> str:
        return f"{self.path} ({self.part}): {self.reason}"


@dataclass
class Reading:
    """What `read_folder` brought back from a folder, and what it could not read."""

    folder: Path
    origin: str | None = None  # None: the manifest cannot be read
    saved: float | None = None  # when it was written (time.time()); None when its time is not one
    gesture: bool = False  # the current step is a drag not yet released
    current: Step | None = None  # None: nothing can be brought back
    undo: list[Step] = field(default_factory=list)  # oldest first, as History keeps them
    redo: list[Step] = field(default_factory=list)
    back: int = 0  # `current` is this many steps before the saved current step (0: that step itself)
    left_out: int = 0  # steps the manifest names that are not brought back
    problems: list[Problem] = field(default_factory=list)
    files: dict[int, str] = field(default_factory=dict)  # step key -> its file's name
    presets: dict[str, Preset] = field(default_factory=dict)  # file name -> the preset it holds

    @property
    def whole(self) -> bool:
        """Everything in the folder was read: the session comes back in it as it was."""
        return not self.problems


class _Damaged(Exception):
    """One part cannot be read (`problem` says which and why)."""

    def __init__(self, path: Path, part: str, reason: str) -> None:
        reason = reason if len(reason) <= 240 else reason[:237] + "..."
        super().__init__(reason)
        self.problem = Problem(path, part, reason)


class _Refused(_Damaged):
    """The whole folder cannot be read (its manifest; a newer somwidget's settings)."""


class NewerSettings(ValueError):
    """A step's settings name one this somwidget does not declare: a newer somwidget wrote them."""


def read_settings(stored: dict, n_dims: int) -> dict:
    """A step's settings as a manifest keeps them, checked against their declaration (each within its declared
    range): a setting the step lacks (declared since it was written) takes its default; one no declaration names
    is refused (NewerSettings); a bad value is a ValueError naming the setting."""
    declared = {s.name: s for s in held_settings()}
    unknown = sorted(set(stored) - set(declared))
    if unknown:
        raise NewerSettings(f"it has settings this somwidget does not know ({', '.join(map(str, unknown[:5]))}): "
                            "a newer somwidget wrote it")
    values = {}
    for name, s in declared.items():
        value = stored.get(name)
        try:
            if name not in stored:
                values[name] = [s.default] * n_dims if s.per else s.default
            elif s.per:
                if not isinstance(value, list) or len(value) != n_dims:
                    raise ValueError(f"{s.label}: expected a list of {n_dims} values (one per feature dimension), "
                                     f"got {_short(value)}")
                values[name] = [float(s.check(x, f"{s.label} {d}")) for d, x in enumerate(value)]
            else:
                values[name] = s.check(value, s.label)
        except (OverflowError, TypeError):  # a number past any float's range, a value of no kind a setting has
            raise ValueError(f"{s.label}: {_short(value)} is not a value it takes") from None
    return values


def read_folder(folder: Path, max_vertices: int) -> Reading:
    """Read a stopped session's folder (locked by the caller); see the module's docstring."""
    reader = _Reader(Path(folder), max_vertices)
    try:
        reader.read()
    except _Damaged as exc:  # the manifest: nothing can be brought back
        reader.nothing(exc.problem)
    except Exception as exc:  # a fault of this reader: the start must go on all the same
        log.exception("readback: reading %s failed", folder)
        reader.nothing(Problem(Path(folder) / MANIFEST, "the list of steps",
                               f"could not be read ({type(exc).__name__})"))
    return reader.reading


class _Reader:
    def __init__(self, folder: Path, max_vertices: int) -> None:
        self.folder = folder
        self.manifest_path = folder / MANIFEST
        self.max_vertices = max_vertices
        self.reading = Reading(folder)
        self._preset_records: dict = {}
        self._presets: dict[str, Preset | _Damaged] = {}

    def nothing(self, problem: Problem) -> None:
        r = self.reading
        r.problems.append(problem)
        r.current, r.undo, r.redo, r.back = None, [], [], 0

    def problem(self, exc: _Damaged) -> None:
        if isinstance(exc, _Refused):
            raise exc
        self.reading.problems.append(exc.problem)

    # -- the manifest -------------------------------------------------------------------------------------------
    def _manifest(self) -> dict:
        path, part = self.manifest_path, "the list of steps"
        try:
            text = read_small(path, MAX_MANIFEST_BYTES).decode("utf-8")
        except Unreadable as exc:
            raise _Refused(path, part, str(exc)) from None
        except UnicodeDecodeError:
            raise _Refused(path, part, "not text: cut short or damaged") from None
        try:
            manifest = json.loads(text)
        except json.JSONDecodeError as exc:
            raise _Refused(path, part, f"cut short or damaged (it cannot be read past character {exc.pos})") from None
        except RecursionError:
            raise _Refused(path, part, "not a somwidget session's list of steps (nested too deeply)") from None
        if not isinstance(manifest, dict):
            raise _Refused(path, part, "not a somwidget session's list of steps")
        fmt = manifest.get("format")
        if type(fmt) is int and fmt > FORMAT:
            raise _Refused(path, part, f"written by a newer somwidget (format {fmt}; this one reads format {FORMAT})")
        if type(fmt) is not int or fmt != FORMAT:
            raise _Refused(path, part, f"not a somwidget session's list of steps (its format is {_short(fmt)}, "
                                       f"expected {FORMAT})")
        origin = manifest.get("origin", "python")
        if not isinstance(origin, str) or not origin or len(origin) > 100:
            raise _Refused(path, part, f"the program that made it is not named (origin {_short(origin)})")
        if not isinstance(manifest.get("presets"), dict):
            raise _Refused(path, part, "it lists no starts of meshes (its 'presets' are missing or damaged)")
        return manifest

    def _time(self, value) -> float | None:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
            and 0 <= value <= LAST_TIME
        if ok:
            return float(value)
        self.reading.problems.append(Problem(self.manifest_path, "when it was saved",
                                             f"{_short(value)} is not a time"))
        return None

    def read(self) -> None:
        r, manifest = self.reading, self._manifest()
        r.origin = manifest.get("origin", "python")
        self._preset_records = manifest["presets"]
        r.saved = self._time(manifest.get("saved"))
        gesture = manifest.get("gesture", False)
        if not isinstance(gesture, bool):
            r.problems.append(Problem(self.manifest_path, "whether a drag was held",
                                      f"{_short(gesture)} is not true or false (taken as false)"))
            gesture = False
        undo, redo = self._records(manifest, "undo"), self._records(manifest, "redo")
        try:
            r.current = self._step(manifest.get("current"), _CURRENT, load=True)
            r.gesture = gesture
        except _Damaged as exc:
            self.problem(exc)
        if r.current is not None:
            r.undo = self._stack(undo, "undo")
            r.redo = self._stack(redo, "redo")
            return
        for j in reversed(range(len(undo))):  # the newest readable undo step in its place
            try:
                r.current = self._step(undo[j], f"undo step {len(undo) - j} of {len(undo)}", load=True)
            except _Damaged as exc:
                self.problem(exc)
                continue
            r.back = len(undo) - j
            r.left_out += r.back  # the current step, and the undo steps after this one
            r.undo = self._stack(undo[:j], "undo", first=r.back + 1, total=len(undo))
            break
        else:
            r.left_out += 1 + len(undo)
        r.left_out += len(redo)  # they went on from the step that cannot be read

    def _records(self, manifest: dict, kind: str) -> list:
        records = manifest.get(kind, [])
        if not isinstance(records, list):
            self.reading.problems.append(Problem(self.manifest_path, f"the {kind} steps",
                                                 f"not a list of steps ({_short(records)}): none are brought back"))
            return []
        return records[-MAX_STEPS:]  # a history keeps no more (older ones would be forgotten at once)

    def _stack(self, records: list, kind: str, first: int = 1, total: int | None = None) -> list[Step]:
        """The steps of an undo or redo stack (oldest first), read from the one reached first; a step that cannot be
        read is left out with those beyond it."""
        total = len(records) if total is None else total
        kept: list[Step] = []
        for i, record in enumerate(reversed(records)):
            try:
                kept.append(self._step(record, f"{kind} step {first + i} of {total}", load=False))
            except _Damaged as exc:
                self.problem(exc)
                self.reading.left_out += len(records) - i
                break
        return kept[::-1]

    # -- one step -----------------------------------------------------------------------------------------------
    def _step(self, record, part: str, load: bool) -> Step:
        """A step the manifest records, checked whole; its weights in memory with `load`, else its file's path."""
        m = self.manifest_path
        if not isinstance(record, dict):
            raise _Damaged(m, part, f"its entry is not a step ({_short(record)})")
        name = record.get("file")
        if not isinstance(name, str) or not STEP_FILE.fullmatch(name):
            raise _Damaged(m, part, f"its entry names the file {_short(name)}, not one of a session's step files")
        path = self.folder / name
        preset = self._preset(record.get("preset"), part)
        n_nodes, n_dims = preset.weights.shape
        parameters = record.get("parameters")
        if not isinstance(parameters, dict):
            raise _Damaged(m, part, f"its settings are missing ({_short(parameters)})")
        try:
            params = read_settings(parameters, n_dims)
        except NewerSettings as exc:  # the current step's: the session is a newer somwidget's (an older step's: damage)
            raise (_Refused if part == _CURRENT else _Damaged)(m, part, str(exc)) from None
        except ValueError as exc:
            raise _Damaged(m, part, f"its setting {exc}") from None
        group = self._symmetry(record.get("symmetry"), n_dims, part)
        strokes = record.get("strokes")
        if strokes is not None and not (isinstance(strokes, list) and all(type(n) is int for n in strokes)):
            raise _Damaged(m, part, f"its strokes are not a list of whole numbers ({_short(strokes)})")
        iteration = record.get("iteration")
        if type(iteration) is not int:
            raise _Damaged(m, part, f"its s (the cycle reached) is not a whole number ({_short(iteration)})")
        arrays = self._arrays(path, part, n_nodes, n_dims)
        radial, mirror = engine_symmetry(group)
        state = {"preset": preset.name, "display": preset.display, "topology": preset.topology,
                 "layout": preset.layout, "start_weights": preset.weights, **arrays, "iteration": iteration,
                 "strokes": None if strokes is None else tuple(strokes), "smooth_dims": preset.smooth_dims,
                 "metric_weights": params["metric_weights"], "mirror": mirror,
                 "symmetry": radial.spec if radial is not None else "none", "smoothing_rule": preset.smoothing_rule,
                 **{s.name: params.get(s.name, s.default) for s in session_file.kept_settings()}}
        try:
            clean = session_file.check_state(state, MANIFEST)  # what Session.load checks
        except ValueError as exc:
            raise _Damaged(m, part, _plain_key(str(exc), MANIFEST)) from None
        except (OverflowError, TypeError):
            raise _Damaged(m, part, "its values do not fit together (a number too large, or of another kind)") \
                from None
        step = Step(preset=preset, controls=clean["controls"], parameters=params,
                    weights=clean["weights"] if load else path, iteration=clean["iteration"], radii=clean["radii"],
                    symmetry=group, strokes=None if strokes is None else clean["strokes"])
        self.reading.files[step.key] = name
        return step

    def _symmetry(self, value, n_dims: int, part: str) -> Symmetry | None:
        if value is None:
            return None
        known = {f.name for f in dataclasses.fields(Symmetry)}
        ok = isinstance(value, dict) and set(value) <= known and isinstance(value.get("kind"), str) \
            and type(value.get("n", 2)) is int and type(value.get("mirrored", False)) is bool and all(
                isinstance(v, list) and all(type(d) is int and 0 <= d < n_dims for d in v)
                for k, v in value.items() if k in ("position", "direction"))
        try:
            if ok:
                fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in value.items()}
                return Symmetry(**fields)
        except (ValueError, TypeError):
            pass
        raise _Damaged(self.manifest_path, part, f"its symmetry group is not one ({_short(value)})")

    def _arrays(self, path: Path, part: str, n_nodes: int, n_dims: int) -> dict:
        """A step file's weights, controls and radii, each of the shape, type and bounds a step has (checked from its
        header before its values are read)."""
        limit = 4 * n_nodes * n_dims + 4 * MAX_CONTROLS * (n_dims + 1) + STEP_FILE_SLACK
        try:
            data = read_small(path, limit)
        except Unreadable as exc:
            raise _Damaged(path, part, str(exc)) from None
        not_one = "not a saved session file (it is not the archive a step is kept in)"
        try:
            archive = zipfile.ZipFile(io.BytesIO(data))
            names = sorted(archive.namelist())
        except Exception:  # zipfile's own words for what is not a zip archive
            raise _Damaged(path, part, not_one) from None
        if tuple(names) != _STEP_ARRAYS:
            raise _Damaged(path, part, f"not a saved session file (it holds {_short(names)} instead of a step's "
                                       "weights, controls and radii)")
        out: dict[str, np.ndarray] = {}
        for member in _STEP_ARRAYS:
            key = member[:-4]
            try:
                with archive.open(member) as f:
                    shape, dtype = session_file.npy_header(f)
            except Exception:
                raise _Damaged(path, part, f"not a saved session file (its {key} are not an array)") from None
            k = len(out.get("controls", ()))
            want = {"weights": (n_nodes, n_dims), "controls": shape[:1] + (n_dims,), "radii": (k,)}[key]
            if shape != want or (key == "controls" and not 1 <= shape[0] <= MAX_CONTROLS):
                expected = f"(k, {n_dims}) with k from 1 to {MAX_CONTROLS}" if key == "controls" else want
                raise _Damaged(path, part, f"its {_WHAT[key]} have the shape {shape}, expected {expected}")
            if dtype.kind != "f" or dtype.itemsize != 4:
                raise _Damaged(path, part, f"its {_WHAT[key]} are {dtype} numbers; a step keeps float32 ones")
            try:
                with archive.open(member) as f:
                    values = np.lib.format.read_array(f, allow_pickle=False).astype(np.float32)
            except Exception:  # a CRC, a stream or values cut short: zipfile's and numpy's own words
                raise _Damaged(path, part, f"cut short or damaged (its {key} cannot be read)") from None
            out[key] = _bounded(values, key, path, part)
        return out

    # -- the start of a mesh ------------------------------------------------------------------------------------
    def _preset(self, name, part: str) -> Preset:
        """The preset (start of a mesh) a step names, read and checked once; a step whose preset cannot be read
        cannot be read either."""
        m = self.manifest_path
        if not isinstance(name, str) or name not in self._preset_records:
            raise _Damaged(m, part, f"its mesh's start {_short(name)} is not one the list of steps names")
        if name not in self._presets:
            try:
                preset = self._read_preset(name)
                self._presets[name] = self.reading.presets[name] = preset
            except _Damaged as exc:
                self._presets[name] = exc
        found = self._presets[name]
        if isinstance(found, _Damaged):
            problem = found.problem
            raise _Damaged(problem.path, f"the start of the mesh of {part}", problem.reason)
        return found

    def _read_preset(self, name: str) -> Preset:
        m, part = self.manifest_path, "a mesh's start"
        record = self._preset_records[name]
        if not PRESET_FILE.fullmatch(name):
            raise _Damaged(m, part, f"it names the file {_short(name)}, not one of a session's files")
        texts = ("name", "title", "description")
        ok = isinstance(record, dict) and all(isinstance(record.get(k), str) and len(record[k]) <= 10_000
                                              for k in texts) \
            and isinstance(record.get("grow"), bool) and isinstance(record.get("meta"), dict) \
            and _transform_ok(record["meta"].get("transform"))
        radius = record.get("radius") if isinstance(record, dict) else None
        if not ok or isinstance(radius, bool) or not isinstance(radius, (int, float)) \
                or not 0 <= radius <= schedule.BY_NAME["radius"].high:
            raise _Damaged(m, part, f"its entry for {name} is damaged ({_short(record)})")
        try:  # what is read is written again with the next save: it must be plain JSON (no NaN, no Infinity)
            json.dumps(record["meta"], allow_nan=False)
        except (ValueError, TypeError, RecursionError):
            raise _Damaged(m, part, f"its entry for {name} holds a value that is not a number ({_short(record)})") \
                from None
        path = self.folder / name
        try:
            check_plain(path, 1 << 40)  # the session file's own checks bound its size
            state = session_file.load_session(path, max_vertices=self.max_vertices,
                                              max_iterations=schedule.MAX_ITERATIONS)
            preset = session_file.preset_from_session(state)
            preset = dataclasses.replace(preset, **{k: record[k] for k in texts}, grow=record["grow"],
                                         radius=float(radius), meta=dict(record["meta"]))
        except Unreadable as exc:
            raise _Damaged(path, part, str(exc)) from None
        except ValueError as exc:
            raise _Damaged(path, part, _plain_key(str(exc), str(path))) from None
        except (OverflowError, TypeError, IndexError, KeyError):  # values that do not fit together
            raise _Damaged(path, part, "not a readable somwidget session: its parts do not fit together") from None
        if len(preset.controls) < 1:
            raise _Damaged(path, part, "it holds no controls")
        return preset


def _bounded(values: np.ndarray, key: str, path: Path, part: str) -> np.ndarray:
    """`values` when finite and within the engine's bounds (checks.MAX_MAGNITUDE; a radius within its declared
    range), else _Damaged saying which value is not."""
    what = _WHAT[key]
    if not np.isfinite(values).all():
        raise _Damaged(path, part, f"its {what} hold a value that is not a number (nan or infinite)")
    largest = float(np.abs(values).max(initial=0.0))
    if largest > checks.MAX_MAGNITUDE:
        raise _Damaged(path, part, f"its {what} hold a value of {largest:.3g}, beyond the {checks.MAX_MAGNITUDE:g} "
                                   "the engine takes")
    high = schedule.BY_NAME["radius"].high
    if key == "radii" and ((values < 0).any() or (values > high).any()):
        raise _Damaged(path, part, f"its {what} must lie in [0, {high:g}], got {float(values.min()):.3g} to "
                                   f"{float(values.max()):.3g}")
    return values


def _transform_ok(transform) -> bool:
    """A loaded mesh's transform (io.load_mesh: {"centre": 3 numbers, "scale": a number > 0}), or none."""
    if transform is None:
        return True
    if not isinstance(transform, dict) or set(transform) != {"centre", "scale"}:
        return False
    centre, scale = transform["centre"], transform["scale"]
    numbers = isinstance(centre, list) and len(centre) == 3 and all(
        type(c) in (int, float) and math.isfinite(c) for c in centre)
    return numbers and type(scale) in (int, float) and math.isfinite(scale) and scale > 0


def _plain_key(message: str, label: str) -> str:
    """A check's message without the file's name in front, and "key 'x'" said as "its x"."""
    if message.startswith(label + ": "):
        message = message[len(label) + 2:]
    return re.sub(r"^key '([^']+)'", r"its \1", message)


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."
