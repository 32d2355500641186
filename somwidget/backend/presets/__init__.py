"""Start shapes: the paper's three case studies and a few general start shapes, with their feature layouts.

Every preset is deterministic (no randomness) and holds float32 arrays. `PRESETS` maps a name to a builder,
`get_preset(name)` builds one; `Preset.make_som()` turns it into a trainable `Som`. The parts: records.py
(FeatureLayout, Preset), geometry.py (the start meshes), colours.py, case_studies.py, shapes.py.
"""

from __future__ import annotations

from collections.abc import Callable

from ..cycle_kernels import MAX_CONTROLS
from .case_studies import CAR_LON, CAR_RADII, CAR_RINGS, SPACE_GRID_SMOOTHING, car, lines, space_grid
from .colours import (CONTROL_PALETTE, NEUTRAL_GREY, colours_of, hex_colour, hsv_to_rgb, palette_colours,
                      parse_hex_colour, rgb_to_colour_dims)
from .geometry import (ellipsoid_normals, lattice, line_display_mesh, open_grid, surface_of_revolution, torus,
                       uv_ellipsoid)
from .records import COLOUR_SPACES, DISPLAYS, XYZ, FeatureLayout, Preset, effective_controls, positions_of
from .shapes import (KEPT_SHAPE_RADIUS, KEPT_SHAPE_REACH, bowl_preset, cone_preset, controls_on, disc_preset,
                     farthest_points, grid_preset, kept_shape, lattice_preset, sphere_preset, torus_preset, tube_preset)

PRESETS: dict[str, Callable[[], Preset]] = {
    "space-grid": space_grid,
    "car": car,
    "lines": lines,
    "lattice": lattice_preset,
    "grid": grid_preset,
    "sphere": sphere_preset,
    "torus": torus_preset,
    "tube": tube_preset,
    "cone": cone_preset,
    "disc": disc_preset,
    "bowl": bowl_preset,
}
#: The presets' names in menus (the web app's preset list, the notebook panel's dropdown); unknown names show as is.
PRESET_LABELS: dict[str, str] = {
    "space-grid": "Case study 1: space grid (16^3 lattice)",
    "car": "Case study 2: car (602 nodes, colours)",
    "lines": "Case study 3: lines (8-D nodes)",
    "lattice": "Lattice 8^3",
    "grid": "Open grid 32 x 32",
    "sphere": "Sphere",
    "torus": "Torus",
    "tube": "Tube (open)",
    "cone": "Cone (open)",
    "disc": "Disc (flat, open)",
    "bowl": "Bowl (half sphere, open)",
}


def get_preset(name: str) -> Preset:
    """Build the preset called `name` (a fresh object each call)."""
    try:
        builder = PRESETS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown preset {name!r}; known presets: {', '.join(PRESETS)}") from None
    return builder()


__all__ = [
    "CAR_LON", "CAR_RADII", "CAR_RINGS", "COLOUR_SPACES", "CONTROL_PALETTE", "DISPLAYS", "KEPT_SHAPE_RADIUS",
    "KEPT_SHAPE_REACH", "MAX_CONTROLS", "NEUTRAL_GREY", "PRESETS", "PRESET_LABELS", "SPACE_GRID_SMOOTHING", "XYZ",
    "FeatureLayout", "Preset", "bowl_preset", "car", "colours_of", "cone_preset", "controls_on", "disc_preset",
    "effective_controls", "ellipsoid_normals", "farthest_points", "get_preset", "grid_preset", "hex_colour",
    "hsv_to_rgb", "kept_shape", "lattice", "lattice_preset", "line_display_mesh", "lines", "open_grid",
    "palette_colours", "parse_hex_colour", "positions_of", "rgb_to_colour_dims", "space_grid", "sphere_preset",
    "surface_of_revolution", "torus", "torus_preset", "tube_preset", "uv_ellipsoid",
]
