"""Session files: a modelling session saved as a versioned .npz (no pickle) and read back, and the files written whole
(`write_atomic`). The web app's Save session, `Session.save` and the autosave's preset files write them.

A file holds the start mesh (topology, layout, start weights), the current weights and s, the controls (radii,
strokes, symmetry) and one member per setting that files keep (schedule.SETTINGS: `saved` and of one value). A
member an older file lacks (a setting declared since) reads as its declared default; a member no setting and no
part of the format names is refused unread.

Every failure a person can cause (a missing or broken file, a bad session) is a ValueError whose message starts with
the file's path and says what is wrong.
"""

from __future__ import annotations

import math
import os
import uuid
from pathlib import Path
from typing import Any

import numpy as np

from . import checks, schedule
from .io import MAX_VERTICES
from .presets import DISPLAYS, MAX_CONTROLS, FeatureLayout, Preset
from .schedule import SMOOTHING_RULES
from .symmetry import Symmetry
from .topology import Topology

#: The session file format this module writes; `load_session` reads this version and older ones.
SESSION_FORMAT_VERSION = 1
#: Keys a session state must have.
SESSION_REQUIRED = ("weights", "start_weights", "controls", "topology", "layout")
#: Keys a session state may have besides the settings, with the value used when it is absent.
SESSION_DEFAULTS = {
    "preset": "", "display": "surface", "smooth_dims": None, "metric_weights": None, "mirror": (), "iteration": 0,
    # the shaping rules (files before them: point controls, no radial group, the paper's smoothing)
    "radii": None, "symmetry": "none", "smoothing_rule": "laplacian", "strokes": None,
}
#: The members of the format itself (np.savez names each key.npy), besides one per kept setting.
FORMAT_MEMBERS = frozenset({
    "format_version", "preset", "display", "weights", "start_weights", "controls", "n_vertices", "edges",
    "iteration", "smooth_dims", "smooth_dims_default", "metric_weights", "metric_weights_default", "mirror", "radii",
    "symmetry", "smoothing_rule", "strokes", "layout_names", "layout_position", "layout_colour",
    "layout_colour_space", "layout_direction", "layout_length", "topology_kind", "face_indices", "face_sizes"})
#: How a file keeps a setting of each kind: a scalar of this numpy type.
_SCALAR = {"int": np.int64, "float": np.float64, "bool": np.bool_, "text": np.str_}
_KIND_CODE = {"int": "i", "float": "f", "bool": "b", "text": "s"}


def kept_settings() -> tuple[schedule.Setting, ...]:
    """The settings a file keeps as members of their names: those of one value that do not follow from the rest."""
    return tuple(s for s in schedule.SETTINGS if s.saved and not s.per)


def settings_defaults() -> dict:
    """Each kept setting's value in a state that lacks it: its declared default."""
    return {s.name: s.default for s in kept_settings()}


def session_members() -> frozenset[str]:
    """The members a session archive may hold: any other is refused unread."""
    return FORMAT_MEMBERS | {s.name for s in kept_settings()}


