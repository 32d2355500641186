"""What a view draws: the display mesh of a session's preset (triangles, segments, points; a decimated mesh for a
clay too big to stream), each frame's display positions and colours, and the topology message that describes them
(messages.TopologyMessage). Made once per preset and kept: a million-vertex mesh takes seconds to
triangulate and decimate.
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable

import numpy as np

from ...backend import io as _io
from ...backend import presets as _presets
from ...backend.refine import cluster_on_grid
from ...backend.symmetry import Symmetry
from ..model.panel import OFF_CLAY, clay_size
from .messages import TopologyMessage

#: Most display vertices a frame streams whole: 32,768 x 15 bytes = 0.5 MB a frame, 15 MB/s at 30 frames/s, which a
#: headset's Wi-Fi and a laptop's browser both take. A bigger clay is shown decimated (`decimate_display`).
STREAM_LIMIT = 32768
#: The display vertices of a clay shown decimated: 0.12 MB a frame, what a page drawing in software (no GPU, two
#: cores) keeps at 30 frames/s while dragging (BENCHMARKS.md, Big clay: 32,768 kept it under 10).
DECIMATED_NODES = 8192


def decimate_display(points: np.ndarray, triangles: np.ndarray, segments: np.ndarray, limit: int = DECIMATED_NODES):
    """A display mesh of at most `limit` of the nodes, for a clay too big to stream whole: the nodes are clustered on
    a uniform grid over their start positions (one node stands for each occupied cell), and the triangles and
    segments are mapped onto those nodes (the degenerate ones dropped). Every frame then sends the trained
    positions of those nodes. Returns (nodes (m,), triangles (T, 3), segments (E, 2)) over 0..m-1."""
    cluster, first = cluster_on_grid(points, limit)

    def remap(idx: np.ndarray, width: int) -> np.ndarray:
        m = cluster[np.asarray(idx, np.int64).reshape(-1, width)]
        distinct = np.ones(len(m), bool)
        for i in range(width):
            for j in range(i + 1, width):
                distinct &= m[:, i] != m[:, j]
        m = m[distinct]
        return np.unique(np.sort(m, axis=1), axis=0) if width == 2 else m

    return first, remap(triangles, 3), remap(segments, 2)


class PerPreset:
    """Values made from a preset (display geometry, a wall's thumbnail shape), each made once and kept while its preset
    lives, the latest `most` of them. Weakly: a preset holds its topology and that its distance tables (184 MB at
    9,602 nodes), which must go with the last session of it (tests/notebook/test_release.py)."""

    def __init__(self, most: int) -> None:
        self.most = most
        self._kept: dict[int, tuple[weakref.ref, object]] = {}  # id(preset) -> (a weak reference to it, its value)
        self._lock = threading.Lock()

    def get(self, preset, make: Callable[[object], object]):
        """The value of `preset`, made by `make(preset)` the first time."""
        with self._lock:
            kept = self._kept.get(id(preset))
            if kept is not None and kept[0]() is preset:
                return kept[1]
        value = make(preset)
        with self._lock:
            if len(self._kept) >= self.most:
                self._kept.clear()
            self._kept[id(preset)] = (weakref.ref(preset), value)
        weakref.finalize(preset, self._forget, id(preset))
        return value

    def _forget(self, key: int) -> None:
        with self._lock:
            self._kept.pop(key, None)


_DISPLAYS = PerPreset(4)  # the latest few presets' display geometry


def display_of(session) -> dict:
    """The display geometry of the session's current preset: triangles, segments, points flag, n_vertices, and
    `nodes` (the nodes a frame streams, in order) when the clay is past STREAM_LIMIT and shown decimated (to
    DECIMATED_NODES). Made once per preset (a million-vertex mesh takes seconds to triangulate and decimate), then
    kept while the preset lives."""
    return _DISPLAYS.get(session.preset, _display_geometry)


def _display_geometry(preset) -> dict:
    topo, display = preset.topology, preset.display
    n = topo.n_vertices
    edges = np.asarray(topo.edges, np.int64).reshape(-1, 2)
    if display == "lines":
        quads = np.stack([edges[:, 0], edges[:, 1], edges[:, 1] + n, edges[:, 0] + n], axis=1)
        tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        segments = np.stack([np.arange(n), np.arange(n) + n], axis=1)
        return {"display": "lines", "n_vertices": 2 * n, "triangles": tris, "segments": segments, "points": False,
                "nodes": None}
    surface = display == "surface" and bool(topo.faces)
    tris = _io.triangulate(topo.faces) if surface else np.zeros((0, 3), np.int64)
    nodes = None
    if n > STREAM_LIMIT:
        nodes, tris, edges = decimate_display(_presets.positions_of(preset.weights, preset.layout), tris, edges)
        n = len(nodes)
    return {"display": "surface" if surface else "points", "n_vertices": n, "triangles": tris, "segments": edges,
            "points": not surface, "nodes": nodes}


def display_arrays(frame, session) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) float32 display positions and (n, 3) float32 colours of a frame (roots then tips for "lines"; the
    streamed nodes only for a decimated clay)."""
    preset = session.preset
    if preset.display == "lines":
        pts, _ = _presets.line_display_mesh(frame.weights, preset.topology, preset.layout)
        return pts, np.concatenate([frame.colours, frame.colours])
    pos, col = np.asarray(frame.positions, np.float32), np.asarray(frame.colours, np.float32)
    if preset.topology.n_vertices > STREAM_LIMIT:
        nodes = display_of(session)["nodes"]
        return pos[nodes], col[nodes]
    return pos, col


def group_maps(group: str) -> list[list[float]]:
    """The symmetry group of a frame (its spec) as the views use it: one 3 x 3 map of a position a copy, row-major,
    the identity first (copy j of the effective controls is control j mod k under map j // k)."""
    symmetry = Symmetry.parse(group)
    maps = np.eye(3)[None] if symmetry is None else symmetry.rotations()
    return [[float(x) for x in m.ravel()] for m in maps]


def mirror_axes(group: str) -> list[bool]:
    """Which position axes (x, y, z) a mirrored copy negates (a mirror group; none for another group)."""
    symmetry = Symmetry.parse(group)
    return [symmetry is not None and symmetry.kind == "mirror" and symmetry.axis == a for a in range(3)]


def topology_message(session, frame) -> TopologyMessage:
    """The topology message for `frame` (whose generation must be the session's current one), but for the fields
    each view's copy fills in (Outbox: its client id, the controls' ids, group, radii and strokes as they are now)."""
    geo = display_of(session)
    pos, _ = display_arrays(frame, session)
    start = _presets.positions_of(session.preset.weights, session.layout)
    if session.preset.display == "lines":
        start = np.concatenate([start, pos])
    everything = np.concatenate([start, np.asarray(frame.effective_positions, np.float32).reshape(-1, 3)])
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    span = float(np.linalg.norm(hi - lo)) or 1.0
    return TopologyMessage(
        generation=int(frame.generation), preset=session.preset.name, title=session.preset.title,
        display=geo["display"], n_vertices=int(geo["n_vertices"]), n_nodes=int(session.topology.n_vertices),
        triangles=geo["triangles"].ravel().tolist(), segments=geo["segments"].ravel().tolist(),
        points=bool(geo["points"]), bounds={"min": [float(x) for x in lo], "max": [float(x) for x in hi]},
        control_radius=0.035 * span, off_clay_gap=OFF_CLAY * clay_size(session.preset),
        colour_space=session.layout.colour_space,
        feature_names=list(session.layout.names))
