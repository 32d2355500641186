"""Handles in the engine (backend/handles.py, shaping_path.py): the Warp kernels in float32 against the float64
reference of the rule (tests/reference_handles.py) on cases whose winners are well apart (controls placed on
nodes), on the CPU and on CUDA; the bound guarantees (no node leaves the box under any symmetry group and any
sequence of moves); the issue's figures at sizes that run in seconds; what grab, release and the events between
drags do."""

from __future__ import annotations

import numpy as np
import pytest
from reference_handles import BOX_MARGIN, HandleSom

from somwidget.backend import metrics, presets
from somwidget.backend.som import Som
from somwidget.backend.symmetry import Symmetry
from somwidget.backend.topology import Topology

GROUPS = {"none": None, "mirror": Symmetry.mirror(1), "radial": Symmetry.radial(4, 2)}


def sphere(n_lon: int = 32, n_rings: int = 15):
    f, p = presets.uv_ellipsoid(n_lon, n_rings)
    return [tuple(int(i) for i in x) for x in f], p.astype(np.float64)


def tube(n_around: int, rings: int):
    """An open tube of radius 1 around z, z -1 .. 1; ring r's node j is r * n_around + j."""
    z = np.linspace(-1.0, 1.0, rings)
    t = 2 * np.pi * np.arange(n_around) / n_around
    p = np.stack(np.broadcast_arrays(np.cos(t)[None], np.sin(t)[None], z[:, None]), -1).reshape(-1, 3)
    f = [(r * n_around + j, r * n_around + (j + 1) % n_around, (r + 1) * n_around + (j + 1) % n_around,
          (r + 1) * n_around + j) for r in range(rings - 1) for j in range(n_around)]
    return f, p


def max_angle(W, faces) -> float:
    return float(np.nanmax(metrics.dihedral_angles(np.asarray(W, np.float64)[:, :3], metrics.triangles_of(faces))))


def kept(faces, p, controls, radii, device, group=None, **kw) -> Som:
    """A Som holding the shape as it is (s = S), as a session keeps a shape."""
    som = Som(Topology.from_faces(faces, len(p)), p.astype(np.float32), np.asarray(controls, np.float32),
              radii=radii, symmetry=group, device=device, reach=0.3, **kw)
    som.restore(p.astype(np.float32), som.iterations)
    return som


def reference(faces, p, controls, radii, group=None, **kw) -> HandleSom:
    maps = None if group is None else group.maps(3)
    kw.setdefault("smoothing_rule", "laplacian")
    return HandleSom(p, controls, radii, faces=faces, maps=maps, **kw)


def drag(som: Som, c: int, place, frames: int = 8, frame_cycles: int = 10, settle: bool = True) -> None:
    """As HandleSom.drag: grab, `frames` even steps of set_controls + cycles, release, the rest of the run."""
    start = som.controls[c].astype(np.float64)
    som.grab(c)
    for f in range(1, frames + 1):
        controls = som.controls
        controls[c] = start + (np.asarray(place, np.float64) - start) * f / frames
        som.set_controls(controls)
        som.step(frame_cycles)
    som.release(c)
    if settle:
        som.train()


def move(som: Som, c: int, place) -> None:
    controls = som.controls
    controls[c] = place
    som.set_controls(controls)


def least_margin(ref: HandleSom) -> float:
    """The smallest winner margin of the reference's point members so far (inf without any)."""
    return min((float(np.min(m)) for m in ref.margins), default=float("inf"))


def apart(som: Som, ref: HandleSom) -> float:
    return float(np.abs(som.weights.astype(np.float64) - ref.W).max() / metrics.bounding_diagonal(ref.W[:, :3]))


# ------------------------------------------------------------------------------------------- against the reference
def test_a_drag_with_nothing_but_handles_matches_the_reference_frame_by_frame(device):
    """No point control and no smoothing: a run carries the patches only, and the engine stops its cycles after the
    first one at whose end every place is on its member (every later one would carry to the same places). Frame by
    frame, with frames longer and shorter than the places need to arrive, and after the rest of the run, as the
    reference's cycle by cycle."""
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    controls = p[[40, 300]].copy()
    radii = [0.12 * size, 0.1 * size]  # a place steps at most a quarter radius a cycle: the frames need several
    som = kept(faces, p, controls, radii, device, smoothing=0.0)
    ref = reference(faces, p, controls, radii, smoothing=0.0)
    target = controls[0] * 1.6 + np.array([0.05, -0.2, 0.1])
    som.grab(0)
    ref.grab(0)
    for f, cycles in enumerate((1, 2, 10, 3, 40), 1):
        place = controls[0] + (target - controls[0]) * f / 5
        move(som, 0, place)
        ref.move(0, place)
        som.step(cycles)
        ref.step(cycles)
        assert apart(som, ref) < 2e-5, f"frame {f}"
    som.release(0)
    ref.release(0)
    move(som, 1, controls[1] * 0.8)  # a typed move of the other control: grabbed and released at once
    ref.move(1, controls[1] * 0.8)
    som.train()
    ref.train()
    assert apart(som, ref) < 2e-5
    assert np.linalg.norm(som.weights[:, :3] - target, axis=1).min() < 0.03 * size  # the clay reached the hand


