"""The batched engine (backend/batch.py): each of B variants equals its own single `Som` run and the float64
reference, on the CPU and (where there is one) the GPU; per-variant schedules; restarts; partial steps; bad input,
and what a batch refuses (controls with a radius, Taubin's rule: such variants run as single Soms,
tests/model/test_variants.py)."""

from __future__ import annotations

import numpy as np
import pytest
from reference import ReferenceSom, lattice_edges

from somwidget import Som, Topology, presets
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
    ({"radii": [0.5, 0, 0, 0, 0, 0]}, "radii: a batch runs point controls only; controls with a radius are handles"),
    ({"smoothing": 0.2, "smoothing_rule": "taubin"}, "smoothing_rule: a batch takes the paper's Laplacian step"),
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


def test_rounds_of_moves_and_steps_equal_single_soms(device):
    """A studio's rounds as the batch sees them: each round some variants' controls moved (`move_rows`, at the cycle
    their Som's `set_controls` restarts from), every variant stepped ten cycles (`step_to`) and all weights read back;
    each round's weights equal those of single Soms given the same moves and steps (on a GPU the controls, the cycles
    and the weights go through page-locked buffers, one wait a round)."""
    p = presets.get_preset("car")
    B, rng = 3, np.random.default_rng(7)
    kw = {"mirror": p.mirror, "smooth_dims": p.smooth_dims, "device": device}
    batch = BatchSom(p.topology, p.weights, np.repeat(p.controls[None], B, axis=0), **kw)
    soms = [Som(p.topology, p.weights, p.controls, **kw) for _ in range(B)]
    for som in soms:
        som.step(40)
    batch.step(40)
    for r in range(4):
        moved = [b for b in range(B) if (r + b) % 2 == 0]
        controls = [(p.controls + rng.normal(0.0, 0.05, p.controls.shape)).astype(np.float32) for _ in moved]
        for b, c in zip(moved, controls):
            soms[b].set_controls(c)
        batch.move_rows(np.array(moved), np.stack(controls), np.array([soms[b].iteration for b in moved]),
                        np.zeros(len(moved), bool))
        batch.step_to(batch.iteration + 10)
        for som in soms:
            som.step(10)
        weights = batch.weights
        assert batch.iteration.tolist() == [som.iteration for som in soms]
        for b in range(B):
            _match(device, weights[b], soms[b].weights)
