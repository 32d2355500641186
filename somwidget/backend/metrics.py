"""Figures that tell whether the clay behaves like clay: size, gaps to the controls, spikes, mirror symmetry, and how
a trained shape follows one moved control (som.py, Restarts). numpy only; positions are (N, 3) float arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .topology import Topology


def bounding_diagonal(positions) -> float:
    """The length of the diagonal of the axis-aligned bounding box: a shape's size."""
    p = np.asarray(positions, np.float64)
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) if len(p) else 0.0


def median_edge(positions, edges) -> float:
    """The median length of a mesh's edges ((E, 2) vertex indices) at `positions`; 0 for a mesh without edges.
    In float64, equal to np.median(np.linalg.norm(p[e0] - p[e1], axis=1)) (the lengths' middle one, or the mean of
    the middle two), found by a partition of the squared lengths (a studio room finds it at every move)."""
    p = np.asarray(positions)
    e = np.asarray(edges, np.int64).reshape(-1, 2)
    n = len(e)
    if not n:
        return 0.0
    d = p[e[:, 0]].astype(np.float64)
    d -= p[e[:, 1]]
    d *= d
    squared = d[:, 0] if d.shape[1] == 1 else d[:, 0] + d[:, 1]
    for j in range(2, d.shape[1]):  # summed in numpy's order for a short row, as np.linalg.norm sums
        squared += d[:, j]
    k = n // 2
    if n % 2:
        return float(np.sqrt(np.partition(squared, k)[k]))
    middle = np.sqrt(np.partition(squared, (k - 1, k))[k - 1:k + 1])
    return float((middle[0] + middle[1]) / 2)


def nearest_distances(points, nodes) -> np.ndarray:
    """(len(points),) the distance from each point to its nearest node (in blocks: memory stays bounded)."""
    pts = np.asarray(points, np.float64)
    nds = np.asarray(nodes, np.float64)
    out = np.zeros(len(pts))
    if not len(pts) or not len(nds):
        return out
    block = max(1, 4_000_000 // len(nds))
    for i in range(0, len(pts), block):
        d = pts[i:i + block, None, :] - nds[None, :, :]
        out[i:i + block] = np.sqrt(np.einsum("kni,kni->kn", d, d).min(axis=1))
    return out


def spike_figures(positions, topology: Topology, nodes) -> np.ndarray:
    """For each of `nodes` (the winners): its distance to the mean of its one-ring over the median edge length. A
    smooth surface gives a small fraction of one; a node drawn out alone towards its control (a needle) several."""
    p = np.asarray(positions, np.float64)
    edges = np.asarray(topology.edges, np.int64).reshape(-1, 2)
    if not len(edges):
        return np.zeros(len(nodes))
    median_edge = float(np.median(np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1))) or 1.0
    out = []
    for v in np.asarray(nodes, np.int64).tolist():
        ring = topology.neighbors[topology.offsets[v]: topology.offsets[v + 1]]
        out.append(np.linalg.norm(p[v] - p[ring].mean(axis=0)) / median_edge if len(ring) else 0.0)
    return np.asarray(out)


