"""A handle's patch (shaping_kernels.py): `flood_block` (seed and every round in one launch, a block a handle row)
binds the same patch as `seed` and `flood` launched round by round, and both equal the rule computed here in float64
with a breadth-first search: the nodes joined to the winner through nodes within the radius of it, weighted
(1 - t^2)^2; a row not marked for binding again is left as it was. The case is a strip folded in a U, whose other
wall lies inside the ball but is joined to the winner only outside it (so it must not be taken)."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
import warp as wp

from somwidget.backend.shaping_kernels import clear_flag, shaping_kernels
from somwidget.backend.topology import Topology

WIDTH, LENGTH, GAP = 6, 40, 0.15  # the strip's nodes across and along, the walls' distance


def folded_strip() -> tuple[np.ndarray, np.ndarray]:
    """(positions (N, 3), edges): a WIDTH x LENGTH grid of spacing 0.1 folded in half along its length."""
    s = np.arange(LENGTH) * 0.1
    half = s[LENGTH // 2 - 1]
    x = np.where(s <= half, s, 2 * half - s + 0.05)
    z = np.where(s <= half, 0.0, GAP)
    positions = np.array([[x[i], 0.1 * j, z[i]] for i in range(LENGTH) for j in range(WIDTH)])
    node = np.arange(LENGTH * WIDTH).reshape(LENGTH, WIDTH)
    edges = np.concatenate([np.stack([node[:-1].ravel(), node[1:].ravel()], 1),
                            np.stack([node[:, :-1].ravel(), node[:, 1:].ravel()], 1)])
    return positions, edges


def patch_by_search(positions: np.ndarray, edges: np.ndarray, u: int, r: float) -> np.ndarray:
    """The rule in float64: -1 for a node not bound, else (1 - t^2)^2 of t = |p_v - p_u| / r."""
    n = len(positions)
    near = [[] for _ in range(n)]
    for a, b in edges:
        near[a].append(b)
        near[b].append(a)
    d = np.linalg.norm(positions - positions[u], axis=1)
    out = np.full(n, -1.0)
    out[u] = 1.0
    queue = deque([u])
    while queue:
        v = queue.popleft()
        for w in near[v]:
            if out[w] < 0 and d[w] < r:
                out[w] = (1 - (d[w] / r) ** 2) ** 2
                queue.append(w)
    return out


@pytest.mark.parametrize("threads", [None, 32])
def test_flood_block_binds_the_patch_of_the_rule_and_of_the_round_by_round_flood(device, threads):
    positions, edges = folded_strip()
    n = len(positions)
    topology = Topology.from_edges(edges, n)
    cases = [(3 * WIDTH + 2, 0.45), (10 * WIDTH + 4, 0.25), (0, 0.08), (7 * WIDTH, 0.3)]  # (winner, radius)
    kern = shaping_kernels(3)

    def arrays():
        patch = np.full((len(cases), n), -1.0, np.float32)
        patch[3] = 0.5  # the row not bound again
        return dict(
            weights=wp.array(positions.astype(np.float32), dtype=wp.vec3, device=device),
            rebind=wp.array([1, 1, 1, 0], dtype=wp.int32, device=device),
            slot_of_row=wp.array([2, 0, 3, 1], dtype=wp.int32, device=device),  # rows hold slots in any order
            winners=wp.array([cases[1][0], cases[3][0], cases[0][0], cases[2][0]], dtype=wp.int32, device=device),
            radius=wp.array([cases[1][1], cases[3][1], cases[0][1], cases[2][1]], dtype=wp.float32, device=device),
            offsets=wp.array(topology.offsets, dtype=wp.int32, device=device),
            neighbors=wp.array(topology.neighbors, dtype=wp.int32, device=device),
            patch=wp.array(patch, dtype=wp.float32, device=device))

    position = wp.vec3(1.0, 1.0, 1.0)
    a = arrays()
    block = 1 if device == "cpu" else threads or 512
    wp.launch(kern.flood_block, dim=len(cases) * block, block_dim=block, device=device,
              inputs=[a["weights"], a["rebind"], a["slot_of_row"], a["winners"], a["radius"], position, a["offsets"],
                      a["neighbors"], a["patch"]])
    one_launch = a["patch"].numpy()

    b = arrays()
    changed = wp.ones(1, dtype=wp.int32, device=device)
    wp.launch(kern.seed, dim=(len(cases), n), device=device,
              inputs=[b["rebind"], b["slot_of_row"], b["winners"], b["patch"]])
    rounds = 0
    while changed.numpy()[0]:
        wp.launch(clear_flag, dim=1, device=device, inputs=[changed])
        wp.launch(kern.flood, dim=(len(cases), n), device=device,
                  inputs=[b["weights"], b["rebind"], b["slot_of_row"], b["winners"], b["radius"], position,
                          b["offsets"], b["neighbors"], b["patch"], changed])
        rounds += 1
    by_rounds = b["patch"].numpy()

    np.testing.assert_array_equal(one_launch, by_rounds)
    for row, case in enumerate([0, 1, 2]):  # row r holds slot slot_of_row[r], whose winner and radius are case r
        expected = patch_by_search(positions, edges, *cases[case])
        assert np.array_equal(one_launch[row] < 0, expected < 0), f"row {row}: another set of nodes bound"
        np.testing.assert_allclose(one_launch[row], expected, atol=2e-6)
    assert np.all(one_launch[3] == 0.5), "a row not marked for binding again changed"
    # the widest ball reaches the other wall (GAP < radius) but takes only what joins it inside the ball
    wide = patch_by_search(positions, edges, *cases[0])
    other_wall = positions[:, 2] > 0
    within = np.linalg.norm(positions - positions[cases[0][0]], axis=1) < cases[0][1]
    assert np.any(other_wall & within) and not np.any((wide >= 0) & other_wall)
    assert rounds > 3  # the patch is several rounds deep
