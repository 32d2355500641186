"""The shape figures of backend/metrics.py (triangles_of, face_normals, dihedral_angles, mesh_volume, chamfer) against
closed-form values: a cube, a regular tetrahedron, a flat grid, a fine UV sphere, shifted point sets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from somwidget.backend import metrics
from somwidget.backend.presets import open_grid, torus, uv_ellipsoid

# A cube [0, 1]^3: 8 corners (bit 0 = x, bit 1 = y, bit 2 = z), 6 quads wound counter-clockwise seen from outside.
CUBE_POINTS = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], np.float64)
CUBE_QUADS = np.array([
    [0, 2, 3, 1],  # z = 0, facing -z
    [4, 5, 7, 6],  # z = 1, facing +z
    [0, 1, 5, 4],  # y = 0, facing -y
    [2, 6, 7, 3],  # y = 1, facing +y
    [0, 4, 6, 2],  # x = 0, facing -x
    [1, 3, 7, 5],  # x = 1, facing +x
], np.int64)
# A regular tetrahedron (every edge 2 sqrt 2), faces wound outward.
TETRA_POINTS = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], np.float64)
TETRA_FACES = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]], np.int64)


# ----------------------------------------------------------------------------------------------- triangles_of
def test_triangles_of_fans_every_face_size():
    faces = [[0, 1, 2], [3, 4, 5, 6], [7, 8, 9, 10, 11], [12, 13]]
    tris = metrics.triangles_of(faces)
    assert tris.dtype == np.int64
    assert tris.tolist() == [[0, 1, 2], [3, 4, 5], [3, 5, 6], [7, 8, 9], [7, 9, 10], [7, 10, 11]]
    assert metrics.triangles_of(np.array([[0, 1, 2, 3]])).tolist() == [[0, 1, 2], [0, 2, 3]]
    assert metrics.triangles_of([]).shape == (0, 3)
    assert metrics.triangles_of([[0, 1]]).shape == (0, 3)


def test_face_normals_point_outward_and_a_degenerate_face_is_nan():
    n = metrics.face_normals(CUBE_POINTS, CUBE_QUADS)
    centres = CUBE_POINTS[CUBE_QUADS].mean(axis=1) - 0.5
    assert np.allclose(n, 2.0 * centres)  # the unit outward normal of each face of the unit cube
    flat = metrics.face_normals(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float), [[0, 1, 2]])
    assert np.isnan(flat).all()


# ----------------------------------------------------------------------------------------------- dihedral angles
def test_cube_dihedrals_are_90_degrees():
    angles = metrics.dihedral_angles(CUBE_POINTS, CUBE_QUADS)
    assert len(angles) == 12
    assert np.allclose(angles, 90.0)
    # triangulated: the 12 edges at 90 degrees, and the 6 diagonals flat
    tri = metrics.dihedral_angles(CUBE_POINTS, metrics.triangles_of(CUBE_QUADS))
    assert len(tri) == 18
    assert np.sum(np.isclose(tri, 90.0)) == 12 and np.sum(np.isclose(tri, 0.0, atol=1e-6)) == 6


def test_dihedrals_do_not_depend_on_winding_scale_or_place():
    flipped = CUBE_QUADS.copy()
    flipped[2] = flipped[2, ::-1]  # one face wound the other way
    assert np.allclose(metrics.dihedral_angles(CUBE_POINTS, flipped), 90.0)
    assert np.allclose(metrics.dihedral_angles(CUBE_POINTS, CUBE_QUADS[:, ::-1]), 90.0)
    moved = 3.0 * CUBE_POINTS + np.array([10.0, -4.0, 7.0])
    assert np.allclose(metrics.dihedral_angles(moved, CUBE_QUADS), 90.0)


def test_regular_tetrahedron_dihedral():
    # the faces' inner angle is arccos(1/3) = 70.53 degrees, so their normals turn by 180 - that = 109.47 degrees
    angles = metrics.dihedral_angles(TETRA_POINTS, TETRA_FACES)
    assert len(angles) == 6
    assert np.allclose(angles, 180.0 - math.degrees(math.acos(1.0 / 3.0)))


def test_flat_grid_is_0_degrees_and_its_boundary_gives_nothing():
    faces, pts = open_grid(7, 5)
    angles = metrics.dihedral_angles(pts, faces)
    interior_edges = (7 - 2) * (5 - 1) + (5 - 2) * (7 - 1)  # edges between two quads of a 6 x 4 sheet
    assert len(angles) == interior_edges
    assert np.allclose(angles, 0.0, atol=1e-6)
    tri = metrics.dihedral_angles(pts, metrics.triangles_of(faces))
    assert len(tri) == interior_edges + 6 * 4 and np.allclose(tri, 0.0, atol=1e-6)


def test_a_fold_in_a_grid_shows_its_angle():
    faces, pts = open_grid(5, 3)
    pts = pts.astype(np.float64)
    right = pts[:, 0] > 1e-9  # fold the sheet up by 40 degrees along x = 0
    a = math.radians(40.0)
    pts[right, 2] = pts[right, 0] * math.sin(a)
    pts[right, 0] = pts[right, 0] * math.cos(a)
    angles = metrics.dihedral_angles(pts, faces)
    assert np.isclose(angles.max(), 40.0)
    assert np.sum(np.isclose(angles, 40.0)) == 2  # the two edges on the fold line between two quads


def test_a_fine_sphere_turns_by_its_edge_length():
    n_lon, n_rings = 64, 31
    faces, pts = uv_ellipsoid(n_lon, n_rings)
    angles = metrics.dihedral_angles(pts.astype(np.float64), metrics.triangles_of(faces))
    assert not np.isnan(angles).any()
    # on the unit sphere, adjacent faces turn by about their centres' spacing in radians; the equator's is 2 pi / 64
    assert angles.max() < 2.0 * math.degrees(2 * math.pi / n_lon)
    assert angles.max() > 0.5 * math.degrees(2 * math.pi / n_lon)


# ----------------------------------------------------------------------------------------------- volume
def test_cube_volume():
    assert metrics.mesh_volume(CUBE_POINTS, CUBE_QUADS) == pytest.approx(1.0, abs=1e-12)
    assert metrics.mesh_volume(CUBE_POINTS, CUBE_QUADS[:, ::-1]) == pytest.approx(1.0, abs=1e-12)  # wound inward
    moved = 2.0 * CUBE_POINTS + np.array([100.0, -50.0, 25.0])
    assert metrics.mesh_volume(moved, CUBE_QUADS) == pytest.approx(8.0, rel=1e-12)
    assert metrics.mesh_volume(CUBE_POINTS, [list(q) for q in CUBE_QUADS]) == pytest.approx(1.0, abs=1e-12)


def test_tetrahedron_volume():
    # edge a = 2 sqrt 2: V = a^3 / (6 sqrt 2) = 8 / 3
    assert metrics.mesh_volume(TETRA_POINTS, TETRA_FACES) == pytest.approx(8.0 / 3.0, rel=1e-12)


def test_unit_sphere_volume():
    faces, pts = uv_ellipsoid(128, 63)
    vol = metrics.mesh_volume(pts.astype(np.float64), faces)
    assert vol == pytest.approx(4.0 / 3.0 * math.pi, rel=2e-3)
    assert vol < 4.0 / 3.0 * math.pi  # an inscribed polyhedron encloses less
    faces, pts = uv_ellipsoid(32, 15)  # the sphere preset's mesh
    coarse = metrics.mesh_volume(pts, faces)
    assert coarse == pytest.approx(4.0 / 3.0 * math.pi, rel=0.03)


def test_ellipsoid_and_torus_volume():
    faces, pts = uv_ellipsoid(128, 63, (2.0, 0.85, 0.6))
    assert metrics.mesh_volume(pts, faces) == pytest.approx(4.0 / 3.0 * math.pi * 2.0 * 0.85 * 0.6, rel=2e-3)
    faces, pts = torus(256, 64, 1.0, 0.35)
    assert metrics.mesh_volume(pts, faces) == pytest.approx(2.0 * math.pi**2 * 1.0 * 0.35**2, rel=2e-3)


# ----------------------------------------------------------------------------------------------- chamfer
def test_chamfer_of_identical_sets_is_zero():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(200, 3))
    assert metrics.chamfer(pts, pts) == 0.0
    assert metrics.chamfer(pts, pts[::-1]) == 0.0  # order does not matter


def test_chamfer_of_a_shifted_set_is_the_shift():
    faces, pts = open_grid(10, 10)  # spacing 2 / 9
    shift = np.array([0.03, -0.04, 0.0])  # 0.05, under half the spacing
    assert metrics.chamfer(pts, pts + shift) == pytest.approx(0.05, rel=1e-6)
    lifted = pts.astype(np.float64) + [0.0, 0.0, 0.7]  # out of the plane: any shift along z
    assert metrics.chamfer(pts, lifted) == pytest.approx(0.7, rel=1e-12)


def test_chamfer_is_symmetric_and_averages_both_ways():
    a = np.array([[0.0, 0.0], [1.0, 0.0]])
    b = np.array([[0.0, 0.0]])
    # a -> b: 0 and 1 (mean 0.5); b -> a: 0 (mean 0); the average 0.25
    assert metrics.chamfer(a, b) == pytest.approx(0.25)
    assert metrics.chamfer(b, a) == pytest.approx(0.25)
    with pytest.raises(ValueError):
        metrics.chamfer(a, np.zeros((0, 2)))


@pytest.mark.parametrize("dims", [1, 2, 3])
def test_median_edge_equals_numpys_median_of_the_float64_lengths(dims):
    """median_edge partitions the squared lengths (a studio room finds it at every move): the same float64 value as
    np.median of np.linalg.norm, for odd and even edge counts, float32 and float64 positions, repeated edges."""
    rng = np.random.default_rng(dims)
    for trial in range(300):
        n = int(rng.integers(2, 50))
        scale = float(rng.choice([1e-3, 1.0, 1e3]))
        p = (rng.normal(size=(n, dims)) * scale).astype(np.float32 if trial % 2 else np.float64)
        e = rng.integers(0, n, size=(int(rng.integers(1, 41)), 2))
        p64 = np.asarray(p, np.float64)
        reference = float(np.median(np.linalg.norm(p64[e[:, 0]] - p64[e[:, 1]], axis=1)))
        assert metrics.median_edge(p, e) == reference
    assert metrics.median_edge(np.zeros((3, 3)), np.zeros((0, 2), np.int64)) == 0.0
    assert metrics.median_edge([[0, 0, 0], [3, 4, 0], [0, 0, 1]], [[0, 1], [0, 2]]) == 3.0  # (5 + 1) / 2
