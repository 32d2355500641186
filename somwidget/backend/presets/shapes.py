"""The general start shapes, kept as they are (a lattice, a grid, a sphere, a torus; the open shapes: a tube, a cone,
a disc, a bowl): each shown as built, with controls on its own nodes (spread over it, or where a designer pulls an
open shape), shaped by controls with a radius of influence (som.py).
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..metrics import bounding_diagonal
from ..symmetry import Symmetry
from ..topology import Topology
from .geometry import lattice, open_grid, surface_of_revolution, torus, uv_ellipsoid
from .records import LATTICE_RATES, XYZ, Preset


def farthest_points(points, k: int) -> np.ndarray:
    """Indices of k points spread over a point set (farthest-point sampling): the point nearest the centroid first,
    then each time the point farthest from those taken (the lowest index on a tie). Deterministic."""
    pts = np.asarray(points, np.float64)
    k = min(checks.integer("k", k, 1), len(pts))
    taken = [int(np.argmin(np.linalg.norm(pts - pts.mean(axis=0), axis=1)))]
    nearest = np.linalg.norm(pts - pts[taken[0]], axis=1)
    while len(taken) < k:
        i = int(np.argmax(nearest))
        taken.append(i)
        nearest = np.minimum(nearest, np.linalg.norm(pts - pts[i], axis=1))
    return np.asarray(taken, np.int64)


def controls_on(weights, k: int = 6) -> np.ndarray:
    """k controls sitting on a shape's own nodes, spread over it (farthest-point samples): a shape kept as it is
    has its controls on it, so that nothing pulls it before the person does."""
    w = np.asarray(weights, np.float32)
    return w[farthest_points(w[:, :3], k)].copy()


#: Shapes kept as they are (the general shapes, uploaded meshes) are shaped by controls with a radius of influence
#: (som.py): each starts at this share of the shape's size (its bounding diagonal: the controls that stay hold the
#: far half within 2% where 0.2 let it move 2.6%), and a restart runs this reach of
#: the schedule, enough cycles for a moved control's winner to reach it (BENCHMARKS.md, "Shaping rules"); any
#: smoothing keeps their volume (Taubin's rule).
KEPT_SHAPE_RADIUS = 0.25
KEPT_SHAPE_REACH = 0.3


def kept_shape(points) -> dict:
    """The Preset fields of a shape kept as it is, for its start positions: its controls' radius, reach and
    smoothing rule."""
    return dict(radius=KEPT_SHAPE_RADIUS * bounding_diagonal(np.asarray(points)[:, :3]), reach=KEPT_SHAPE_REACH,
                smoothing_rule="taubin")


# The general shapes below are kept as they are (grow False): each is shown as built, with controls on its own nodes
# (controls_on), and trains only when the person moves, adds or removes a control, changes a setting or presses
# Train. They have no smoothing: a Laplacian step shrinks any curved shape a little at every restart.
def lattice_preset() -> Preset:
    """A small 8^3 lattice spanning [-1, 1]^3 with 6 controls on its nodes."""
    edges, pts = lattice(8, 8, 8, spacing=2.0 / 7.0)
    return Preset(
        name="lattice", title="Lattice", description="An 8 x 8 x 8 lattice (6-neighbour synapses) with 6 controls "
                                                     "on its nodes: drag one to pull the lattice.",
        topology=Topology.from_edges(edges, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
        **LATTICE_RATES, display="points", **kept_shape(pts))


def grid_preset() -> Preset:
    """An open 32 x 32 sheet in the xy-plane (z = 0), spanning [-1, 1]^2, with 6 controls on it."""
    faces, pts = open_grid(32, 32)
    return Preset(
        name="grid", title="Grid", description="An open 32 x 32 quad sheet lying in the xy-plane, with 6 controls on "
                                               "it: drag one up or down to shape the sheet.",
        topology=Topology.from_faces(faces, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
        **kept_shape(pts))


def sphere_preset() -> Preset:
    """A unit UV sphere (32 longitudes x 15 rings + 2 poles = 482 vertices) with 6 controls on it."""
    faces, pts = uv_ellipsoid(32, 15, (1.0, 1.0, 1.0))
    return Preset(
        name="sphere", title="Sphere", description="A UV sphere of quads and pole triangles, with 6 controls on it: "
                                                   "drag one to push or pull the surface.",
        topology=Topology.from_faces(faces, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
        **kept_shape(pts))


def torus_preset() -> Preset:
    """A closed quad torus (48 x 16 = 768 vertices, R 1, r 0.35) with 6 controls on it."""
    faces, pts = torus(48, 16, 1.0, 0.35)
    return Preset(
        name="torus", title="Torus", description="A periodic quad torus around the z-axis, with 6 controls on it: "
                                                 "drag one to reshape the ring.",
        topology=Topology.from_faces(faces, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
        **kept_shape(pts))


# The open shapes: surfaces of revolution about the z-axis to start a vase, a lamp shade, a plate or a chair from. Their
# controls sit where a designer pulls (a ring's control with its copies about the axis, a rim, the centre), on their
# own nodes; 32 longitudes put every copy of a 16-fold group on a node.
OPEN_LONGITUDES = 32


def _revolved(name: str, title: str, description: str, radii, heights, at, **fields) -> Preset:
    """A preset of the surface of revolution of the profile (radii, heights), its controls on the profile's points
    `at` (at longitude 0: on the xz-plane, x >= 0) or on (profile point, longitude) pairs, centred on its centroid."""
    faces, pts = surface_of_revolution(radii, heights, OPEN_LONGITUDES)
    middle = pts[:, 2].astype(np.float64).mean()
    if abs(middle) > 1e-6:
        pts[:, 2] -= np.float32(middle)
    pole = int(radii[0] == 0)

    def node(i: int, j: int = 0) -> int:  # profile point i at longitude j (a pole: its one vertex)
        return 0 if i == 0 and pole else (i - pole) * OPEN_LONGITUDES + pole + j * (radii[i] > 0)

    controls = pts[[node(*a) if isinstance(a, tuple) else node(a) for a in at]].copy()
    return Preset(name=name, title=title, description=description, topology=Topology.from_faces(faces, len(pts)),
                  weights=pts, controls=controls, layout=XYZ, **kept_shape(pts), **fields)


def tube_preset() -> Preset:
    """An open tube (no caps): radius 0.5, z -1 .. 1, 25 rings of 32; a control on 5 rings, 16-fold about z (where
    the copies' handles overlap their weights are normalised, so a vase script stays in its box:
    tests/engine/test_presets.py)."""
    rings = 25
    return _revolved(
        "tube", "Tube", "An open tube (no caps) standing on the z-axis, with a control on five of its rings and "
                        "16-fold symmetry about the axis: pull a ring to swell or pinch the tube; draw a profile "
                        "with Revolve (R) to lathe a vase.",
        np.full(rings, 0.5), np.linspace(-1.0, 1.0, rings), at=(0, 6, 12, 18, 24), symmetry=Symmetry.radial(16, 2))


def cone_preset() -> Preset:
    """An open cone, its tip cut off (no caps): radius 1 at z -0.8 to 0.3 at z 0.8, 25 rings of 32; a control on
    3 rings, 16-fold about z."""
    rings = 25
    return _revolved(
        "cone", "Cone", "An open cone (no base, its tip cut off) standing on the z-axis, with a control on its "
                        "base rim, its middle and its top rim, and 16-fold symmetry about the axis: a lamp shade to "
                        "pull into shape.",
        np.linspace(1.0, 0.3, rings), np.linspace(-0.8, 0.8, rings), at=(0, 12, 24), symmetry=Symmetry.radial(16, 2))


def disc_preset() -> Preset:
    """A flat disc of radius 1 in the xy-plane (a centre node and 16 rings of 32), facing +z; controls on its centre,
    front, back and side rims, mirrored across the xz-plane."""
    rings = 16
    radii = np.linspace(1.0, 0.0, rings + 1)  # from the rim in to the centre: the faces face +z
    at = (rings, 0, (0, OPEN_LONGITUDES // 2), (0, OPEN_LONGITUDES // 4))  # centre, front (+x), back (-x), side (+y)
    return _revolved(
        "disc", "Disc", "A flat open disc in the xy-plane, with controls on its centre and on its rim at the front, "
                        "the back and the side (mirrored across the xz-plane): lift the back for a chair, press the "
                        "centre for a dish.",
        radii, np.zeros(rings + 1), at=at, mirror=(1,))


def bowl_preset() -> Preset:
    """A half sphere of radius 1, open at the top (a bottom node and 16 rings of 32); a control on its bottom, its
    middle ring and its rim, 16-fold about z."""
    rings = 16
    polar = 0.5 * np.pi * np.arange(rings + 1) / rings  # from the bottom pole up to the rim
    return _revolved(
        "bowl", "Bowl", "A half sphere open at the top, with a control on its bottom, its middle ring and its rim, "
                        "and 16-fold symmetry about the z-axis: flare the rim, flatten the bottom.",
        np.sin(polar), -np.cos(polar), at=(0, rings // 2, rings), symmetry=Symmetry.radial(16, 2))
