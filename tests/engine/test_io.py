"""io: mesh import from files trimesh writes, export round trips, and session save / load."""

from __future__ import annotations

import zipfile

import helpers
import numpy as np
import pytest
import trimesh

from somwidget.backend import io, session_file
from somwidget.backend.presets import (
    KEPT_SHAPE_REACH,
    XYZ,
    FeatureLayout,
    Preset,
    colours_of,
    get_preset,
    line_display_mesh,
)
from somwidget.backend.topology import Topology

LOAD_FORMATS = ["obj", "ply", "stl", "off", "glb"]


def source_mesh() -> trimesh.Trimesh:
    """An icosphere (162 vertices, 320 faces) stretched, moved and scaled away from the origin."""
    m = trimesh.creation.icosphere(subdivisions=2)
    m.vertices = m.vertices * np.array([2.0, 1.0, 0.5]) * 5.0 + np.array([3.0, -2.0, 1.0])
    return m


def rows_sorted(a) -> np.ndarray:
    a = np.round(np.asarray(a, np.float64), 4)
    return a[np.lexsort(a.T[::-1])]


#: Export formats that keep vertex colours (STL keeps none), and those load_mesh reads back (trimesh's).
COLOURED = [e for e in io.EXPORT_FORMATS if e != "stl"]
READ_BACK = [e for e in io.EXPORT_FORMATS if e != "3dm"]
#: Formats that keep the vertices once each, in order (STL keeps each triangle's corners: test_export_formats.py).
ORDERED = [e for e in io.EXPORT_FORMATS if e != "stl"]


def geometry_of(path):
    """The one geometry trimesh (rhino3dm for .3dm) reads back from a file (a Scene's single geometry, or the object
    itself)."""
    if str(path).endswith(".3dm"):
        return helpers.read_3dm(path)["clay"]
    if str(path).endswith(".stl"):  # each triangle's corners apart: merged, as a reader does
        mesh = trimesh.load(str(path), process=False)
        mesh.merge_vertices()
        return mesh
    loaded = trimesh.load(str(path), process=False)
    geoms = loaded.dump() if isinstance(loaded, trimesh.Scene) else [loaded]
    assert len(geoms) == 1
    return geoms[0]


# --------------------------------------------------------------------------------------------------- load
@pytest.mark.parametrize("ext", LOAD_FORMATS)
def test_load_mesh_round_trip(tmp_path, ext):
    src = source_mesh()
    path = tmp_path / f"shape.{ext}"
    src.export(str(path))
    preset = io.load_mesh(path)
    assert isinstance(preset, Preset) and preset.display == "surface" and preset.layout == XYZ
    assert preset.name == "shape" and preset.title == f"shape.{ext}"
    # duplicates merged: STL's 960 corners become the 162 vertices again
    assert preset.topology.n_vertices == 162 and len(preset.topology.faces) == 320
    assert len(preset.topology.edges) == 480
    assert preset.weights.dtype == np.float32 and preset.weights.shape == (162, 3)
    # normalised: bounding box centred on the origin, longest side spanning [-1, 1]
    lo, hi = preset.weights.min(axis=0), preset.weights.max(axis=0)
    np.testing.assert_allclose((lo + hi) / 2, 0, atol=1e-6)
    assert float((hi - lo).max()) == pytest.approx(2.0, abs=1e-6)
    # the remembered transform maps the original vertices onto the normalised ones
    t = preset.meta["transform"]
    expected = (np.asarray(src.vertices) - np.asarray(t["centre"])) * t["scale"]
    np.testing.assert_allclose(rows_sorted(preset.weights), rows_sorted(expected), atol=2e-4)
    np.testing.assert_allclose(t["centre"], [3.0, -2.0, 1.0], atol=1e-6)
    assert t["scale"] == pytest.approx(2.0 / 20.0, rel=1e-6)
    assert preset.meta["source"] == str(path)
    # the person's own shape: kept as it is, six 3-D controls on its vertices, spread over it
    assert not preset.grow and preset.reach == KEPT_SHAPE_REACH
    assert preset.controls.shape == (6, 3)
    gaps = np.sqrt(((preset.controls[:, None] - preset.weights[None]) ** 2).sum(-1)).min(axis=1)
    np.testing.assert_array_equal(gaps, 0.0)
    apart = np.sqrt(((preset.controls[:, None] - preset.controls[None]) ** 2).sum(-1))
    assert apart[~np.eye(6, dtype=bool)].min() > 0.5  # spread, not bunched (the mesh spans 2)
    som = preset.make_som(device="cpu")
    assert som.step(2) == 2