def mirror_map(positions, dim: int = 1) -> np.ndarray:
    """For each node, the node nearest its mirror image (coordinate `dim` negated): the pairing of a symmetric
    start mesh, against which a trained shape's symmetry is measured."""
    p = np.asarray(positions, np.float64)
    image = p.copy()
    image[:, dim] *= -1.0
    out = np.empty(len(p), np.int64)
    block = max(1, 4_000_000 // max(1, len(p)))
    for i in range(0, len(p), block):
        d = image[i:i + block, None, :] - p[None, :, :]
        out[i:i + block] = np.einsum("kni,kni->kn", d, d).argmin(axis=1)
    return out


def symmetry_error(positions, pairing: np.ndarray, dim: int = 1) -> float:
    """The largest distance between a node's mirror image and its partner's position, over the shape's size."""
    p = np.asarray(positions, np.float64)
    image = p.copy()
    image[:, dim] *= -1.0
    size = bounding_diagonal(p) or 1.0
    return float(np.linalg.norm(image - p[pairing], axis=1).max() / size)


def far_half_moved(before, after, target, mirrored_axes=()) -> float:
    """How far the half of the nodes farther from `target` (and from its mirror image, `mirrored_axes` of the
    position negated) moved from `before` to `after`: the 90th percentile, over the size of `before`."""
    before = np.asarray(before, np.float64)
    target = np.asarray(target, np.float64)
    near = np.linalg.norm(before - target, axis=1)
    if len(mirrored_axes):
        image = target.copy()
        image[list(mirrored_axes)] *= -1.0
        near = np.minimum(near, np.linalg.norm(before - image, axis=1))
    far = near > np.median(near)
    moved = np.linalg.norm(np.asarray(after, np.float64) - before, axis=1)
    return float(np.percentile(moved[far], 90)) / (bounding_diagonal(before) or 1.0)


@dataclass(frozen=True)
class FollowFigures:
    """How a trained shape followed one control moved by `share` of its size, run to s = S (all as shares of the
    size before the move): `least_size` the smallest bounding diagonal at any frame over the one before;
    `far_moved_p90` the 90th percentile of how far the half of the nodes farther from the moved control (and its
    mirror) moved; `gap` the distance from the moved control to its nearest node at the end; `spike` the largest
    spike figure of the winners at the end (median edge lengths)."""

    least_size: float
    far_moved_p90: float
    gap: float
    spike: float
    cycles: int


def follow(som, control: int, share: float = 0.05, direction=None, position_dims=(0, 1, 2),
           frame_cycles: int = 10) -> FollowFigures:
    """Move control `control` of a Som by `share` of the shape's size (along `direction`, default: away from the
    shape's centroid), then run the restarted schedule to s = S in frames of `frame_cycles` cycles, as the app does,
    measuring the size after every frame. The Som is left at the end of the run."""
    dims = list(position_dims)
    before = som.weights[:, dims].astype(np.float64)
    size = bounding_diagonal(before)
    controls = som.controls
    where = controls[control, dims].astype(np.float64)
    d = where - before.mean(axis=0) if direction is None else np.asarray(direction, np.float64)
    d = d / (np.linalg.norm(d) or 1.0)
    controls[control, dims] = (where + share * size * d).astype(np.float32)
    som.set_controls(controls)
    least, cycles = size, 0
    while som.iteration < som.iterations:
        cycles += som.step(frame_cycles)
        least = min(least, bounding_diagonal(som.weights[:, dims]))
    after = som.weights[:, dims].astype(np.float64)
    target = controls[control, dims].astype(np.float64)
    mirrored = [dims.index(m) for m in som.mirror if m in dims]
    return FollowFigures(
        least_size=least / size, far_moved_p90=far_half_moved(before, after, target, mirrored),
        gap=float(nearest_distances(target[None, :], after)[0]) / size,
        spike=float(spike_figures(after, som.topology, np.unique(som.winners())).max()), cycles=cycles)


# --------------------------------------------------------------------------------------------------------------
# Shape figures: how smooth a surface is, what it encloses, how far one point set lies from another (float64)
# --------------------------------------------------------------------------------------------------------------
def _face_arrays(faces) -> tuple[np.ndarray, np.ndarray]:
    """Faces of any size (a list of index sequences or an (F, k) int array) as (flat vertex indices, sizes)."""
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        arr = faces.astype(np.int64)
        return arr.ravel(), np.full(len(arr), arr.shape[1], np.int64)
    rows = [np.asarray(f, np.int64).ravel() for f in faces]
    sizes = np.array([len(f) for f in rows], np.int64)
    flat = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    return flat, sizes


def triangles_of(faces) -> np.ndarray:
    """(T, 3) int64 triangles of faces of any size, each face fanned from its first vertex: (f0, f_j, f_j+1) for
    j = 1 .. k - 2, in face order. A triangle stays as it is; a face of fewer than 3 vertices gives none. The fan
    keeps each face's winding, so outward faces give outward triangles."""
    flat, sizes = _face_arrays(faces)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]) if len(sizes) else sizes
    count = np.maximum(sizes - 2, 0)
    if not count.sum():
        return np.zeros((0, 3), np.int64)
    face = np.repeat(np.arange(len(sizes)), count)
    j = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count) + 1  # 1 .. k - 2 in each face
    first = starts[face]
    return np.stack([flat[first], flat[first + j], flat[first + j + 1]], axis=1)


def face_normals(positions, faces) -> np.ndarray:
    """(F, 3) unit normals of faces of any size by Newell's method (for a triangle: the normalised cross product
    (p1 - p0) x (p2 - p0)); a face wound counter-clockwise seen from outside points outward. A degenerate face (no
    area) gets NaN."""
    p = np.asarray(positions, np.float64)
    flat, sizes = _face_arrays(faces)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]) if len(sizes) else sizes
    nxt = np.arange(1, len(flat) + 1)
    some = sizes > 0
    nxt[(starts + sizes - 1)[some]] = starts[some]  # each face's closing pair
    a, b = p[flat], p[flat[nxt]]
    terms = np.stack([(a[:, 1] - b[:, 1]) * (a[:, 2] + b[:, 2]),
                      (a[:, 2] - b[:, 2]) * (a[:, 0] + b[:, 0]),
                      (a[:, 0] - b[:, 0]) * (a[:, 1] + b[:, 1])], axis=1)
    face = np.repeat(np.arange(len(sizes)), sizes)
    n = np.stack([np.bincount(face, terms[:, k], minlength=len(sizes)) for k in range(3)], axis=1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length > 0, n / length, np.nan)


