"""Geometry builders: the start meshes of the presets (a lattice, an open grid, a UV ellipsoid, a torus, a surface
of revolution), as (faces or edges, points (N, 3) float32), and the lines display of case study 3.
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..topology import Topology
from .records import FeatureLayout


def lattice(nx: int, ny: int, nz: int, spacing: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A 3-D grid of nx * ny * nz points centred on the origin, with its 6-neighbour edges.

    Unlike the other builders this returns (edges (E, 2) int64, points (N, 3) float32): a solid lattice has no
    faces to draw, so build its topology with `Topology.from_edges(edges, len(points))`. Vertex (i, j, k) has
    index (i * ny + j) * nz + k and sits at ((i - (nx - 1) / 2) * spacing, ...). d_max = nx + ny + nz - 3.
    """
    for name, v in (("nx", nx), ("ny", ny), ("nz", nz)):
        checks.integer(name, v, 1)
    idx = np.arange(nx * ny * nz, dtype=np.int64).reshape(nx, ny, nz)
    edges = np.concatenate([
        np.stack([idx[:-1, :, :].ravel(), idx[1:, :, :].ravel()], axis=1),
        np.stack([idx[:, :-1, :].ravel(), idx[:, 1:, :].ravel()], axis=1),
        np.stack([idx[:, :, :-1].ravel(), idx[:, :, 1:].ravel()], axis=1),
    ])
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    pts = np.stack([i - (nx - 1) / 2, j - (ny - 1) / 2, k - (nz - 1) / 2], axis=-1).reshape(-1, 3) * spacing
    return edges, pts.astype(np.float32)