def test_load_mesh_keeps_topology_of_a_quad_obj(tmp_path):
    path = tmp_path / "quads.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\nf 1 2 3 4\nf 2 5 6 3\n")
    preset = io.load_mesh(path)
    assert preset.topology.n_vertices == 6
    assert len(preset.topology.faces) == 4  # trimesh triangulates polygons on import
    assert preset.weights[:, 2].max() == preset.weights[:, 2].min() == 0  # flat in z stays flat


def test_load_mesh_scene_with_two_meshes(tmp_path):
    a = trimesh.creation.box()
    b = trimesh.creation.box()
    b.apply_translation([3, 0, 0])
    path = tmp_path / "two.glb"
    trimesh.Scene([a, b]).export(str(path))
    preset = io.load_mesh(path)
    assert preset.topology.n_vertices == 16 and len(preset.topology.faces) == 24
    assert preset.weights[:, 0].min() == pytest.approx(-1.0) and preset.weights[:, 0].max() == pytest.approx(1.0)


def _bad(tmp_path, name: str, content: str | bytes) -> str:
    path = tmp_path / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


BAD_FILES = {
    "empty.obj": ("", "no mesh"),
    "garbage.obj": ("hello world\nthis is not a mesh\n", "no mesh"),
    "garbage.ply": ("hello world\n", "cannot be read"),
    "garbage.stl": (b"\x00\x01garbage" * 3, "no mesh"),
    "garbage.glb": (b"glTFgarbage", "cannot be read"),
    "points.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
    "nan.obj": ("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", "NaN or infinite"),
    "inf.obj": ("v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n", "NaN or infinite"),
    "same.obj": ("v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n", "all vertices coincide"),
    "notes.txt": ("v 0 0 0\n", "cannot be read"),
}


@pytest.mark.parametrize("name", list(BAD_FILES))
def test_load_mesh_bad_files(tmp_path, name):
    content, problem = BAD_FILES[name]
    path = _bad(tmp_path, name, content)
    with pytest.raises(ValueError, match=problem) as info:
        io.load_mesh(path)
    assert str(path) in str(info.value) and name in str(info.value)


def test_load_mesh_point_cloud_ply(tmp_path):
    path = tmp_path / "cloud.ply"
    trimesh.PointCloud(np.arange(30, dtype=float).reshape(10, 3)).export(str(path))
    with pytest.raises(ValueError, match="no faces") as info:
        io.load_mesh(path)
    assert "cloud.ply" in str(info.value)


def test_load_mesh_missing_file_and_directory(tmp_path):
    with pytest.raises(ValueError, match="no such file") as info:
        io.load_mesh(tmp_path / "nowhere.obj")
    assert "nowhere.obj" in str(info.value)
    with pytest.raises(ValueError, match="not a file") as info:
        io.load_mesh(tmp_path)
    assert str(tmp_path) in str(info.value)


def test_load_mesh_too_many_vertices(tmp_path):
    path = tmp_path / "big.stl"
    source_mesh().export(str(path))  # 960 corners in the file, 162 vertices once merged
    assert io.load_mesh(path, max_vertices=162).topology.n_vertices == 162
    with pytest.raises(ValueError, match="limit of 161") as info:
        io.load_mesh(path, max_vertices=161)
    assert "big.stl" in str(info.value) and "162" in str(info.value)
    assert io.MAX_VERTICES == 65536


