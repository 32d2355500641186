"""Topology: edges from faces / edge lists, BFS grid distances and d_max, against the float64 reference."""

from __future__ import annotations

import numpy as np
import pytest
from reference import (
    UNREACHABLE,
    adjacency,
    bfs_distances,
    d_max_of,
    edges_from_edges,
    edges_from_faces,
    grid_quads,
    lattice_edges,
    lattice_quads,
    mixed_faces,
    torus_quads,
)

from somwidget import Topology


def _check_against_reference(topo, n_vertices: int, ref_edges: np.ndarray) -> np.ndarray:
    """Common checks: n_vertices, canonical edges, CSR adjacency, degree, distances, d_max."""
    assert topo.n_vertices == n_vertices
    np.testing.assert_array_equal(np.asarray(topo.edges, dtype=np.int64), ref_edges)
    ref_nbrs = adjacency(n_vertices, ref_edges)
    offsets = np.asarray(topo.offsets)
    neighbors = np.asarray(topo.neighbors)
    assert offsets.shape == (n_vertices + 1,)
    assert offsets[0] == 0 and offsets[-1] == 2 * len(ref_edges) == neighbors.shape[0]
    for v in range(n_vertices):
        assert sorted(neighbors[offsets[v] : offsets[v + 1]].tolist()) == ref_nbrs[v], f"neighbours of {v}"
    np.testing.assert_array_equal(np.asarray(topo.degree()), [len(nb) for nb in ref_nbrs])
    D = topo.grid_distances()
    assert isinstance(D, np.ndarray)
    assert D.dtype == np.uint16
    assert D.shape == (n_vertices, n_vertices)
    ref_D = bfs_distances(n_vertices, ref_edges)
    np.testing.assert_array_equal(D, ref_D)
    assert topo.d_max == d_max_of(ref_D)
    assert np.all(np.diag(D) == 0)
    np.testing.assert_array_equal(D, D.T)
    return D


# ------------------------------------------------------------------------------------- the reference itself
def test_reference_bfs_matches_closed_forms():
    """The reference BFS agrees with Manhattan distance on a lattice and wrap-around distance on a torus."""
    nx, ny, nz = 4, 4, 3
    edges, points = lattice_edges(nx, ny, nz)
    D = bfs_distances(nx * ny * nz, edges)
    manhattan = np.abs(points[:, None, :] - points[None, :, :]).sum(-1)
    np.testing.assert_array_equal(D, manhattan)

    nu, nv = 6, 5
    D = bfs_distances(nu * nv, edges_from_faces(torus_quads(nu, nv)))
    i, j = np.arange(nu * nv) % nu, np.arange(nu * nv) // nu
    di = np.abs(i[:, None] - i[None, :])
    dj = np.abs(j[:, None] - j[None, :])
    expect = np.minimum(di, nu - di) + np.minimum(dj, nv - dj)
    np.testing.assert_array_equal(D, expect)


def test_reference_edges_from_faces_by_hand():
    assert edges_from_faces([[0, 1, 2]]).tolist() == [[0, 1], [0, 2], [1, 2]]
    assert edges_from_faces([[3, 2, 1, 0], [0, 1, 1]]).tolist() == [[0, 1], [0, 3], [1, 2], [2, 3]]
    assert edges_from_edges([[1, 0], [0, 1], [2, 2]]).tolist() == [[0, 1]]


# ------------------------------------------------------------------------------------- lattice
def test_lattice_from_edges():
    nx, ny, nz = 4, 4, 3
    edges, points = lattice_edges(nx, ny, nz)
    topo = Topology.from_edges(edges, nx * ny * nz)
    D = _check_against_reference(topo, nx * ny * nz, edges_from_edges(edges))
    assert topo.d_max == (nx - 1) + (ny - 1) + (nz - 1)
    manhattan = np.abs(points[:, None, :] - points[None, :, :]).sum(-1)
    np.testing.assert_array_equal(D, manhattan)
    assert topo.faces is None