@pytest.mark.parametrize("group", list(GROUPS))
def test_a_drag_matches_the_float64_reference(device, group):
    """Control 0 of the sphere (radius a quarter of the size) dragged out and sideways in six frames, a point
    control beside it; frame by frame and after the rest of the run."""
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    controls = p[[40, 300]].copy()  # on nodes: the winners are those nodes, far from any tie
    radii = [0.26 * size, 0.0]
    som = kept(faces, p, controls, radii, device, GROUPS[group])
    ref = reference(faces, p, controls, radii, GROUPS[group])
    target = controls[0] * 1.35 + np.array([0.05, 0.21, 0.0])
    som.grab(0)
    ref.grab(0)
    assert som.held == (0,)
    for f in range(1, 7):
        place = controls[0] + (target - controls[0]) * f / 6
        move(som, 0, place)
        ref.move(0, place)
        som.step(10)
        ref.step(10)
        assert apart(som, ref) < 2e-5, f"frame {f}"
    som.release(0)
    ref.release(0)
    som.train()
    ref.train()
    assert apart(som, ref) < 2e-5  # (the point control's nodes crowd round it by the end: no margin to speak of)
    moved = np.linalg.norm(som.weights - p, axis=1).max()
    assert moved > 0.2 * size  # the clay went with the hand


def test_a_typed_move_with_taubin_smoothing_matches_the_float64_reference(device):
    """A typed move (grab at the old place, release at once) under 4-fold symmetry, Taubin's smoothing 0.3 of the free
    nodes with the volume put back and the clamp, a point control in the mix."""
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    controls = p[[72, 250]].copy()
    radii = [0.23 * size, 0.0]
    kw = dict(smoothing=0.3, smoothing_rule="taubin")
    som = kept(faces, p, controls, radii, device, Symmetry.radial(4, 2), **kw)
    ref = reference(faces, p, controls, radii, Symmetry.radial(4, 2), **kw)
    place = controls[0] * np.array([1.3, 1.3, 0.8])
    move(som, 0, place)
    ref.move(0, place)
    for _ in range(6):
        som.step(50)
        ref.step(50)
        assert apart(som, ref) < 5e-5
    som.train()
    ref.train()
    assert apart(som, ref) < 5e-5
    assert not som.held and least_margin(ref) > 1e-4


def test_winners_are_the_nodes_the_bindings_took(device):
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    som = kept(faces, p, p[[40, 300]], [0.25 * size, 0.0], device)
    som.grab(0)
    move(som, 0, p[40] * 1.4)
    som.step(20)
    assert som.winners()[0] == 40  # the node it grabbed, though the clay moved under it


def test_distance_rows_give_the_dense_table_s_weights(device):
    """A drag of a handle beside a point control under 4-fold symmetry, in distance rows mode (the point members'
    rows fetched each cycle, cycles launched one by one) and with the dense table (captured runs): the same weights
    but for the rows' cut of rates below 2^-24."""
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    soms = [kept(faces, p, p[[72, 250]], [0.23 * size, 0.0], device, Symmetry.radial(4, 2), distances=distances,
                 smoothing=0.2, smoothing_rule="taubin") for distances in ("rows", "dense")]
    for som in soms:
        drag(som, 0, p[72] * 1.3, frames=3, settle=False)
        som.step(40)
    rows, dense = (som.weights.astype(np.float64) for som in soms)
    assert np.abs(rows - dense).max() < 1e-5 * size
    assert np.abs(dense - p).max() > 0.05 * size


# ------------------------------------------------------------------------------------------- bounded
@pytest.mark.parametrize("group", ["mirror", "radial-16", "radial-8-mirror"])
@pytest.mark.parametrize("smoothing", [0.0, 0.3])
def test_no_node_leaves_the_box_whatever_the_moves(group, smoothing):
    """Random drags and typed moves of three controls (radii up to 0.6) on the sphere: every frame, every node lies
    in the box of the start and every place of every member, grown by the largest radius (and, with Taubin's
    smoothing, BOX_MARGIN of the size)."""
    sym = {"mirror": Symmetry.mirror(1), "radial-16": Symmetry.radial(16, 2),
           "radial-8-mirror": Symmetry.radial(4, 2, mirror=True)}[group]
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    rng = np.random.default_rng(7)
    controls = p[[40, 200, 420]].copy()
    radii = np.array([0.6, 0.45, 0.3])
    som = kept(faces, p, controls, radii, "cpu", sym, smoothing=smoothing, smoothing_rule="taubin")
    maps = sym.maps(3)
    lo, hi = p.min(axis=0), p.max(axis=0)
    slack = radii.max() + (BOX_MARGIN * size if smoothing else 0.0) + 1e-5 * size
    for _ in range(10):
        c = int(rng.integers(3))
        target = som.controls[c] + rng.normal(scale=0.6, size=3)
        members = np.einsum("gij,j->gi", maps, target)
        lo, hi = np.minimum(lo, members.min(axis=0)), np.maximum(hi, members.max(axis=0))
        if rng.random() < 0.5:
            drag(som, c, target, frames=3, settle=False)
        else:
            move(som, c, target)
        for _ in range(4):
            som.step(25)
            w = som.weights
            assert np.isfinite(w).all()
            assert (w >= lo - slack).all() and (w <= hi + slack).all()