# ------------------------------------------------------------------------------------------------- export
@pytest.mark.parametrize("ext", ORDERED)
@pytest.mark.parametrize("name", ["car", "sphere", "grid", "torus"])
def test_export_surface_round_trip(tmp_path, name, ext):
    p = get_preset(name)
    som = p.make_som(device="cpu")
    som.step(20)
    w = som.weights
    path = tmp_path / f"{name}.{ext}"
    io.export_mesh(path, w, p.topology, p.layout)
    g = geometry_of(path)
    assert isinstance(g, trimesh.Trimesh)
    n_tri = sum(len(f) - 2 for f in p.topology.faces)
    want = np.round(colours_of(w, p.layout) * 255)
    pts, tris, cols = io.weld(w[:, :3], io.triangulate(p.topology.faces), want)  # nodes a control pulled together
    np.testing.assert_allclose(g.vertices, pts, atol=1e-5)  # the same vertices, in the same order
    assert len(g.faces) == len(tris) and n_tri - len(tris) <= 8
    if ext in COLOURED:
        np.testing.assert_allclose(np.asarray(g.visual.vertex_colors)[:, :3], cols, atol=1)
    if ext not in READ_BACK:
        return
    # load_mesh reads our own export of the start shape back (a partly trained SOM can have neurons so close
    # together that merging duplicate vertices joins them, so the untrained start is the fair round trip)
    start = tmp_path / f"{name}_start.{ext}"
    io.export_mesh(start, p.weights, p.topology, p.layout)
    back = io.load_mesh(start)
    assert back.topology.n_vertices == p.topology.n_vertices
    assert len(back.topology.faces) == n_tri


@pytest.mark.parametrize("ext", io.EXPORT_FORMATS)
def test_a_trained_car_exports_clean_and_stays_closed_after_a_vertex_merge(tmp_path, ext):
    """The paper's rule pulls the car's pole caps onto points (18 pairs of nodes within 1e-4 of each other, some
    exactly): the export has no face without area, welds the neighbours that coincide, sets the touching sheets
    apart, and stays watertight when any tool merges its vertices (trimesh's merge_vertices here)."""
    p = get_preset("car")
    som = p.make_som(device="cpu")
    som.train()
    w = som.weights
    raw = trimesh.Trimesh(w[:, :3], io.triangulate(p.topology.faces), process=False)
    raw.merge_vertices()
    assert not raw.is_watertight  # what an export of the nodes as they are would give: a check that can fail
    path = tmp_path / f"car.{ext}"
    io.export_mesh(path, w, p.topology, p.layout)
    g = geometry_of(path)
    size = np.linalg.norm(np.ptp(g.vertices, axis=0))
    assert g.is_watertight and g.area_faces.min() > (1e-6 * size) ** 2
    edges = g.edges_unique_length
    assert edges.min() > 1e-6 * size
    g.merge_vertices()
    assert g.is_watertight and g.is_winding_consistent
    from somwidget.backend import metrics  # the shape is kept: every vertex on a node, every node on a vertex

    v = np.asarray(geometry_of(path).vertices)
    assert metrics.nearest_distances(v, w[:, :3]).max() < 1e-4 * size
    assert metrics.nearest_distances(w[:, :3], v).max() < 1e-4 * size


@pytest.mark.parametrize("ext", ORDERED)
def test_export_lines_round_trip(tmp_path, ext):
    p = get_preset("lines")
    path = tmp_path / f"lines.{ext}"
    io.export_mesh(path, p.weights, p.topology, p.layout)  # display inferred from the layout: lines
    g = geometry_of(path)
    pts, quads = line_display_mesh(p.weights, p.topology, p.layout)
    assert len(g.vertices) == 1204 and len(g.faces) == 2 * len(quads) == 2450
    np.testing.assert_allclose(g.vertices, pts, atol=1e-5)
    cols = np.round(colours_of(p.weights, p.layout) * 255)
    if ext in COLOURED:
        np.testing.assert_allclose(np.asarray(g.visual.vertex_colors)[:, :3], np.concatenate([cols, cols]), atol=1)