def test_lattice_from_quad_array():
    """The unit squares of a 4x4x3 lattice as an (F, 4) array give the lattice's 6-neighbour edges."""
    nx, ny, nz = 4, 4, 3
    quads = lattice_quads(nx, ny, nz)
    topo = Topology.from_faces(quads)
    edges, _ = lattice_edges(nx, ny, nz)
    assert np.array_equal(edges_from_faces(quads), edges_from_edges(edges))
    _check_against_reference(topo, nx * ny * nz, edges_from_edges(edges))
    assert topo.d_max == 8


# ------------------------------------------------------------------------------------- faces
def test_mixed_mesh_triangles_quads_ngons():
    faces = mixed_faces()
    assert sorted({len(f) for f in faces}) == [3, 4, 5, 6]
    topo = Topology.from_faces(faces)
    _check_against_reference(topo, 14, edges_from_faces(faces))
    assert [list(map(int, f)) for f in topo.faces] == faces  # kept as given, for display


def test_mixed_mesh_sequence_types():
    """Faces as a list of lists, tuples and numpy arrays of different lengths all read the same."""
    faces = mixed_faces()
    as_mixed = [tuple(f) if i % 3 == 0 else (np.array(f) if i % 3 == 1 else list(f)) for i, f in enumerate(faces)]
    a = Topology.from_faces(faces)
    b = Topology.from_faces(as_mixed)
    np.testing.assert_array_equal(a.edges, b.edges)
    np.testing.assert_array_equal(a.grid_distances(), b.grid_distances())


def test_faces_list_and_array_agree():
    quads = grid_quads(5, 4)
    from_array = Topology.from_faces(quads)
    from_list = Topology.from_faces([list(map(int, q)) for q in quads])
    from_int32 = Topology.from_faces(quads.astype(np.int32))
    for topo in (from_array, from_list, from_int32):
        _check_against_reference(topo, 20, edges_from_faces(quads))
    assert from_array.d_max == 3 + 4


def test_triangle_array():
    tris = np.array([[0, 1, 2], [2, 1, 3], [2, 3, 4], [4, 3, 5]], dtype=np.int64)
    topo = Topology.from_faces(tris)
    _check_against_reference(topo, 6, edges_from_faces(tris))


def test_torus_grid_periodic():
    nu, nv = 8, 5
    quads = torus_quads(nu, nv)
    topo = Topology.from_faces(quads)
    _check_against_reference(topo, nu * nv, edges_from_faces(quads))
    assert topo.d_max == nu // 2 + nv // 2
    assert np.all(topo.degree() == 4)


def test_face_duplicates_and_degenerate_faces_ignored():
    """Faces repeating an edge, or repeating a vertex (a self-loop), add nothing."""
    faces = [[0, 1, 2], [2, 1, 0], [0, 1, 2, 3], [3, 3, 4], [4, 4, 4]]
    topo = Topology.from_faces(faces)
    ref = edges_from_faces(faces)
    assert ref.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3], [3, 4]]
    _check_against_reference(topo, 5, ref)


def test_n_vertices_beyond_faces_are_isolated():
    faces = [[0, 1, 2]]
    topo = Topology.from_faces(faces, n_vertices=5)
    D = _check_against_reference(topo, 5, edges_from_faces(faces))
    assert topo.d_max == 1
    assert np.all(D[3, [0, 1, 2, 4]] == UNREACHABLE) and np.all(D[:3, 3:] == UNREACHABLE)


def test_n_vertices_inferred_from_faces():
    assert Topology.from_faces([[0, 1, 2], [2, 1, 6]]).n_vertices == 7


