"""Block halos for the one-kernel smoothing cycle on CUDA (`spread_kernels.spread_smoothing_cycle_kernel`).

A block owns 32 neurons (block b: b * 32 .. b * 32 + 31). Smoothing neuron v needs the moved weights of v's
neighbours, some of which other blocks own; rather than wait for every block (a second kernel), each block also
moves its halo, the neighbours of its neurons that other blocks own, and smooths its own neurons from those.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BLOCK = 32


@dataclass(frozen=True)
class BlockHalos:
    """chunks: 32-neuron chunks each block moves (its own neurons, then its halo, padded to the largest halo);
    width: the most neighbours of a neuron; neurons: (blocks, chunks * 32) the neurons each block moves, its own
    first (past the mesh: its last neuron; halo padding: the block's first neuron, moved but never read);
    local: (n, width) where each neighbour of v (in the topology's order) sits in its block's list, -1 past the last.
    """

    chunks: int
    width: int
    neurons: np.ndarray
    local: np.ndarray


def block_halos(offsets: np.ndarray, neighbors: np.ndarray, n: int) -> BlockHalos:
    """The halos of the blocks of 32 neurons of a mesh with CSR adjacency (offsets, neighbors)."""
    offsets = np.asarray(offsets, np.int64)
    neighbors = np.asarray(neighbors, np.int64)[: offsets[-1]]
    degree = np.diff(offsets)
    blocks = -(-n // BLOCK)
    source = np.repeat(np.arange(n), degree)
    home = source // BLOCK
    outside = home != neighbors // BLOCK
    pairs = np.unique(home[outside] * n + neighbors[outside])  # (block, halo neuron), sorted by block then neuron
    pair_block, pair_neuron = pairs // n, pairs % n
    halo_size = np.bincount(pair_block, minlength=blocks)
    halo_start = np.concatenate([[0], np.cumsum(halo_size)[:-1]])
    rank = np.arange(len(pairs)) - halo_start[pair_block]  # place of each pair in its block's halo
    chunks = 1 + int(-(-halo_size.max() // BLOCK)) if n else 1

    own = np.minimum(np.arange(blocks)[:, None] * BLOCK + np.arange(BLOCK), max(n - 1, 0))
    listed = np.repeat(own[:, :1], chunks * BLOCK, axis=1)
    listed[:, :BLOCK] = own
    listed[pair_block, BLOCK + rank] = pair_neuron

    place = neighbors - home * BLOCK
    place[outside] = BLOCK + rank[np.searchsorted(pairs, home[outside] * n + neighbors[outside])]
    width = max(1, int(degree.max()) if n else 1)
    local = np.full((n, width), -1, np.int32)
    local[source, np.arange(len(source)) - offsets[source]] = place
    return BlockHalos(chunks, width, listed.astype(np.int32), local)
