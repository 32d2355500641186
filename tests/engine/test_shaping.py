"""The shaping rules in the engine (backend/shaping_path.py, handles.py): controls with a radius (handles), symmetry
groups, Taubin's smoothing, strokes; against the independent float64 reference of the rule (tests/reference_handles.py)
and by the figures a designer sees (the swell's volume, the far side staying, the symmetry kept). Real Warp kernels on
the CPU, and on CUDA where there is a GPU. (The handles' own guarantees and the issue's figures: test_handles.py.)"""

from __future__ import annotations

import numpy as np
import pytest
from reference_handles import HandleSom

from somwidget.backend import io, metrics, presets
from somwidget.backend.shaping_path import ShapingPath
from somwidget.backend.som import Som
from somwidget.backend.symmetry import Symmetry
from somwidget.backend.topology import Topology


def _mesh(n_lon=12, n_rings=7):
    faces, pts = presets.uv_ellipsoid(n_lon, n_rings, (1.0, 0.8, 0.6))
    return Topology.from_faces(faces, len(pts)), pts.astype(np.float32), faces


def _volume(points, faces) -> float:
    t = io.triangulate(faces)
    p = np.asarray(points, np.float64)
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    return abs(float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)


def _reference(faces, pts, controls, radii=None, symmetry=None, mirror=(), **kw) -> HandleSom:
    """The float64 reference of the same Som (a mirror as the group of its dim)."""
    maps = symmetry.maps(3) if symmetry is not None else Symmetry.mirror(mirror[0]).maps(3) if mirror else None
    kw.setdefault("smoothing_rule", "laplacian")
    return HandleSom(np.asarray(pts, np.float64), np.asarray(controls, np.float64), radii, faces=faces, maps=maps,
                     **kw)


def _compare(som: Som, ref: HandleSom, cycles: int, tol: float) -> None:
    """Run both the same cycles; the point controls' winners well apart all along (no near-tie decides the
    comparison)."""
    som.step(cycles)
    ref.step(cycles)
    margin = min((float(np.min(m)) for m in ref.margins), default=float("inf"))
    assert margin > 1e-4, f"a near-tie ({margin:.2e}): choose another case"
    size = metrics.bounding_diagonal(ref.W[:, :3])
    err = np.abs(som.weights.astype(np.float64) - ref.W).max() / size
    assert err < tol, f"engine and float64 reference part by {err:.2e} of the size"


def _on_shaping_path(som: Som) -> bool:
    """Whether the shaping path runs the Som's next cycles (Som.parts, the engine's internal API)."""
    return isinstance(som.parts.next_path(), ShapingPath)


def test_point_controls_keep_the_case_studies_path():
    topo, pts, _ = _mesh()
    som = Som(topo, pts, pts[[0, 20]], device="cpu", radii=[0.0, 0.0], mirror=(1,))
    assert not _on_shaping_path(som)  # the case studies' paths, bit for bit
    som.radii = [0.0, 0.3]
    assert _on_shaping_path(som)
    som.radii = [0.0, 0.0]
    som.smoothing, som.smoothing_rule = 0.2, "laplacian"
    assert not _on_shaping_path(som)


@pytest.mark.parametrize("mirror", [(), (1,)])
def test_radius_rule_matches_the_float64_reference(device, mirror):
    """Typed moves: each moved control with a radius grabbed at its old place and released at once."""
    topo, pts, faces = _mesh()
    controls = pts[[3, 40, 70]].copy()
    controls[0, :3] += [0.0, 0.0, 0.35]  # pulled out
    controls[1, :3] *= 0.85  # pushed in
    radii = [0.6, 0.0, 0.4]  # a point control among controls with radii
    kw = dict(iterations=300, l_start=0.25, l_end=0.03, reach=0.3)
    som = Som(topo, pts, pts[[3, 40, 70]], device=device, radii=radii, mirror=mirror, **kw)
    ref = _reference(faces, pts, pts[[3, 40, 70]], radii, mirror=mirror, **kw)
    som.restore(pts, 300)
    som.set_controls(controls)
    ref.set_controls(controls)
    _compare(som, ref, 90, 2e-5)
    moved = np.linalg.norm(som.weights - pts, axis=1)
    assert moved.max() > 0.05  # the run did something worth comparing