# ------------------------------------------------------------------------------------- components
def test_two_disconnected_components():
    a = grid_quads(3, 3)
    b = grid_quads(4, 2, offset=9)
    faces = np.concatenate([a, b])
    topo = Topology.from_faces(faces)
    D = _check_against_reference(topo, 17, edges_from_faces(faces))
    assert np.all(D[:9, 9:] == UNREACHABLE) and np.all(D[9:, :9] == UNREACHABLE)
    assert topo.d_max == max(2 + 2, 3 + 1)  # the largest finite distance; 65535 does not count


def test_two_components_from_edges_unequal_diameter():
    edges = [(0, 1), (1, 2), (2, 3), (3, 4), (5, 6)]  # a path of 5 and a single edge
    topo = Topology.from_edges(np.array(edges), 7)
    D = _check_against_reference(topo, 7, edges_from_edges(edges))
    assert topo.d_max == 4
    assert D[0, 6] == UNREACHABLE


# ------------------------------------------------------------------------------------- edge lists
def test_from_edges_duplicates_and_self_loops_ignored():
    clean = np.array([(0, 1), (1, 2), (2, 3), (3, 0), (1, 4)])
    noisy = np.array([(0, 1), (1, 0), (1, 2), (2, 2), (2, 3), (3, 0), (0, 3), (1, 4), (4, 1), (0, 1), (4, 4)])
    a = Topology.from_edges(clean, 5)
    b = Topology.from_edges(noisy, 5)
    _check_against_reference(a, 5, edges_from_edges(clean))
    _check_against_reference(b, 5, edges_from_edges(clean))
    np.testing.assert_array_equal(a.edges, b.edges)
    assert len(b.edges) == 5


def test_from_edges_accepts_lists_and_int32():
    edges = [[0, 1], [1, 2], [2, 3]]
    for given in (edges, np.array(edges, dtype=np.int32), np.array(edges, dtype=np.int64)):
        topo = Topology.from_edges(given, 4)
        _check_against_reference(topo, 4, edges_from_edges(edges))
        assert topo.d_max == 3


def test_single_vertex_no_edges():
    topo = Topology.from_edges(np.zeros((0, 2), dtype=np.int64), 1)
    D = _check_against_reference(topo, 1, np.zeros((0, 2), dtype=np.int64))
    assert topo.d_max == 0
    np.testing.assert_array_equal(D, [[0]])


def test_single_vertex_only_self_loop():
    topo = Topology.from_edges(np.array([[0, 0]]), 1)
    _check_against_reference(topo, 1, np.zeros((0, 2), dtype=np.int64))
    assert topo.d_max == 0


def test_vertices_without_edges_all_unreachable():
    topo = Topology.from_edges(np.zeros((0, 2), dtype=np.int64), 4)
    D = topo.grid_distances()
    expect = np.full((4, 4), UNREACHABLE, dtype=np.uint16)
    np.fill_diagonal(expect, 0)
    np.testing.assert_array_equal(D, expect)
    assert topo.d_max == 0


@pytest.mark.parametrize("n", [2, 17, 300])
def test_path_distances(n):
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    topo = Topology.from_edges(edges, n)
    D = topo.grid_distances()
    idx = np.arange(n)
    np.testing.assert_array_equal(D, np.abs(idx[:, None] - idx[None, :]))
    assert topo.d_max == n - 1


# ------------------------------------------------------------------------------------- the two dense builds
def _build_graphs() -> dict[str, Topology]:
    """Meshes and edge cases for comparing the builds: lattice, torus, mixed faces, disconnected components,
    isolated vertices, a single vertex, a path, a star (one wide level) and random graphs."""
    path = np.stack([np.arange(59), np.arange(1, 60)], axis=1)
    out = {
        "lattice": Topology.from_edges(lattice_edges(4, 4, 3)[0], 48),
        "torus": Topology.from_faces(torus_quads(9, 7)),
        "mixed": Topology.from_faces(mixed_faces()),
        "two_components": Topology.from_faces(np.concatenate([grid_quads(3, 3), grid_quads(4, 2, offset=9)])),
        "isolated": Topology.from_faces([[0, 1, 2]], n_vertices=6),
        "single": Topology.from_edges(np.zeros((0, 2), dtype=np.int64), 1),
        "no_edges": Topology.from_edges(np.zeros((0, 2), dtype=np.int64), 5),
        "path": Topology.from_edges(path, 60),
        "star": Topology.from_edges(np.stack([np.zeros(40, np.int64), np.arange(1, 41)], axis=1), 41),
    }
    rng = np.random.default_rng(3)
    for i in range(4):
        n = int(rng.integers(2, 90))
        out[f"random{i}"] = Topology.from_edges(rng.integers(0, n, size=(int(rng.integers(0, 2 * n)), 2)), n)
    return out


