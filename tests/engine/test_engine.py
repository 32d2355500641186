"""The Warp engine (real kernels, CPU and CUDA where present) against the independent float64 reference.

Weights are compared with an absolute tolerance of 1e-4 times the coordinate scale, which suits float32
over the short runs used here (the engine stays within about 1e-7 of the reference on them). Every
comparison first asserts that the reference's winners were well separated on every iteration: relative
margin (d2 - d1) / d2 between best and second-best distance >= MIN_MARGIN = 1e-4, about 840 float32 eps
and three orders of magnitude above the drift seen, so a near-tie cannot explain a mismatch and the
tolerance never needs loosening. Seeds and lengths were picked so that this holds (most runs have
margins >= 1e-3); runs through the SOM's early collapse with many controls are what make margins small.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from reference import (
    UNREACHABLE,
    ReferenceSom,
    edges_from_edges,
    edges_from_faces,
    effective_controls,
    grid_quads,
    lattice_edges,
    lattice_quads,
    mixed_faces,
    torus_points,
    torus_quads,
    winner_margins,
    winners,
)

from somwidget import Som, Topology

ATOL_REL = 1e-4  # absolute weight tolerance, relative to the coordinate scale
MIN_MARGIN = 1e-4  # smallest relative winner margin accepted: ~840 float32 eps; engine drift seen is ~1e-7


# ------------------------------------------------------------------------------------- cases
@dataclass
class Case:
    """One topology, as the engine reads it and as the reference reads it, with start positions."""

    name: str
    topo: Topology
    n: int
    ref_edges: np.ndarray
    points: np.ndarray  # (N, 3) start positions


def _case(name: str) -> Case:
    rng = np.random.default_rng(sum(map(ord, name)))
    if name == "lattice":
        edges, pts = lattice_edges(4, 4, 3)
        topo = Topology.from_edges(edges, 48)
        ref_edges = edges_from_edges(edges)
        pts = (pts - pts.mean(0)) / 1.5
    elif name == "lattice_quads":
        quads = lattice_quads(4, 4, 3)
        _, pts = lattice_edges(4, 4, 3)
        topo = Topology.from_faces(quads)
        ref_edges = edges_from_faces(quads)
        pts = (pts - pts.mean(0)) / 1.5
    elif name == "mixed":
        faces = mixed_faces()
        topo = Topology.from_faces(faces)
        ref_edges = edges_from_faces(faces)
        pts = rng.uniform(-1, 1, size=(14, 3))
    elif name == "torus":
        quads = torus_quads(8, 5)
        topo = Topology.from_faces(quads)
        ref_edges = edges_from_faces(quads)
        pts = torus_points(8, 5, R=1.0, r=0.4)
    elif name == "two_components":
        faces = np.concatenate([grid_quads(3, 3), grid_quads(4, 2, offset=9)])
        topo = Topology.from_faces(faces)
        ref_edges = edges_from_faces(faces)
        pts = rng.uniform(-1, 1, size=(17, 3))
    elif name == "from_edges":
        n = 30
        ring = [(i, (i + 1) % n) for i in range(n)]
        chords = [(i, (i + 7) % n) for i in range(0, n, 5)]
        noise = [(b, a) for a, b in ring[:5]] + [(3, 3), (9, 9)] + chords[:2]  # duplicates and self-loops
        raw = np.array(ring + chords + noise)
        topo = Topology.from_edges(raw, n)
        ref_edges = edges_from_edges(raw)
        pts = rng.uniform(-1, 1, size=(n, 3))
    elif name == "single":
        topo = Topology.from_edges(np.zeros((0, 2), dtype=np.int64), 1)
        ref_edges = np.zeros((0, 2), dtype=np.int64)
        pts = np.array([[0.3, -0.2, 0.5]])
    else:
        raise KeyError(name)
    pts = pts + rng.normal(scale=0.05, size=pts.shape)  # break the lattice's exact symmetries
    return Case(name, topo, topo.n_vertices, ref_edges, pts)


def _f32(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float32))


def _pair(case: Case, weights, controls, device, **kw) -> tuple[Som, ReferenceSom]:
    """The engine and the reference from the same float32-rounded inputs."""
    w = _f32(weights)
    c = _f32(controls)
    som = Som(case.topo, w, c, device=device, **kw)
    ref = ReferenceSom(case.n, case.ref_edges, w.astype(np.float64), c.astype(np.float64), **kw)
    return som, ref


def _scale(*arrays) -> float:
    return max(1.0, *(float(np.abs(a).max()) for a in arrays if np.size(a)))


def _assert_matches(som: Som, ref: ReferenceSom, scale: float, min_margin: float = MIN_MARGIN):
    assert ref.min_margin() >= min_margin, f"near-tie in the reference run (margin {ref.min_margin():.3g})"
    assert som.iteration == ref.iteration
    got = som.weights
    assert got.dtype == np.float32 and got.shape == ref.W.shape
    np.testing.assert_allclose(got, ref.W, rtol=0, atol=ATOL_REL * scale)


def _controls(rng, k: int, n: int, lo=-1.2, hi=1.2) -> np.ndarray:
    return rng.uniform(lo, hi, size=(k, n))


# ------------------------------------------------------------------------------------- the reference itself
def test_reference_two_neurons_by_hand():
    """Two neurons on one edge, one control, S = 1 (L = [[0.25, 0.125]]), without and with smoothing."""
    ref = ReferenceSom(2, [(0, 1)], [[0.0], [4.0]], [[1.0]], iterations=1)
    assert ref.step(3) == 1 and ref.iteration == 1
    np.testing.assert_allclose(ref.W[:, 0], [0.25, 4.0 + 0.125 * (1.0 - 4.0)], rtol=1e-15)
    ref = ReferenceSom(2, [(0, 1)], [[0.0], [4.0]], [[1.0]], iterations=1, smoothing=0.5)
    ref.step()
    np.testing.assert_allclose(ref.W[:, 0], [1.9375, 1.9375], rtol=1e-15)


def test_reference_controls_apply_in_list_order():
    """Two controls with the same winner: the second pulls from where the first left the neuron."""
    ref = ReferenceSom(1, [], [[0.0]], [[1.0], [2.0]], iterations=1, l_start=0.5, l_end=0.5)
    ref.step()
    w = 0.0 + 0.5 * (1.0 - 0.0)
    w = w + 0.5 * (2.0 - w)
    assert ref.W[0, 0] == pytest.approx(w, rel=1e-15)


def test_reference_mirroring_and_winners():
    C = np.array([[1.0, 2.0, 3.0], [0.5, 0.0, -1.0]])
    np.testing.assert_array_equal(effective_controls(C, (1,)), [[1, 2, 3], [0.5, 0, -1], [1, -2, 3], [0.5, -0.0, -1]])
    np.testing.assert_array_equal(effective_controls(C, ()), C)
    W = np.array([[0.0], [2.0], [2.0], [0.0]])
    assert winners(W, [[1.0]]).tolist() == [0]  # exact tie: lowest index
    assert winners(np.array([[5.0, 0.0], [0.0, 1.0]]), [[4.0, 1.0]], [0.0, 1.0]).tolist() == [1]
    assert winner_margins(W, [[1.0]])[0] == 0.0


def test_reference_unreachable_neurons_stay():
    ref = ReferenceSom(4, [(0, 1), (2, 3)], np.zeros((4, 2)), [[1.0, 1.0]], iterations=3)
    ref.step(3)
    assert np.all(ref.W[2:] == 0) and np.all(ref.W[:2] > 0)
    assert ref.dist[0, 2] == UNREACHABLE


# ------------------------------------------------------------------------------------- hand examples on the engine
def test_engine_two_neurons_by_hand(device):
    topo = Topology.from_edges(np.array([[0, 1]]), 2)
    som = Som(topo, _f32([[0.0], [4.0]]), _f32([[1.0]]), iterations=1, device=device)
    assert som.step(3) == 1 and som.iteration == 1
    np.testing.assert_allclose(som.weights[:, 0], [0.25, 3.625], rtol=1e-6)
    som = Som(topo, _f32([[0.0], [4.0]]), _f32([[1.0]]), iterations=1, smoothing=0.5, device=device)
    som.step()
    np.testing.assert_allclose(som.weights[:, 0], [1.9375, 1.9375], rtol=1e-6)


def test_engine_controls_apply_in_list_order(device):
    topo = Topology.from_edges(np.zeros((0, 2), dtype=np.int64), 1)
    som = Som(topo, _f32([[0.0]]), _f32([[1.0], [2.0]]), iterations=1, l_start=0.5, l_end=0.5, device=device)
    som.step()
    assert som.weights[0, 0] == pytest.approx(1.25, rel=1e-6)


def test_engine_exact_tie_lowest_index_wins(device):
    """Exactly representable equal distances: the lowest neuron index is the winner."""
    topo = Topology.from_edges(np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5]]), 6)
    W = _f32([[9.0, 0.0], [4.0, 1.0], [2.0, 0.0], [9.0, 9.0], [0.0, 0.0], [2.0, 2.0]])
    C = _f32([[1.0, 0.0], [2.0, 1.0]])  # C0: neurons 2 and 4 at distance 1; C1: neurons 2 and 5 at distance 1
    som = Som(topo, W, C, iterations=5, device=device)
    assert winners(W, C).tolist() == [2, 2]
    assert som.winners().tolist() == [2, 2]
    W2 = W[::-1].copy()  # now the tied neurons are 1 and 3 (C0), 0 and 3 (C1)
    som.set_weights(W2)
    assert winners(W2, C).tolist() == [1, 0]
    assert som.winners().tolist() == [1, 0]


def test_engine_tie_with_metric_weights(device):
    """A zero metric weight makes dims invisible: neurons differing only there tie, lowest index wins."""
    topo = Topology.from_edges(np.array([[0, 1], [1, 2]]), 3)
    W = _f32([[5.0, 1.0], [0.0, 7.0], [0.0, -3.0]])
    C = _f32([[0.0, 0.0]])
    som = Som(topo, W, C, metric_weights=[1.0, 0.0], iterations=5, device=device)
    assert som.winners().tolist() == [1] == winners(W, C, [1.0, 0.0]).tolist()
    som2 = Som(topo, W, C, iterations=5, device=device)
    assert som2.winners().tolist() == [2] == winners(W, C).tolist()


def test_unreachable_component_does_not_move(device):
    """theta(unreachable) = 0: a component holding no winner keeps its weights bit for bit."""
    case = _case("two_components")
    rng = np.random.default_rng(3)
    W = case.points.copy()
    W[9:] += 5.0  # second component far away: every winner lies in the first
    C = rng.uniform(-1, 1, size=(3, 3))
    som, ref = _pair(case, W, C, device, iterations=40)
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(W, C))
    np.testing.assert_array_equal(som.weights[9:], _f32(W)[9:])
    assert not np.allclose(som.weights[:9], _f32(W)[:9])


# ------------------------------------------------------------------------------------- topologies
# (topology, smoothing, seed): seeds picked so every winner of the run is well separated (margin >= 1e-3)
TOPOLOGY_RUNS = [
    ("lattice", 0.0, 2),
    ("lattice", 0.35, 1),
    ("lattice_quads", 0.0, 5),
    ("lattice_quads", 0.35, 1),
    ("mixed", 0.0, 5),
    ("mixed", 0.35, 1),
    ("torus", 0.0, 7),
    ("torus", 0.35, 1),
    ("two_components", 0.0, 0),
    ("two_components", 0.35, 1),
    ("from_edges", 0.0, 1),
    ("from_edges", 0.35, 3),
    ("single", 0.0, 0),
    ("single", 0.35, 0),
]


@pytest.mark.parametrize(("name", "smoothing", "seed"), TOPOLOGY_RUNS)
def test_topologies_match_reference(device, name, smoothing, seed):
    case = _case(name)
    rng = np.random.default_rng(seed)
    C = _controls(rng, 4, 3)
    som, ref = _pair(case, case.points, C, device, iterations=60, smoothing=smoothing)
    assert som.n_neurons == case.n and som.n_dims == 3
    assert som.train() in (None, 60)
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C))
    assert som.winners().tolist() == ref.winners().tolist()


# ------------------------------------------------------------------------------------- mirroring
@pytest.mark.parametrize(("n_dims", "mirror", "seed"), [(3, (1,), 1), (3, (0, 2), 5), (5, (1, 3), 1)])
def test_mirror_matches_reference(device, n_dims, mirror, seed):
    """Mirrored pairs act together (the algorithm's step 2); seeds whose winners stay well apart over the run."""
    case = _case("torus")
    rng = np.random.default_rng(seed)
    W = np.concatenate([case.points, rng.uniform(0, 1, size=(case.n, n_dims - 3))], axis=1)
    C = _controls(rng, 3, n_dims)
    C[2, list(mirror)] = 0.0  # a control on the mirror plane still gets its (identical) copy
    som, ref = _pair(case, W, C, device, iterations=50, mirror=mirror, smoothing=0.2)
    eff = som.effective_controls
    assert eff.shape == (6, n_dims)
    np.testing.assert_allclose(eff, effective_controls(_f32(C), mirror), rtol=0, atol=0)
    np.testing.assert_array_equal(som.controls, _f32(C))
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(W, C))


