"""A drag costs what it touches (backend/local_path.py): the CPU's local cycle, which moves only the blocks of neurons
within reach of a winner and searches only the blocks that may hold one, against the full computation (the engine's
paths that move and search every neuron, run on the Som's parts: the same weights bit for bit) and against the float64
reference with the cut the engine states: past the dense table theta < 2^-24 is 0 (schedule.NEIGHBOURHOOD_CUT).
Past the cut the nodes stay exactly where they were. (Handles in distance rows mode: test_handles.py.)
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from reference import ROWS_CUT, ReferenceSom, edges_from_faces, grid_quads
from test_engine import _assert_matches, _scale

from somwidget import Som, Topology
from somwidget.backend.cpu_path import CpuPath
from somwidget.backend.local_kernels import BLOCK
from somwidget.backend.local_path import find_in_blocks
from somwidget.backend.rows_path import RowsPath

S = 200


def _strip(nx: int = 16, ny: int = 40):
    """An open nx x ny sheet 0.1 apart, gently waved (no two nodes equally near a control)."""
    quads = grid_quads(nx, ny)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    i, j = i.ravel(), j.ravel()
    pts = np.stack([0.1 * i - 0.05 * (nx - 1), 0.1 * j - 0.05 * (ny - 1), 0.03 * np.sin(0.7 * i + 0.3 * j)], 1)
    return Topology.from_faces(quads), edges_from_faces(quads), pts.astype(np.float32)


def _full_run(som: Som, cycles: int) -> None:
    """`cycles` cycles of the paper's rule as the full computation runs them, with the Som's own state and cut table:
    distance rows mode driving the CPU's dense cycle (rows_path.RowsPath over cpu_path.CpuPath: every neuron moved
    and searched)."""
    parts = som.parts
    RowsPath(CpuPath(parts.cores)).run(parts.model, parts.state, parts.controls, parts.schedule, cycles)


def _drag(pts: np.ndarray, controls: np.ndarray, frames: int = 4):
    """The controls of each frame of a drag of control 0."""
    moved = controls.copy()
    for _ in range(frames):
        moved[0] += np.float32([0.03, 0.012, 0.05])
        yield moved.copy()


def _drag_matches_reference(som: Som, ref, pts: np.ndarray, controls: np.ndarray, frames: int = 4) -> None:
    """A drag restarted from its anchor each frame (6 cycles a frame) in the Som and in the float64 reference with
    its cuts: the weights match, and the nodes the reference leaves exactly in place (some, not all) are exactly in
    place in the Som too."""
    som.restore(pts, S)
    som.anchor()
    for moved in _drag(pts, controls, frames):
        som.set_controls(moved, from_anchor=True)
        som.step(6)
        ref.restore(pts.astype(np.float64), S)
        ref.set_controls(moved.astype(np.float64))
        ref.step(6)
        _assert_matches(som, ref, _scale(pts, moved))
        still = (ref.W == pts).all(axis=1)
        assert 0 < still.sum() < len(pts)
        np.testing.assert_array_equal(som.weights[still], pts[still])


@pytest.mark.parametrize(("mirror", "cores"), [((), 1), ((1,), 1), ((1,), 2)])
def test_paper_rule_local_equals_full_computation(mirror, cores):
    """Rows mode on the CPU, a drag restarted from its anchor each frame: the local cycle (on one core, or the blocks
    and controls split between two) gives the full computation's weights and winners bit for bit, and leaves the
    blocks out of reach exactly as they were."""
    topo, _, pts = _strip(16, 520)  # 8,320 neurons: three superblocks of 4,096
    controls = pts[[4147, 4168, 4188]] + np.float32([0.004, 0.003, 0.02])  # mid-sheet: the mirrored copies too
    local = Som(topo, pts, controls, iterations=S, reach=0.04, mirror=mirror, distances="rows", device="cpu",
                cpu_cores=cores)
    full = Som(topo, pts, controls, iterations=S, reach=0.04, mirror=mirror, distances="rows", device="cpu")
    for som in (local, full):
        som.restore(pts, S)
        som.anchor()
    untouched = 0
    for moved in _drag(pts, controls):
        local.set_controls(moved, from_anchor=True)
        local.step(5)
        full.set_controls(moved, from_anchor=True)
        _full_run(full, 5)
        np.testing.assert_array_equal(local.weights, full.weights)
        assert local.winners().tolist() == full.winners().tolist()
        same = (local.weights == pts).all(axis=1)
        untouched = max(untouched, int(same.reshape(-1)[: len(same) // BLOCK * BLOCK].reshape(-1, BLOCK)
                                       .all(axis=1).sum()))
    assert untouched >= 1  # whole blocks lay out of reach (and stayed bit for bit)


def test_paper_rule_local_matches_reference_with_the_cut():
    """The same drag against the float64 reference with theta < 2^-24 taken as 0: equal within float32 rounding, and
    every node the reference leaves exactly in place (out of reach) stays exactly in place."""
    topo, edges, pts = _strip()
    controls = pts[[291, 328, 348]] + np.float32([0.004, 0.003, 0.02])
    som = Som(topo, pts, controls, iterations=S, reach=0.04, distances="rows", device="cpu")
    ref = ReferenceSom(len(pts), edges, pts.astype(np.float64), controls.astype(np.float64), iterations=S,
                       reach=0.04, cut=ROWS_CUT)
    _drag_matches_reference(som, ref, pts, controls)


def test_block_search_equals_full_scan():
    """The search that skips blocks whose box cannot hold a nearer neuron finds the full scan's winners, with metric
    weights, blocks in no spatial order, and exact ties (the lowest index wins)."""
    rng = np.random.default_rng(4)
    n = 150 * int(BLOCK) + 17  # three superblocks
    pts = rng.normal(size=(n, 4)).astype(np.float32)
    pts[: n // 2] = np.sort(pts[: n // 2], axis=0)  # half the blocks tight, half spread
    pts[n // 2: n // 2 + 3000] *= 30.0  # a superblock far away
    pts[n - 5] = pts[7]  # a tie: 7 wins
    pts[n - 9] = pts[n // 3]
    controls = np.concatenate([pts[[7, n // 3, 100, n - 1]], rng.normal(size=(12, 4)).astype(np.float32)])
    topo = Topology.from_edges(np.stack([np.arange(n - 1), np.arange(1, n)], 1), n)
    som = Som(topo, pts, controls, metric_weights=[1.0, 0.5, 2.0, 0.0], distances="rows", device="cpu")
    full = som.winners()
    parts = som.parts
    k = len(controls)
    for hint in (0, n - 1, 777):  # the search starts in a hinted block: any will do
        keys = wp.full(2 * k, hint, dtype=wp.uint64, device="cpu")  # hints, then the keys found
        find_in_blocks(parts.model, parts.state, parts.cores, parts.state.c, k, keys, 0, k)
        found = (keys.numpy()[k:] & np.uint64(0xFFFFFFFF)).astype(np.int64)
        assert found.tolist() == full.tolist()
    assert full[0] == 7 and full[1] == n // 3
