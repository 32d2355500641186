"""Mesh files: import (any mesh trimesh reads) and export (OBJ, PLY, binary STL, glTF / GLB with the controls as named
nodes, Rhino's .3dm with the controls as named points on a layer of their own). Session files are session_file.py's.

Every failure a person can cause (a missing or broken file, an unsupported format) is a ValueError whose message
starts with the file's path and says what is wrong.
"""

from __future__ import annotations

from pathlib import Path
from struct import error as struct_error

import numpy as np

from . import checks
from .presets import (
    DISPLAYS,
    XYZ,
    FeatureLayout,
    Preset,
    colours_of,
    controls_on,
    kept_shape,
    line_display_mesh,
    positions_of,
)
from .refine import coarsen
from .topology import Topology

#: The default vertex limit of `load_mesh`: the dense distance table's cap (2^16 neurons).
MAX_VERTICES = 65536
#: File extensions `export_mesh` writes.
EXPORT_FORMATS = ("obj", "ply", "stl", "glb", "gltf", "3dm")
#: The unit a .3dm says its coordinates are in (Rhino's ModelUnitSystem), unless `export_mesh(units=...)` says.
DEFAULT_UNITS = "meters"


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

    def __init__(self, message: str, n: int, limit: int) -> None:
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
                transform: dict | None = None, controls=None, radii=None, units: str = DEFAULT_UNITS) -> None:
    """Write the current shape to OBJ, PLY, STL (binary), glTF, GLB or .3dm (chosen by the extension) with vertex
    colours from `layout` (STL has none).

    controls: (k, n) control values in the feature space of `weights` (and `radii`, (k,)), written where the format
    has a place for them: glTF / GLB as empty nodes named "control 0", "control 1"... placed at each control, beside
    the node "clay" that holds the mesh; .3dm as points of those names on the layer "controls" (each with its
    radius as the user string "radius"), the mesh named "clay" on the layer "clay". units: a .3dm's unit system
    (a name of rhino3dm.UnitSystem, case ignored: "meters", "millimeters", "inches"...).

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
    if len(faces) and display == "surface":
        points, faces, rgba = weld(points, faces, rgba)
    if ext == "stl" and not len(faces):
        raise ValueError(f"{label}: STL holds triangles only; this shape has none (export .ply or .obj for points)")
    marks = _control_marks(label, controls, radii, layout, transform)
    if ext == "3dm":
        data = _rhino_file(label, points, faces, rgba, marks, units)
    else:
        geom = (trimesh.Trimesh(vertices=points, faces=faces, vertex_colors=rgba, process=False) if len(faces)
                else trimesh.PointCloud(points, colors=rgba))
        data = _gltf(geom, marks, ext) if ext in ("glb", "gltf") else geom.export(file_type=ext)
    with open(path, "wb") as f:
        f.write(data.encode("utf-8") if isinstance(data, str) else data)


def _control_marks(label: str, controls, radii, layout: FeatureLayout, transform: dict | None) -> list:
    """[(name, (3,) position in the file's frame, radius)] of the controls an export names ([] without controls)."""
    if controls is None:
        return []
    c = checks.finite_array("controls", controls, 2)
    if c.shape[1] != layout.n_dims:
        raise ValueError(f"{label}: controls have shape {c.shape}, expected (k, {layout.n_dims}) (layout dims)")
    r = np.zeros(len(c)) if radii is None else np.asarray(radii, np.float64).reshape(-1)
    if len(r) != len(c):
        raise ValueError(f"{label}: {len(r)} radii for {len(c)} controls")
    at = positions_of(c, layout).astype(np.float64)
    if transform is not None:
        at = at / float(transform["scale"]) + np.asarray(transform["centre"], np.float64)
        r = r / float(transform["scale"])
    return [(f"control {i}", at[i], float(r[i])) for i in range(len(c))]


def _gltf(geom, marks: list, ext: str) -> bytes:
    """A glTF scene (binary for .glb, one JSON file with its buffers inside for .gltf): the node "clay" with the
    mesh, and an empty node per control, named and placed at it (a translation)."""
    import trimesh
    from trimesh.exchange import gltf

    scene = trimesh.Scene()
    scene.add_geometry(geom, node_name="clay", geom_name="clay")
    for name, at, _radius in marks:
        matrix = np.eye(4)
        matrix[:3, 3] = at
        scene.graph.update(frame_to=name, frame_from=scene.graph.base_frame, matrix=matrix)
    if ext == "glb":
        return gltf.export_glb(scene)
    return next(iter(gltf.export_gltf(scene, embed_buffers=True).values()))


def _rhino_file(label: str, points, faces, rgba, marks: list, units: str) -> bytes:
    """A Rhino .3dm (version 8) in `units`: the mesh "clay" with its vertex colours on the layer "clay" (a point
    cloud where there are no faces), each control a point named after it on the layer "controls"."""
    import tempfile

    import rhino3dm

    unit = {name.lower(): name for name in dir(rhino3dm.UnitSystem) if not name.startswith("_")}.get(
        str(units).lower())
    if unit is None or unit in ("name", "value", "Unset", "None", "CustomUnits", "UnitScale"):
        raise ValueError(f"{label}: unknown units {units!r}; use meters, millimeters, centimeters, inches, feet...")
    model = rhino3dm.File3dm()
    # rhino3dm's stubs (__init__.pyi, 8.35) are wrong where the ignores below say: they give settable properties no
    # setter and File3dmObjectTable.AddMesh / AddPointCloud no `attributes` (the module itself has both)
    model.Settings.ModelUnitSystem = getattr(rhino3dm.UnitSystem, unit)  # type: ignore[misc]

    def layer(name: str, colour: tuple) -> int:
        entry = rhino3dm.Layer()
        entry.Name, entry.Color = name, colour
        return model.Layers.Add(entry)

    def named(name: str, on: int):
        attrs = rhino3dm.ObjectAttributes()
        attrs.Name, attrs.LayerIndex = name, on  # type: ignore[misc]
        return attrs

    clay = layer("clay", (200, 200, 210, 255))
    if len(faces):
        mesh = rhino3dm.Mesh()
        mesh.Vertices.UseDoublePrecisionVertices = True  # type: ignore[misc]
        for x, y, z in points.tolist():
            mesh.Vertices.Add(x, y, z)
        for a, b, c in np.asarray(faces, np.int64).tolist():
            mesh.Faces.AddFace(a, b, c)
        for r, g, b, _a in rgba.tolist():
            mesh.VertexColors.Add(r, g, b)
        mesh.Normals.ComputeNormals()
        mesh.Compact()
        model.Objects.AddMesh(mesh, named("clay", clay))  # type: ignore[call-arg]
    else:
        cloud = rhino3dm.PointCloud()
        for x, y, z in points.tolist():
            cloud.Add(rhino3dm.Point3d(x, y, z))
        model.Objects.AddPointCloud(cloud, named("clay", clay))  # type: ignore[call-arg]
    if marks:
        on = layer("controls", (220, 60, 40, 255))
        for name, at, radius in marks:
            attrs = named(name, on)
            attrs.SetUserString("radius", repr(radius))
            model.Objects.AddPoint(rhino3dm.Point3d(*map(float, at)), attrs)
    with tempfile.TemporaryDirectory(prefix="somwidget-3dm-") as folder:
        out = f"{folder}/clay.3dm"
        if not model.Write(out, 8):
            raise ValueError(f"{label}: rhino3dm could not write the .3dm file")
        with open(out, "rb") as f:
            return f.read()


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