def test_mirror_off_is_originals(device):
    case = _case("lattice")
    C = _controls(np.random.default_rng(2), 5, 3)
    som, _ = _pair(case, case.points, C, device, iterations=10)
    np.testing.assert_array_equal(som.effective_controls, _f32(C))


# ------------------------------------------------------------------------------------- smoothing
@pytest.mark.parametrize(
    ("n_dims", "smooth_dims"),
    [(1, None), (2, None), (5, None), (5, (1, 3)), (8, (0, 4, 7)), (3, (2,))],
)
def test_smoothing_dims_match_reference(device, n_dims, smooth_dims):
    case = _case("mixed")
    rng = np.random.default_rng(17 + n_dims)
    W = np.concatenate([case.points, rng.uniform(-1, 1, size=(case.n, max(0, n_dims - 3)))], axis=1)[:, :n_dims]
    C = _controls(rng, 3, n_dims)
    som, ref = _pair(case, W, C, device, iterations=40, smoothing=0.5, smooth_dims=smooth_dims)
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(W, C))


def test_smoothing_default_leaves_non_position_dims(device):
    """With smooth_dims=None only dims 0, 1, 2 are smoothed: dims 3+ equal a run without smoothing."""
    case = _case("mixed")
    rng = np.random.default_rng(4)
    W = np.concatenate([case.points, rng.uniform(-1, 1, size=(case.n, 2))], axis=1)
    C = _controls(rng, 1, 5)
    smooth, _ = _pair(case, W, C, device, iterations=1, smoothing=1.0)
    plain, _ = _pair(case, W, C, device, iterations=1, smoothing=0.0)
    smooth.step()
    plain.step()
    np.testing.assert_allclose(smooth.weights[:, 3:], plain.weights[:, 3:], rtol=0, atol=1e-6)
    assert not np.allclose(smooth.weights[:, :3], plain.weights[:, :3], atol=1e-3)


