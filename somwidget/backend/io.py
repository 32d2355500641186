"""Mesh import (any mesh trimesh reads) and export (OBJ, PLY, GLB), and session save / load (.npz, no pickle).

Every failure a person can cause (a missing or broken file, an unsupported format, a bad session) is a ValueError
whose message starts with the file's path and says what is wrong.
"""

from __future__ import annotations

import os
import uuid
from pathlib import Path
from struct import error as struct_error

import numpy as np

from . import checks
from .refine import coarsen
from .presets import (DISPLAYS, XYZ, FeatureLayout, Preset, colours_of, controls_on, kept_shape,
                      line_display_mesh, positions_of)
from .schedule import BY_NAME, KEYS, SMOOTHING_RULES
from .symmetry import Symmetry
from .topology import Topology

#: The default vertex limit of `load_mesh`: the dense distance table's cap (2^16 neurons).
MAX_VERTICES = 65536
#: File extensions `export_mesh` writes.
EXPORT_FORMATS = ("obj", "ply", "glb")
#: The session file format this module writes; `load_session` reads this version and older ones.
SESSION_FORMAT_VERSION = 1


# --------------------------------------------------------------------------------------------------------------
# Import
# --------------------------------------------------------------------------------------------------------------
#: A scene may hold at most this many times the vertex limit before it is flattened (a glTF splits vertices at seams,
#: so the count before merging runs above the count after).
SCENE_VERTEX_FACTOR = 8


class _TooBig(Exception):
    """A file that would expand past the limits: refused before it is expanded."""


def _check_instances(scene, label: str, max_vertices: int) -> None:
    """Count a scene's vertices over every placed instance before flattening it: a small GLB can place one mesh
    thousands of times (5 million vertices and 2 GB from 150 KB). The copies a placement adds beyond the file's own
    vertices sit elsewhere and never merge: past `max_vertices` of them the scene is refused, and so is one past
    SCENE_VERTEX_FACTOR times the limit in all. Counted from the scene graph in milliseconds, nothing expanded."""
    own = added = 0
    instances = 0
    for name, nodes in scene.graph.geometry_nodes.items():
        n = len(getattr(scene.geometry.get(name), "vertices", ()))
        own += n
        added += n * max(0, len(nodes) - 1)
        instances += len(nodes)
    total = own + added
    if added > max_vertices or total > SCENE_VERTEX_FACTOR * max_vertices:
        raise _TooBig(f"{label}: the scene places its meshes {instances:,} times, {total:,} vertices in all, past the "
                      f"limit of {max_vertices:,} vertices; export the one mesh you want to model")


def _reader_reason(exc: Exception) -> str:
    """What went wrong reading a file, in words (a reader's own message where it wrote one for people; never a
    Python exception's internals)."""
    if isinstance(exc, IndexError):
        return "a face refers to a vertex that does not exist"
    if isinstance(exc, (EOFError, UnicodeDecodeError, struct_error)):
        return "the file is cut short or is not in the format its name says"
    message = str(exc).strip()
    if isinstance(exc, ValueError) and message and "\n" not in message and len(message) < 160:
        return message
    return "the file is damaged or is not in the format its name says"


class TooManyVertices(ValueError):
    """A mesh with more vertices than a session takes: `n` of them, `limit` at most (load it with decimate=True)."""

    def __init__(self, message: str, n: int, limit: int):
        super().__init__(message)
        self.n, self.limit = n, limit


#: The most vertices a mesh may have to be decimated on loading (it is read whole first).
MAX_DECIMATE_SOURCE = 4_194_304