def test_radial_group_matches_the_float64_reference(device):
    """A point control and its copies under 4-fold symmetry; the control with a radius, never moved, does nothing."""
    topo, pts, faces = _mesh(n_lon=12)
    group = Symmetry.radial(4, 2)
    controls = pts[[14, 50]].copy()
    controls[:, :2] *= 1.3
    kw = dict(iterations=200, reach=0.3)
    som = Som(topo, pts, controls, device=device, radii=[0.5, 0.0], symmetry=group, **kw)
    ref = _reference(faces, pts, controls, [0.5, 0.0], group, **kw)
    ref.restart()
    som.restart()
    _compare(som, ref, 60, 2e-5)
    eff = som.effective_controls
    assert eff.shape == (8, 3)
    np.testing.assert_allclose(eff[2], group.maps(3)[1] @ controls[0], atol=1e-6)  # copy j of control j mod k


def test_taubin_smoothing_matches_the_float64_reference(device):
    """Point controls with Taubin's smoothing: lambda and mu, the volume put back, the clamp into the box."""
    topo, pts, faces = _mesh()
    kw = dict(iterations=200, reach=0.5, smoothing=0.3, smoothing_rule="taubin")
    som = Som(topo, pts, pts[[3, 40]], device=device, **kw)
    ref = _reference(faces, pts, pts[[3, 40]], **kw)
    som.restart()
    ref.restart()
    _compare(som, ref, 50, 2e-5)


def test_a_radial_start_stays_radial(device):
    """The sphere preset (32 longitudes) with 8-fold symmetry about z: a control with a radius pulled out, the copies
    follow, and every node's rotated image stays on its partner to 1e-4 of the size."""
    p = presets.get_preset("sphere")
    group = Symmetry.radial(8, 2)
    pts = p.weights.astype(np.float32)
    rot = group.rotations()[1]
    image = pts.astype(np.float64) @ rot.T
    partner = np.argmin(((image[:, None, :] - pts[None, :, :]) ** 2).sum(-1), axis=1)
    assert np.abs(pts[partner] - image).max() < 1e-5  # the start is 8-fold symmetric
    c = pts[[100]].copy()
    c[0, :2] *= 1.4
    som = Som(p.topology, pts, pts[[100]], device=device, radii=[0.6], symmetry=group, reach=0.3)
    som.restore(pts, som.iterations)
    som.set_controls(c)  # a typed move: each copy's patch goes with it
    som.train()
    w = som.weights.astype(np.float64)
    size = metrics.bounding_diagonal(w)
    assert np.linalg.norm(w - pts, axis=1).max() > 0.05 * size  # it moved
    assert np.abs(w[partner] - w @ rot.T).max() / size < 1e-4


@pytest.mark.parametrize("whole", [True, False], ids=["whole run", "local restart"])
@pytest.mark.parametrize("strength", [0.1, 0.3])
def test_taubin_keeps_the_sphere_s_volume(whole, strength):
    """Smoothing with lambda up to 0.3 changes the sphere's volume by at most 1% against the same run without it
    (the paper's Laplacian step shrinks it to a third)."""
    p = presets.get_preset("sphere")
    size = metrics.bounding_diagonal(p.weights)

    def volume(rule, lam):
        som = Som(p.topology, p.weights, p.controls, device="cpu", reach=0.3, smoothing=lam, smoothing_rule=rule,
                  radii=np.full(len(p.controls), 0.25 * size, np.float32))
        if whole:
            som.reset()
        else:
            som.restore(p.weights, som.iterations)
            som.restart()
        som.train()
        return _volume(som.weights, p.topology.faces)

    plain = volume("laplacian", 0.0)
    assert abs(volume("taubin", strength) / plain - 1.0) < 0.01
    if whole:
        assert volume("laplacian", strength) / plain < 0.6  # what the paper's step does: a check that can fail


def test_a_control_with_a_radius_swells_the_sphere_where_the_paper_s_rule_makes_a_spike():
    p = presets.get_preset("sphere")
    pts = p.weights.astype(np.float64)
    size = metrics.bounding_diagonal(pts)
    out = {}
    for name, radius, reach in (("paper", 0.0, 0.3), ("radius", 0.25 * size, 0.3)):
        som = Som(p.topology, p.weights, p.controls, device="cpu", reach=reach,
                  radii=np.full(len(p.controls), radius, np.float32))
        som.restore(p.weights, som.iterations)
        c = som.controls
        i = 1  # a control away from the poles
        c[i] += 0.3 * size * c[i] / np.linalg.norm(c[i])
        som.set_controls(c)
        som.train()
        w = som.weights.astype(np.float64)
        out[name] = dict(volume=_volume(w, p.topology.faces) / _volume(pts, p.topology.faces),
                         far=metrics.far_half_moved(pts, w, c[i]),
                         gap=float(metrics.nearest_distances(c[i:i + 1], w)[0]) / size)
    assert out["radius"]["volume"] >= 0.95 and out["radius"]["far"] <= 0.02 and out["radius"]["gap"] <= 0.01
    assert out["paper"]["volume"] < out["radius"]["volume"] - 0.1  # the paper's rule at this reach caves in