@pytest.mark.parametrize("ext", [e for e in io.EXPORT_FORMATS if e != "stl"])
def test_export_points_for_an_edge_topology(tmp_path, ext):
    p = get_preset("lattice")
    path = tmp_path / f"cloud.{ext}"
    io.export_mesh(path, p.weights, p.topology, p.layout)  # no faces: a point cloud
    g = geometry_of(path)
    assert isinstance(g, trimesh.PointCloud) and len(g.vertices) == 512
    np.testing.assert_allclose(g.vertices, p.weights, atol=1e-5)
    with pytest.raises(ValueError, match="no faces"):
        io.export_mesh(tmp_path / f"surf.{ext}", p.weights, p.topology, p.layout, display="surface")


def test_export_car_surface_points_and_transform(tmp_path):
    p = get_preset("car")
    io.export_mesh(tmp_path / "car_points.ply", p.weights, p.topology, p.layout, display="points")
    assert isinstance(geometry_of(tmp_path / "car_points.ply"), trimesh.PointCloud)
    # a loaded mesh exported with its transform lands back in the file's frame
    src = source_mesh()
    src.export(str(tmp_path / "src.obj"))
    loaded = io.load_mesh(tmp_path / "src.obj")
    io.export_mesh(tmp_path / "back.obj", loaded.weights, loaded.topology, loaded.layout,
                   transform=loaded.meta["transform"])
    np.testing.assert_allclose(geometry_of(tmp_path / "back.obj").vertices, src.vertices, atol=1e-4)


def test_export_refuses_unknown_formats_and_bad_weights(tmp_path):
    p = get_preset("sphere")
    for name in ("shape.fbx", "shape.txt", "shape"):
        with pytest.raises(ValueError, match="cannot export") as info:
            io.export_mesh(tmp_path / name, p.weights, p.topology, p.layout)
        assert name in str(info.value)
        assert not (tmp_path / name).exists()
    with pytest.raises(ValueError, match="shape"):
        io.export_mesh(tmp_path / "x.obj", p.weights[:, :2], p.topology, p.layout)
    with pytest.raises(ValueError, match="display"):
        io.export_mesh(tmp_path / "x.obj", p.weights, p.topology, p.layout, display="voxels")
    lattice = get_preset("lattice")  # points only: STL holds triangles
    with pytest.raises(ValueError, match="x.stl: STL holds triangles only"):
        io.export_mesh(tmp_path / "x.stl", lattice.weights, lattice.topology, lattice.layout)
    with pytest.raises(ValueError, match="x.3dm: unknown units 'furlongs'"):
        io.export_mesh(tmp_path / "x.3dm", p.weights, p.topology, p.layout, units="furlongs")
    with pytest.raises(ValueError, match=r"x.glb: controls have shape \(2, 2\)"):
        io.export_mesh(tmp_path / "x.glb", p.weights, p.topology, p.layout, controls=np.zeros((2, 2)))