def test_full_smoothing_is_neighbour_mean(device):
    """lambda = 1: each neuron becomes the mean of its neighbours' pre-smoothing weights (Jacobi)."""
    topo = Topology.from_edges(np.array([[0, 1], [1, 2], [2, 3]]), 5)  # vertex 4 has no neighbour
    W = _f32([[0.0, 0, 0], [1, 0, 0], [3, 0, 0], [7, 0, 0], [5, 5, 5]])
    # a control sitting on neuron 4 with l = 1e-6 barely moves anything; smoothing dominates
    som = Som(topo, W, _f32([[5.0, 5.0, 5.0]]), iterations=1, l_start=1e-6, l_end=1e-6, smoothing=1.0, device=device)
    som.step()
    np.testing.assert_allclose(som.weights[:, 0], [1.0, 1.5, 4.0, 3.0, 5.0], atol=1e-5)


# ------------------------------------------------------------------------------------- metric weights
@pytest.mark.parametrize(
    ("metric", "seed"),
    [([1.0, 0.0, 2.0, 0.5, 0.0], 0), ([0.0, 0.0, 0.0, 1.0, 3.0], 0), ([2.0, 2.0, 2.0, 2.0, 2.0], 3)],
)
def test_metric_weights_match_reference(device, metric, seed):
    case = _case("lattice")
    rng = np.random.default_rng(seed)
    W = np.concatenate([case.points, rng.uniform(-1, 1, size=(case.n, 2))], axis=1)
    C = _controls(rng, 2, 5)
    som, ref = _pair(case, W, C, device, iterations=50, metric_weights=metric, mirror=(1,))
    assert som.winners().tolist() == ref.winners().tolist()
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(W, C))


