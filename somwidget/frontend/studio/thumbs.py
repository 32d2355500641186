"""The wall's thumbnails: a room's clay made small and cheap, once a second at most, drawn by the wall's page.

A room's *shape* (once per preset: `shape_of`) says what to draw: triangles (a surface), segments (the paper's lines,
drawn as the roots' mesh edges) or points, over at most THUMB_NODES nodes (a bigger clay is clustered on a grid by
the view's own decimation, transport/display.py). A *thumbnail* (`thumbnail`) is one frame of those nodes: float32
positions, then RGB bytes; about 7 KB for the car. Nothing here runs unless a wall is open.
"""

from __future__ import annotations

import numpy as np

from ...backend import io as _io
from ...backend import presets as _presets
from ..transport.display import PerPreset, decimate_display

#: Most nodes a thumbnail carries.
THUMB_NODES = 2048

_SHAPES = PerPreset(64)  # each preset's shape while it lives


def shape_of(preset) -> dict:
    """What the wall draws of `preset`: {"draw": "surface" | "lines" | "points", "n": nodes a thumbnail carries,
    "triangles": flat indices, "segments": flat indices} and "nodes" (the nodes carried, None: all), kept per preset."""
    return _SHAPES.get(preset, _shape)


def _shape(preset) -> dict:
    topo = preset.topology
    n = topo.n_vertices
    edges = np.asarray(topo.edges, np.int64).reshape(-1, 2)
    surface = preset.display == "surface" and bool(topo.faces)
    triangles = _io.triangulate(topo.faces) if surface else np.zeros((0, 3), np.int64)
    segments = edges if preset.display == "lines" else np.zeros((0, 2), np.int64)
    nodes = None
    if n > THUMB_NODES:
        start = _presets.positions_of(preset.weights, preset.layout)
        nodes, triangles, segments = decimate_display(start, triangles, segments if len(segments) else edges[:0],
                                                      THUMB_NODES)
        n = len(nodes)
    shape = {"draw": "surface" if surface else ("lines" if preset.display == "lines" else "points"), "n": int(n),
             "triangles": np.asarray(triangles, np.int64).ravel().tolist(),
             "segments": np.asarray(segments, np.int64).ravel().tolist(), "nodes": nodes}
    return shape


def thumbnail(frame, shape: dict) -> bytes:
    """One frame of a room as the wall draws it: shape["n"] positions (float32 x, y, z), then as many RGB bytes."""
    positions, colours = frame.positions, frame.colours
    nodes = shape["nodes"]
    if nodes is not None:
        positions, colours = positions[nodes], colours[nodes]
    rgb = np.clip(np.asarray(colours, np.float32) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return np.ascontiguousarray(positions, np.float32).tobytes() + rgb.tobytes()


def public_shape(shape: dict) -> dict:
    """The shape as the wall's page takes it (JSON)."""
    return {k: v for k, v in shape.items() if k != "nodes"}
