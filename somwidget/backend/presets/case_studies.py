"""The paper's three case studies (Felbrich et al. 2018, section IV): the space grid, the car and the lines, each grown
from a generic start mesh by its whole schedule.

Coordinates: x points forward (the car's nose is at +x), y sideways, z up. The paper mirrors controls across the
xz-plane (y is negated), so every mirrored preset is centred on y = 0 and symmetric under y -> -y.
"""

from __future__ import annotations

import numpy as np

from ..topology import Topology
from .geometry import ellipsoid_normals, lattice, uv_ellipsoid
from .records import LATTICE_RATES, XYZ, FeatureLayout, Preset

#: The car body: an ellipsoid 4 long (x), 1.7 wide (y), 1.2 high (z); 25 x 24 + 2 = 602 vertices.
CAR_RADII = (2.0, 0.85, 0.6)
CAR_LON, CAR_RINGS = 25, 24


#: lambda of the space grid's Laplacian step: enough to keep the lattice even without holding it back from the
#: controls (at 0.2 it stopped 12% of its size short of them, and every restart shrank it further).
SPACE_GRID_SMOOTHING = 0.02
def space_grid() -> Preset:
    """Case study 1: a 16^3 lattice (6-neighbour synapses, d_max 45) pulled by 8 three-dimensional controls."""
    edges, pts = lattice(16, 16, 16, spacing=1.0)
    controls = np.array([
        [9.5, 2.0, -3.0],
        [-9.0, -3.5, 4.5],
        [3.0, 9.5, 5.5],
        [-2.5, -9.5, -5.0],
        [5.5, -4.0, 9.5],
        [-5.0, 5.0, -9.0],
        [8.5, 7.5, 8.0],
        [-8.5, -6.5, -8.0],
    ], np.float32)
    return Preset(
        name="space-grid", title="Space grid",
        description="Case study 1 of Felbrich et al. 2018: a 16 x 16 x 16 lattice of neurons joined to their six "
                    "neighbours, shaped by 8 controls, with one Laplacian smoothing step per cycle.",
        topology=Topology.from_edges(edges, len(pts)), weights=pts, controls=controls, layout=XYZ,
        iterations=1000, **LATTICE_RATES, smoothing=SPACE_GRID_SMOOTHING, display="points", grow=True)


def _car_start() -> tuple[Topology, np.ndarray]:
    faces, pts = uv_ellipsoid(CAR_LON, CAR_RINGS, CAR_RADII)
    return Topology.from_faces(faces, len(pts)), pts


def car() -> Preset:
    """Case study 2: an ellipsoid car body with 5-D nodes (x, y, z, hue, saturation) and 9 mirrored controls."""
    topo, pts = _car_start()
    start = np.concatenate([pts, np.tile(np.array([0.0, 0.08], np.float32), (len(pts), 1))], axis=1)  # near-white
    #                    x     y      z     hue   sat
    controls = np.array([
        [1.30, 0.95, -0.75, 0.62, 0.85],  # front wheel (blue)
        [-1.30, 0.95, -0.75, 0.72, 0.85],  # rear wheel (indigo)
        [2.60, 0.25, -0.20, 0.00, 0.90],  # nose (red)
        [-2.50, 0.30, -0.05, 0.08, 0.90],  # tail (orange)
        [-0.30, 0.45, 0.95, 0.15, 0.85],  # roof (yellow)
        [1.55, 0.50, 0.30, 0.93, 0.75],  # bonnet (rose)
        [0.65, 0.45, 0.70, 0.50, 0.70],  # windscreen (cyan)
        [-1.35, 0.45, 0.60, 0.80, 0.60],  # rear window (violet)
        [0.00, 1.05, -0.20, 0.33, 0.80],  # door sill (green)
    ], np.float32)
    layout = FeatureLayout(names=("x", "y", "z", "hue", "saturation"), position=(0, 1, 2), colour=(3, 4),
                           colour_space="hs")
    return Preset(
        name="car", title="Car",
        description="Case study 2 of Felbrich et al. 2018: an ellipsoid of 602 vertices (quads and pole triangles) "
                    "with 5-D nodes (x, y, z, hue, saturation); 9 controls mirrored across the xz-plane make 18, "
                    "and the body takes on their colours.",
        topology=topo, weights=start, controls=controls, layout=layout,
        iterations=1000, l_start=0.25, l_end=0.03, mirror=(1,), display="surface", grow=True)


def lines() -> Preset:
    """Case study 3: the car's topology with 8-D nodes (root x, y, z, direction x, y, z, hue, length)."""
    topo, pts = _car_start()
    normals = ellipsoid_normals(pts, CAR_RADII)
    n = len(pts)
    start = np.concatenate([pts, normals, np.full((n, 1), 0.58, np.float32), np.full((n, 1), 0.3, np.float32)],
                           axis=1)

    def control(root, direction, hue, length):
        d = np.asarray(direction, np.float64)
        return [*root, *(d / np.linalg.norm(d)), hue, length]

    controls = np.array([
        control((1.40, 0.95, -0.55), (0.2, 0.6, -0.8), 0.00, 0.70),  # front flank, long red lines down
        control((-1.40, 0.95, -0.55), (-0.2, 0.6, -0.8), 0.08, 0.70),  # rear flank, orange
        control((2.45, 0.20, 0.00), (1.0, 0.1, 0.3), 0.15, 0.90),  # nose, yellow spikes forward
        control((-2.40, 0.25, 0.10), (-1.0, 0.2, 0.4), 0.33, 0.50),  # tail, green
        control((0.00, 0.35, 0.85), (0.0, 0.2, 1.0), 0.50, 1.00),  # roof, tall cyan crest
        control((1.20, 0.45, 0.55), (0.6, 0.2, 0.8), 0.62, 0.35),  # bonnet, blue
        control((-1.10, 0.50, 0.55), (-0.5, 0.3, 0.8), 0.80, 0.25),  # rear deck, violet
        control((0.00, 1.10, 0.00), (0.0, 1.0, 0.0), 0.93, 0.15),  # side, short rose bristles
    ], np.float32)
    layout = FeatureLayout(names=("x", "y", "z", "dx", "dy", "dz", "hue", "length"), position=(0, 1, 2),
                           colour=(6,), colour_space="hue", direction=(3, 4, 5), length=7)
    return Preset(
        name="lines", title="Lines",
        description="Case study 3 of Felbrich et al. 2018: the car's 602-vertex topology with 8-D nodes (root, "
                    "direction, hue, length), drawn as coloured lines whose neighbours are joined by quads; 8 "
                    "controls mirrored across the xz-plane (root y and direction y) make 16.",
        topology=topo, weights=start, controls=controls, layout=layout,
        iterations=1000, l_start=0.25, l_end=0.03, mirror=(1, 4), display="lines", grow=True)