def test_radii_and_symmetry_are_checked():
    topo, pts, _ = _mesh()
    with pytest.raises(ValueError, match="radii: expected one radius per control"):
        Som(topo, pts, pts[:2], device="cpu", radii=[0.1])
    with pytest.raises(ValueError, match="radii: each radius"):
        Som(topo, pts, pts[:2], device="cpu", radii=[0.1, -1.0])
    with pytest.raises(ValueError, match="radii"):
        Som(topo, pts, pts[:2], device="cpu", radii=[0.1, float("nan")])
    with pytest.raises(ValueError, match="symmetry: expected a Symmetry"):
        Som(topo, pts, pts[:2], device="cpu", symmetry="radial")
    with pytest.raises(ValueError, match="either symmetry or mirror"):
        Som(topo, pts, pts[:2], device="cpu", symmetry=Symmetry.mirror(1), mirror=(1,))
    with pytest.raises(ValueError, match="n: expected at least 2 and at most 32"):
        Symmetry.radial(33, 2)
    with pytest.raises(ValueError, match="counting symmetric copies"):
        Som(topo, pts, np.repeat(pts[:1], 9, axis=0), device="cpu", symmetry=Symmetry.radial(32, 2))
    with pytest.raises(ValueError, match="do not fit 2 feature dims"):
        Som(topo, pts[:, :2], pts[:2, :2], device="cpu", symmetry=Symmetry.radial(4, 2))
    assert Symmetry.parse("radial-6-z-mirror") == Symmetry.radial(6, 2, mirror=True)
    assert Symmetry.parse(Symmetry.mirror("x").spec) == Symmetry.mirror(0) and Symmetry.parse("none") is None
    with pytest.raises(ValueError, match="expected none, mirror-x"):
        Symmetry.parse("spiral")
    with pytest.raises(ValueError, match="smoothing_rule"):
        Som(topo, pts, pts[:2], device="cpu", smoothing_rule="bilaplacian")


# -- in a session ------------------------------------------------------------------------------------------------
def test_a_session_s_controls_carry_their_radii_through_edits_undo_and_files(tmp_path):
    from somwidget.frontend.model import Session

    with Session("sphere", device="cpu", autosave=False) as s:
        size = metrics.bounding_diagonal(s.preset.weights)
        # a kept shape's controls start with a radius
        assert np.allclose(s.control_edits.radii, presets.KEPT_SHAPE_RADIUS * size)
        i = s.add_control([0.0, 0.0, 1.3], radius=0.3)
        s.set_control_radius(0, 0.5)
        s.set_control_radius(0, 0.45)  # a slider's drag: one step
        assert s.wait_applied(30)
        np.testing.assert_allclose(s.frame.radii[[0, i]], [0.45, 0.3])
        np.testing.assert_allclose(s.modelling.som.radii[[0, i]], [0.45, 0.3])
        with pytest.raises(ValueError, match="radius"):
            s.set_control_radius(0, -1)
        with pytest.raises(ValueError, match="new control radius"):
            s.add_control([0.0, 0.0, 1.0], radius=float("inf"))
        s.settings.set_symmetry("radial-4-z")
        assert s.wait_applied(30) and s.wait_idle(60)
        assert s.parameters["group"] == "radial-4-z" and len(s.frame.effective_controls) == 4 * s.n_controls
        assert s.n_controls == 7  # a group turned on keeps every control (each with its own copies): nothing merges
        s.save(tmp_path / "s.npz")
        radii = s.control_edits.radii
        assert s.undo() and s.parameters["group"] == "none"
        # both radius changes: one step
        assert s.undo() and s.control_edits.radii[0] == pytest.approx(presets.KEPT_SHAPE_RADIUS * size)
        s.load(tmp_path / "s.npz")
        assert s.parameters["group"] == "radial-4-z"
        np.testing.assert_allclose(s.control_edits.radii, radii)
        s.remove_control(s.n_controls - 1)
        assert len(s.control_edits.radii) == s.n_controls == len(radii) - 1


def test_a_case_study_keeps_its_point_controls():
    from somwidget.frontend.model import Session

    with Session("car", device="cpu", autosave=False, start=False) as s:
        assert not s.control_edits.radii.any() and not _on_shaping_path(s.modelling.som)
        s.add_control(s.controls[0])
        assert s.control_edits.radii[-1] == 0.0


