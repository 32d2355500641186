"""Block halos of the one-kernel smoothing cycle (halos.py), against sets built neuron by neuron in Python."""

from __future__ import annotations

import numpy as np
import pytest
from reference import lattice_edges

from somwidget import Topology
from somwidget.backend.halos import BLOCK, block_halos


def _shuffled_lattice() -> Topology:
    edges, _ = lattice_edges(9, 7, 5)
    order = np.random.default_rng(1).permutation(9 * 7 * 5)
    return Topology.from_edges(order[edges], 9 * 7 * 5)


def _paths() -> Topology:
    starts = np.arange(0, 300, 3)
    edges = np.concatenate([np.stack([starts, starts + 1], 1), np.stack([starts + 1, starts + 2], 1)])
    return Topology.from_edges(edges, 300)


TOPOLOGIES = {
    "lattice 16^3": lambda: Topology.from_edges(lattice_edges(16, 16, 16)[0], 16 ** 3),
    "shuffled lattice": _shuffled_lattice,
    "separate paths": _paths,
    "isolated vertices": lambda: Topology.from_edges(np.array([[0, 1], [40, 41]]), 70),
    "one vertex": lambda: Topology.from_edges(np.zeros((0, 2), int), 1),
}


@pytest.mark.parametrize("name", TOPOLOGIES)
def test_each_neighbour_is_listed_by_its_block(name):
    topo = TOPOLOGIES[name]()
    n, offsets, neighbors = topo.n_vertices, topo.offsets, topo.neighbors
    halos = block_halos(offsets, neighbors, n)
    blocks = -(-n // BLOCK)
    assert halos.neurons.shape == (blocks, halos.chunks * BLOCK)
    assert halos.local.shape == (n, halos.width)
    halo_sizes = []
    for b in range(blocks):
        own = set(range(b * BLOCK, min(n, (b + 1) * BLOCK)))
        own_slots = np.minimum(np.arange(b * BLOCK, (b + 1) * BLOCK), n - 1)
        np.testing.assert_array_equal(halos.neurons[b, :BLOCK], own_slots)
        halo = {int(u) for v in own for u in neighbors[offsets[v]:offsets[v + 1]]} - own
        halo_sizes.append(len(halo))
        listed = halos.neurons[b, BLOCK:BLOCK + len(halo)]
        assert set(listed.tolist()) == halo and len(set(listed.tolist())) == len(halo)
        for v in own:
            near = neighbors[offsets[v]:offsets[v + 1]]
            np.testing.assert_array_equal(halos.neurons[b, halos.local[v, :len(near)]], near)  # in the same order
            assert (halos.local[v, len(near):] == -1).all()
    assert halos.chunks == 1 + -(-max(halo_sizes) // BLOCK)
    assert halos.width == max(1, int(np.diff(offsets).max()))
