"""Refining the clay: more nodes where it needs them, its shape kept; and coarsening a mesh too big to model here.

`subdivide` splits every face at its edges' midpoints (a triangle into four triangles, a quad or n-gon into n quads
around its centre): the new nodes lie on the old faces, so the surface stays where it was (exactly, for planar
faces) and only gets finer. `refine_stretched` splits only the edges stretched past `factor` times the median edge
(each split triangle into two, three or four, so no node hangs on an edge): where a pull has drawn the clay thin.
A new node's weights (position, colour, every feature) are the mean of the nodes it lies between.

`coarsen` goes the other way, for an upload past a device's limit: the vertices are clustered on a uniform grid
(`cluster_on_grid`, as fine as the limit allows), each cluster becomes one vertex at its mean, and the faces are
mapped onto the clusters (those that collapse dropped).
"""

from __future__ import annotations

import numpy as np

from . import checks


def _edge_index(faces: list[np.ndarray], n: int) -> tuple[dict, np.ndarray]:
    """{(a, b) with a < b: index of the edge}, and the edges (E, 2)."""
    index: dict[tuple[int, int], int] = {}
    for f in faces:
        m = len(f)
        for i in range(m):
            a, b = int(f[i]), int(f[(i + 1) % m])
            key = (a, b) if a < b else (b, a)
            if key not in index:
                index[key] = len(index)
    edges = np.array(list(index), np.int64).reshape(-1, 2)
    return index, edges


def subdivide(faces, weights) -> tuple[list[np.ndarray], np.ndarray]:
    """(faces, weights) of the mesh with every face split at its edges' midpoints (see the module's docstring):
    node i stays node i, then one node per edge, then one per face of more than three sides."""
    w = checks.finite_array("weights", weights, 2, np.float64)
    faces = [np.asarray(f, np.int64).ravel() for f in faces]
    n = len(w)
    index, edges = _edge_index(faces, n)
    mid = n + np.arange(len(edges))
    new = [w, (w[edges[:, 0]] + w[edges[:, 1]]) / 2.0]
    out: list[np.ndarray] = []
    centres: list[np.ndarray] = []
    for f in faces:
        m = len(f)
        e = [mid[index[(min(f[i], f[(i + 1) % m]), max(f[i], f[(i + 1) % m]))]] for i in range(m)]
        if m == 3:
            a, b, c = f
            ab, bc, ca = e
            out += [np.array([a, ab, ca]), np.array([ab, b, bc]), np.array([ca, bc, c]), np.array([ab, bc, ca])]
        else:
            centre = n + len(edges) + len(centres)
            centres.append(w[f].mean(axis=0))
            for i in range(m):
                out.append(np.array([f[i], e[i], centre, e[i - 1]]))
    if centres:
        new.append(np.array(centres))
    return out, np.concatenate(new).astype(np.float32)


def stretched_edges(faces, weights, factor: float, position=(0, 1, 2)) -> np.ndarray:
    """(E, 2) the edges longer than `factor` times the median edge (in the position dims)."""
    factor = checks.real("factor", factor, 1.0, 1e6)
    w = np.asarray(weights, np.float64)[:, list(position)]
    _, edges = _edge_index([np.asarray(f, np.int64).ravel() for f in faces], len(w))
    if not len(edges):
        return edges
    length = np.linalg.norm(w[edges[:, 0]] - w[edges[:, 1]], axis=1)
    return edges[length > factor * np.median(length)]