# -- refine --------------------------------------------------------------------------------------------------------
def test_subdivision_keeps_the_surface_and_the_node_order():
    from somwidget.backend import refine

    p = presets.get_preset("sphere")
    faces, w = refine.subdivide(p.topology.faces, p.weights)
    n = p.topology.n_vertices
    np.testing.assert_array_equal(w[:n], p.weights)  # the old nodes stay, in order
    topo = Topology.from_faces(faces, len(w))
    assert topo.n_vertices == len(w) > 3 * n
    # every new node lies on the old surface: on an old edge or in an old face
    old = metrics.triangles_of(p.topology.faces)
    a, b, c = (p.weights[old[:, i]].astype(np.float64) for i in range(3))
    normals = np.cross(b - a, c - a)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    off = np.abs(np.einsum("tk,vtk->vt", normals, w[n:, None, :].astype(np.float64) - a[None])).min(axis=1)
    size = metrics.bounding_diagonal(p.weights)
    assert off.max() < 0.005 * size
    assert abs(metrics.mesh_volume(w, metrics.triangles_of(faces)) / metrics.mesh_volume(p.weights, old) - 1) < 0.01


def test_stretched_edges_are_split_and_the_mesh_stays_closed():
    from somwidget.backend import refine

    p = presets.get_preset("sphere")
    w = p.weights.copy()
    w[:40, 2] += 1.0  # the cap pulled out: its ring of edges stretched
    long = refine.stretched_edges(metrics.triangles_of(p.topology.faces), w, 2.0)  # quads: with their diagonals
    assert len(long) > 10
    faces, w2 = refine.refine_stretched(p.topology.faces, w, 2.0)
    assert len(w2) == len(w) + len(long)
    tris = np.array(faces)
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()  # every edge between two triangles: no node hangs on an edge
    def longest(faces, w):
        e = np.sort(np.concatenate([np.array(faces)[:, [0, 1]], np.array(faces)[:, [1, 2]]]), axis=1)
        return np.linalg.norm(w[e[:, 0]] - w[e[:, 1]], axis=1).max()

    assert longest(faces, w2) < 0.6 * longest(metrics.triangles_of(p.topology.faces), w)  # the long ones halved


def test_a_session_refines_its_clay_as_one_step():
    from somwidget.frontend.model import Session

    with Session("sphere", device="cpu", autosave=False) as s:
        c = s.controls
        c[0, 2] += 0.5
        s.move_control(0, c[0])
        assert s.wait_idle(60)
        before = s.frame.positions.copy()
        radii, n, p_faces = s.control_edits.radii, s.preset.n_vertices, s.preset.topology.faces
        m = s.refine()
        assert s.wait_applied(30)
        assert s.preset.n_vertices == m == s.frame.positions.shape[0] > 3 * n
        np.testing.assert_array_equal(s.frame.positions[:n], before)  # the shape as it was, nothing trained
        np.testing.assert_allclose(s.control_edits.radii, radii)
        from somwidget.backend import refine

        np.testing.assert_array_equal(s.frame.positions, refine.subdivide(p_faces, before)[1])  # the same surface
        assert s.preset.name == "sphere (refined)" and s.frame.held
        c = s.controls
        c[1, 0] += 0.3
        s.move_control(1, c[1])  # the refined clay trains as any other
        assert s.wait_idle(60) and not s.frame.held
        assert s.undo() and s.undo()
        assert s.preset.n_vertices == n
        np.testing.assert_array_equal(s.frame.positions, before)
        with pytest.raises(ValueError, match="would have"):
            Session("sphere", device="cpu", autosave=False, start=False, max_vertices=600).refine()
    with Session("space-grid", device="cpu", autosave=False, start=False) as s:
        with pytest.raises(ValueError, match="refine works on a surface"):
            s.refine()