def save_session(path, state: dict) -> None:
    """Write a modelling session to `path` as a compressed .npz (no pickle), whatever the file's extension.

    state keys (load_session returns the same, plus "format_version" and "n_vertices"):
      weights (N, n), start_weights (N, n), controls (k, n): float arrays; topology: a Topology (its faces are kept
      when it has them, else its edges); layout: a FeatureLayout; and optionally preset (str), display (str),
      each kept setting (`kept_settings`: the schedule's, as the engine keeps them), iteration (an int),
      smooth_dims (None or dims),
      metric_weights (None or (n,) floats), mirror (dims), radii (None or (k,) floats >= 0), symmetry (a radial
      group's spec, Symmetry.spec, or "none"), smoothing_rule ("laplacian" or "taubin"). `session_state()` builds
      one from a Preset and a Som.
      n_vertices and format_version may be present (as in a loaded state) and are checked / ignored.
    """
    label = str(path)
    defaults = {**SESSION_DEFAULTS, **settings_defaults()}
    unknown = set(state) - set(SESSION_REQUIRED) - set(defaults) - {"n_vertices", "format_version"}
    if unknown:
        raise ValueError(f"{label}: unknown session keys {sorted(unknown)}; known: "
                         f"{sorted([*SESSION_REQUIRED, *defaults])}")
    full = {**defaults, **{k: v for k, v in state.items() if k != "format_version"}}
    for key in SESSION_REQUIRED:
        if key not in full:
            raise ValueError(f"{label}: session state lacks the key {key!r}")
    clean = check_state(full, label)
    topo, layout = clean["topology"], clean["layout"]
    # arrays and numpy scalars; Any: numpy types savez_compressed(**kwds) beside its keyword allow_pickle: bool
    arrays: dict[str, Any] = {
        "format_version": np.int64(SESSION_FORMAT_VERSION),
        "preset": np.str_(clean["preset"]),
        "display": np.str_(clean["display"]),
        "weights": clean["weights"], "start_weights": clean["start_weights"], "controls": clean["controls"],
        "n_vertices": np.int64(topo.n_vertices),
        "edges": np.asarray(topo.edges, np.int64).reshape(-1, 2),
        **{s.name: _SCALAR[s.kind](clean[s.name]) for s in kept_settings()},
        "iteration": np.int64(clean["iteration"]),
        "smooth_dims": np.asarray(clean["smooth_dims"] or (), np.int64),
        "smooth_dims_default": np.bool_(clean["smooth_dims"] is None),
        "metric_weights": (np.zeros(0, np.float32) if clean["metric_weights"] is None else clean["metric_weights"]),
        "metric_weights_default": np.bool_(clean["metric_weights"] is None),
        "mirror": np.asarray(clean["mirror"], np.int64),
        "radii": np.asarray(clean["radii"], np.float64),
        "strokes": np.asarray(clean["strokes"], np.int64),
        "symmetry": np.str_(clean["symmetry"]),
        "smoothing_rule": np.str_(clean["smoothing_rule"]),
        "layout_names": np.asarray(layout.names, dtype=np.str_),
        "layout_position": np.asarray(layout.position, np.int64),
        "layout_colour": np.asarray(layout.colour, np.int64),
        "layout_colour_space": np.str_(layout.colour_space),
        "layout_direction": np.asarray(layout.direction, np.int64),
        "layout_length": np.int64(-1 if layout.length is None else layout.length),
    }
    if topo.faces is not None:
        face_list = [np.asarray(f, np.int64).ravel() for f in topo.faces]
        arrays["topology_kind"] = np.str_("faces")
        arrays["face_indices"] = np.concatenate(face_list) if face_list else np.zeros(0, np.int64)
        arrays["face_sizes"] = np.asarray([len(f) for f in face_list], np.int64)
    else:
        arrays["topology_kind"] = np.str_("edges")
    write_atomic(Path(path), lambda f: np.savez_compressed(f, **arrays))