def test_zero_metric_dim_changes_winner(device):
    """The metric only picks winners: a zero weight hides a dim from the search, the move still pulls it."""
    case = _case("lattice")
    rng = np.random.default_rng(8)
    W = np.concatenate([case.points, rng.uniform(-1, 1, size=(case.n, 1))], axis=1)
    C = np.array([[0.4, 0.1, -0.3, 9.0]])
    som_a, ref_a = _pair(case, W, C, device, iterations=30, metric_weights=[1, 1, 1, 0])
    som_b, ref_b = _pair(case, W, C, device, iterations=30)
    assert ref_a.winners()[0] != ref_b.winners()[0]
    assert som_a.winners().tolist() == ref_a.winners().tolist()
    assert som_b.winners().tolist() == ref_b.winners().tolist()
    for som, ref in ((som_a, ref_a), (som_b, ref_b)):
        som.train()
        ref.train()
        _assert_matches(som, ref, _scale(W, C))
    assert som_a.weights[:, 3].max() > 1.0  # the hidden dim was still trained towards 9


# ------------------------------------------------------------------------------------- stepping
def test_partial_steps_equal_one_run(device):
    case = _case("torus")
    C = _controls(np.random.default_rng(1), 3, 3)
    a, ref = _pair(case, case.points, C, device, iterations=30, smoothing=0.25, mirror=(1,))
    b, _ = _pair(case, case.points, C, device, iterations=30, smoothing=0.25, mirror=(1,))
    assert a.step(7) == 7 and a.iteration == 7
    assert a.step(5) == 5 and a.iteration == 12
    assert b.step(12) == 12 and b.iteration == 12
    np.testing.assert_allclose(a.weights, b.weights, rtol=0, atol=1e-6)
    ref.step(7)
    ref.step(5)
    _assert_matches(a, ref, _scale(case.points, C))
    singles = _pair(case, case.points, C, device, iterations=30, smoothing=0.25, mirror=(1,))[0]
    for _ in range(12):
        assert singles.step() == 1
    np.testing.assert_allclose(singles.weights, b.weights, rtol=0, atol=1e-6)


