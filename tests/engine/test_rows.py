"""Distance rows on demand (past the dense table): the exact diameter, rows mode against the dense mode and the
float64 reference, a cache smaller than the winners, and a 90,000-vertex grid that the dense table cannot hold.

Rows mode reads the same hop counts as the dense table (int32 rows instead of uint16) and applies the controls in
the same order; its table cuts the neighbourhood where theta < 2^-24 (schedule.NEIGHBOURHOOD_CUT), so the two modes
part by less than that share of a node's distance from a control a cycle.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from reference import (
    ROWS_CUT,
    ReferenceSom,
    alpha,
    bfs_distances,
    d_max_of,
    edges_from_edges,
    edges_from_faces,
    grid_quads,
    lattice_edges,
    learning_table,
    mixed_faces,
    sigma_of,
    torus_quads,
    winner_margins,
)
from test_engine import MIN_MARGIN, _assert_matches, _case, _scale

from somwidget import Som, Topology
from somwidget.backend.topology import MAX_DENSE_NEURONS, RowSearch


def _fresh(topo: Topology) -> Topology:
    """The same graph with nothing computed yet (no dense table, no d_max)."""
    return Topology(topo.n_vertices, topo.edges, topo.faces)


def _path(n: int) -> Topology:
    return Topology.from_edges(np.stack([np.arange(n - 1), np.arange(1, n)], axis=1), n)


def _grid(nx: int, ny: int) -> Topology:
    """An open nx x ny quad grid, vertex i + nx * j: hop distance = |di| + |dj|."""
    idx = np.arange(nx * ny).reshape(ny, nx)
    quads = np.stack([idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()], axis=1)
    return Topology.from_faces(quads)


# ------------------------------------------------------------------------------------- exact diameter
def _ring(n: int) -> np.ndarray:
    return np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)


def _graphs() -> dict[str, tuple[int, np.ndarray]]:
    """name -> (n_vertices, edges): meshes, disconnected graphs, symmetric ones (the hard case) and random ones."""
    out = {
        "lattice": (48, lattice_edges(4, 4, 3)[0]),
        "torus": (40, edges_from_faces(torus_quads(8, 5))),
        "torus_odd": (21 * 13, edges_from_faces(torus_quads(21, 13))),
        "mixed": (14, edges_from_faces(mixed_faces())),
        "two_components": (17, edges_from_faces(np.concatenate([grid_quads(3, 3), grid_quads(4, 2, offset=9)]))),
        "isolated_vertices": (6, np.array([[0, 1], [1, 2]])),
        "no_edges": (4, np.zeros((0, 2), dtype=np.int64)),
        "ring": (101, _ring(101)),
        "path": (64, np.stack([np.arange(63), np.arange(1, 64)], axis=1)),
        "grid_and_ring": (85, np.concatenate([edges_from_faces(grid_quads(10, 6)), 60 + _ring(25)])),
        # a hub of degree 41 (past the eight neighbours a row search reads at once) on a path, and a loose piece
        "hub_on_path": (70, np.concatenate([np.stack([np.zeros(40, int), np.arange(1, 41)], axis=1),
                                            np.stack([np.arange(40, 64), np.arange(41, 65)], axis=1),
                                            [[66, 67], [67, 68]]])),
    }
    rng = np.random.default_rng(11)
    for i in range(12):
        n = int(rng.integers(2, 150))
        out[f"random{i}"] = (n, rng.integers(0, n, size=(int(rng.integers(0, 2 * n)), 2)))
    return out


GRAPHS = _graphs()


@pytest.mark.parametrize("name", ["two_components", "grid_and_ring", "path", "isolated_vertices", "random3",
                                  "hub_on_path"])
def test_row_search_methods_match_reference(device, name):
    """Every way a batch of rows is searched (a thread per row; on CUDA also a block per row, its visited set and
    frontier in shared memory or not, and a launch per level) gives the reference's hop counts from single and
    multiple sources, and the largest distance per row. The shared-memory search also runs with a frontier of two
    vertices, so wider levels spill to global memory. On the CPU the block-per-row kernel runs with one thread a
    block."""
    import warp as wp

    from somwidget.backend import distance_kernels

    n, edges = GRAPHS[name]
    topo = Topology.from_edges(edges, n)
    ref = bfs_distances(n, edges_from_edges(edges)).astype(np.int64)
    ref[ref == 65535] = -1
    rng = np.random.default_rng(3)
    sources = [[0], [n - 1], rng.choice(n, size=min(3, n), replace=False).tolist(), [n // 2]]
    expected = np.stack([np.where((ref[s] >= 0).any(0), np.where(ref[s] >= 0, ref[s], 1 << 30).min(0), -1)
                         for s in sources])
    search = RowSearch(topo, device)
    methods = ["thread"] if device == "cpu" else ["thread", "block", "levels", "shared", "shared, spilling"]
    for method in methods:
        if method == "shared, spilling":
            search._shared = (search._shared[0], 2)
        search.method = lambda levels, method=method: method.split(",")[0]
        rows = wp.full((len(sources) + 1, n), 7, dtype=wp.int32, device=device)
        slots = [2, 0, 4, 1]
        far = search.run(sources, slots, rows, max(topo.d_max, 1), far=True)
        np.testing.assert_array_equal(rows.numpy()[slots], expected, err_msg=method)
        np.testing.assert_array_equal(far, expected.max(1), err_msg=method)
    if device == "cpu":
        b = search._buffer()
        rows = wp.full((len(sources) + 1, n), 7, dtype=wp.int32, device=device)
        search.run(sources, [2, 0, 4, 1], rows, n)  # fills the batch's buffers
        wp.launch(distance_kernels.bfs_row_blocks, dim=len(sources), device="cpu",
                  inputs=[search.offsets, search.neighbors, b["sources"], b["first"], b["slots"], rows, b["queue"],
                          b["size"], b["far"]])
        np.testing.assert_array_equal(rows.numpy()[[2, 0, 4, 1]], expected)
        np.testing.assert_array_equal(b["far"].numpy()[: len(sources)], expected.max(1))


@pytest.mark.parametrize("name", sorted(GRAPHS))
def test_diameter_equals_dense_d_max(name):
    n, edges = GRAPHS[name]
    topo = Topology.from_edges(edges, n)
    expected = d_max_of(bfs_distances(n, edges))
    assert topo.d_max == expected  # the dense path
    assert _fresh(topo).diameter("cpu") == expected  # the iFUB path, without the dense table


def test_diameter_of_symmetric_torus(device):
    """A torus: every vertex has the same eccentricity, iFUB's worst case (a search from about half the vertices),
    which moves to batches on `device` after a few rounds. 80 x 60 quads: d_max = 40 + 30."""
    topo = Topology.from_faces(torus_quads(80, 60))
    assert topo.diameter(device) == 70


def test_d_max_past_dense_cap_uses_diameter():
    """A 300 x 300 grid (90,000 vertices): d_max = 2 * 299 without a table; grid_distances() refuses and says why."""
    topo = _grid(300, 300)
    assert topo.n_vertices == 90_000 > MAX_DENSE_NEURONS
    assert topo.d_max == 598
    with pytest.raises(ValueError) as info:
        topo.grid_distances()
    msg = str(info.value)
    assert "65,536" in msg and re.search(r"on demand", msg) and "distances='rows'" in msg, msg


# ------------------------------------------------------------------------------------- rows mode vs dense mode
def _scenario(som: Som, controls: np.ndarray) -> list[np.ndarray]:
    """Partial steps, a restart by set_controls, a reset, and the rest of the run: the weights after each."""
    seen = []
    for act in (
        lambda: som.step(3),
        lambda: som.step(5),
        lambda: som.set_controls(controls[::-1] * 0.8),
        lambda: som.step(7),
        lambda: som.reset(),
        lambda: som.step(2),
        lambda: som.train(),
    ):
        act()
        seen.append(som.weights)
    return seen


MODE_RUNS = [  # (case, keywords)
    ("lattice", {}),
    ("lattice", {"smoothing": 0.3}),
    ("torus", {"mirror": (1,)}),
    ("torus", {"mirror": (1,), "smoothing": 0.2}),
    ("two_components", {}),
    ("two_components", {"smoothing": 0.35}),
    ("mixed", {"metric_weights": [1.0, 0.5, 2.0]}),
]


@pytest.mark.parametrize(("name", "kw"), MODE_RUNS)
@pytest.mark.parametrize("cache_rows", [None, 2])
def test_rows_equal_dense(device, name, kw, cache_rows):
    """Same device, same weights bit for bit, with the default cache and with one smaller than the winners."""
    case = _case(name)
    rng = np.random.default_rng(5)
    W = case.points.astype(np.float32)
    C = rng.uniform(-1.2, 1.2, size=(4, 3)).astype(np.float32)
    dense = Som(case.topo, W, C, iterations=30, device=device, distances="dense", **kw)
    rows = Som(case.topo, W, C, iterations=30, device=device, distances="rows", cache_rows=cache_rows, **kw)
    assert (dense.distances, rows.distances) == ("dense", "rows")
    # the same table but where theta < 2^-24 (the float64 reference's theta decides)
    ref = learning_table(30, dense.learning_table().shape[1] - 1)
    kept = ref >= ROWS_CUT * ref[:, :1]
    assert not kept.all()  # the cut takes entries off this table
    np.testing.assert_array_equal(rows.learning_table(), np.where(kept, dense.learning_table(), 0.0))
    for a, b in zip(_scenario(dense, C), _scenario(rows, C), strict=True):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-6)
    assert rows.winners().tolist() == dense.winners().tolist()


def test_rows_stall_and_cache_paths_run(device):
    """On CUDA the cycle that lacks a row stalls and resumes; a cache of two rows (one is taken as two: a mirrored pair
    moves in one part) runs each cycle in parts. Both are used."""
    case = _case("torus")
    rng = np.random.default_rng(2)
    W = case.points.astype(np.float32)
    C = rng.uniform(-1.2, 1.2, size=(3, 3)).astype(np.float32)
    dense = Som(case.topo, W, C, iterations=40, mirror=(1,), device=device, distances="dense")
    dense.train()
    for size in (None, 1, 3):
        som = Som(case.topo, W, C, iterations=40, mirror=(1,), device=device, distances="rows", cache_rows=size)
        som.train()
        np.testing.assert_allclose(som.weights, dense.weights, rtol=0, atol=1e-6)
        cache = som.parts.model.cache
        assert cache.size == (case.n if size is None else max(size, 2))
        assert cache.computed >= len(set(som.winners().tolist()))
        if size is None:  # winners moved during the run: on CUDA a graph stopped and went on (the CPU fetches
            # each cycle's rows before its move, and never stalls)
            assert (cache.stalls >= 1) == (device != "cpu")
            assert (cache.prefetched > 0) == (device != "cpu")  # on CUDA the winners' neighbours come along
        else:
            assert cache.computed > cache.size  # rows were evicted and searched again


@pytest.mark.parametrize(
    ("name", "smoothing", "seed"), [("lattice", 0.0, 2), ("torus", 0.35, 1), ("two_components", 0.0, 0)]
)
def test_rows_match_reference(device, name, smoothing, seed):
    """Rows mode against the float64 reference (the seeds of test_engine's TOPOLOGY_RUNS: well separated winners)."""
    case = _case(name)
    rng = np.random.default_rng(seed)
    C = rng.uniform(-1.2, 1.2, size=(4, 3))
    w, c = case.points.astype(np.float32), C.astype(np.float32)
    som = Som(case.topo, w, c, iterations=60, smoothing=smoothing, device=device, distances="rows", cache_rows=3)
    ref = ReferenceSom(case.n, case.ref_edges, w.astype(np.float64), c.astype(np.float64), iterations=60,
                       smoothing=smoothing, cut=ROWS_CUT)
    som.train()
    ref.train()
    _assert_matches(som, ref, _scale(case.points, C))


# ------------------------------------------------------------------------------------- choosing the mode
def test_distances_argument():
    topo = _case("lattice").topo
    W = np.zeros((topo.n_vertices, 3), np.float32)
    assert Som(topo, W, [[1.0, 0.0, 0.0]], device="cpu").distances == "dense"  # N <= 16,384: dense by default
    for bad in ("sparse", 1, True):
        with pytest.raises(ValueError, match=r"^distances: "):
            Som(topo, W, [[1.0, 0.0, 0.0]], device="cpu", distances=bad)
    for bad in (0, -3, 1.5):
        with pytest.raises(ValueError, match=r"^cache_rows: "):
            Som(topo, W, [[1.0, 0.0, 0.0]], device="cpu", distances="rows", cache_rows=bad)


def test_rows_by_default_on_the_cpu_past_16384():
    """On the CPU a mesh past 16,384 neurons takes distance rows by default (its dense table would take the CPU's
    cores a long time and 8 GiB at 65,536); a GPU keeps the dense table up to 65,536."""
    topo = _grid(130, 130)
    W = np.zeros((topo.n_vertices, 3), np.float32)
    assert Som(topo, W, [[1.0, 0.0, 0.0]], device="cpu").distances == "rows"


def test_dense_refused_past_cap_rows_by_default():
    """70,000 neurons on a path (d_max 69,999 > the uint16 table's range): rows by default, "dense" refused."""
    n = 70_000
    topo = _path(n)
    W = np.zeros((n, 1), np.float32)
    W[:, 0] = np.linspace(-1.0, 1.0, n)
    with pytest.raises(ValueError, match=r"^distances: .*65,536.*distances='rows'"):
        Som(topo, W, [[0.5]], device="cpu", distances="dense")
    C = np.array([[0.5], [-0.9]], np.float32)
    som = Som(topo, W, C, iterations=4, device="cpu")
    assert som.distances == "rows" and topo.d_max == n - 1
    assert som.learning_table().shape == (4, n)
    som.train()
    # float64 reference: hop distance on a path is |i - j| (the reference's theta reads 65535 as unreachable)
    s_, d_ = np.arange(4.0)[:, None], np.arange(n, dtype=np.float64)[None, :]
    c_ = sigma_of(n - 1) * (1 - s_ / 4)
    table = alpha(s_, 4, 0.25, 0.03) * np.exp(-(d_**2) / (2 * c_**2))
    ref, index = W.astype(np.float64), np.arange(n)
    for s in range(4):
        assert winner_margins(ref, C.astype(np.float64)).min() >= MIN_MARGIN
        winners = [int(np.argmin((ref[:, 0] - c) ** 2)) for c in C[:, 0].astype(np.float64)]
        for c, u in zip(C.astype(np.float64), winners, strict=True):
            ref += table[s, np.abs(index - u)][:, None] * (c - ref)
    np.testing.assert_allclose(som.weights, ref, rtol=0, atol=1e-5)


# ------------------------------------------------------------------------------------- past the dense table
def test_grid_past_dense_cap_matches_reference(device):
    """300 x 300 grid (90,000 vertices), 3-D weights, 2 controls, 5 cycles in rows mode, against a float64
    reference that reads hop distances as |di| + |dj| (exact on an open grid)."""
    nx = ny = 300
    topo = _grid(nx, ny)
    jj, ii = np.divmod(np.arange(nx * ny), nx)
    W = np.stack([ii / (nx - 1) * 2 - 1, jj / (ny - 1) * 2 - 1, 0.1 * np.sin(ii * 0.05) * np.cos(jj * 0.07)], 1)
    W = W.astype(np.float32)
    # each control just off a neuron (well separated winners: the sheet is dense, a far control would near-tie)
    C = (W[[77403, 40530]] + [[0.0018, -0.0016, -0.0027], [-0.0006, -0.0018, -0.0025]]).astype(np.float32)
    S, cycles = 100, 5
    som = Som(topo, W, C, iterations=S, device=device)
    assert som.distances == "rows" and som.parts.schedule.d_max == 598
    assert som.step(2) == 2 and som.step(3) == 3

    table = learning_table(S, 598, cut=ROWS_CUT)
    ref = W.astype(np.float64)
    c64 = C.astype(np.float64)
    for s in range(cycles):
        assert winner_margins(ref, c64).min() >= MIN_MARGIN
        winners = [int(np.argmin(((ref - c) ** 2).sum(1))) for c in c64]  # all winners before any move
        for c, u in zip(c64, winners, strict=True):
            ref += table[s, np.abs(ii - ii[u]) + np.abs(jj - jj[u])][:, None] * (c - ref)
    np.testing.assert_allclose(som.weights, ref, rtol=0, atol=1e-4)
    assert som.parts.model.cache.computed >= 2


def test_cpu_cache_holds_a_quarter_gib_at_262144():
    """A CPU session's memory stays bounded at its largest mesh (issue 28: 1 GB for 262,144 vertices): the distance
    rows of a 262,144-neuron mesh take at most 256 MiB (256 rows), a GPU's its own share."""
    from somwidget.backend.row_cache import RowCache

    n = 262_144
    cache = RowCache(_path(n), "cpu", None)
    assert cache.size == 256 and cache.size * 4 * n <= 256 << 20
    assert RowCache(_path(4096), "cpu", None).size == 4096  # a small mesh: every row fits
