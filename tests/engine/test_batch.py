"""The batched engine (backend/batch.py): each of B variants equals its own single `Som` run and the float64
reference, on the CPU and (where there is one) the GPU; per-variant schedules; restarts; partial steps; controls with
radii (the shaping rules, mirrored pairs included); bad input."""

from __future__ import annotations

import numpy as np
import pytest
from reference import ReferenceSom, lattice_edges

from somwidget import Som, Topology, presets
from somwidget.backend import metrics
from somwidget.backend.batch import BatchSom


def _jittered(controls, count, scale, seed):
    rng = np.random.default_rng(seed)
    return np.stack([controls + rng.normal(0.0, scale, controls.shape) for _ in range(count)]).astype(np.float32)


def _single(topology, start, controls, device, restart_from=None, **kw):
    som = Som(topology, start, controls, device=device, **kw)
    if restart_from is not None:
        som.restore(restart_from, som.iterations)
        som.set_controls(controls)
    som.train()
    return som.weights


def _match(device, batched, single):
    if device == "cpu":  # the same arithmetic in the same order: the same bits
        np.testing.assert_array_equal(batched, single)
    else:
        np.testing.assert_allclose(batched, single, rtol=0, atol=2e-5)


def test_car_variants_equal_their_single_runs(device):
    """Mirrored pairs, each variant its own S, l_start, l_end and reach."""
    p = presets.get_preset("car")
    controls = _jittered(p.controls, 4, 0.03, 1)
    schedule = {"iterations": [300, 200, 250, 120], "l_start": [0.25, 0.3, 0.2, 0.6], "l_end": [0.03, 0.05, 0.02, 0.03],
                "reach": [0.08, 0.2, 0.05, 1.0]}
    metric = np.float32([1.0, 1.0, 1.0, 0.5, 2.0])  # colour dims weighed apart (the unit-metric path: below)
    som = BatchSom(p.topology, p.weights, controls, mirror=p.mirror, metric_weights=metric,
                   smooth_dims=p.smooth_dims, device=device, **schedule)
    assert som.step(0) == 0 and som.train() == 300
    assert som.iteration.tolist() == schedule["iterations"]
    weights = som.weights
    assert weights.shape == (4, p.n_vertices, 5)
    for b in range(4):
        one = {key: values[b] for key, values in schedule.items()}
        _match(device, weights[b], _single(p.topology, p.weights, controls[b], device, mirror=p.mirror,
                                           metric_weights=metric, smooth_dims=p.smooth_dims, **one))
    assert som.params[3] == {"iterations": 120, "l_start": 0.6, "l_end": 0.03, "smoothing": 0.0, "reach": 1.0}


def test_smoothing_variants_and_local_restarts_equal_single_runs(device):
    """The space grid (smoothing) restarted from a trained shape, as moving its controls would: s0 per variant."""
    p = presets.get_preset("space-grid")
    trained = p.make_som(device=device)
    trained.iterations = 150
    trained.reset()
    trained.train()
    shape = trained.weights
    controls = _jittered(p.controls, 3, 0.05, 2)
    kw = {"iterations": 150, "l_start": p.l_start, "l_end": p.l_end, "reach": [0.1, 0.3, 0.5]}
    som = BatchSom(p.topology, shape, controls, smoothing=[0.02, 0.0, 0.1], device=device, **kw)
    som.restart()
    assert som.iteration.tolist() == [135, 105, 75]
    som.train()
    for b, (smoothing, reach) in enumerate([(0.02, 0.1), (0.0, 0.3), (0.1, 0.5)]):
        single = _single(p.topology, p.weights, controls[b], device, restart_from=shape, smoothing=smoothing,
                         iterations=150, l_start=p.l_start, l_end=p.l_end, reach=reach)
        _match(device, som.weights[b], single)