def test_step_past_end_stops(device):
    case = _case("mixed")
    C = _controls(np.random.default_rng(1), 2, 3)
    som, ref = _pair(case, case.points, C, device, iterations=10)
    assert som.step(7) == 7
    assert som.step(5) == 3
    assert som.iteration == 10
    done = som.weights
    assert som.step(4) == 0
    assert som.step() == 0
    assert som.iteration == 10
    np.testing.assert_array_equal(som.weights, done)
    som.train()
    assert som.iteration == 10
    np.testing.assert_array_equal(som.weights, done)
    ref.step(12)
    _assert_matches(som, ref, _scale(case.points, C))


def test_step_zero_runs_nothing(device):
    case = _case("mixed")
    som, _ = _pair(case, case.points, _controls(np.random.default_rng(1), 2, 3), device, iterations=10)
    assert som.step(0) == 0
    assert som.iteration == 0
    np.testing.assert_array_equal(som.weights, _f32(case.points))


def test_train_runs_the_rest(device):
    case = _case("lattice")
    C = _controls(np.random.default_rng(12), 4, 3)
    som, ref = _pair(case, case.points, C, device, iterations=45, smoothing=0.1)
    som.step(3)
    som.train()
    assert som.iteration == 45
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C))


# ------------------------------------------------------------------------------------- restart / reset
def test_set_controls_restarts_from_latest_weights(device):
    case = _case("torus")
    rng = np.random.default_rng(45)  # winners well apart through the restart
    C1 = _controls(rng, 3, 3)
    C2 = _controls(rng, 5, 3)  # a different count k
    som, ref = _pair(case, case.points, C1, device, iterations=40, smoothing=0.2, mirror=(1,), reach=0.5)
    som.step(25)
    ref.step(25)
    before = som.weights
    som.set_controls(_f32(C2))
    ref.set_controls(_f32(C2).astype(np.float64))
    assert som.iteration == som.restart_iteration == 20  # floor((1 - 0.5) 40): a local restart
    np.testing.assert_array_equal(som.weights, before)  # the mesh follows, it does not snap back
    np.testing.assert_array_equal(som.controls, _f32(C2))
    assert som.effective_controls.shape == (10, 3)
    assert som.step(15) == 15
    ref.step(15)
    _assert_matches(som, ref, _scale(case.points, C1, C2))
    assert som.train() == 5  # the rest of the restarted schedule
    ref.train()
    assert som.iteration == 40
    _assert_matches(som, ref, _scale(case.points, C1, C2))


@pytest.mark.parametrize(("reach", "s0"), [(1.0, 0), (0.5, 20), (0.08, 36), (0.02, 39), (1e-9, 39)])
def test_restart_iteration_follows_reach(device, reach, s0):
    """s0 = floor((1 - reach) S), at most S - 1; reach = 1 is the paper's restart at s = 0."""
    case = _case("mixed")
    som, _ = _pair(case, case.points, _controls(np.random.default_rng(1), 2, 3), device, iterations=40, reach=reach)
    som.train()
    som.set_controls(_f32(_controls(np.random.default_rng(2), 2, 3)))
    assert som.reach == reach and som.iteration == s0
    assert som.train() == 40 - s0


@pytest.mark.parametrize("bad", [0.0, -0.1, 1.5, float("nan"), "half", None])
def test_reach_is_checked(device, bad):
    case = _case("mixed")
    with pytest.raises(ValueError, match="reach"):
        _pair(case, case.points, _controls(np.random.default_rng(1), 2, 3), device, reach=bad)
    som, _ = _pair(case, case.points, _controls(np.random.default_rng(1), 2, 3), device)
    with pytest.raises(ValueError, match="reach"):
        som.reach = bad
    assert som.reach == 0.08