def test_triangulate_fans():
    np.testing.assert_array_equal(io.triangulate([[0, 1, 2, 3]]), [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_array_equal(io.triangulate([[5, 6, 7], [0, 1, 2, 3, 4], [8, 9]]),
                                  [[5, 6, 7], [0, 1, 2], [0, 2, 3], [0, 3, 4]])
    np.testing.assert_array_equal(io.triangulate(np.array([[0, 1, 2, 3], [4, 5, 6, 7]])),
                                  [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    assert io.triangulate([]).shape == (0, 3)


# ------------------------------------------------------------------------------------------------ sessions
def assert_states_equal(a: dict, b: dict):
    for key in ("weights", "start_weights", "controls"):
        np.testing.assert_array_equal(a[key], b[key])
        assert b[key].dtype == np.float32
    for key in ("preset", "display", "iterations", "iteration", "l_start", "l_end", "smoothing", "reach", "mirror",
                "smooth_dims", "layout"):
        assert a[key] == b[key], key
    if a["metric_weights"] is None:
        assert b["metric_weights"] is None
    else:
        np.testing.assert_array_equal(a["metric_weights"], b["metric_weights"])
    ta, tb = a["topology"], b["topology"]
    assert ta.n_vertices == tb.n_vertices == b["n_vertices"]
    np.testing.assert_array_equal(ta.edges, tb.edges)
    if ta.faces is None:
        assert tb.faces is None
    else:
        assert len(ta.faces) == len(tb.faces)
        for fa, fb in zip(ta.faces, tb.faces):
            np.testing.assert_array_equal(fa, fb)


@pytest.mark.parametrize("name", ["car", "lines", "space-grid"])
def test_session_round_trip(tmp_path, name):
    p = get_preset(name)
    som = p.make_som(device="cpu")
    som.step(7)
    som.set_controls(som.controls + 0.1)
    som.step(3)
    assert som.iteration == som.restart_iteration + 3
    state = session_file.session_state(p, som)
    path = tmp_path / "session.somwidget"  # any extension: written as it is, no ".npz" appended
    session_file.save_session(path, state)
    assert path.is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["session.somwidget"]
    assert zipfile.is_zipfile(path)
    with np.load(path, allow_pickle=False) as z:  # plain arrays only: readable without pickle
        assert int(z["format_version"]) == session_file.SESSION_FORMAT_VERSION
        assert all(z[k].dtype != object for k in z.files)
    back = session_file.load_session(path)
    assert back["format_version"] == session_file.SESSION_FORMAT_VERSION
    assert back["iteration"] == som.iteration and back["preset"] == name and back["reach"] == p.reach
    assert_states_equal(state | {"smooth_dims": tuple(state["smooth_dims"]), "mirror": tuple(state["mirror"])}, back)
    # a saved session comes back to life: same start, controls and settings; carry on exactly from the saved
    # weights and s, as the saved run would have gone on
    again = session_file.preset_from_session(back)
    som2 = again.make_som(device="cpu")
    som2.restore(back["weights"], back["iteration"])
    np.testing.assert_array_equal(som2.weights, som.weights)
    np.testing.assert_array_equal(som2.controls, som.controls)
    assert som2.reach == som.reach and som2.iteration == som.iteration
    som.train()
    som2.train()
    np.testing.assert_array_equal(som2.weights, som.weights)
    # a loaded state saves again unchanged
    session_file.save_session(tmp_path / "again.npz", back)
    assert_states_equal(back, session_file.load_session(tmp_path / "again.npz"))


def test_session_defaults_and_mixed_faces(tmp_path):
    faces = [[0, 1, 2], [0, 2, 3, 4], [4, 3, 5, 6, 7]]
    topo = Topology.from_faces(faces)
    layout = FeatureLayout(names=("x", "y", "z", "r", "g", "b"), position=(0, 1, 2), colour=(3, 4, 5),
                           colour_space="rgb")
    w = np.arange(48, dtype=np.float32).reshape(8, 6) / 48
    state = {"weights": w, "start_weights": w * 2, "controls": w[:2], "topology": topo, "layout": layout,
             "metric_weights": np.array([1, 1, 1, 0.5, 0.5, 0.5]), "smooth_dims": (0, 1)}
    session_file.save_session(tmp_path / "s.npz", state)
    back = session_file.load_session(tmp_path / "s.npz")
    assert [list(f) for f in back["topology"].faces] == faces
    assert back["iterations"] == 1000 and back["iteration"] == 0 and back["mirror"] == () and back["preset"] == ""
    assert back["smooth_dims"] == (0, 1) and back["metric_weights"].tolist() == [1, 1, 1, 0.5, 0.5, 0.5]
    assert back["layout"] == layout


def test_save_session_refuses_bad_states(tmp_path):
    p = get_preset("sphere")
    good = session_file.session_state(p)
    path = tmp_path / "bad.npz"
    missing = dict(good)
    del missing["controls"]
    with pytest.raises(ValueError, match="'controls'") as info:
        session_file.save_session(path, missing)
    assert "bad.npz" in str(info.value)
    with pytest.raises(ValueError, match="unknown session keys"):
        session_file.save_session(path, good | {"colour": "red"})
    with pytest.raises(ValueError, match="'weights'"):
        session_file.save_session(path, good | {"weights": good["weights"][:-1]})
    with pytest.raises(ValueError, match="'iteration'"):
        session_file.save_session(path, good | {"iteration": 2000})
    with pytest.raises(ValueError, match="'topology'"):
        session_file.save_session(path, good | {"topology": "sphere"})
    assert not path.exists() and list(tmp_path.iterdir()) == []  # nothing half-written


def _rewrite(src, dst, drop=(), **replace):
    with np.load(src, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files if k not in drop}
    data.update(replace)
    with open(dst, "wb") as f:
        np.savez_compressed(f, **data)
    return dst


def test_load_session_errors(tmp_path):
    p = get_preset("car")
    good = tmp_path / "good.npz"
    session_file.save_session(good, session_file.session_state(p))
    cases = {
        "missing.npz": (None, "no such session file"),
        "garbage.npz": (b"this is not a zip archive" * 10, "not a readable somwidget session"),
        "truncated.npz": (good.read_bytes()[: len(good.read_bytes()) // 2], "not a readable somwidget session"),
    }
    for name, (content, problem) in cases.items():
        path = tmp_path / name
        if content is not None:
            path.write_bytes(content)
        with pytest.raises(ValueError, match=problem) as info:
            session_file.load_session(path)
        assert name in str(info.value)
    npy = tmp_path / "array.npy"
    np.save(npy, np.zeros(3))
    with pytest.raises(ValueError, match="npz") as info:
        session_file.load_session(npy)
    assert "array.npy" in str(info.value)
    keyed = {
        "no_weights.npz": (dict(drop=("weights",)), "'weights'"),
        "no_version.npz": (dict(drop=("format_version",)), "'format_version'"),
        "future.npz": (dict(format_version=np.int64(99)), "'format_version'"),
        "short.npz": (dict(weights=np.zeros((3, 5), np.float32)), "'weights'"),
        "nan.npz": (dict(controls=np.full((9, 5), np.nan, np.float32)), "'controls'"),
        "faces.npz": (dict(face_sizes=np.array([3, 4], np.int64)), "'face_sizes'"),
        "kind.npz": (dict(topology_kind=np.str_("voxels")), "'topology_kind'"),
        "mirror.npz": (dict(mirror=np.array([7])), "'mirror'"),
        "iteration.npz": (dict(iteration=np.array([1, 2])), "'iteration'"),
        "layout.npz": (dict(layout_colour_space=np.str_("cmyk")), "layout"),
        "pickled.npz": (dict(preset=np.array([{"a": 1}], dtype=object)), "not a readable somwidget session"),
    }
    for name, (change, problem) in keyed.items():
        path = _rewrite(good, tmp_path / name, **change)
        with pytest.raises(ValueError, match=problem) as info:
            session_file.load_session(path)
        assert name in str(info.value), info.value


def test_load_session_refuses_a_member_that_would_unpack_too_large(tmp_path):
    """A small archive whose member inflates to hundreds of MB is refused before anything is decompressed."""
    import io as byte_io

    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as archive:
        buf = byte_io.BytesIO()
        np.save(buf, np.zeros(100_000_000, np.uint8))
        archive.writestr("weights.npy", buf.getvalue())
    assert bomb.stat().st_size < 1_000_000
    with pytest.raises(ValueError, match="bomb.npz.*unpacks to"):
        session_file.load_session(bomb)


def test_a_mesh_past_the_limit_is_refused_with_the_figures_or_loaded_decimated(tmp_path):
    m = trimesh.creation.icosphere(subdivisions=4)  # 2562 vertices
    path = tmp_path / "ball.ply"
    m.export(str(path))
    with pytest.raises(io.TooManyVertices, match="2,562 vertices .* exceed the limit of 1,000") as info:
        io.load_mesh(path, max_vertices=1000)
    assert (info.value.n, info.value.limit) == (2562, 1000)
    p = io.load_mesh(path, max_vertices=1000, decimate=True)
    assert 300 < p.n_vertices <= 1000 and "decimated from 2,562" in p.description
    from somwidget.backend import metrics  # the shape kept: every coarse vertex near the sphere, and the other way

    sphere = np.asarray(m.vertices) / np.abs(m.vertices).max()
    assert metrics.nearest_distances(p.weights, sphere).max() < 0.1
    assert metrics.chamfer(p.weights, sphere) < 0.05