def test_the_seven_ring_vase_stays_in_the_box():
    """The designer's script that `carry` blew up to z -5.2 .. 10.5: seven rings of radius 0.5 under 16-fold symmetry
    dragged to a vase within z -1.35 .. 1.45, from a tube."""
    faces, p = tube(32, 13)
    rings = [r * 32 for r in range(0, 13, 2)]
    som = kept(faces, p, p[rings], [0.5] * 7, "cpu", Symmetry.radial(16, 2))
    vase = [(0.6, -1.35), (0.9, -1.0), (1.05, -0.45), (0.9, 0.15), (0.45, 0.75), (0.32, 1.1), (0.5, 1.45)]
    for c, (rho, z) in enumerate(vase):
        drag(som, c, (rho, 0.0, z))
    w = som.weights
    assert -1.85 - 1e-5 <= w[:, 2].min() and w[:, 2].max() <= 1.95 + 1e-5
    assert np.hypot(w[:, 0], w[:, 1]).max() <= 1.05 + 0.5 + 1e-5


# ------------------------------------------------------------------------------------------- the figures
def test_a_push_through_the_sphere_takes_the_clay_with_it():
    """The top pole's control (radius a quarter of the size) typed to z -0.6 on a UV sphere of 1,986 nodes: the
    control ends within 3% of the size of the clay, no crease over 45 degrees, at least half the volume."""
    faces, p = sphere(64, 31)
    size = metrics.bounding_diagonal(p)
    som = kept(faces, p, p[:1], [0.25 * size], "cpu")
    target = np.array([0.0, 0.0, -0.6])
    move(som, 0, target)
    som.train()
    w = som.weights.astype(np.float64)
    assert np.allclose(w[0], target, atol=1e-5)  # the node it grabbed is at the control
    assert metrics.surface_distances(target[None], w, faces)[0] <= 0.03 * size
    assert max_angle(w, faces) <= 45.0
    assert metrics.mesh_volume(w, faces) >= 0.5 * metrics.mesh_volume(p, faces)


def test_a_ring_flared_under_16_fold_symmetry_reaches_without_a_crease():
    faces, p = tube(64, 25)
    size = metrics.bounding_diagonal(p)
    c0 = p[12 * 64].copy()
    group = Symmetry.radial(16, 2)
    som = kept(faces, p, c0[None], [0.5], "cpu", group)
    target = c0 + np.array([0.4, 0.0, 0.0])
    drag(som, 0, target)
    members = np.einsum("gij,j->gi", group.maps(3), target)
    w = som.weights.astype(np.float64)
    assert metrics.surface_distances(members, w, faces).max() <= 0.01 * size
    assert max_angle(w, faces) <= 35.0


@pytest.mark.parametrize("control", [0, 4])
def test_a_pull_moves_the_far_half_by_at_most_two_percent(control):
    s = presets.sphere_preset()
    p = s.weights.astype(np.float64)
    size = metrics.bounding_diagonal(p)
    controls = s.controls.astype(np.float64)
    som = kept(s.topology.faces, p, controls, [0.25 * size] * len(controls), "cpu")
    d = controls[control] - p.mean(axis=0)
    target = controls[control] + 0.3 * size * d / np.linalg.norm(d)
    drag(som, control, target)
    assert metrics.far_half_moved(p, som.weights, target) <= 0.02
    assert metrics.surface_distances(target[None], som.weights, s.topology.faces)[0] <= 0.01 * size


def _closed_mesh(name: str):
    if name == "uv sphere":
        return sphere()
    if name == "icosphere 642":
        trimesh = pytest.importorskip("trimesh")
        m = trimesh.creation.icosphere(subdivisions=3)
        return [tuple(int(i) for i in f) for f in m.faces], np.asarray(m.vertices, np.float64)
    if name == "torus":
        f, p = presets.torus(48, 16, 1.0, 0.35)
        return [tuple(int(i) for i in x) for x in f], p.astype(np.float64)
    car = presets.get_preset("car")
    som = car.make_som("cpu")
    som.train()  # the case study's body, folds and all
    return [tuple(int(i) for i in f) for f in car.topology.faces], som.weights[:, :3].astype(np.float64)