def test_variants_match_the_float64_reference(device):
    """A 4 x 3 x 2 lattice, three variants, against the independent float64 reference (well-separated winners)."""
    edges, points = lattice_edges(4, 3, 2)
    points = (points + np.random.default_rng(5).uniform(-0.2, 0.2, points.shape)).astype(np.float32)
    topology = Topology.from_edges(edges, len(points))
    controls = np.array([[[0.2, 0.1, 0.9], [2.6, 1.8, 0.2]], [[3.4, 0.3, 1.2], [0.1, 2.2, -0.4]],
                         [[1.5, 1.0, 2.0], [1.4, 0.9, -1.0]]], np.float32)
    som = BatchSom(topology, points, controls, iterations=40, l_start=[0.25, 0.4, 0.3], smoothing=[0.0, 0.1, 0.05],
                   device=device)
    som.train()
    for b in range(3):
        ref = ReferenceSom(len(points), edges, points.astype(np.float64), controls[b].astype(np.float64),
                           iterations=40, l_start=[0.25, 0.4, 0.3][b], smoothing=[0.0, 0.1, 0.05][b])
        ref.train()
        assert ref.min_margin() > 1e-4
        np.testing.assert_allclose(som.weights[b], ref.W, atol=2e-5)


def test_taubin_variants_match_the_float64_reference_and_keep_the_sphere_s_volume(device):
    """Taubin's smoothing batched: each variant against the float64 reference (the lattice), and the sphere's volume
    kept within 1% over a whole run at lambda 0.1 and 0.3, where the paper's step shrinks it."""
    edges, points = lattice_edges(4, 3, 2)
    points = (points + np.random.default_rng(5).uniform(-0.2, 0.2, points.shape)).astype(np.float32)
    topology = Topology.from_edges(edges, len(points))
    controls = np.array([[[0.2, 0.1, 0.9], [2.6, 1.8, 0.2]], [[3.4, 0.3, 1.2], [0.1, 2.2, -0.4]]], np.float32)
    som = BatchSom(topology, points, controls, iterations=40, smoothing=[0.3, 0.1], smoothing_rule="taubin",
                   device=device)
    som.train()
    for b in range(2):
        ref = ReferenceSom(len(points), edges, points.astype(np.float64), controls[b].astype(np.float64),
                           iterations=40, smoothing=[0.3, 0.1][b], smoothing_rule="taubin")
        ref.train()
        assert ref.min_margin() > 1e-4
        np.testing.assert_allclose(som.weights[b], ref.W, atol=2e-5)

    p = presets.get_preset("sphere")
    tris = metrics.triangles_of(p.topology.faces)
    c = np.stack([p.controls] * 3)
    volumes = {}
    for rule in ("laplacian", "taubin"):
        # learning rates near 0: the controls' point rule would draw the sphere onto them; here only smoothing acts
        som = BatchSom(p.topology, p.weights, c, smoothing=[0.0, 0.1, 0.3], smoothing_rule=rule, l_start=1e-6,
                       l_end=1e-6, device=device)
        som.train()
        volumes[rule] = [metrics.mesh_volume(w.astype(np.float64), tris) for w in som.weights]
    plain = volumes["taubin"][0]
    for v in volumes["taubin"][1:]:
        assert abs(v / plain - 1.0) < 0.01
    assert volumes["laplacian"][2] / plain < 0.6  # the paper's step at 0.3: a check that can fail


def test_sphere_variants_with_radii_equal_their_single_runs(device):
    """The sphere preset with its radii (a quarter of the size) and Taubin's smoothing: a kept shape pulled once by a
    single Som, then variants that each pull one more control from that shape (a local restart, as a move in the
    session), each equal to the Som that makes the same move; partial steps first. The falloffs' scale comes from
    the start mesh (origin), as the session's Som measures it."""
    p = presets.get_preset("sphere")
    radii = p.control_radii()
    size = metrics.bounding_diagonal(p.weights)
    kw = {"iterations": 200, "reach": p.reach, "smoothing_rule": p.smoothing_rule}
    pulled = p.controls.copy()
    pulled[0] *= 1.3
    first = Som(p.topology, p.weights, p.controls, radii=radii, device=device, **kw)
    first.restore(p.weights, 200)
    first.set_controls(pulled)
    first.train()
    shape = first.weights
    controls = np.stack([pulled] * 3)
    for b, share in enumerate([0.3, -0.15, 0.15]):  # out, in, out: one control each
        controls[b, b + 1] += share * size * pulled[b + 1] / np.linalg.norm(pulled[b + 1])
    smoothing = [0.0, 0.1, 0.3]
    som = BatchSom(p.topology, shape, controls, radii=radii, origin=p.weights, smoothing=smoothing, device=device,
                   **kw)
    som.restart()
    assert som.step(13) == 13 and som.train() == 47
    np.testing.assert_array_equal(som.radii, radii)
    for b in range(3):
        single = Som(p.topology, p.weights, pulled, radii=radii, smoothing=smoothing[b], device=device, **kw)
        single.restore(shape, 200)
        single.set_controls(controls[b])
        single.train()
        _match(device, som.weights[b], single.weights)
        moved = np.linalg.norm(som.weights[b] - shape, axis=1)
        assert moved[single.winners()[b + 1]] > 0.1 * size  # the pulled control's region went with it


