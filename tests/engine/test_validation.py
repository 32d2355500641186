"""Bad input: every case raises ValueError whose message names the offending argument."""

from __future__ import annotations

import re

import numpy as np
import pytest
from reference import grid_quads

from somwidget import Som, Topology

NAN = float("nan")
INF = float("inf")


def _topo() -> Topology:
    return Topology.from_faces(grid_quads(4, 3))  # 12 vertices, d_max 5


def _w(n_dims: int = 3, n: int = 12) -> np.ndarray:
    return np.random.default_rng(0).uniform(-1, 1, size=(n, n_dims)).astype(np.float32)


def _c(k: int = 2, n_dims: int = 3) -> np.ndarray:
    return np.random.default_rng(1).uniform(-1, 1, size=(k, n_dims)).astype(np.float32)


def _raises(name: str):
    """pytest.raises(ValueError) whose message must name `name` (word-ish match, case-insensitive)."""
    return pytest.raises(ValueError, match=re.compile(re.escape(name), re.IGNORECASE))


def _som(**kw) -> Som:
    args = {"topo": _topo(), "weights": _w(), "controls": _c(), "iterations": 20, "device": "cpu"}
    args.update(kw)
    topo = args.pop("topo")
    w = args.pop("weights")
    c = args.pop("controls")
    return Som(topo, w, c, **args)


def test_valid_baseline_builds():
    som = _som()
    assert som.n_neurons == 12 and som.n_dims == 3


# ------------------------------------------------------------------------------------- weights
@pytest.mark.parametrize("bad", [NAN, INF, -INF])
def test_weights_not_finite(bad):
    w = _w()
    w[4, 1] = bad
    with _raises("weights"):
        _som(weights=w)


@pytest.mark.parametrize(
    "w",
    [
        np.zeros(12, dtype=np.float32),  # 1-D
        np.zeros((12, 3, 1), dtype=np.float32),  # 3-D
        np.zeros((11, 3), dtype=np.float32),  # one row short of n_vertices
        np.zeros((13, 3), dtype=np.float32),  # one row too many
        np.zeros((), dtype=np.float32),  # a scalar
    ],
    ids=["1d", "3d", "short", "long", "scalar"],
)
def test_weights_bad_shape(w):
    with _raises("weights"):
        _som(weights=w, controls=_c(2, 3))


@pytest.mark.parametrize("n_dims", [0, 33])
def test_feature_dims_out_of_range(n_dims):
    with _raises("weights"):
        _som(weights=np.zeros((12, n_dims), dtype=np.float32), controls=np.zeros((2, n_dims), dtype=np.float32))


@pytest.mark.parametrize("n_dims", [1, 32])
def test_feature_dims_limits_accepted(n_dims):
    som = _som(weights=_w(n_dims), controls=_c(2, n_dims))
    assert som.n_dims == n_dims


# ------------------------------------------------------------------------------------- controls
@pytest.mark.parametrize("bad", [NAN, INF, -INF])
def test_controls_not_finite(bad):
    c = _c()
    c[1, 2] = bad
    with _raises("controls"):
        _som(controls=c)


@pytest.mark.parametrize("n_dims", [2, 4])
def test_controls_feature_count_differs(n_dims):
    with _raises("controls"):
        _som(controls=_c(2, n_dims))


@pytest.mark.parametrize(
    "c",
    [np.zeros(4, dtype=np.float32), np.zeros((2, 3, 1), dtype=np.float32), np.zeros((0, 3), dtype=np.float32)],
    ids=["1d-wrong-length", "3d", "none"],
)
def test_controls_bad_shape(c):
    with _raises("controls"):
        _som(controls=c)


def test_too_many_controls():
    with _raises("controls"):
        _som(controls=_c(257))


def test_too_many_mirrored_controls():
    """129 originals mirrored are 258 effective controls: over the 256 limit (128 mirrored are fine)."""
    assert _som(controls=_c(128), mirror=(1,)).effective_controls.shape == (256, 3)
    with _raises("controls"):
        _som(controls=_c(129), mirror=(1,))


