"""The learning table L[s, d] = alpha(s) * theta(d, s) against the float64 reference."""

from __future__ import annotations

import numpy as np
import pytest
from reference import alpha, lattice_edges, learning_table

from somwidget import Som, Topology

RTOL = 1e-6  # float32 table vs float64 reference
# exp(-x) evaluated in float32 is off by about x * eps relative, so by at most max(x e^-x) * eps = 0.37 eps
# absolute (times alpha <= 1): far entries may differ by that much, which is float32 noise, not a bug.
ATOL = 2e-7


def _path(n: int) -> Topology:
    """A path of n vertices: d_max = n - 1 (a single vertex for n = 1)."""
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1) if n > 1 else np.zeros((0, 2), dtype=np.int64)
    return Topology.from_edges(edges, n)


def _som(topo: Topology, device: str = "cpu", **kw) -> Som:
    rng = np.random.default_rng(7)
    w = rng.uniform(-1, 1, size=(topo.n_vertices, 3)).astype(np.float32)
    c = rng.uniform(-1, 1, size=(2, 3)).astype(np.float32)
    return Som(topo, w, c, device=device, **kw)


# ------------------------------------------------------------------------------------- the reference itself
def test_reference_table_by_hand():
    """S = 2, d_max = 1: sigma = 1/sqrt(2 ln 2) makes theta(d_max, 0) = 1/2 and theta(1, 1) = 1/16."""
    L = learning_table(2, 1, 0.25, 0.03)
    a1 = 0.25 * 0.03 / (0.03 + 0.22 * 0.5)
    np.testing.assert_allclose(L, [[0.25, 0.125], [a1, a1 / 16]], rtol=1e-14)
    np.testing.assert_allclose(alpha([0, 2], 2, 0.25, 0.03), [0.25, 0.03], rtol=1e-14)  # alpha(S) = l_end


# ------------------------------------------------------------------------------------- engine vs reference
@pytest.mark.parametrize(
    ("S", "n", "l_start", "l_end"),
    [
        (1, 1, 0.25, 0.03),  # S = 1 and d_max = 0
        (50, 1, 0.25, 0.03),  # d_max = 0: a single column, alpha(s)
        (1, 6, 0.25, 0.03),  # S = 1: a single row
        (2, 2, 0.25, 0.03),
        (100, 9, 0.25, 0.03),
        (37, 46, 0.3, 0.03),  # the space grid's d_max 45
        (200, 20, 1.0, 1.0),  # constant alpha = 1
        (64, 12, 0.03, 0.25),  # l_start < l_end: alpha grows
        (1000, 5, 0.5, 1e-3),
    ],
)
def test_learning_table_matches_reference(device, S, n, l_start, l_end):
    som = _som(_path(n), device, iterations=S, l_start=l_start, l_end=l_end)
    L = som.learning_table()
    assert isinstance(L, np.ndarray)
    assert L.dtype == np.float32
    assert L.shape == (S, n)  # d_max + 1 = n columns
    ref = learning_table(S, n - 1, l_start, l_end)
    np.testing.assert_allclose(L, ref, rtol=RTOL, atol=ATOL)
    # theta(0, s) = 1: the first column is alpha(s) itself
    np.testing.assert_allclose(L[:, 0], alpha(np.arange(S), S, l_start, l_end), rtol=RTOL)
    assert L[0, 0] == pytest.approx(l_start, rel=RTOL)


def test_table_single_vertex_is_alpha(device):
    som = _som(_path(1), device, iterations=1)
    L = som.learning_table()
    assert L.shape == (1, 1)
    assert L[0, 0] == pytest.approx(0.25, rel=RTOL)


def test_table_half_at_d_max_on_first_iteration(device):
    """sigma = d_max / sqrt(2 ln 2) puts theta(d_max, 0) at exactly one half."""
    edges, _ = lattice_edges(4, 4, 3)
    topo = Topology.from_edges(edges, 48)
    som = _som(topo, device, iterations=30, l_start=0.3, l_end=0.03)
    L = som.learning_table()
    assert L.shape == (30, topo.d_max + 1) == (30, 9)
    assert L[0, -1] == pytest.approx(0.15, rel=RTOL)
    np.testing.assert_allclose(L, learning_table(30, 8, 0.3, 0.03), rtol=RTOL, atol=ATOL)


def test_table_of_disconnected_topology_uses_largest_finite_distance(device):
    edges = np.array([(0, 1), (1, 2), (2, 3), (4, 5)])
    topo = Topology.from_edges(edges, 6)
    som = _som(topo, device, iterations=10)
    L = som.learning_table()
    assert L.shape == (10, 4)
    np.testing.assert_allclose(L, learning_table(10, 3), rtol=RTOL, atol=ATOL)


def test_table_values_decrease_with_distance_and_time(device):
    som = _som(_path(10), device, iterations=40, l_start=0.25, l_end=0.03)
    L = som.learning_table().astype(np.float64)
    assert np.all(np.diff(L, axis=1) <= 0)  # farther neurons learn less
    assert np.all(np.diff(L, axis=0) <= 0)  # later iterations learn less (l_start > l_end)
    assert np.all(L[:, 0] <= 0.25 + 1e-7) and np.all(L >= 0)


def test_table_follows_schedule_setters(device):
    som = _som(_path(6), device, iterations=20)
    np.testing.assert_allclose(som.learning_table(), learning_table(20, 5), rtol=RTOL, atol=ATOL)
    som.iterations = 33
    np.testing.assert_allclose(som.learning_table(), learning_table(33, 5), rtol=RTOL, atol=ATOL)
    som.l_start = 0.5
    np.testing.assert_allclose(som.learning_table(), learning_table(33, 5, 0.5, 0.03), rtol=RTOL, atol=ATOL)
    som.l_end = 0.1
    np.testing.assert_allclose(som.learning_table(), learning_table(33, 5, 0.5, 0.1), rtol=RTOL, atol=ATOL)
    assert (som.iterations, som.l_start, som.l_end) == (33, pytest.approx(0.5), pytest.approx(0.1))


def test_default_schedule(device):
    som = _som(_path(4), device)
    assert som.iterations == 1000
    assert som.l_start == pytest.approx(0.25) and som.l_end == pytest.approx(0.03)
    np.testing.assert_allclose(som.learning_table(), learning_table(1000, 3), rtol=RTOL, atol=ATOL)