def write_atomic(path: Path, write) -> None:
    """`write(f)` into a temporary file beside `path` (".tmp-<name>-<random>"), flushed to the disk, then renamed
    over `path`: `path` is either its old content or the whole new one, whatever happens meanwhile."""
    tmp = path.with_name(f".tmp-{path.name}-{uuid.uuid4().hex[:8]}")
    try:
        with open(tmp, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise


def npy_header(stream) -> tuple[tuple[int, ...], np.dtype]:
    """(shape, dtype) of the .npy array `stream` starts with, read from its header alone (no data is read, nothing
    is allocated); ValueError when it is not the header of a plain array (a version this reads, no Python objects)."""
    try:
        version = np.lib.format.read_magic(stream)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(stream)
        elif version == (2, 0):
            shape, _, dtype = np.lib.format.read_array_header_2_0(stream)
        else:
            raise ValueError(f"array format {version}")
    except Exception as exc:  # numpy's words for a header it cannot parse: ours are given instead
        raise ValueError("not an array") from exc
    if dtype.hasobject or not all(isinstance(n, int) and n >= 0 for n in shape):
        raise ValueError("not an array of numbers or text")
    return tuple(shape), dtype


def _check_archive_sizes(p: Path, label: str, max_vertices: int) -> None:
    """Refuse an archive whose members would unpack beyond what a session of `max_vertices` vertices needs: each
    member, and all of them together, are bounded, a member the format does not define is refused unread, and each
    array's header must declare no more data than its member holds (so nothing larger is ever allocated)."""
    import zipfile

    # the largest member: (N, 32) weights at 8 bytes a value (256 B a vertex), or face indices (~100 B a vertex);
    # all of them: two weight arrays, edges and faces, ~1 KB a vertex at most
    limit = max(512 * max_vertices, 1 << 20)
    total_limit = max(1024 * max_vertices, 4 << 20)
    members = session_members()
    try:
        with zipfile.ZipFile(p) as archive:
            total = 0
            for info in archive.infolist():
                key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
                if key not in members:
                    raise ValueError(f"{label}: member {info.filename[:60]!r} is not part of a somwidget session")
                if info.file_size > limit:
                    raise ValueError(f"{label}: member {info.filename!r} unpacks to {info.file_size:,} bytes, more "
                                     f"than a session of at most {max_vertices:,} vertices holds ({limit:,})")
                total += info.file_size
                if total > total_limit:
                    raise ValueError(f"{label}: the archive unpacks to more than {total_limit:,} bytes, more than a "
                                     f"session of at most {max_vertices:,} vertices holds")
                try:
                    with archive.open(info) as member:
                        shape, dtype = npy_header(member)
                except ValueError:
                    raise ValueError(f"{label}: not a readable somwidget session: the archive is damaged "
                                     f"(member {info.filename!r} is not an array)") from None
                except Exception:  # a damaged archive: zipfile's and zlib's own errors
                    raise ValueError(f"{label}: not a readable somwidget session: the archive is damaged") from None
                if math.prod(shape) * dtype.itemsize > info.file_size:
                    raise ValueError(f"{label}: not a readable somwidget session: member {info.filename!r} is cut "
                                     f"short (its header declares more values than it holds)")
    except zipfile.BadZipFile:
        return  # not a zip: np.load below reports what it is


def load_session(path, *, max_vertices: int = MAX_VERTICES, max_iterations: int | None = None) -> dict:
    """Read a session written by `save_session`; ValueError naming the file and the missing or bad key.
    `max_iterations`: the largest S to accept (a Session passes its panel's cap), checked before anything is built.

    The archive's members are size-checked before they are read, so a small file cannot unpack into gigabytes,
    and a topology of more than `max_vertices` vertices is refused before anything is built.
    """
    label = str(path)
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{label}: no such session file")
    _check_archive_sizes(p, label, max_vertices)
    try:
        z = np.load(p, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise ValueError("a single .npy array, not an .npz archive")
        with z:
            members = session_members()
            data = {k: z[k] for k in z.files if k in members}
    except Exception as exc:  # zipfile, zlib, numpy format errors, pickled data refused...
        import zipfile

        why = ("it is not an .npz archive (a session file is what Save session writes)"
               if isinstance(exc, (zipfile.BadZipFile, OSError)) or "pickle" in str(exc) or "npy" in str(exc)
               else "the archive is damaged")
        raise ValueError(f"{label}: not a readable somwidget session: {why}") from None

    def get(key: str) -> np.ndarray:
        if key not in data:
            raise ValueError(f"{label}: session file lacks the key {key!r}")
        return data[key]

    def scalar(key: str, kind: str):
        arr = get(key)
        if arr.ndim != 0:
            raise ValueError(f"{label}: key {key!r}: expected a single value, got shape {arr.shape}")
        ok = {"i": np.issubdtype(arr.dtype, np.integer), "f": np.issubdtype(arr.dtype, np.number),
              "s": arr.dtype.kind == "U", "b": arr.dtype == np.bool_}[kind]
        if not ok:
            raise ValueError(f"{label}: key {key!r}: unexpected type {arr.dtype}")
        return {"i": int, "f": float, "s": str, "b": bool}[kind](arr[()])

    def ints(key: str, ndim: int = 1) -> np.ndarray:
        arr = get(key)
        if arr.ndim != ndim or not (np.issubdtype(arr.dtype, np.integer) or arr.size == 0):
            raise ValueError(f"{label}: key {key!r}: expected a {ndim}-D integer array, got {arr.dtype} {arr.shape}")
        return arr.astype(np.int64)

    version = scalar("format_version", "i")
    if version < 1 or version > SESSION_FORMAT_VERSION:
        raise ValueError(f"{label}: key 'format_version': session format {version} is not one this somwidget reads "
                         f"(1 to {SESSION_FORMAT_VERSION}); it may come from a newer somwidget")

    n_vertices = scalar("n_vertices", "i")
    if not 1 <= n_vertices <= max_vertices:
        raise ValueError(f"{label}: key 'n_vertices': expected 1 to {max_vertices:,} vertices, got {n_vertices:,}")
    iterations = scalar("iterations", "i")
    if max_iterations is not None and not 1 <= iterations <= max_iterations:
        raise ValueError(f"{label}: key 'iterations': S = {iterations:,} is more than this session allows "
                         f"(1 to {max_iterations:,})")
    kind = scalar("topology_kind", "s")
    try:
        if kind == "faces":
            flat, sizes = ints("face_indices"), ints("face_sizes")
            if (sizes < 0).any() or sizes.sum() != len(flat):
                raise ValueError(f"{label}: key 'face_sizes': sizes sum to {int(sizes.sum())}, but 'face_indices' "
                                 f"holds {len(flat)} indices")
            topology = Topology.from_faces(np.split(flat, np.cumsum(sizes)[:-1]) if len(sizes) else [],
                                           n_vertices=n_vertices)
        elif kind == "edges":
            topology = Topology.from_edges(ints("edges", 2), n_vertices)
        else:
            raise ValueError(f"{label}: key 'topology_kind': expected 'faces' or 'edges', got {kind!r}")
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(msg if msg.startswith(label) else f"{label}: bad topology ({msg})") from None
    stored_edges = ints("edges", 2) if get("edges").size else np.zeros((0, 2), np.int64)
    if stored_edges.shape != topology.edges.shape or not np.array_equal(stored_edges, topology.edges):
        raise ValueError(f"{label}: key 'edges' does not match the edges of the stored topology")

    length = scalar("layout_length", "i")
    try:
        layout = FeatureLayout(names=tuple(str(s) for s in get("layout_names").ravel()),
                               position=tuple(ints("layout_position")), colour=tuple(ints("layout_colour")),
                               colour_space=scalar("layout_colour_space", "s"),
                               direction=tuple(ints("layout_direction")), length=None if length < 0 else length)
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(msg if msg.startswith(label) else f"{label}: bad layout ({msg})") from None

    state = {
        "preset": scalar("preset", "s"), "display": scalar("display", "s"),
        "weights": get("weights"), "start_weights": get("start_weights"), "controls": get("controls"),
        "topology": topology, "layout": layout,
        # a setting the file lacks (it was written before there was one: reach) takes its default
        **{s.name: scalar(s.name, _KIND_CODE[s.kind]) if s.name in data else s.default for s in kept_settings()},
        "iteration": scalar("iteration", "i"),
        "smooth_dims": None if scalar("smooth_dims_default", "b") else tuple(int(d) for d in ints("smooth_dims")),
        "metric_weights": None if scalar("metric_weights_default", "b") else get("metric_weights"),
        "mirror": tuple(int(d) for d in ints("mirror")),
        "radii": get("radii") if "radii" in data else None,
        "strokes": tuple(int(n) for n in ints("strokes")) if "strokes" in data else None,
        "symmetry": scalar("symmetry", "s") if "symmetry" in data else "none",
        "smoothing_rule": scalar("smoothing_rule", "s") if "smoothing_rule" in data else "laplacian",
    }
    clean = check_state(state, label)
    clean["format_version"] = version
    clean["n_vertices"] = topology.n_vertices
    return clean


def check_state(state: dict, label: str) -> dict:
    """Types, shapes and ranges of a session state (`save_session`'s keys), as the engine will take them: arrays of
    finite float32 values with |x| <= checks.MAX_MAGNITUDE, each setting within its declared range (schedule.SETTINGS),
    s within 0..S, controls within the engine's limit counting their symmetric copies; returns a cleaned copy (float32
    arrays, tuples, ints). ValueError whose message starts with `label` and names the key. The autosave's reader
    (frontend/model/readback.py) checks each saved step with it too."""
    out = dict(state)
    topo, layout = state["topology"], state["layout"]
    if not isinstance(topo, Topology):
        raise ValueError(f"{label}: key 'topology': expected a Topology, got {type(topo).__name__}")
    if not isinstance(layout, FeatureLayout):
        raise ValueError(f"{label}: key 'layout': expected a FeatureLayout, got {type(layout).__name__}")
    if state.get("n_vertices") is not None and state["n_vertices"] != topo.n_vertices:
        raise ValueError(f"{label}: key 'n_vertices': {state['n_vertices']} does not match the topology's "
                         f"{topo.n_vertices}")
    n = layout.n_dims
    for key in ("weights", "start_weights"):
        arr = checks.finite_array(f"{label}: key {key!r}", state[key], 2)
        if arr.shape != (topo.n_vertices, n):
            raise ValueError(f"{label}: key {key!r}: expected shape ({topo.n_vertices}, {n}) (topology vertices, "
                             f"layout dims), got {arr.shape}")
        out[key] = arr
    controls = np.asarray(state["controls"])
    controls = checks.finite_array(f"{label}: key 'controls'", controls.reshape(0, n) if controls.size == 0
                                   else controls, 2)
    if controls.shape[1] != n:
        raise ValueError(f"{label}: key 'controls': expected {n} dims (the layout's), got shape {controls.shape}")
    out["controls"] = controls
    for key in ("preset", "display"):
        if not isinstance(state[key], str):
            raise ValueError(f"{label}: key {key!r}: expected a string, got {type(state[key]).__name__}")
    if state["display"] not in DISPLAYS:
        raise ValueError(f"{label}: key 'display': expected one of {DISPLAYS}, got {state['display']!r}")
    for setting in kept_settings():
        out[setting.name] = setting.check(state[setting.name], f"{label}: key {setting.name!r}")
    out["iteration"] = checks.integer(f"{label}: key 'iteration'", state["iteration"], 0, out["iterations"])
    out["mirror"] = checks.dims(f"{label}: key 'mirror'", state["mirror"], n)
    if state["smooth_dims"] is not None:
        out["smooth_dims"] = checks.dims(f"{label}: key 'smooth_dims'", state["smooth_dims"], n)
    if state["metric_weights"] is not None:
        mw = checks.finite_array(f"{label}: key 'metric_weights'", state["metric_weights"], 1)
        if mw.shape != (n,) or (mw < 0).any():
            raise ValueError(f"{label}: key 'metric_weights': expected {n} values >= 0, got {mw}")
        out["metric_weights"] = mw
        high = schedule.BY_NAME["metric_weights"].high
        if (mw > high).any() or not (mw > 0).any():
            raise ValueError(f"{label}: key 'metric_weights': expected values in [0, {high:g}], at least one of them "
                             f"above 0, got {mw.tolist()}")
    k = len(controls)
    radii = np.zeros(k, np.float32) if state.get("radii") is None else np.asarray(state["radii"])
    radii = checks.finite_array(f"{label}: key 'radii'", radii.reshape(-1) if radii.size == k else radii, 1)
    high = schedule.BY_NAME["radius"].high
    if radii.shape != (k,) or (radii < 0).any() or (radii > high).any():
        raise ValueError(f"{label}: key 'radii': expected {k} values in [0, {high:g}] (one per control), got "
                         f"{radii.tolist()[:8]}")
    out["radii"] = radii
    out["strokes"] = (1,) * k if state.get("strokes") is None else \
        checks.runs(f"{label}: key 'strokes'", tuple(state["strokes"]), k)
    try:
        group = Symmetry.parse(state.get("symmetry", "none"))
    except ValueError as exc:
        raise ValueError(f"{label}: key 'symmetry': {exc}") from None
    if group is not None and (group.kind != "radial" or out["mirror"]):
        raise ValueError(f"{label}: key 'symmetry': a file keeps a mirror in 'mirror' and a radial group here, got "
                         f"{state['symmetry']!r} with mirror {out['mirror']}")
    out["symmetry"] = "none" if group is None else group.spec
    order = group.order if group is not None else 2 if out["mirror"] else 1
    if not 1 <= k * order <= MAX_CONTROLS:
        raise ValueError(f"{label}: key 'controls': expected 1 to {MAX_CONTROLS} controls counting their symmetric "
                         f"copies, got {k} ({k * order} with their copies)")
    out["smoothing_rule"] = checks.choice(f"{label}: key 'smoothing_rule'", state.get("smoothing_rule", "laplacian"),
                                          SMOOTHING_RULES)
    return out


def session_state(preset: Preset, som=None) -> dict:
    """A `save_session` state from a preset and, if given, the Som trained from it (its current weights,
    controls, iteration and settings); without a Som the preset's start is saved."""
    state = {
        "preset": preset.name, "display": preset.display, "topology": preset.topology, "layout": preset.layout,
        "start_weights": preset.weights, "weights": preset.weights, "controls": preset.controls,
        **{key: getattr(preset, key) for key in schedule.KEYS}, "iteration": 0,
        "smooth_dims": preset.smooth_dims, "metric_weights": preset.metric_weights, "mirror": preset.mirror,
        "radii": preset.control_radii(), "symmetry": preset.symmetry.spec if preset.symmetry else "none",
        "strokes": preset.strokes,
        "smoothing_rule": preset.smoothing_rule,
    }
    if som is not None:
        state.update({key: getattr(som, key) for key in schedule.KEYS})
        radial = som.symmetry if som.symmetry is not None and som.symmetry.kind == "radial" else None
        state.update(weights=som.weights, controls=som.controls, iteration=som.iteration, smooth_dims=som.smooth_dims,
                     metric_weights=som.metric_weights, mirror=som.mirror, radii=som.radii, strokes=som.strokes,
                     symmetry=radial.spec if radial else "none", smoothing_rule=som.smoothing_rule)
    return state


def preset_from_session(state: dict) -> Preset:
    """The Preset a session started from (start weights, the session's controls and settings; a shape kept as it
    is). The session's current weights and s are state["weights"] and state["iteration"]: give them to
    `Som.restore` to carry on exactly from where it was saved."""
    return Preset(
        name=state.get("preset") or "session", title=state.get("preset") or "Session", description="A saved session.",
        topology=state["topology"], weights=state["start_weights"], controls=state["controls"],
        layout=state["layout"], mirror=state["mirror"], metric_weights=state["metric_weights"],
        display=state["display"], smooth_dims=state["smooth_dims"], radii=state.get("radii"),
        strokes=state.get("strokes"),
        symmetry=Symmetry.parse(state.get("symmetry", "none")), smoothing_rule=state.get("smoothing_rule", "laplacian"),
        radius=float(np.max(state["radii"])) if state.get("radii") is not None and len(state["radii"]) else 0.0,
        **{key: state.get(key, schedule.BY_NAME[key].default) for key in schedule.KEYS})