def test_set_controls_bad_values():
    som = _som(mirror=(1,))
    som.step(3)
    before = som.weights
    bad_inputs = [
        np.array([[0.0, NAN, 0.0]], dtype=np.float32),
        np.array([[0.0, 0.0, INF]], dtype=np.float32),
        _c(2, 4),  # wrong feature count
        np.zeros(4, dtype=np.float32),  # 1-D of the wrong length
        np.zeros((2, 3, 1), dtype=np.float32),  # 3-D
        _c(129),  # 258 effective with the mirror
        _c(300),
    ]
    for bad in bad_inputs:
        with _raises("controls"):
            som.set_controls(bad)
    # a refused call changes nothing
    assert som.iteration == 3
    np.testing.assert_array_equal(som.weights, before)
    np.testing.assert_array_equal(som.controls, _c())
    som.set_controls(_c(128))  # 256 effective: accepted, a local restart
    assert som.iteration == som.restart_iteration


def test_set_weights_bad_values():
    som = _som()
    w = _w()
    w[0, 0] = NAN
    with _raises("weights"):
        som.set_weights(w)
    with _raises("weights"):
        som.set_weights(_w(n=11))
    with _raises("weights"):
        som.set_weights(_w(n_dims=4))


# ------------------------------------------------------------------------------------- schedule
@pytest.mark.parametrize("S", [0, -3, 2.5, NAN, "10"])
def test_iterations_invalid(S):
    with _raises("iterations"):
        _som(iterations=S)


@pytest.mark.parametrize("S", [1, np.int64(40), np.int32(7)])
def test_iterations_integer_types_accepted(S):
    assert _som(iterations=S).iterations == int(S)


@pytest.mark.parametrize("name", ["l_start", "l_end"])
@pytest.mark.parametrize("value", [0.0, -0.1, 1.5, NAN, INF])
def test_rates_outside_unit_interval(name, value):
    with _raises(name):
        _som(**{name: value})


@pytest.mark.parametrize("name", ["l_start", "l_end"])
def test_rate_one_accepted(name):
    som = _som(**{name: 1.0})
    assert getattr(som, name) == 1.0
    assert som.step(2) == 2 and np.isfinite(som.weights).all()


@pytest.mark.parametrize("value", [-0.1, 1.5, NAN, INF])
def test_smoothing_outside_unit_interval(value):
    with _raises("smoothing"):
        _som(smoothing=value)


@pytest.mark.parametrize("value", [0.0, 1.0])
def test_smoothing_bounds_accepted(value):
    som = _som(smoothing=value)
    assert som.smoothing == value
    assert som.step(2) == 2 and np.isfinite(som.weights).all()


def test_setters_validate():
    som = _som()
    som.step(4)
    for attr, bad in [
        ("iterations", 0),
        ("iterations", -3),
        ("iterations", 2.5),
        ("l_start", 0.0),
        ("l_start", 1.5),
        ("l_end", -0.1),
        ("l_end", NAN),
        ("smoothing", 1.5),
        ("smoothing", -0.1),
        ("mirror", (3,)),
        ("smooth_dims", (-1,)),
        ("metric_weights", [1.0, -1.0, 1.0]),
    ]:
        with _raises(attr):
            setattr(som, attr, bad)
    # refused settings leave the run as it was
    assert som.iteration == 4
    assert som.iterations == 20 and som.l_start == pytest.approx(0.25) and som.l_end == pytest.approx(0.03)
    assert som.smoothing == 0.0


# ------------------------------------------------------------------------------------- dims
@pytest.mark.parametrize("name", ["mirror", "smooth_dims"])
@pytest.mark.parametrize("dims", [(3,), (0, 7), (-1,), (1.5,)])
def test_dims_out_of_range(name, dims):
    with _raises(name):
        _som(**{name: dims})


@pytest.mark.parametrize(
    "m",
    [
        [1.0, -1.0, 1.0],  # negative
        [0.0, 0.0, 0.0],  # all zero
        [1.0, 1.0],  # too short
        [1.0, 1.0, 1.0, 1.0],  # too long
        [1.0, NAN, 1.0],
        [1.0, INF, 1.0],
    ],
    ids=["negative", "all-zero", "short", "long", "nan", "inf"],
)
def test_metric_weights_invalid(m):
    with _raises("metric_weights"):
        _som(metric_weights=m)