def test_restore_puts_weights_and_iteration_back_without_training(device):
    """A loaded session or an undo: weights and s exactly as saved, and training goes on from there as the
    uninterrupted run would."""
    case = _case("torus")
    C = _controls(np.random.default_rng(3), 3, 3)
    som, ref = _pair(case, case.points, C, device, iterations=30, smoothing=0.1, mirror=(1,))
    som.step(12)
    saved = som.weights
    som.step(5)
    som.restore(saved, 12)
    assert som.iteration == 12
    np.testing.assert_array_equal(som.weights, saved)
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C))
    # a drag: anchor the shape it begins with; every frame restarts from it, wherever the last frame left off
    som.anchor()
    anchored = som.weights
    som.set_controls(C + 0.05, from_anchor=True)
    np.testing.assert_array_equal(som.weights, anchored)  # read before the run: the anchor already
    som.step(5)
    som.set_controls(C + 0.1, from_anchor=True)
    assert som.iteration == som.restart_iteration
    som.train()
    fresh, _ = _pair(case, case.points, C, device, iterations=30, smoothing=0.1, mirror=(1,))
    fresh.restore(anchored, 12)
    fresh.set_controls(C + 0.1)
    fresh.train()
    np.testing.assert_array_equal(som.weights, fresh.weights)  # as one move from the anchored shape
    other, _ = _pair(_case("mixed"), _case("mixed").points, C, device, iterations=30)
    with pytest.raises(ValueError, match="anchor"):
        other.set_controls(C + 1.0, from_anchor=True)
    np.testing.assert_array_equal(other.controls, _f32(C))  # refused: nothing changed
    with pytest.raises(ValueError, match="iteration"):
        som.restore(saved, 31)
    with pytest.raises(ValueError, match="weights"):
        som.restore(saved[:-1], 3)


def test_set_controls_after_end_restarts(device):
    case = _case("mixed")
    rng = np.random.default_rng(41)
    C = _controls(rng, 2, 3)
    som, ref = _pair(case, case.points, C, device, iterations=15, reach=0.6)
    som.train()
    ref.train()
    assert som.step() == 0
    C2 = C + 0.1
    som.set_controls(_f32(C2))
    ref.set_controls(_f32(C2).astype(np.float64))
    assert som.step(15) == 9  # s0 = floor(0.4 x 15) = 6
    ref.step(15)
    _assert_matches(som, ref, _scale(case.points, C2))


def test_reset_restores_start_and_keeps_controls(device):
    case = _case("lattice")
    rng = np.random.default_rng(50)
    C1 = _controls(rng, 2, 3)
    C2 = _controls(rng, 3, 3)
    som, ref = _pair(case, case.points, C1, device, iterations=30, smoothing=0.2)
    som.step(20)
    som.set_controls(_f32(C2))
    som.step(4)
    som.reset()
    assert som.iteration == 0  # the whole schedule, not a local restart
    np.testing.assert_array_equal(som.weights, _f32(case.points))
    np.testing.assert_array_equal(som.controls, _f32(C2))
    ref.set_controls(_f32(C2).astype(np.float64))
    ref.reset()
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C1, C2))


def test_reset_ignores_later_changes_to_the_input_array(device):
    case = _case("mixed")
    W = _f32(case.points)
    som = Som(case.topo, W, _f32(_controls(np.random.default_rng(0), 2, 3)), iterations=5, device=device)
    start = W.copy()
    W += 100.0  # the caller reuses its array
    got = som.weights
    np.testing.assert_array_equal(got, start)
    got += 50.0  # som.weights is a copy
    np.testing.assert_array_equal(som.weights, start)
    som.step(5)
    som.reset()
    np.testing.assert_array_equal(som.weights, start)


def test_set_weights(device):
    case = _case("mixed")
    rng = np.random.default_rng(60)
    C = _controls(rng, 2, 3)
    W2 = rng.uniform(-1, 1, size=(case.n, 3))
    som, ref = _pair(case, case.points, C, device, iterations=20)
    som.step(8)
    som.set_weights(_f32(W2))
    assert som.iteration == som.restart_iteration == 18
    np.testing.assert_array_equal(som.weights, _f32(W2))
    ref.set_weights(_f32(W2).astype(np.float64))
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(W2, C))


@pytest.mark.parametrize(("attr", "value"), [("iterations", 25), ("l_start", 0.4), ("l_end", 0.1)])
def test_schedule_change_restarts(device, attr, value):
    case = _case("torus")
    C = _controls(np.random.default_rng(70), 3, 3)
    som, ref = _pair(case, case.points, C, device, iterations=40, smoothing=0.15)
    som.step(12)
    ref.step(12)
    before = som.weights
    setattr(som, attr, value)
    setattr(ref, attr, value)
    assert som.iteration == som.restart_iteration == ref.iteration > 0
    assert getattr(som, attr) == pytest.approx(value)
    np.testing.assert_array_equal(som.weights, before)
    som.train()
    ref.train()
    assert som.iteration == ref.iterations
    _assert_matches(som, ref, _scale(case.points, C))