def load_mesh(path, *, max_vertices: int = MAX_VERTICES, decimate: bool = False) -> Preset:
    """A `Preset` (3-D nodes, display "surface") from any mesh file trimesh reads: OBJ, PLY, STL, OFF, GLB...

    Duplicate vertices are merged by position (STL stores every triangle's corners apart; glTF splits vertices at
    UV and normal seams), unreferenced vertices and faces that collapse onto a repeated vertex are dropped. trimesh
    triangulates polygons on import, so quads arrive as triangle pairs. A file with several meshes (a glTF scene)
    is flattened into one, with its scene transforms applied.

    The mesh is normalised: its bounding box is centred on the origin (so it lies centred on y = 0, ready for the
    xz-plane mirror) and scaled so its longest side spans [-1, 1]. `preset.meta["transform"]` holds
    {"centre": (3,) floats, "scale": float} with normalised = (original - centre) * scale; pass it to
    `export_mesh(..., transform=...)` to write the original frame back. The mesh is the person's own shape
    (`grow` False: shown as it is, nothing trains until they act), with six controls on its vertices, spread over
    it (`presets.controls_on`).

    A mesh past `max_vertices` is refused with TooManyVertices (a ValueError that says how many and offers
    decimation); with `decimate` it is coarsened to at most that many vertices (refine.coarsen: vertex clustering on
    a grid), up to MAX_DECIMATE_SOURCE vertices read.
    """
    import trimesh

    label = str(path)
    p = Path(path)
    max_vertices = checks.integer("max_vertices", max_vertices, 1)
    limit = max_vertices
    if decimate:  # read past the limit, then coarsen
        max_vertices = max(max_vertices, MAX_DECIMATE_SOURCE)
    if not p.exists():
        raise ValueError(f"{label}: no such file")
    if not p.is_file():
        raise ValueError(f"{label}: not a file")
    try:
        loaded = trimesh.load(str(p), process=False)
        if isinstance(loaded, trimesh.Scene):
            _check_instances(loaded, label, max_vertices)
        geoms = loaded.dump() if isinstance(loaded, trimesh.Scene) else [loaded]
        if not isinstance(geoms, (list, tuple)):
            geoms = [geoms]
    except _TooBig as exc:
        raise ValueError(str(exc)) from None
    except Exception as exc:  # each format's reader raises its own kinds of error
        raise ValueError(f"{label}: cannot be read as a mesh: {_reader_reason(exc)}") from None

    meshes = [g for g in geoms if isinstance(g, trimesh.Trimesh) and len(g.faces)]
    if not meshes:
        n_points = sum(len(getattr(g, "vertices", ())) for g in geoms)
        if n_points:
            raise ValueError(f"{label}: has {n_points} vertices but no faces (a point cloud or lines); "
                             "a mesh with faces is needed")
        raise ValueError(f"{label}: holds no mesh (the file is empty or not a mesh file)")
    mesh = meshes[0] if len(meshes) == 1 else trimesh.util.concatenate(meshes)

    vertices = np.asarray(mesh.vertices, np.float64)
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise ValueError(f"{label}: {int(bad.sum())} vertices have NaN or infinite coordinates "
                         f"(first at vertex {int(np.argmax(bad))})")
    faces = np.asarray(mesh.faces, np.int64)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f"{label}: a face refers to a vertex that does not exist")

    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    faces = np.asarray(mesh.faces, np.int64)
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    lo, hi = np.asarray(mesh.vertices).min(axis=0), np.asarray(mesh.vertices).max(axis=0)
    extent = float((hi - lo).max())
    magnitude = max(1.0, float(np.abs(mesh.vertices).max()))
    if not np.isfinite(extent) or extent <= 1e-9 * magnitude:
        raise ValueError(f"{label}: degenerate mesh: all vertices coincide (zero extent)")
    if not keep.any():
        raise ValueError(f"{label}: degenerate mesh: every face collapses onto a repeated vertex")
    mesh.update_faces(keep)
    mesh.remove_unreferenced_vertices()
    n = len(mesh.vertices)
    source = ""
    if n > limit and decimate:
        vertices, faces = coarsen(mesh.vertices, mesh.faces, limit)
        mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
        source, n = f", decimated from {n:,} vertices", len(mesh.vertices)
    elif n > limit:
        raise TooManyVertices(f"{label}: {n:,} vertices (after merging duplicates) exceed the limit of {limit:,} on "
                              f"this device; it can be loaded decimated to at most {limit:,} (vertex clustering: the "
                              "app's Decimate button, or load_mesh(..., decimate=True))", n, limit)

    vertices = np.asarray(mesh.vertices, np.float64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = (lo + hi) / 2.0
    scale = 2.0 / float((hi - lo).max())
    points = ((vertices - centre) * scale).astype(np.float32)
    topology = Topology.from_faces(np.asarray(mesh.faces, np.int64), n_vertices=n)
    return Preset(
        name=p.stem or p.name, title=p.name,
        description=f"Loaded from {p.name}: {n} vertices, {len(mesh.faces)} triangles{source}.",
        topology=topology, weights=points, controls=controls_on(points), layout=XYZ, display="surface",
        **kept_shape(points),
        meta={"source": str(p), "transform": {"centre": tuple(float(c) for c in centre), "scale": scale}})


# --------------------------------------------------------------------------------------------------------------
# Export
# --------------------------------------------------------------------------------------------------------------
def export_mesh(path, weights, topology: Topology, layout: FeatureLayout, *, display: str | None = None,
                transform: dict | None = None) -> None:
    """Write the current shape to OBJ, PLY or GLB (chosen by the extension) with vertex colours from `layout`.

    display: "surface" (the topology's faces, n-gons fan-triangulated since trimesh holds triangles), "lines" (the
    line display mesh of case study 3: 2N vertices, two triangles per edge quad), "points" (a point cloud: all three
    formats store one), or None to choose: "lines" when the layout has direction dims, else "surface" when the
    topology has faces, else "points". transform: the {"centre", "scale"} of `Preset.meta["transform"]` to map the
    positions back to a loaded file's frame.

    A surface is welded (`weld`): neighbouring nodes within WELD_SHARE of the shape's size of each other (a control
    pulled them onto one place) become one vertex and the faces that collapse with them go, so the file has no faces
    without area and no edge of zero length; where two sheets of the clay touch, their vertices are set 1e-5 of the
    size apart along their normals, so a closed clay stays closed after any tool's vertex merge. The vertices keep
    their order otherwise: vertex i of the file is neuron i when nothing was welded (for "lines": N roots, then N
    tips).
    """
    import trimesh

    label = str(path)
    ext = Path(path).suffix.lower().lstrip(".")
    if ext not in EXPORT_FORMATS:
        what = f"'.{ext}'" if ext else "a name without an extension"
        raise ValueError(f"{label}: cannot export to {what}; use one of " + ", ".join("." + e for e in EXPORT_FORMATS))
    w = checks.finite_array("weights", weights, 2)
    if w.shape != (topology.n_vertices, layout.n_dims):
        raise ValueError(f"{label}: weights have shape {w.shape}, expected ({topology.n_vertices}, {layout.n_dims}) "
                         "(topology vertices, layout dims)")
    if display is None:
        display = "lines" if layout.direction else ("surface" if topology.faces else "points")
    if display not in DISPLAYS:
        raise ValueError(f"{label}: display must be one of {DISPLAYS}, got {display!r}")

    colours = colours_of(w, layout)
    if display == "lines":
        points, quads = line_display_mesh(w, topology, layout)
        colours = np.concatenate([colours, colours])
        faces = triangulate(quads)
    elif display == "surface":
        if not topology.faces:
            raise ValueError(f"{label}: the topology has no faces to export as a surface; export display='points'")
        points, faces = positions_of(w, layout), triangulate(topology.faces)
    else:
        points, faces = positions_of(w, layout), np.zeros((0, 3), np.int64)
    points = points.astype(np.float64)
    if transform is not None:
        centre = np.asarray(transform["centre"], np.float64)
        points = points / float(transform["scale"]) + centre
    rgba = np.concatenate([np.round(colours * 255.0), np.full((len(colours), 1), 255.0)], axis=1).astype(np.uint8)
    if len(faces):
        if display == "surface":
            points, faces, rgba = weld(points, faces, rgba)
        geom = trimesh.Trimesh(vertices=points, faces=faces, vertex_colors=rgba, process=False)
    else:
        geom = trimesh.PointCloud(points, colors=rgba)
    data = geom.export(file_type=ext)
    with open(path, "wb") as f:
        f.write(data.encode("utf-8") if isinstance(data, str) else data)


#: Export: two vertices joined by an edge and closer than this share of the shape's size (its bounding diagonal)
#: are welded into one.
WELD_SHARE = 1e-6


def weld(points: np.ndarray, triangles: np.ndarray, colours: np.ndarray | None = None):
    """(points, triangles, colours) with each edge shorter than WELD_SHARE of the size collapsed (its vertices become
    the lower-indexed one), the triangles that collapse with it (a repeated vertex, or no area) dropped, and the
    vertices no triangle uses any more removed; the rest keep their order. Vertices that coincide without an edge
    between them (two sheets of the clay touching) stay apart: joining them would pinch the surface open."""
    p = np.asarray(points, np.float64)
    tris = np.asarray(triangles, np.int64).reshape(-1, 3)
    size = float(np.linalg.norm(np.ptp(p, axis=0))) if len(p) else 0.0
    tol = WELD_SHARE * (size or 1.0)
    target = np.arange(len(p))
    edges = np.unique(np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1), axis=0)
    short = edges[np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1) <= tol]
    for a, b in short.tolist():  # union of short edges, each group to its lowest vertex
        ra, rb = a, b
        while target[ra] != ra:
            ra = target[ra]
        while target[rb] != rb:
            rb = target[rb]
        target[max(ra, rb)] = min(ra, rb)
    while not np.array_equal(root := target[target], target):  # each vertex to its group's lowest one
        target = root
    tris = target[tris]
    distinct = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    area2 = np.linalg.norm(np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]]), axis=1)
    tris = tris[distinct & (area2 > tol * tol)]
    used = np.zeros(len(p), bool)
    used[tris.ravel()] = True
    index = np.cumsum(used) - 1
    p, tris = _apart(p[used], index[tris], tol)
    return p, tris, None if colours is None else np.asarray(colours)[used]