def refine_stretched(faces, weights, factor: float = 2.0, position=(0, 1, 2)) -> tuple[list[np.ndarray], np.ndarray]:
    """(triangles, weights) with only the edges stretched past `factor` times the median edge split at their
    midpoints (faces of more than three sides are fan-triangulated first); the mesh stays conforming: a triangle
    with one, two or three split edges becomes two, three or four."""
    w = checks.finite_array("weights", weights, 2, np.float64)
    tris = []
    for f in faces:
        f = np.asarray(f, np.int64).ravel()
        tris += [np.array([f[0], f[i], f[i + 1]]) for i in range(1, len(f) - 1)]
    long = {tuple(e) for e in stretched_edges(tris, w, factor, position).tolist()}
    mids: dict[tuple[int, int], int] = {}
    extra: list[np.ndarray] = []

    def mid(a: int, b: int) -> int | None:
        key = (a, b) if a < b else (b, a)
        if key not in long:
            return None
        if key not in mids:
            mids[key] = len(w) + len(extra)
            extra.append((w[a] + w[b]) / 2.0)
        return mids[key]

    out = []
    for a, b, c in (t.tolist() for t in tris):
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        split = [x is not None for x in (ab, bc, ca)]
        if not any(split):
            out.append([a, b, c])
        elif all(split):
            out += [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
        else:  # rotate so that the first edge (a, b) is split
            for _ in range(3):
                if split[0] and (sum(split) == 1 or split[1]):
                    break
                a, b, c = b, c, a
                ab, bc, ca = bc, ca, ab
                split = split[1:] + split[:1]
            if sum(split) == 1:
                out += [[a, ab, c], [ab, b, c]]
            else:  # (a, b) and (b, c) split
                out += [[a, ab, c], [ab, b, bc], [ab, bc, c]]
    weights_out = np.concatenate([w, np.array(extra).reshape(-1, w.shape[1])]) if extra else w
    return [np.array(t, np.int64) for t in out], weights_out.astype(np.float32)


def cluster_on_grid(points, limit: int) -> tuple[np.ndarray, np.ndarray]:
    """(cluster of each point (N,), the first point of each cluster (m,)) for a uniform grid over the points' bounding
    box as fine as keeps m <= limit (a surface fills about cells^2 of cells^3 cells)."""
    pts = np.asarray(points, np.float64)
    lo, span = pts.min(axis=0), np.ptp(pts, axis=0)
    span[span <= 0] = 1.0
    cells = max(2, int(round(limit ** (1 / 3))))

    def clusters(cells: int):
        key = np.minimum((pts - lo) / span * cells, cells - 1).astype(np.int64)
        key = (key[:, 0] * cells + key[:, 1]) * cells + key[:, 2]
        _, first, cluster = np.unique(key, return_index=True, return_inverse=True)
        return first, cluster.ravel()

    first, cluster = clusters(cells)
    for _ in range(40):  # coarser while past the limit, finer while well under it
        if len(first) > limit:
            cells = max(2, int(cells / 1.15))
            first, cluster = clusters(cells)
            continue
        finer = max(cells + 1, int(cells * min(1.5, (limit / len(first)) ** 0.5)))
        first2, cluster2 = clusters(finer)
        if len(first2) > limit:
            break
        cells, first, cluster = finer, first2, cluster2
    return cluster, first.astype(np.int64)


def coarsen(points, triangles, limit: int) -> tuple[np.ndarray, np.ndarray]:
    """(points (m, 3), triangles) of a mesh with at most `limit` vertices: its vertices clustered on a grid, each
    cluster at its mean, the triangles mapped onto the clusters (the ones that collapse, and repeats, dropped)."""
    pts = np.asarray(points, np.float64)
    cluster, first = cluster_on_grid(pts, checks.integer("limit", limit, 4))
    m = len(first)
    sums = np.zeros((m, pts.shape[1]))
    np.add.at(sums, cluster, pts)
    counts = np.bincount(cluster, minlength=m)[:, None]
    tris = cluster[np.asarray(triangles, np.int64).reshape(-1, 3)]
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])]
    _, keep = np.unique(np.sort(tris, axis=1), axis=0, return_index=True)
    tris = tris[np.sort(keep)]
    used = np.zeros(m, bool)
    used[tris.ravel()] = True
    index = np.cumsum(used) - 1
    return (sums / counts)[used].astype(np.float32), index[tris]
