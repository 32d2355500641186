"""Mesh topology: faces or edges -> undirected adjacency (CSR) -> BFS grid distances (paper section III-D)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import warp as wp

from . import checks, kernels
from .device import resolve

#: The dense distance table holds at most 2^16 neurons (the paper's cap: 8 GiB of uint16).
MAX_DENSE_NEURONS = 65536
UNREACHABLE = 65535
#: Rows computed per BFS launch; bounds the int32 queue to BATCH x N entries.
_BFS_BATCH = 4096


class Topology:
    """The neurons (vertices) and synapses (edges) of the map. Build with `from_faces` or `from_edges`."""

    def __init__(self, n_vertices: int, edges: np.ndarray, faces: list[np.ndarray] | None = None):
        self.n_vertices = int(n_vertices)
        self.edges = edges
        self.faces = faces
        both = np.concatenate([edges, edges[:, ::-1]]) if len(edges) else np.zeros((0, 2), np.int64)
        order = np.lexsort((both[:, 1], both[:, 0]))
        both = both[order]
        counts = np.bincount(both[:, 0], minlength=self.n_vertices) if len(both) else np.zeros(self.n_vertices, int)
        self.offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        self.neighbors = both[:, 1].astype(np.int32)
        self._tables: dict[str, wp.array] = {}
        self._d_max: int | None = None

    # -- construction -------------------------------------------------------------------------------------
    @classmethod
    def from_faces(cls, faces, n_vertices: int | None = None) -> Topology:
        """Faces of any size (triangles, quads, n-gons), as a list of index sequences or an (F, k) int array.

        Each face's consecutive vertices and its closing pair are edges; duplicates and self-loops are dropped.
        """
        face_list = _face_list(faces)
        flat = np.concatenate(face_list) if face_list else np.zeros(0, np.int64)
        n = _vertex_count(flat, n_vertices, "faces")
        sizes = np.array([len(f) for f in face_list], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]) if len(sizes) else sizes
        nxt = np.arange(1, len(flat) + 1)
        last = starts + sizes - 1
        nxt[last[sizes > 0]] = starts[sizes > 0]  # closing pair of each face
        edges = _clean_edges(np.stack([flat, flat[nxt]], axis=1) if len(flat) else np.zeros((0, 2), np.int64))
        return cls(n, edges, face_list)

    @classmethod
    def from_edges(cls, edges, n_vertices: int) -> Topology:
        """An (E, 2) integer edge list over `n_vertices` vertices; duplicates and self-loops are dropped."""
        arr = checks.index_array("edges", edges)
        if arr.size == 0:
            arr = arr.reshape(0, 2)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"edges: expected shape (E, 2), got {arr.shape}")
        n = checks.integer("n_vertices", n_vertices, 1)
        _vertex_count(arr.ravel(), n, "edges")
        return cls(n, _clean_edges(arr))

    # -- queries ------------------------------------------------------------------------------------------
    def degree(self) -> np.ndarray:
        return np.diff(self.offsets)

    @property
    def d_max(self) -> int:
        """The largest finite grid distance (0 for a graph without edges)."""
        if self._d_max is None:
            self.distance_table(None)
        return self._d_max

    def grid_distances(self) -> np.ndarray:
        """(N, N) uint16 BFS hop counts, 0 on the diagonal, 65535 between separate components."""
        return self.distance_table(None).numpy()

    def distance_table(self, device: str | None) -> wp.array:
        """The dense table as a Warp array on `device`, computed there once (one BFS per neuron) and cached."""
        device = resolve(device)
        if device in self._tables:
            return self._tables[device]
        if self.n_vertices > MAX_DENSE_NEURONS:
            raise ValueError(
                f"topology: {self.n_vertices:,} vertices exceed the dense distance table's limit of "
                f"{MAX_DENSE_NEURONS:,} (2^16 neurons, 8 GiB of uint16); use a coarser mesh (decimate it, e.g. with "
                "trimesh's simplify_quadric_decimation) for the dense table"
            )
        if self._tables:  # computed on another device already: copy rather than search again
            table = wp.clone(next(iter(self._tables.values())), device=device)
        else:
            table = self._bfs_table(device)
        self._tables[device] = table
        return table

    def _bfs_table(self, device: str) -> wp.array:
        n = self.n_vertices
        table = wp.full((n, n), UNREACHABLE, dtype=wp.uint16, device=device)
        offsets = wp.array(self.offsets, dtype=wp.int32, device=device)
        neighbors = wp.array(self.neighbors if len(self.neighbors) else np.zeros(1, np.int32), dtype=wp.int32,
                             device=device)
        batch = min(n, _BFS_BATCH)
        queue = wp.empty((batch, n), dtype=wp.int32, device=device)
        far = wp.zeros(n, dtype=wp.int32, device=device)
        sources = wp.array(np.arange(n, dtype=np.int32), device=device)
        for start in range(0, n, batch):
            stop = min(n, start + batch)
            wp.launch(kernels.bfs_rows, dim=stop - start, device=device,
                      inputs=[offsets, neighbors, sources[start:stop], table[start:stop], queue, far[start:stop]])
        d_max = int(far.numpy().max(initial=0))
        if d_max >= UNREACHABLE:
            raise ValueError(f"topology: a grid distance reaches {UNREACHABLE}, which the uint16 table reserves for "
                             "'unreachable'; the graph is a path too long for the dense table")
        self._d_max = d_max
        return table

    def __repr__(self) -> str:
        return f"Topology(n_vertices={self.n_vertices}, edges={len(self.edges)})"


def _face_list(faces) -> list[np.ndarray]:
    if isinstance(faces, np.ndarray):
        arr = checks.index_array("faces", faces)
        if arr.ndim != 2:
            raise ValueError(f"faces: an array of faces must have shape (F, k), got {arr.shape}")
        return list(arr)
    if not isinstance(faces, Sequence) or isinstance(faces, (str, bytes)):
        raise ValueError(f"faces: expected a list of index sequences or an (F, k) array, got {type(faces).__name__}")
    out = []
    for i, face in enumerate(faces):
        try:
            arr = checks.index_array(f"faces[{i}]", face, ndim=1)
        except ValueError as exc:
            raise ValueError(f"faces: face {i} is not a sequence of integer vertex indices ({exc})") from None
        out.append(arr)
    return out


def _vertex_count(flat: np.ndarray, n_vertices: int | None, name: str) -> int:
    if flat.size and flat.min() < 0:
        raise ValueError(f"{name}: vertex indices must be >= 0, found {int(flat.min())}")
    if n_vertices is None:
        if not flat.size:
            raise ValueError(f"{name}: no vertex index given; pass n_vertices")
        return int(flat.max()) + 1
    n = checks.integer("n_vertices", n_vertices, 1)
    if flat.size and flat.max() >= n:
        raise ValueError(f"{name}: vertex index {int(flat.max())} is out of range for n_vertices={n}")
    return n


def _clean_edges(pairs: np.ndarray) -> np.ndarray:
    """Sorted unique undirected edges (i < j), self-loops dropped."""
    pairs = np.sort(pairs.astype(np.int64), axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return np.unique(pairs, axis=0) if len(pairs) else np.zeros((0, 2), np.int64)
