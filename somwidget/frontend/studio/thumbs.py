"""The wall's thumbnails: a room's clay made small and cheap, once a second at most, drawn by the wall's page.

A room's *shape* (once per preset: `shape_of`) says what to draw: triangles (a surface), segments (the paper's lines,
drawn as the roots' mesh edges) or points, over at most THUMB_NODES nodes (a bigger clay is clustered on a grid by
the view's own decimation, transport/display.py). A *thumbnail* (`thumbnail`) is one frame of those nodes: float32
positions, then RGB bytes; about 7 KB for the car. Nothing here runs unless a wall is open, or a room parks.

A room's last thumbnail is kept in its folder (`save_thumb`, THUMB_FILE, written atomically) so that the wall shows a
parked room's last clay after the studio restarts (`read_thumb`):

    b"SOMTHUMB1\n", a little-endian uint32 (the header's length), the header (JSON: generation, seq, shape), the bytes
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from ...backend import io as _io
from ...backend import presets as _presets
from ...backend.session_file import write_atomic
from ..transport.display import PerPreset, decimate_display

#: Most nodes a thumbnail carries.
THUMB_NODES = 2048

#: The file in a room's folder that keeps its last thumbnail.
THUMB_FILE = "thumb.bin"
_MAGIC = b"SOMTHUMB1\n"
_LENGTH = struct.Struct("<I")

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


def save_thumb(folder: Path, kept: tuple[int, int, dict, bytes]) -> None:
    """Keep (generation, seq, public shape, thumbnail bytes) in `folder`'s THUMB_FILE, written atomically."""
    generation, seq, shape, data = kept
    header = json.dumps({"generation": int(generation), "seq": int(seq), "shape": shape}).encode("utf-8")
    write_atomic(folder / THUMB_FILE, lambda f: f.write(_MAGIC + _LENGTH.pack(len(header)) + header + data))


def read_thumb(folder: Path) -> tuple[int, int, dict, bytes] | None:
    """What `save_thumb` kept in `folder`; None when there is none. ValueError (naming the file) when it is not one
    or its bytes do not match its shape."""
    path = folder / THUMB_FILE
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return None
    start = len(_MAGIC) + _LENGTH.size
    if not raw.startswith(_MAGIC) or len(raw) < start:
        raise ValueError(f"{path}: not a room's thumbnail (it should start with {_MAGIC!r})")
    (length,) = _LENGTH.unpack_from(raw, len(_MAGIC))
    try:
        header = json.loads(raw[start:start + length])
        generation, seq, shape = int(header["generation"]), int(header["seq"]), header["shape"]
        n = int(shape["n"])
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: its header cannot be read ({exc})") from None
    data = raw[start + length:]
    if len(data) != 15 * n:  # n float32 x, y, z and n RGB bytes
        raise ValueError(f"{path}: {len(data)} bytes of thumbnail, expected {15 * n} for its {n} nodes")
    return generation, seq, shape, data
