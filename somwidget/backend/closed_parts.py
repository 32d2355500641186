"""The closed parts of a mesh (each edge of their faces on exactly two faces) and their triangles: Taubin's smoothing
puts back the volume each encloses (shaping_kernels.part_volumes, volume_gradient, put_back).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .metrics import _face_arrays, triangles_of
from .topology import Topology, _components


@dataclass
class ClosedParts:
    """node_part (N,): the closed part of each node (-1: in none); triangles (T, 3) the closed parts' faces fanned
    from their first node, in face order, with triangle_part (T,); triangle_offsets (N + 1,) and triangles_of: each
    node's triangles (CSR); count: the closed parts."""

    node_part: np.ndarray
    triangles: np.ndarray
    triangle_part: np.ndarray
    triangle_offsets: np.ndarray
    triangles_of: np.ndarray
    count: int

    def on(self, device: str) -> DeviceParts:
        """The arrays on `device` (a one-element stand-in for an empty one)."""
        def put(a, dtype):
            a = np.ascontiguousarray(a, np.int32)
            return wp.array(a if a.size else np.zeros((1,) + a.shape[1:], np.int32), dtype=dtype, device=device)

        return DeviceParts(put(self.node_part, wp.int32),
                            wp.array(self.triangles if len(self.triangles) else np.zeros((1, 3), np.int32),
                                     dtype=wp.int32, device=device),
                            put(self.triangle_part, wp.int32), put(self.triangle_offsets, wp.int32),
                            put(self.triangles_of, wp.int32), len(self.triangles), self.count)


@dataclass
class DeviceParts:
    node_part: wp.array
    triangles: wp.array
    triangle_part: wp.array
    triangle_offsets: wp.array
    triangles_of: wp.array
    n_triangles: int
    count: int


def no_closed_parts(n: int) -> ClosedParts:
    """None of n nodes is in a closed part."""
    return ClosedParts(np.full(n, -1, np.int32), np.zeros((0, 3), np.int32), np.zeros(0, np.int32),
                       np.zeros(n + 1, np.int32), np.zeros(0, np.int32), 0)


def closed_parts(topology: Topology) -> ClosedParts:
    """The closed connected parts of the topology's faces (none for a topology without faces)."""
    n = topology.n_vertices
    none = no_closed_parts(n)
    if topology.faces is None or not len(topology.faces):
        return none
    flat, sizes = _face_arrays(getattr(topology.faces, "array", topology.faces))
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    after = np.arange(len(flat)) + 1  # each face's next node, its first after its last
    ends = starts + sizes
    after[ends[sizes > 0] - 1] = starts[sizes > 0]
    a, b = flat, flat[after]
    keep = a != b
    lo, hi = np.minimum(a[keep], b[keep]), np.maximum(a[keep], b[keep])
    keys, uses = np.unique(lo * n + hi, return_counts=True)
    labels = _components(topology)[0]
    open_labels = np.unique(labels[keys[uses != 2] // n])
    tris = triangles_of(getattr(topology.faces, "array", topology.faces))
    if not len(tris):
        return none
    tri_label = labels[tris[:, 0]]
    closed = ~np.isin(tri_label, open_labels)
    tris, tri_label = tris[closed], tri_label[closed]
    if not len(tris):
        return none
    part_labels, tri_part = np.unique(tri_label, return_inverse=True)
    lookup = np.full(int(labels.max()) + 1, -1, np.int64)
    lookup[part_labels] = np.arange(len(part_labels))
    node_part = lookup[labels]
    corner_node = tris.ravel()
    corner_tri = np.repeat(np.arange(len(tris)), 3)
    pairs = np.unique(corner_node * len(tris) + corner_tri)  # each (node, triangle) once, by node then triangle
    nodes, of = pairs // len(tris), pairs % len(tris)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(nodes, minlength=n))])
    return ClosedParts(node_part.astype(np.int32), tris.astype(np.int32), tri_part.astype(np.int32),
                       offsets.astype(np.int32), of.astype(np.int32), len(part_labels))