def dihedral_angles(positions, faces) -> np.ndarray:
    """The angle in degrees between the normals of the two faces on each edge they share, one value per such edge
    (in no particular order): 0 where the surface is flat across the edge, 90 at a cube's edge, up to 180 where it
    folds back on itself. It is the turn of the surface from face to face, so it grows with the curvature times the
    edge length: a smooth surface gives small angles everywhere, a crease or a spike large ones.

    faces: any size (a list of index sequences or an (F, k) int array); a face's normal is Newell's (face_normals),
    so a non-planar quad counts as one face: pass `triangles_of(faces)` to measure the triangles a renderer draws,
    including the fold across each quad's diagonal. Where the two faces run the shared edge the same way (their
    windings disagree) one normal is flipped first, so the figure does not depend on the faces' orientation.
    A boundary edge (one face) gives nothing; an edge of more than two faces gives the pairs of its consecutive
    faces in face order. A pair with a degenerate face (no area) gives NaN."""
    flat, sizes = _face_arrays(faces)
    if not len(sizes):
        return np.zeros(0)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    nxt = np.arange(1, len(flat) + 1)
    some = sizes > 0
    nxt[(starts + sizes - 1)[some]] = starts[some]
    a, b = flat, flat[nxt]
    face = np.repeat(np.arange(len(sizes)), sizes)
    keep = a != b
    a, b, face = a[keep], b[keep], face[keep]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((face, hi, lo))
    lo, hi, face, forward = lo[order], hi[order], face[order], (a < b)[order]
    same = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1]) & (face[1:] != face[:-1])  # consecutive half-edges of an edge
    f1, f2 = face[:-1][same], face[1:][same]
    flip = np.where(forward[:-1][same] == forward[1:][same], -1.0, 1.0)  # the same direction: windings disagree
    normals = face_normals(positions, faces)
    cos = np.einsum("ij,ij->i", normals[f1], normals[f2]) * flip
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def mesh_volume(positions, faces) -> float:
    """The volume a closed mesh encloses, by the divergence theorem: the sum over its triangles (faces fanned by
    `triangles_of`) of p0 . (p1 x p2) / 6, as an absolute value, so that it does not depend on whether the faces are
    wound outward or inward (they must all agree) nor on where the origin lies. For an open or inconsistently wound
    mesh the figure means nothing. Faces of any size; a non-planar face counts as its fan of triangles."""
    p = np.asarray(positions, np.float64)
    t = triangles_of(faces)
    if not len(t):
        return 0.0
    p = p - p.mean(axis=0)  # the same sum, with less cancellation far from the origin
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    return float(abs(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)


def chamfer(a, b) -> float:
    """The symmetric Chamfer distance between two point sets (M, d) and (K, d): the mean distance from each point of
    `a` to its nearest point of `b` and the mean from each point of `b` to its nearest in `a`, averaged:
    (mean_i min_j |a_i - b_j| + mean_j min_i |a_i - b_j|) / 2. Plain (not squared) Euclidean distances, so it is in
    the points' units: 0 for identical sets, the shift for a set shifted by less than half the spacing of its points.
    Both sets must have points (ValueError otherwise)."""
    pa = np.asarray(a, np.float64)
    pb = np.asarray(b, np.float64)
    if not len(pa) or not len(pb):
        raise ValueError("chamfer: both point sets must have points")
    return float((nearest_distances(pa, pb).mean() + nearest_distances(pb, pa).mean()) / 2.0)


def surface_distances(points, positions, faces) -> np.ndarray:
    """(len(points),) the distance from each point to the nearest point of the surface (the faces fan-triangulated),
    float64; each point against every triangle (closest point on a triangle: Ericson, Real-Time Collision
    Detection, 5.1.5), in blocks."""
    tris = triangles_of(faces)
    p = np.asarray(positions, np.float64)
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    ab, ac = b - a, c - a
    out = np.empty(len(points))
    for i, q in enumerate(np.asarray(points, np.float64)):
        ap, bp, cp = q - a, q - b, q - c
        d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
        d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
        d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
        va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
        with np.errstate(divide="ignore", invalid="ignore"):
            denom = va + vb + vc
            v_in, w_in = vb / denom, vc / denom
            t_ab = np.clip(d1 / (d1 - d3), 0, 1)
            t_ac = np.clip(d2 / (d2 - d6), 0, 1)
            t_bc = np.clip((d4 - d3) / ((d4 - d3) + (d5 - d6)), 0, 1)
        closest = a + v_in[:, None] * ab + w_in[:, None] * ac  # inside the face
        edges = np.stack([a + t_ab[:, None] * ab, a + t_ac[:, None] * ac, b + t_bc[:, None] * (c - b)])
        corners = np.stack([a, b, c])
        inside = (va >= 0) & (vb >= 0) & (vc >= 0) & np.isfinite(v_in) & np.isfinite(w_in)
        d_face = np.where(inside, np.linalg.norm(q - closest, axis=1), np.inf)
        d_edge = np.nan_to_num(np.linalg.norm(q - edges, axis=2), nan=np.inf).min(axis=0)
        d_corner = np.linalg.norm(q - corners, axis=2).min(axis=0)
        out[i] = min(d_face.min(), d_edge.min(), d_corner.min())
    return out