BUILD_GRAPHS = _build_graphs()


def _fresh(topo: Topology) -> Topology:
    return Topology(topo.n_vertices, topo.edges, topo.faces)


def _block_build(topo: Topology, threads: int, blocks: int | None, fibers: bool) -> tuple[np.ndarray, int]:
    """The "block" build (CUDA's) on the CPU: one thread a block, or `threads` cooperative fibers a block with
    Warp's CPU blocks (the barriers then really separate the levels)."""
    import warp as wp

    topo = _fresh(topo)
    saved = wp.config.enable_cpu_blocks
    wp.config.enable_cpu_blocks = fibers
    try:
        table = topo._bfs_table("cpu", "block", threads=threads, blocks=blocks).numpy()
    finally:
        wp.config.enable_cpu_blocks = saved
    return table, topo.d_max


@pytest.mark.parametrize("name", sorted(BUILD_GRAPHS))
def test_block_build_equals_thread_build(name):
    """The level-synchronous build that CUDA uses gives the table and d_max of the thread-per-source build, with
    one thread or several (fibers) per block and fewer blocks than sources (each block then takes several)."""
    topo = BUILD_GRAPHS[name]
    old = _fresh(topo)
    expect = old._bfs_table("cpu", "thread").numpy()
    np.testing.assert_array_equal(expect, bfs_distances(topo.n_vertices, topo.edges))
    for threads, blocks, fibers in [(1, None, False), (1, 1, False), (8, 3, True), (32, None, True)]:
        table, d_max = _block_build(topo, threads, blocks, fibers)
        np.testing.assert_array_equal(table, expect, err_msg=f"threads {threads}, blocks {blocks}")
        assert d_max == old.d_max


def test_block_threads_follow_level_width():
    """Threads per search: the power of two at or above N / levels (from one sweep), within _BLOCK_THREADS."""
    from somwidget.backend.topology import _BLOCK_THREADS

    lo, hi = _BLOCK_THREADS
    assert _fresh(BUILD_GRAPHS["path"])._block_threads() == lo  # 60 vertices over 60 levels
    cube = Topology.from_edges(lattice_edges(10, 10, 10)[0], 1000)  # 1,000 vertices over 28 levels: 35.7 a level
    assert _fresh(cube)._block_threads() == 64
    star = Topology.from_edges(np.stack([np.zeros(600, np.int64), np.arange(1, 601)], axis=1), 601)
    assert _fresh(star)._block_threads() == hi


def test_block_build_overflow_raises(monkeypatch):
    """A finite distance reaching the cap is an error in the block build too (the real cap, 65535, needs a path of
    65,536 vertices; here the cap is lowered to the path's length)."""
    from somwidget.backend import topology as topology_module

    n = 30
    path = Topology.from_edges(np.stack([np.arange(n - 1), np.arange(1, n)], axis=1), n)
    monkeypatch.setattr(topology_module, "UNREACHABLE", n)  # d_max n - 1: below the cap
    assert _fresh(path)._bfs_table("cpu", "block", threads=1) is not None
    monkeypatch.setattr(topology_module, "UNREACHABLE", n - 1)  # d_max n - 1: reaches it
    with pytest.raises(ValueError, match="path too long for the dense table"):
        _fresh(path)._bfs_table("cpu", "block", threads=1)