# ------------------------------------------------------------------------------------- device
@pytest.mark.parametrize("dev", ["tpu", "cuda:banana", "gpu0"])
def test_unknown_device(dev):
    with _raises("device"):
        _som(device=dev)


# ------------------------------------------------------------------------------------- topology
@pytest.mark.parametrize(
    "faces",
    [
        [[0, 1, 2], [2, 1, -1]],  # negative index
        np.array([[0, 1, -2]]),
        [[0, 1, 2], [1, 2.5, 3]],  # not an integer
        np.array([[0.0, 1.5, 2.0]]),
        [[0, 1, "2"]],
    ],
    ids=["negative", "negative-array", "float", "float-array", "string"],
)
def test_faces_bad_indices(faces):
    with _raises("faces"):
        Topology.from_faces(faces)


def test_faces_out_of_range():
    with _raises("faces"):
        Topology.from_faces([[0, 1, 2], [2, 1, 5]], n_vertices=5)
    with _raises("faces"):
        Topology.from_faces(np.array([[0, 1, 9]]), n_vertices=4)


@pytest.mark.parametrize(
    ("edges", "n"),
    [
        (np.array([[0, 1], [1, -1]]), 3),  # negative
        (np.array([[0, 1], [1, 3]]), 3),  # out of range
        (np.array([[0.0, 1.5]]), 3),  # not integers
        (np.array([0, 1, 2]), 3),  # not (E, 2)
        (np.array([[0, 1, 2]]), 3),
    ],
    ids=["negative", "out-of-range", "float", "1d", "three-columns"],
)
def test_edges_bad(edges, n):
    with _raises("edges"):
        Topology.from_edges(edges, n)


def test_grid_distances_refused_past_dense_cap():
    """N = 65537 > 65536: grid_distances() refuses (without building 8 GiB) and says what to do instead."""
    n = 65_537
    path = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    topo = Topology.from_edges(path, n)
    assert topo.n_vertices == n
    with pytest.raises(ValueError) as info:
        topo.grid_distances()
    msg = str(info.value)
    assert re.search(r"65[,_ ]?53[67]", msg), msg  # names the cap (or the size asked for)
    # says what to do instead: the engine's on-demand distance rows (or another way around the dense table)
    assert re.search(r"(?i)on[- ]demand|row|instead|use ", msg), msg


@pytest.mark.parametrize("build", [
    lambda: Topology.from_faces([[0, 1, 2**40]]),
    lambda: Topology.from_edges([[0, 1]], 10**12),
])
def test_absurd_vertex_counts_are_refused_before_allocating(build):
    """A stray huge index must give a ValueError naming the limit, not a MemoryError from an 8 TiB array."""
    with pytest.raises(ValueError, match="134"):
        build()


def test_a_move_with_the_radii_it_had_keeps_them_and_a_changed_radius_is_checked():
    """Controls.moved keeps the radii array a drag's every move gives again (the handles' layout found without a
    look), and checks any other: a radius changed by a move takes effect, a bad one is refused naming it."""
    from somwidget.backend.som_controls import Controls

    c = Controls.make(np.zeros((2, 3), np.float32), [0.0, 0.0], None, (None, ()), 3)
    assert c.any_radius is False
    same = c.moved(np.ones((2, 3), np.float32), np.zeros(2, np.float32), (1, 1))
    assert same.radii is c.radii and same.strokes is c.strokes and same.any_radius is False
    wider = c.moved(np.ones((2, 3), np.float32), np.array([0.0, 0.2], np.float32), (1, 1))
    assert wider.radii is not c.radii and wider.any_radius is True and wider.radii.tolist() == pytest.approx([0, 0.2])
    assert wider.moved(np.zeros((2, 3), np.float32)).any_radius is True  # kept with the radii
    with pytest.raises(ValueError, match="radii"):
        c.moved(np.ones((2, 3), np.float32), np.array([0.0, np.nan], np.float32))
    with pytest.raises(ValueError, match="strokes"):
        c.moved(np.ones((2, 3), np.float32), None, (1, 2))