def open_grid(nx: int, ny: int, size: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """An open sheet of (nx - 1) * (ny - 1) quads in the xy-plane (z = 0), centred on the origin.

    Returns (faces (F, 4) int64, points (nx * ny, 3) float32). Vertex (i, j) (i along x) has index j * nx + i;
    the spacing is size / (max(nx, ny) - 1), so the longer side spans [-size / 2, size / 2]. The quads face +z
    (counter-clockwise seen from above). Being centred, the sheet is symmetric under y -> -y.
    """
    checks.integer("nx", nx, 2)
    checks.integer("ny", ny, 2)
    step = size / (max(nx, ny) - 1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")  # shape (ny, nx): index j * nx + i
    pts = np.stack([(i - (nx - 1) / 2) * step, (j - (ny - 1) / 2) * step, np.zeros_like(i, float)], axis=-1)
    v = np.arange(nx * ny, dtype=np.int64).reshape(ny, nx)
    faces = np.stack([v[:-1, :-1], v[:-1, 1:], v[1:, 1:], v[1:, :-1]], axis=-1).reshape(-1, 4)
    return faces, pts.reshape(-1, 3).astype(np.float32)


def uv_ellipsoid(n_lon: int, n_rings: int, radii=(1.0, 1.0, 1.0)) -> tuple[list[tuple[int, ...]], np.ndarray]:
    """A UV ellipsoid around the z-axis: `n_rings` rings of `n_lon` vertices plus two poles.

    Returns (faces, points (n_lon * n_rings + 2, 3) float32). Index 0 is the top pole (+z), then ring r's
    vertex j at 1 + r * n_lon + j, and the bottom pole last. Ring r lies at polar angle pi (r + 1) / (n_rings + 1),
    vertex j at longitude 2 pi j / n_lon measured from +x towards +y, so the point set is symmetric under
    y -> -y. Faces: quads between neighbouring rings, triangles at the poles, all wound counter-clockwise seen
    from outside. 25 longitudes x 24 rings gives the paper's 602 vertices (575 quads, 50 triangles).
    """
    checks.integer("n_lon", n_lon, 3)
    checks.integer("n_rings", n_rings, 1)
    a, b, c = (float(r) for r in radii)
    theta = np.pi * (np.arange(n_rings) + 1) / (n_rings + 1)
    phi = 2 * np.pi * np.arange(n_lon) / n_lon
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack([a * st * np.cos(phi), b * st * np.sin(phi), c * ct * np.ones_like(phi)], axis=-1)
    pts = np.concatenate([[[0.0, 0.0, c]], ring.reshape(-1, 3), [[0.0, 0.0, -c]]])
    pts[np.abs(pts) < 1e-12] = 0.0  # exact zeros (sin(pi) and friends) keep the mirror symmetry exact
    south = n_lon * n_rings + 1

    def vid(r: int, j: int) -> int:
        return 1 + r * n_lon + j % n_lon

    faces: list[tuple[int, ...]] = [(0, vid(0, j), vid(0, j + 1)) for j in range(n_lon)]
    for r in range(n_rings - 1):
        faces += [(vid(r, j), vid(r + 1, j), vid(r + 1, j + 1), vid(r, j + 1)) for j in range(n_lon)]
    faces += [(south, vid(n_rings - 1, j + 1), vid(n_rings - 1, j)) for j in range(n_lon)]
    return faces, pts.astype(np.float32)


def torus(n_major: int, n_minor: int, R: float = 1.0, r: float = 0.35) -> tuple[np.ndarray, np.ndarray]:
    """A closed (periodic) quad torus around the z-axis, major radius R, tube radius r.

    Returns (faces (n_major * n_minor, 4) int64, points (n_major * n_minor, 3) float32); vertex (i, j) (i around
    the axis, j around the tube) has index i * n_minor + j. Quads face outward; symmetric under y -> -y.
    """
    checks.integer("n_major", n_major, 3)
    checks.integer("n_minor", n_minor, 3)
    u = 2 * np.pi * np.arange(n_major) / n_major
    v = 2 * np.pi * np.arange(n_minor) / n_minor
    uu, vv = np.meshgrid(u, v, indexing="ij")
    rad = R + r * np.cos(vv)
    pts = np.stack([rad * np.cos(uu), rad * np.sin(uu), r * np.sin(vv)], axis=-1).reshape(-1, 3)
    pts[np.abs(pts) < 1e-12] = 0.0
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    i1, j1 = (i + 1) % n_major, (j + 1) % n_minor
    faces = np.stack([i * n_minor + j, i1 * n_minor + j, i1 * n_minor + j1, i * n_minor + j1], axis=-1)
    return faces.reshape(-1, 4).astype(np.int64), pts.astype(np.float32)


def surface_of_revolution(radii, heights, n_lon: int) -> tuple[list[tuple[int, ...]], np.ndarray]:
    """A surface of revolution about the z-axis: the profile (radii[i], heights[i]), i = 0..m-1, turned through
    `n_lon` longitudes (from +x towards +y, so the point set is symmetric under y -> -y).

    Returns (faces, points (float32)). Profile point i at longitude j has index i * n_lon + j, except that an end of
    the profile with radius 0 is one pole vertex (a fan of triangles) in its ring's place. Faces: quads between
    neighbouring rings, wound so that their normal is (the longitude's direction) x (the profile's direction): facing
    outwards from the axis where the profile runs up (+z), downwards where it runs outwards from the axis.
    """
    checks.integer("n_lon", n_lon, 3)
    r = np.asarray(radii, np.float64)
    h = np.asarray(heights, np.float64)
    if r.ndim != 1 or r.shape != h.shape or len(r) < 2 or (r < 0).any() or (r[1:-1] == 0).any():
        raise ValueError("surface_of_revolution: expected 2 or more (radius, height) pairs, radii >= 0 and only the "
                         "ends on the axis")
    phi = 2 * np.pi * np.arange(n_lon) / n_lon
    pole = [r[0] == 0, r[-1] == 0]
    rows, index, first = [], [], 0
    for i in range(len(r)):
        if (i == 0 and pole[0]) or (i == len(r) - 1 and pole[1]):
            rows.append([[0.0, 0.0, h[i]]])
            index.append(np.full(n_lon, first))
            first += 1
        else:
            rows.append(np.stack([r[i] * np.cos(phi), r[i] * np.sin(phi), np.full(n_lon, h[i])], axis=-1))
            index.append(first + np.arange(n_lon))
            first += n_lon
    pts = np.concatenate(rows)
    pts[np.abs(pts) < 1e-12] = 0.0  # exact zeros keep the mirror symmetry exact
    faces: list[tuple[int, ...]] = []
    for i in range(len(r) - 1):
        a, b = index[i], index[i + 1]
        for j in range(n_lon):
            k = (j + 1) % n_lon
            quad = (int(a[j]), int(a[k]), int(b[k]), int(b[j]))
            faces.append(tuple(v for n, v in enumerate(quad) if v not in quad[:n]))  # a pole's quad: a triangle
    return faces, pts.astype(np.float32)


def ellipsoid_normals(points, radii) -> np.ndarray:
    """Outward unit normals of the ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 at `points` (N, 3)."""
    g = np.asarray(points, np.float64) / np.asarray(radii, np.float64) ** 2
    return (g / np.linalg.norm(g, axis=1, keepdims=True)).astype(np.float32)


def line_display_mesh(weights, topology: Topology, layout: FeatureLayout) -> tuple[np.ndarray, np.ndarray]:
    """The lines display of case study 3: each node is a line from its root to its tip, neighbours joined by quads.

    Returns (points (2N, 3) float32, faces (E, 4) int64): the N roots (layout.position), then the N tips
    (root + direction * length; length 1 when the layout has no length dim), and one quad
    (root_a, root_b, tip_b, tip_a) per topology edge (a, b). Vertex colours for both halves: tile colours_of twice.

    For the 602-vertex "lines" preset this gives 1204 vertices, as in the paper, and 1225 quads: one per edge of
    the UV ellipsoid (600 along the rings, 575 between rings, 50 to the poles), i.e. 2450 triangles. The paper
    reports 2400 faces for its display mesh, exactly twice the 1200 triangles of the car's surface (575 quads as
    two triangles each, plus 50 pole triangles); its exact face set is not published, so ours follows the rule
    above (one quad per synapse) rather than matching that count.
    """
    if not layout.direction:
        raise ValueError("line_display_mesh: the layout has no direction dims")
    w = np.asarray(weights, np.float32)
    if w.ndim != 2 or w.shape != (topology.n_vertices, layout.n_dims):
        raise ValueError(f"line_display_mesh: weights have shape {w.shape}, expected "
                         f"({topology.n_vertices}, {layout.n_dims})")
    roots = w[:, list(layout.position)]
    direction = w[:, list(layout.direction)]
    length = w[:, layout.length:layout.length + 1] if layout.length is not None else 1.0
    tips = roots + direction * length
    n = len(w)
    e = np.asarray(topology.edges, np.int64).reshape(-1, 2)
    faces = np.stack([e[:, 0], e[:, 1], e[:, 1] + n, e[:, 0] + n], axis=1)
    return np.concatenate([roots, tips]).astype(np.float32), faces