def _apart(p: np.ndarray, tris: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices that coincide (within 10 tol) without an edge between them, two sheets of the clay touching, each
    moved 10 tol along its own normal: a later vertex merge (any tool's) then cannot join the sheets and pinch the
    surface open. Nothing moves when no such vertices exist."""
    gap = 10.0 * tol
    keys = np.floor(p / gap).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    cell = inverse.ravel()
    crowded = np.flatnonzero(counts[cell] > 1)
    if not len(crowded):
        return p, tris
    # of the vertices sharing a cell, those with one there that no edge joins to it (a short edge is not a touch)
    edges = {(min(a, b), max(a, b)) for t in tris[np.isin(tris, crowded).any(axis=1)].tolist()
             for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    groups: dict[int, list[int]] = {}
    for v in crowded.tolist():
        groups.setdefault(int(cell[v]), []).append(v)
    touching = np.zeros(len(p), bool)
    for members in groups.values():
        for i, a in enumerate(members):
            for b in members[i + 1:]:
                if (a, b) not in edges:
                    touching[a] = touching[b] = True
    if not touching.any():
        return p, tris
    crowded = touching
    normals = np.zeros_like(p)
    face_n = np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]])
    for corner in range(3):
        np.add.at(normals, tris[:, corner], face_n)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 0, normals / np.where(length > 0, length, 1.0), 0.0)
    out = p.copy()
    out[crowded] += gap * normals[crowded]
    return out, tris


def triangulate(faces) -> np.ndarray:
    """(T, 3) int64 triangles from faces of any size by a fan from each face's first vertex (a k-gon gives k - 2
    triangles, in face order); faces of fewer than 3 vertices give none."""
    faces = getattr(faces, "array", faces)  # topology.Faces: faces of one size, one array
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        groups = {faces.shape[1]: np.asarray(faces, np.int64)} if faces.shape[1] >= 3 else {}
        order = None
    else:
        face_list = [np.asarray(f, np.int64).ravel() for f in faces]
        by_size: dict[int, list[int]] = {}
        for i, f in enumerate(face_list):
            if len(f) >= 3:
                by_size.setdefault(len(f), []).append(i)
        groups = {k: np.stack([face_list[i] for i in idx]) for k, idx in by_size.items()}
        order = by_size
    if not groups:
        return np.zeros((0, 3), np.int64)
    tris, keys = [], []
    for k, arr in groups.items():
        for j in range(1, k - 1):
            tris.append(np.stack([arr[:, 0], arr[:, j], arr[:, j + 1]], axis=1))
            face_ids = np.arange(len(arr)) if order is None else np.asarray(order[k])
            keys.append(face_ids * 1_000_000 + j)
    tris_all, keys_all = np.concatenate(tris), np.concatenate(keys)
    return tris_all[np.argsort(keys_all, kind="stable")]


# --------------------------------------------------------------------------------------------------------------
# Sessions
# --------------------------------------------------------------------------------------------------------------
#: Keys a session state must have.
SESSION_REQUIRED = ("weights", "start_weights", "controls", "topology", "layout")
#: Keys a session state may have, with the value used when it is absent (the schedule's: schedule.SETTINGS).
SESSION_DEFAULTS = {
    "preset": "", "display": "surface", **{key: BY_NAME[key].default for key in KEYS},
    "smooth_dims": None, "metric_weights": None, "mirror": (), "iteration": 0,
    # the shaping rules (files before them: point controls, no radial group, the paper's smoothing)
    "radii": None, "symmetry": "none", "smoothing_rule": "laplacian", "strokes": None,
}
#: How a session file stores each schedule parameter: an int64 or a float64 scalar.
_SCALAR_KIND = {key: "i" if BY_NAME[key].kind == "int" else "f" for key in KEYS}


def save_session(path, state: dict) -> None:
    """Write a modelling session to `path` as a compressed .npz (no pickle), whatever the file's extension.

    state keys (load_session returns the same, plus "format_version" and "n_vertices"):
      weights (N, n), start_weights (N, n), controls (k, n): float arrays; topology: a Topology (its faces are kept
      when it has them, else its edges); layout: a FeatureLayout; and optionally preset (str), display (str),
      the schedule (schedule.KEYS: iterations an int, l_start, l_end, smoothing, reach floats), iteration (an
      int), smooth_dims (None or dims),
      metric_weights (None or (n,) floats), mirror (dims), radii (None or (k,) floats >= 0), symmetry (a radial
      group's spec, Symmetry.spec, or "none"), smoothing_rule ("laplacian" or "taubin"). `session_state()` builds
      one from a Preset and a Som.
      n_vertices and format_version may be present (as in a loaded state) and are checked / ignored.
    """
    label = str(path)
    unknown = set(state) - set(SESSION_REQUIRED) - set(SESSION_DEFAULTS) - {"n_vertices", "format_version"}
    if unknown:
        raise ValueError(f"{label}: unknown session keys {sorted(unknown)}; known: "
                         f"{sorted([*SESSION_REQUIRED, *SESSION_DEFAULTS])}")
    full = {**SESSION_DEFAULTS, **{k: v for k, v in state.items() if k != "format_version"}}
    for key in SESSION_REQUIRED:
        if key not in full:
            raise ValueError(f"{label}: session state lacks the key {key!r}")
    clean = _check_state(full, label)
    topo, layout = clean["topology"], clean["layout"]
    arrays: dict[str, np.ndarray] = {
        "format_version": np.int64(SESSION_FORMAT_VERSION),
        "preset": np.str_(clean["preset"]),
        "display": np.str_(clean["display"]),
        "weights": clean["weights"], "start_weights": clean["start_weights"], "controls": clean["controls"],
        "n_vertices": np.int64(topo.n_vertices),
        "edges": np.asarray(topo.edges, np.int64).reshape(-1, 2),
        **{key: (np.int64 if kind == "i" else np.float64)(clean[key]) for key, kind in _SCALAR_KIND.items()},
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


#: The members a session archive may hold (np.savez names each key.npy): any other is refused unread.
SESSION_MEMBERS = frozenset({
    "format_version", "preset", "display", "weights", "start_weights", "controls", "n_vertices", "edges",
    *KEYS, "iteration", "smooth_dims", "smooth_dims_default",
    "metric_weights", "metric_weights_default", "mirror", "radii", "symmetry", "smoothing_rule", "strokes",
    "layout_names", "layout_position", "layout_colour",
    "layout_colour_space", "layout_direction", "layout_length", "topology_kind", "face_indices", "face_sizes"})


def _check_archive_sizes(p: Path, label: str, max_vertices: int) -> None:
    """Refuse an archive whose members would unpack beyond what a session of `max_vertices` vertices needs: each
    member, and all of them together, are bounded, and a member the format does not define is refused unread."""
    import zipfile

    # the largest member: (N, 32) weights at 8 bytes a value (256 B a vertex), or face indices (~100 B a vertex);
    # all of them: two weight arrays, edges and faces, ~1 KB a vertex at most
    limit = max(512 * max_vertices, 1 << 20)
    total_limit = max(1024 * max_vertices, 4 << 20)
    try:
        with zipfile.ZipFile(p) as archive:
            total = 0
            for info in archive.infolist():
                key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
                if key not in SESSION_MEMBERS:
                    raise ValueError(f"{label}: member {info.filename[:60]!r} is not part of a somwidget session")
                if info.file_size > limit:
                    raise ValueError(f"{label}: member {info.filename!r} unpacks to {info.file_size:,} bytes, more "
                                     f"than a session of at most {max_vertices:,} vertices holds ({limit:,})")
                total += info.file_size
                if total > total_limit:
                    raise ValueError(f"{label}: the archive unpacks to more than {total_limit:,} bytes, more than a "
                                     f"session of at most {max_vertices:,} vertices holds")
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
            data = {k: z[k] for k in z.files if k in SESSION_MEMBERS}
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
        # a schedule parameter the file lacks (it was written before there was one: reach) takes its default
        **{key: scalar(key, kind) if key in data else BY_NAME[key].default for key, kind in _SCALAR_KIND.items()},
        "iteration": scalar("iteration", "i"),
        "smooth_dims": None if scalar("smooth_dims_default", "b") else tuple(int(d) for d in ints("smooth_dims")),
        "metric_weights": None if scalar("metric_weights_default", "b") else get("metric_weights"),
        "mirror": tuple(int(d) for d in ints("mirror")),
        "radii": get("radii") if "radii" in data else None,
        "strokes": tuple(int(n) for n in ints("strokes")) if "strokes" in data else None,
        "symmetry": scalar("symmetry", "s") if "symmetry" in data else "none",
        "smoothing_rule": scalar("smoothing_rule", "s") if "smoothing_rule" in data else "laplacian",
    }
    clean = _check_state(state, label)
    clean["format_version"] = version
    clean["n_vertices"] = topology.n_vertices
    return clean


def _check_state(state: dict, label: str) -> dict:
    """Types, shapes and ranges of a session state; returns a cleaned copy (float32 arrays, tuples, ints)."""
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
    for key in KEYS:
        out[key] = BY_NAME[key].check(state[key], f"{label}: key {key!r}")
    out["iteration"] = checks.integer(f"{label}: key 'iteration'", state["iteration"], 0, out["iterations"])
    out["mirror"] = checks.dims(f"{label}: key 'mirror'", state["mirror"], n)
    if state["smooth_dims"] is not None:
        out["smooth_dims"] = checks.dims(f"{label}: key 'smooth_dims'", state["smooth_dims"], n)
    if state["metric_weights"] is not None:
        mw = checks.finite_array(f"{label}: key 'metric_weights'", state["metric_weights"], 1)
        if mw.shape != (n,) or (mw < 0).any():
            raise ValueError(f"{label}: key 'metric_weights': expected {n} values >= 0, got {mw}")
        out["metric_weights"] = mw
    k = len(controls)
    radii = np.zeros(k, np.float32) if state.get("radii") is None else np.asarray(state["radii"])
    radii = checks.finite_array(f"{label}: key 'radii'", radii.reshape(-1) if radii.size == k else radii, 1)
    if radii.shape != (k,) or (radii < 0).any():
        raise ValueError(f"{label}: key 'radii': expected {k} values >= 0 (one per control), got {radii.tolist()}")
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
    out["smoothing_rule"] = checks.choice(f"{label}: key 'smoothing_rule'", state.get("smoothing_rule", "laplacian"),
                                          SMOOTHING_RULES)
    return out


def session_state(preset: Preset, som=None) -> dict:
    """A `save_session` state from a preset and, if given, the Som trained from it (its current weights,
    controls, iteration and settings); without a Som the preset's start is saved."""
    state = {
        "preset": preset.name, "display": preset.display, "topology": preset.topology, "layout": preset.layout,
        "start_weights": preset.weights, "weights": preset.weights, "controls": preset.controls,
        **{key: getattr(preset, key) for key in KEYS}, "iteration": 0,
        "smooth_dims": preset.smooth_dims, "metric_weights": preset.metric_weights, "mirror": preset.mirror,
        "radii": preset.control_radii(), "symmetry": preset.symmetry.spec if preset.symmetry else "none",
        "strokes": preset.strokes,
        "smoothing_rule": preset.smoothing_rule,
    }
    if som is not None:
        state.update({key: getattr(som, key) for key in KEYS})
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
        **{key: state.get(key, BY_NAME[key].default) for key in KEYS})