def test_grabbed_winners_carry_over_launches(device):
    """The sphere preset, variants pulling control 4 or 5 out (the clay slides under controls 0 and 1, which keep the
    nodes they grabbed at the restart), run in two launches: each equal to its single Som."""
    p = presets.get_preset("sphere")
    radii = p.control_radii()
    size = metrics.bounding_diagonal(p.weights)
    kw = {"iterations": 1000, "reach": p.reach, "smoothing_rule": p.smoothing_rule}
    controls = np.stack([p.controls] * 2)
    for b, c in enumerate((4, 5)):
        controls[b, c, :3] += 0.3 * size * p.controls[c, :3] / np.linalg.norm(p.controls[c, :3])
    som = BatchSom(p.topology, p.weights, controls, radii=radii, device=device, **kw)
    som.restart()
    assert som.step(37) == 37
    som.train()
    for b in range(2):
        single = Som(p.topology, p.weights, p.controls, radii=radii, device=device, **kw)
        single.restore(p.weights, 1000)
        single.set_controls(controls[b])
        single.train()
        _match(device, som.weights[b], single.weights)


def test_car_variants_with_a_radius_equal_their_single_runs(device):
    """The car's mirrored pairs with the nose's pair given a radius (a carrying pair among point pairs), colour dims
    weighed apart, each variant its own schedule: whole runs, then a local restart with other controls."""
    p = presets.get_preset("car")
    radii = np.zeros(len(p.controls), np.float32)
    radii[0] = 0.6
    controls = _jittered(p.controls, 3, 0.03, 4)
    schedule = {"iterations": [200, 150, 120], "l_start": [0.25, 0.3, 0.2], "reach": [0.08, 0.2, 1.0]}
    metric = np.float32([1.0, 1.0, 1.0, 0.5, 2.0])
    som = BatchSom(p.topology, p.weights, controls, radii=radii, mirror=p.mirror, metric_weights=metric,
                   smooth_dims=p.smooth_dims, device=device, **schedule)
    som.train()
    trained = som.weights
    moved = _jittered(p.controls, 3, 0.03, 5)
    restarted = BatchSom(p.topology, trained, moved, radii=radii, mirror=p.mirror, metric_weights=metric,
                         smooth_dims=p.smooth_dims, origin=p.weights, device=device, **schedule)
    restarted.restart()
    restarted.train()
    for b in range(3):
        one = {key: values[b] for key, values in schedule.items()}
        single = Som(p.topology, p.weights, controls[b], radii=radii, mirror=p.mirror, metric_weights=metric,
                     smooth_dims=p.smooth_dims, device=device, **one)
        single.train()
        _match(device, trained[b], single.weights)
        single.set_controls(moved[b])
        single.train()
        _match(device, restarted.weights[b], single.weights)
    assert metrics.symmetry_error(trained[0, :, :3], metrics.mirror_map(p.weights[:, :3], 1), 1) < 1e-4