# -- strokes -------------------------------------------------------------------------------------------------------
def test_a_stroke_matches_the_float64_reference(device):
    """A hand takes a stroke by any of its samples: the engine's grab of sample 2 holds all three, as the
    reference's grab of each; dragged out, released, the run to S."""
    topo, pts, faces = _mesh()
    start = pts[[3, 30, 31, 32, 70]].astype(np.float32)
    controls = np.concatenate([pts[[3]], pts[[30, 31, 32]] * 1.15, pts[[70]]]).astype(np.float32)
    radii = [0.0, 0.4, 0.4, 0.4, 0.5]
    som = Som(topo, pts, start, device=device, iterations=200, reach=0.3, radii=radii, strokes=[1, 3, 1])
    ref = _reference(faces, pts, start, radii, iterations=200, reach=0.3, strokes=[1, 3, 1])
    som.restore(pts, 200)
    som.grab(2)
    for c in (1, 2, 3):
        ref.grab(c)
    assert som.held == (1, 2, 3)
    som.set_controls(controls)
    ref.set_controls(controls)
    _compare(som, ref, 30, 2e-5)
    som.release(1)
    for c in (1, 2, 3):
        ref.release(c)
    _compare(som, ref, 200, 2e-5)
    assert som.strokes == (1, 3, 1)


def test_a_stroke_drawn_over_the_grid_raises_a_smooth_ridge():
    """A stroke across the open grid (the controls near it taken away first), lifted by a fifth of the size: after
    training its points lie within 1% of the size of the clay's surface, and the clay along it has no crease above
    30 degrees; dragging one sample moves the whole stroke; removing one removes it; undo takes each step back."""
    from somwidget.frontend.model import Session

    with Session("grid", device="cpu", autosave=False) as s:
        size = metrics.bounding_diagonal(s.preset.weights)
        s.remove_control(5)  # the one beside the stroke's end
        s.remove_control(0)  # the centre's: the four corners' stay
        line = np.array([[-0.6, -0.3, 0.0], [0.0, 0.1, 0.0], [0.6, 0.3, 0.0]])
        radius = 0.25 * size
        first = s.add_stroke(line, radius=radius)
        n = s.control_edits.strokes[-1]
        assert first == 4 and n >= 3 and s.n_controls == 4 + n and s.control_edits.strokes == (1,) * 4 + (n,)
        lifted = s.controls
        lifted[first:, 2] += 0.2 * size
        with s.gesture():
            s.move_control(first + 1, lifted[first + 1])  # one sample dragged: the whole stroke follows
        assert s.wait_applied(30) and s.wait_idle(120)
        np.testing.assert_allclose(s.controls[first:], lifted[first:], atol=1e-6)
        w = s.frame.positions.astype(np.float64)
        faces = s.preset.topology.faces
        gaps = metrics.surface_distances(s.controls[first:, :3], w, faces)
        assert gaps.max() < 0.01 * size, gaps.max() / size
        tris = metrics.triangles_of(faces)
        centres = s.preset.weights[tris].mean(axis=1)  # where each face was: along the stroke, within its radius
        along = metrics.nearest_distances(centres[:, :2], lifted[first:, :2]) < radius
        angles = metrics.dihedral_angles(w, tris)  # one per edge: take the faces along the stroke by their edges
        near = metrics.dihedral_angles(w, tris[along])
        assert np.nanmax(near) < 30.0, np.nanmax(near)
        assert np.isfinite(angles).any() and np.linalg.norm(w - s.preset.weights, axis=1).max() > 0.15 * size
        s.remove_control(first + 2)  # the whole stroke goes
        assert s.n_controls == 4 and s.control_edits.strokes == (1,) * 4
        assert s.undo() and s.n_controls == 4 + n
        assert s.undo() and s.undo() and s.n_controls == 4
        with pytest.raises(ValueError, match="at least 2 points"):
            s.add_stroke([[0.0, 0.0, 0.0]])


def test_a_pulled_handle_keeps_the_node_it_grabbed(device):
    """The sphere preset with control 4 typed 30% of the size out: its binding keeps the node it grabbed while the
    clay moves under it, and nothing else moves the far half. Against the float64 reference."""
    p = presets.get_preset("sphere")
    size = metrics.bounding_diagonal(p.weights[:, :3])
    controls = p.controls.copy()
    controls[4, :3] += 0.3 * size * controls[4, :3] / np.linalg.norm(controls[4, :3])
    kw = dict(iterations=1000, reach=p.reach)
    som = Som(p.topology, p.weights, p.controls, device=device, radii=p.control_radii(), **kw)
    ref = _reference(p.topology.faces, p.weights, p.controls, p.control_radii(), **kw)
    som.restore(p.weights, 1000)
    som.set_controls(controls)
    ref.set_controls(controls)
    grabbed = som.winners()
    _compare(som, ref, 300, 2e-5)
    np.testing.assert_array_equal(som.winners(), grabbed)
    far = metrics.far_half_moved(p.weights[:, :3], som.weights[:, :3], controls[4, :3])
    assert far < 0.02, f"the far half moved {far:.2%}"
