"""The general start shapes, kept as they are (a lattice, a grid, a sphere, a torus): each shown as built, with
controls spread over its own nodes, shaped by controls with a radius of influence (som.py).
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..metrics import bounding_diagonal
from ..topology import Topology
from .geometry import lattice, open_grid, torus, uv_ellipsoid
from .records import XYZ, Preset


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
        l_start=0.3, display="points", **kept_shape(pts))


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