def test_variants_with_radii_match_the_float64_reference(device):
    """Controls with radii among a point control, mirrored, on a small ellipsoid: two variants, each its own
    controls and schedule, against the float64 reference's shaping rules (well-separated winners)."""
    faces, pts = presets.uv_ellipsoid(12, 7, (1.0, 0.8, 0.6))
    pts = pts.astype(np.float32)
    topology = Topology.from_faces(faces, len(pts))
    radii = [0.6, 0.0, 0.4]
    controls = np.stack([pts[[3, 40, 70]]] * 2)
    controls[0, 0, :3] += [0.0, 0.0, 0.35]  # pulled out
    controls[0, 1, :3] *= 0.85  # pushed in
    controls[1, 2, :3] *= 1.3
    controls[1, 0, :3] *= 0.9
    schedule = {"iterations": [300, 240], "l_start": [0.25, 0.35], "reach": [0.3, 0.4], "smoothing": [0.0, 0.05]}
    som = BatchSom(topology, pts, controls, radii=radii, mirror=(1,), device=device, **schedule)
    som.restart()
    som.train()
    size = metrics.bounding_diagonal(pts)
    for b in range(2):
        one = {key: values[b] for key, values in schedule.items()}
        ref = ReferenceSom(topology.n_vertices, topology.edges, pts.astype(np.float64), controls[b].astype(np.float64),
                           radii=radii, mirror=(1,), **one)
        ref.restore(pts, one["iterations"])
        ref.set_controls(controls[b])
        ref.train()
        assert ref.min_margin() > 1e-4
        assert np.abs(som.weights[b] - ref.W).max() / size < 2e-5
        assert np.linalg.norm(som.weights[b] - pts, axis=1).max() > 0.05  # the run did something worth comparing


def test_steps_then_train_equal_one_train_and_reset_starts_again():
    p = presets.get_preset("lattice")
    controls = _jittered(p.controls, 2, 0.1, 3)
    whole = BatchSom(p.topology, p.weights, controls, iterations=[60, 90], device="cpu")
    whole.train()
    parts = BatchSom(p.topology, p.weights, controls, iterations=[60, 90], device="cpu")
    assert parts.step(50) == 50 and parts.iteration.tolist() == [50, 50]
    assert parts.step(50) == 40 and parts.iteration.tolist() == [60, 90]
    np.testing.assert_array_equal(parts.weights, whole.weights)
    parts.reset()
    assert parts.iteration.tolist() == [0, 0]
    np.testing.assert_array_equal(parts.weights, np.broadcast_to(p.weights, parts.weights.shape))


@pytest.mark.parametrize("kwargs, message", [
    ({"controls": np.zeros((3, 4))}, "controls: expected an array (variants, controls, dims)"),
    ({"controls": np.zeros((0, 2, 3))}, "expected at least one variant"),
    ({"controls": np.full((2, 1, 3), np.nan)}, "controls"),
    ({"weights": np.zeros((5, 3))}, "weights: expected (512, 3) shared weights or (2, 512, 3)"),
    ({"l_start": [0.2, 1.5]}, "l_start[1]"),
    ({"iterations": [10, 0]}, "iterations[1]"),
    ({"iterations": [10, 20, 30]}, "iterations: expected one value or 2 (one per variant)"),
    ({"reach": 0.0}, "reach[0]"),
    ({"mirror": (7,)}, "mirror"),
    ({"metric_weights": [1, -1, 1]}, "metric_weights: expected 3 weights >= 0"),
    ({"radii": [0.5, 0.5]}, "radii: expected one radius per control (6), got 2"),
    ({"radii": [0.5, -0.1, 0, 0, 0, 0]}, "radii: each radius must lie in [0, 1e+06]"),
    ({"radii": [0.5, np.inf, 0, 0, 0, 0]}, "radii: entries must be finite"),
    ({"origin": np.zeros((5, 3))}, "origin: expected shape (512, 3) (the start mesh)"),
])
def test_bad_input_is_named(kwargs, message):
    p = presets.get_preset("lattice")
    args = {"weights": p.weights, "controls": np.stack([p.controls, p.controls])}
    args.update(kwargs)
    with pytest.raises(ValueError) as info:
        BatchSom(p.topology, device="cpu", **args)
    assert message in str(info.value)


def test_a_mesh_past_the_batch_limit_is_refused():
    edges = np.stack([np.arange(20000), np.arange(1, 20001)], axis=1)
    topology = Topology.from_edges(edges, 20001)
    with pytest.raises(ValueError, match="at most 16,384 vertices"):
        BatchSom(topology, np.zeros((20001, 3)), np.zeros((1, 1, 3)), device="cpu")
