"""Exports for the next tool (issue 36, item 6): a trained session written to every format and read back with the
library a person's next tool uses (trimesh for OBJ, PLY, STL, glTF, GLB; rhino3dm for .3dm): the vertices where the
nodes are to 1e-6 of the clay's size, a closed clay still closed (watertight), the controls as named nodes (glTF) or
named points on their own layer with the file's units (.3dm), and the file named after the session."""

from __future__ import annotations

import datetime

import helpers
import numpy as np
import pytest
import trimesh

from somwidget.backend import io, metrics
from somwidget.backend.presets import positions_of
from somwidget.frontend.model import Session
from somwidget.frontend.model.files import export_name


@pytest.fixture(scope="module")
def sphere():
    """The sphere preset trained to its end with one control moved and a radius set (a closed clay)."""
    s = Session("sphere", device="cpu", autosave=False)
    assert s.wait_idle(120)
    s.set_control_radius(1, 0.25)
    s.move_control(0, s.controls[0, :3] * 1.2)
    assert s.wait_idle(120)
    yield s
    s.close()


def read(path) -> tuple:
    """(the clay as trimesh reads it, {control name: (3,) position}) of an exported file."""
    if path.suffix == ".3dm":
        got = helpers.read_3dm(path)
        return got["clay"], {name: at for name, (at, _layer, _radius) in got["controls"].items()}
    scene = trimesh.load(str(path), process=False, force="scene")
    clay = scene.geometry["clay"] if "clay" in scene.geometry else next(iter(scene.geometry.values()))
    nodes = {n: scene.graph.get(n)[0][:3, 3] for n in scene.graph.nodes if n.startswith("control ")}
    return clay, nodes


@pytest.mark.parametrize("ext", io.EXPORT_FORMATS)
def test_a_closed_clay_round_trips_with_its_controls(sphere, tmp_path, ext):
    snap = sphere.files.snapshot()
    preset = snap["preset"]
    path = tmp_path / export_name(preset.name, ext)
    sphere.export_mesh(path)
    clay, nodes = read(path)

    # the reference: the nodes' positions in float64, welded as the export welds them (io.weld is tested on its own)
    w = snap["weights"].astype(np.float64)
    pts, tris, _ = io.weld(positions_of(w, preset.layout), io.triangulate(preset.topology.faces))
    size = float(np.linalg.norm(np.ptp(pts, axis=0)))
    if ext == "stl":  # STL keeps every triangle's corners apart, in float32: a reader merges them
        assert len(clay.vertices) == 3 * len(tris)
        clay.merge_vertices()
        assert len(clay.vertices) == len(pts) and len(clay.faces) == len(tris)
        assert metrics.nearest_distances(np.asarray(clay.vertices), pts).max() <= 1e-6 * size
        assert metrics.nearest_distances(pts, np.asarray(clay.vertices)).max() <= 1e-6 * size
    else:  # the same vertices in the same order
        assert len(clay.vertices) == len(pts) and len(clay.faces) == len(tris)
        assert np.abs(np.asarray(clay.vertices) - pts).max() <= 1e-6 * size
    assert clay.is_watertight and clay.is_winding_consistent
    controls = positions_of(snap["controls"], preset.layout)
    if ext in ("glb", "gltf", "3dm"):
        assert sorted(nodes) == sorted(f"control {i}" for i in range(len(controls)))
        for i, at in enumerate(controls):
            assert np.abs(nodes[f"control {i}"] - at).max() <= 1e-6 * size
    else:
        assert nodes == {}


def test_the_3dm_has_units_layers_and_each_controls_radius(sphere, tmp_path):
    path = tmp_path / "sphere.3dm"
    sphere.export_mesh(path, units="millimeters")
    got = helpers.read_3dm(path)
    assert got["units"] == "Millimeters" and got["layers"] == ["clay", "controls"]
    radii = sphere.files.snapshot()["radii"]
    assert len(got["controls"]) == len(radii) == 6
    for i, r in enumerate(radii):
        _at, layer, radius = got["controls"][f"control {i}"]
        assert layer == "controls" and float(radius) == pytest.approx(float(r), rel=1e-7)
    assert float(got["controls"]["control 1"][2]) == pytest.approx(0.25)
    colours = np.asarray(got["clay"].visual.vertex_colors)
    assert colours.shape == (len(got["clay"].vertices), 4)


def test_a_loaded_mesh_goes_back_in_its_own_frame_with_its_controls(tmp_path):
    """A mesh loaded from a file (normalised inside the session) is exported in the file's frame: its controls too."""
    src = trimesh.creation.icosphere(subdivisions=2)
    src.vertices = src.vertices * 40.0 + np.array([100.0, -20.0, 5.0])  # a 80 mm ball away from the origin
    src.export(str(tmp_path / "ball.stl"))
    s = Session("car", device="cpu", autosave=False, start=False)
    try:
        s.load_mesh(tmp_path / "ball.stl")
        before = datetime.datetime.now()
        path = tmp_path / s.files.export_name("3dm")
        assert path.name in {f"ball-{t:%Y-%m-%d-%H%M}.3dm" for t in (before, datetime.datetime.now())}
        s.export_mesh(path, units="millimeters")
        got = helpers.read_3dm(path)
        np.testing.assert_allclose(np.ptp(got["clay"].vertices, axis=0), np.ptp(src.vertices, axis=0), rtol=1e-6)
        scale = s.preset.meta["transform"]["scale"]
        centre = np.asarray(s.preset.meta["transform"]["centre"])
        first = s.controls[0, :3] / scale + centre
        np.testing.assert_allclose(got["controls"]["control 0"][0], first, atol=1e-6 * 80)
        assert np.linalg.norm(got["controls"]["control 0"][0] - src.vertices, axis=1).min() < 1e-3
    finally:
        s.close()


def test_export_names_say_the_session_the_day_and_the_time():
    """Two exports of a day do not collide (the chair and the canopy of the trial, both grids, did)."""
    when = datetime.datetime(2026, 11, 27, 10, 42, 31)
    assert export_name("sphere", "obj", when) == "sphere-2026-11-27-1042.obj"
    assert export_name("mesh:my chair (v2)", ".3DM", when) == "my-chair-v2-2026-11-27-1042.3dm"
    assert export_name("../../etc/passwd", "stl", when) == "etc-passwd-2026-11-27-1042.stl"
    assert export_name("", "glb", when) == "clay-2026-11-27-1042.glb"
    assert export_name("grid", "obj", when.replace(hour=9, minute=5)) == "grid-2026-11-27-0905.obj"