@pytest.mark.parametrize(
    ("attr", "value"),
    [("smoothing", 0.4), ("smooth_dims", (0, 2)), ("metric_weights", [1.0, 0.0, 2.0]), ("mirror", (1,))],
)
def test_other_settings_take_effect(device, attr, value):
    """Settable controls of the run; after reset() the run equals a fresh reference with that setting."""
    case = _case("torus")
    C = _controls(np.random.default_rng(80), 3, 3)
    som, _ = _pair(case, case.points, C, device, iterations=30, smoothing=0.1)
    som.step(5)
    setattr(som, attr, value)
    som.reset()
    kw = {"iterations": 30, "smoothing": 0.1, attr: value}
    _, ref = _pair(case, case.points, C, device, **kw)
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C))


@pytest.mark.parametrize(
    ("attr", "before", "after", "seed"),
    [
        ("smoothing", 0.1, 0.4, 1),
        ("smoothing", 0.3, 0.0, 1),
        ("smoothing", 0.0, 0.3, 1),
        ("smooth_dims", (0, 1, 2), (1,), 1),
        ("metric_weights", [1.0, 1.0, 1.0], [1.0, 0.0, 2.0], 5),  # seed 5: the new metric changes winners at once
    ],
)
def test_settings_change_mid_run(device, attr, before, after, seed):
    """Smoothing, smooth_dims and metric weights set mid-run restart locally (som.py, Restarts): s0 from the
    latest weights, with the new setting from the first cycle on. Same-sized steps before and after the change
    also catch a replayed run that kept the old setting."""
    case = _case("torus")
    C = _controls(np.random.default_rng(seed), 3, 3)
    kw = {"iterations": 30, "smoothing": 0.1, attr: before, "reach": 0.5}
    som, ref = _pair(case, case.points, C, device, **kw)
    for _ in range(3):
        assert som.step(1) == 1
    som.step(4)
    ref.step(7)
    if attr == "metric_weights":  # guard: winners stale by one cycle would show
        assert winners(ref.W, ref.effective_controls, after).tolist() != ref.winners().tolist()
    setattr(som, attr, after)
    setattr(ref, attr, after)
    ref.restart()
    assert som.iteration == 15
    for _ in range(3):
        assert som.step(1) == 1
    som.step(4)
    ref.step(7)
    assert som.iteration == 22
    _assert_matches(som, ref, _scale(case.points, C))


# ------------------------------------------------------------------------------------- feature dims and counts
@pytest.mark.parametrize(("n_dims", "seed"), [(1, 1), (3, 3), (5, 0), (8, 0), (32, 1)])
def test_feature_dims(device, n_dims, seed):
    case = _case("lattice")
    rng = np.random.default_rng(seed)
    extra = rng.uniform(-1, 1, size=(case.n, max(0, n_dims - 3)))
    W = np.concatenate([case.points, extra], axis=1)[:, :n_dims]
    C = _controls(rng, 2, n_dims)
    kw = {"iterations": 40, "smoothing": 0.2}
    if n_dims >= 2:
        kw["mirror"] = (1,)
    if n_dims >= 5:
        kw["metric_weights"] = rng.uniform(0.5, 2.0, size=n_dims)
    som, ref = _pair(case, W, C, device, **kw)
    assert som.n_dims == n_dims
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(W, C))
    assert som.winners().tolist() == ref.winners().tolist()


def test_one_control(device):
    case = _case("torus")
    C = np.array([[0.2, 1.9, -0.1]])
    som, ref = _pair(case, case.points, C, device, iterations=80, smoothing=0.1)
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C))
    assert som.effective_controls.shape == (1, 3)


def _paths_case(rng) -> Case:
    """300 neurons: 100 separate paths of 3 (d_max 2), laid out on a grid symmetric in y, 1 apart in a path."""
    bases = [(4.0 * i, y, 3.0 * j) for i in range(5) for y in (-4.5, -1.5, 1.5, 4.5) for j in range(5)]
    points = np.array([(x + t, y, z) for (x, y, z) in bases for t in range(3)], dtype=np.float64)
    points += rng.normal(scale=0.02, size=points.shape)
    edges = np.array([(3 * p + t, 3 * p + t + 1) for p in range(100) for t in range(2)], dtype=np.int64)
    topo = Topology.from_edges(edges, 300)
    return Case("paths", topo, 300, edges_from_edges(edges), points)


@pytest.mark.parametrize(("k", "mirror"), [(256, ()), (128, (1,))])
def test_256_effective_controls(device, k, mirror):
    """The 256 limit counts the effective list: 256 plain controls, or 128 mirrored ones, are accepted.

    Each control sits near its own neuron (mirrored copies near the mirror-image neurons), in a topology of
    100 separate 3-neuron paths, so 256 controls pull without collapsing the mesh and winners stay distinct.
    """
    rng = np.random.default_rng(256)
    case = _paths_case(rng)
    pool = np.flatnonzero(case.points[:, 1] > 0) if mirror else np.arange(case.n)
    targets = rng.choice(pool, size=k, replace=False)
    C = case.points[targets] + rng.uniform(-0.2, 0.2, size=(k, 3))
    som, ref = _pair(case, case.points, C, device, iterations=12, smoothing=0.1, mirror=mirror)
    assert som.effective_controls.shape == (256, 3)
    assert len(set(ref.winners().tolist())) == 256  # every effective control has a winner of its own
    assert som.winners().tolist() == ref.winners().tolist()
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C))
    assert som.winners().tolist() == ref.winners().tolist()