@pytest.mark.parametrize("name", ["uv sphere", "icosphere 642", "torus", "car"])
def test_smoothing_keeps_the_volume_of_any_closed_mesh(name):
    """A whole run (s = 0 .. S) of Taubin's smoothing at 0.3 and at 0.7, no control bound: within 1% of the
    volume (Taubin's pair alone lost 16% of the torus and 22% of the car)."""
    faces, p = _closed_mesh(name)
    v0 = metrics.mesh_volume(p, faces)
    size = metrics.bounding_diagonal(p)
    for strength in (0.3, 0.7):
        som = Som(Topology.from_faces(faces, len(p)), p.astype(np.float32), p[:1].astype(np.float32),
                  radii=[0.2 * size], smoothing=strength, smoothing_rule="taubin", device="cpu")
        som.reset()
        som.train()
        w = som.weights.astype(np.float64)
        assert abs(metrics.mesh_volume(w, faces) / v0 - 1.0) < 0.01, strength
        assert np.abs(w - p).max() > 1e-3 * size  # it did smooth


def test_taubin_no_longer_diverges_at_smoothing_one(device):
    """The torus preset at smoothing 1.0 (Taubin's rule) went to NaN 200 cycles after a move: lambda is capped at
    0.7."""
    t = presets.get_preset("torus")
    som = t.make_som(device)
    som.smoothing_rule, som.smoothing = "taubin", 1.0
    c = som.controls
    c[0, :3] *= 1.15
    som.set_controls(c)
    som.train()
    w = som.weights
    assert np.isfinite(w).all()
    assert abs(metrics.bounding_diagonal(w[:, :3]) / metrics.bounding_diagonal(t.weights[:, :3]) - 1.0) < 0.1


# ------------------------------------------------------------------------------------------- the events
def test_grab_release_and_what_happens_between_drags(device):
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    controls = presets.controls_on(p.astype(np.float32)).astype(np.float64)
    som = kept(faces, p, controls, [0.25 * size] * 6, device)
    before = som.weights
    som.grab(2)
    som.step(50)  # a grab moves nothing
    np.testing.assert_array_equal(som.weights, before)
    move(som, 2, controls[2] * 1.3)
    som.step(10)
    som.release(2)
    assert som.held == ()
    som.train()
    kept_shape = som.weights
    assert np.linalg.norm(kept_shape - before, axis=1).max() > 0.08 * size
    som.restart()  # a parameter change: nothing held, no point control, no smoothing
    som.train()
    np.testing.assert_array_equal(som.weights, kept_shape)  # nothing pulls the clay back or carries it again
    som.radii = [0.0] + [0.25 * size] * 5
    som.grab(0)  # a point control binds nothing
    assert som.held == ()


def test_a_stroke_is_grabbed_and_released_as_one(device):
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    controls = p[[40, 41, 42, 300]]
    som = kept(faces, p, controls, [0.1 * size] * 4, device, strokes=[3, 1])
    som.grab(1)
    assert som.held == (0, 1, 2)
    c = som.controls
    c[:3] *= 1.2
    som.set_controls(c)
    som.step(20)
    som.release(0)
    assert som.held == ()
    som.train()
    assert metrics.surface_distances(c[:3].astype(np.float64), som.weights, faces).max() < 0.01 * size


def test_restored_weights_end_every_binding(device):
    faces, p = sphere()
    size = metrics.bounding_diagonal(p)
    som = kept(faces, p, p[[40]], [0.25 * size], device)
    som.grab(0)
    move(som, 0, p[40] * 1.3)
    som.step(10)
    som.restore(p.astype(np.float32), som.iterations)  # an undo
    assert som.held == ()
    som.restart()
    som.train()
    np.testing.assert_array_equal(som.weights, p.astype(np.float32))  # nothing bound: nothing moves


def test_a_growing_reset_grows_the_case_study_whatever_the_radii():
    """reset(grow=True) runs the paper's point rule to S (the car grows from its ellipsoid as with radius 0, bit for
    bit), then the radii are handles again; a plain reset from the start mesh binds nothing, so handles grow
    nothing (the ellipsoid stays)."""
    car = presets.get_preset("car")
    points = car.make_som("cpu")
    points.train()
    som = car.make_som("cpu")
    som.radii = np.full(len(som.controls), 0.5)
    som.reset(grow=True)
    som.train()
    assert np.array_equal(som.weights, points.weights)
    assert som.parts.controls.radii.min() == pytest.approx(0.5)  # handles again
    som.reset()
    som.train()
    assert np.abs(som.weights - car.weights).max() < 1e-5