# ------------------------------------------------------------------------------------- misc API
def test_default_device_and_properties():
    case = _case("mixed")
    C = _controls(np.random.default_rng(9), 2, 3)
    som = Som(case.topo, _f32(case.points), _f32(C), iterations=7)
    import warp as wp

    assert som.device == ("cuda:0" if wp.get_cuda_device_count() else "cpu")  # None = the best available
    assert som.n_neurons == 14 and som.n_dims == 3 and som.iteration == 0
    ref = ReferenceSom(
        case.n, case.ref_edges, _f32(case.points).astype(np.float64), _f32(C).astype(np.float64), iterations=7
    )
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C))


def test_float64_inputs_are_accepted(device):
    case = _case("mixed")
    C = _controls(np.random.default_rng(9), 2, 3)
    som = Som(case.topo, np.asarray(case.points, dtype=np.float64), C, iterations=5, device=device)
    np.testing.assert_array_equal(som.weights, _f32(case.points))
    np.testing.assert_array_equal(som.controls, _f32(C))


def test_winner_margins_of_compared_runs_are_recorded():
    """Guard on the guard: the reference records one margin array per iteration, one entry per control."""
    case = _case("lattice")
    C = _controls(np.random.default_rng(3), 3, 3)
    ref = ReferenceSom(case.n, case.ref_edges, case.points, C, iterations=9, mirror=(1,))
    ref.train()
    assert len(ref.margins) == 9 and all(m.shape == (6,) for m in ref.margins)
    assert np.all(np.concatenate(ref.margins) >= 0)


@pytest.mark.parametrize("smoothing", [0.0, 0.3])
@pytest.mark.parametrize("cores", [2, 3])
def test_cpu_cores_split_gives_the_reference_weights(cores, smoothing):
    """The CPU cycle split over several cores (barriers between phases) matches the float64 reference."""
    faces = torus_quads(9, 7)
    points = torus_points(9, 7).astype(np.float32)
    controls = np.array([[2.0, 1.0, 0.5], [-1.5, 0.5, 1.0], [0.3, -2.0, -0.4]], np.float32)
    som = Som(Topology.from_faces(faces), points, controls, iterations=40, smoothing=smoothing, mirror=(1,),
              device="cpu", cpu_cores=cores)
    expect = ReferenceSom(len(points), edges_from_faces(faces), points, controls, iterations=40,
                          smoothing=smoothing, mirror=(1,))
    som.step(9)
    expect.step(9)
    som.train()
    expect.train()
    assert expect.min_margin() > 1e-4
    np.testing.assert_allclose(som.weights, expect.weights, atol=1e-4)


def test_two_threads_can_build_and_train_at_once():
    """A Som trains (capturing graphs) on one thread while another builds Soms and uploads to them: Warp records
    every launch on the device during a capture, so without the engine's lock the other thread's work lands in
    (or breaks) the capture."""
    import threading
    import time

    faces = torus_quads(8, 6)
    points = torus_points(8, 6).astype(np.float32)
    topo = Topology.from_faces(faces)
    controls = np.array([[2.0, 1.0, 0.5], [-1.5, 0.5, 1.0]], np.float32)
    trainer = Som(topo, points, controls, iterations=50, device="cpu")
    errors: list[BaseException] = []
    done = threading.Event()
    trained = 0

    def train():
        nonlocal trained
        try:
            while not done.is_set():  # until the other thread has built its Soms, however the two are scheduled
                trainer.set_controls(controls + np.float32(0.01 * (trained % 7)))  # new controls: graphs recaptured
                trainer.step(3)
                trained += 1
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    thread = threading.Thread(target=train)
    thread.start()
    built = 0
    try:
        while built < 20 and not errors:
            other = Som(Topology.from_faces(faces), points, controls, iterations=10, device="cpu")
            other.set_weights(points * np.float32(1.01))
            other.step(2)
            built += 1
        deadline = time.monotonic() + 60.0
        while trained < 3 and not errors and time.monotonic() < deadline:  # a starved trainer gets its turn
            time.sleep(0.01)
    finally:
        done.set()
        thread.join()
    assert not errors, errors
    assert built == 20 and trained > 0
