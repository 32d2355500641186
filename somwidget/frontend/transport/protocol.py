"""The clay view's protocol: what a server sends every view, what it accepts from one, and how it checks it.

One protocol for every view: the web app's page and the XR page over the websocket /xr/ws (xr/server.py), the
notebook widget over the kernel's comm (widget.py; a frame there is a custom message {"type": "frame"} whose one
binary buffer is the frame below). Pure functions over numpy and the session's Frame: no aiohttp, no event loop, so
tests and benchmarks can encode and decode frames without a server. The JavaScript twin is xr/src/protocol.js.

Server -> client
----------------
1. Text, JSON, once per connection and again whenever the session's generation changes (a new preset or mesh):

   {"type": "topology", "protocol": 1, "generation": g, "preset": "car", "title": "Car",
    "display": "surface" | "lines" | "points",
    "n_vertices": n,            display vertices in each frame (N nodes; 2N for "lines": roots then tips)
    "n_nodes": N,
    "triangles": [i, j, k, ...] flat triangle list over the display vertices (faces fanned; quads for "lines")
    "segments": [i, j, ...]     flat line-segment list (mesh edges / synapses; root -> tip for "lines")
    "points": bool              draw each vertex as a point ("points" display)
    "n_controls": k, "n_effective": k_eff,
    "mirror_axes": [bool, bool, bool]  the position axes a mirrored copy negates (copy j >= k mirrors control j - k)
    "up_axis": 2,               the model's up axis (z; x forward, y sideways)
    "bounds": {"min": [x, y, z], "max": [x, y, z]}  start mesh and controls, for placing the clay
    "control_radius": r,        the drawn radius of a control (model units)
    "colour_space": "hs", "feature_names": [...], "max_coordinate": 1e4, "max_message_bytes": 2048,
    "client": id}

2. Binary frames (little-endian), each the latest state of the session; a slow client skips frames, never lags:

   offset  size       type  field
   0       4          4s    magic b"SOMF"
   4       2          u16   protocol version (1)
   6       2          u16   flags: 1 running, 2 paused, 4 mirrored copies present, 8 a step to undo, 16 a step
                              to redo
   8       4          u32   seq: the session's frame number (increases by one per published frame)
   12      4          u32   generation (matches the latest topology message)
   16      4          u32   iteration s
   20      4          u32   iterations S
   24      4          u32   n: display vertices
   28      2          u16   k: controls (the originals)
   30      2          u16   k_eff: effective controls (originals, then mirrored copies)
   32      12 n       f32   vertex positions (n, 3), model units
   ..      12 k_eff   f32   effective control positions (k_eff, 3)
   ..      3 n        u8    vertex colours (n, 3) RGB
   ..      3 k_eff    u8    effective control colours (k_eff, 3) RGB
   ..      0-3        -     zero padding to a multiple of 4 bytes
   Total: 32 + 15 (n + k_eff) rounded up to 4. The float arrays come first so they are 4-byte aligned.

3. Text, JSON, as things happen:
   {"type": "grabs", "grabs": [{"index": i, "id": c, "own": bool}, ...]}   controls held now (own: this client)
   {"type": "controls", "ids": [c, ...]}                           each control's stable id, in index order:
                                                                   sent (before the frame) whenever they change
                                                                   (a control added or removed, new controls)
   {"type": "error", "message": "...", "intent": "move" | null}     a refused message (see below)
   {"type": "pong", "t": t}                                        the answer to a ping
   {"type": "status", "cycle_ms": c, "fps": f}                     the engine's time per cycle and the frames
                                                                   published per second (about twice a second
                                                                   while frames flow)

Client -> server: JSON text, one intent per message, at most MAX_MESSAGE_BYTES bytes
------------------------------------------------------------------------------------
   {"type": "grab", "id": c}                             hold the control whose id is c (the topology's
                                                         "control_ids", then "controls" messages); refused while
                                                         another client holds it. "index": i (0 <= i < k) instead
                                                         of "id" names a control by its place now
   {"type": "move", "id": c, "position": [x, y, z]}      move a held control (model units)
   {"type": "release", "id": c}                          let go (optionally with a last "position"); a grab to
                                                         its release is one undo step (one gesture). A held control
                                                         that is removed (elsewhere) ends the grab, with an error
                                                         message to the client that held it
   {"type": "reset"} | {"type": "train"} | {"type": "pause"} | {"type": "undo"} | {"type": "redo"}
   {"type": "ping", "t": number}
   {"type": "hello"}                                     send the topology and the latest frame again (a new view
                                                         on an existing connection: the notebook's outputs)
   {"type": "set", "name": n, "value": v}                set a parameter declared in parameters.py (the topology
                                                         message lists them: "parameters"), checked against its
                                                         bounds

Anything else is refused with an error message sent back (and logged) and changes nothing: binary messages,
messages over the size limit, text that is not JSON (NaN and Infinity included), non-objects, unknown types,
unknown or missing fields, indices that are not integers or out of range, positions that are not three finite
numbers within +-MAX_COORDINATE. A mirrored copy is moved through its original (the client reflects the point).
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass

import numpy as np

from ...backend import io as _io
from ...backend import presets as _presets
from ..model import parameters as _parameters

PROTOCOL_VERSION = 1
MAGIC = b"SOMF"
HEADER = struct.Struct("<4sHHIIIIIHH")
HEADER_SIZE = HEADER.size  # 32
FLAG_RUNNING, FLAG_PAUSED, FLAG_MIRRORED, FLAG_CAN_UNDO, FLAG_CAN_REDO = 1, 2, 4, 8, 16
#: Frames a second a view is sent at most (the websocket hub and the notebook widget alike).
MAX_FPS = 60.0
#: Seconds between status messages (cycle time, frames/s) while frames flow.
STATUS_PERIOD = 0.5
#: Longest intent message accepted (bytes of UTF-8 text).
MAX_MESSAGE_BYTES = 2048
#: Largest |coordinate| a move may carry (model units; the presets span a few units, meshes are normalised).
MAX_COORDINATE = 1e4

INTENT_FIELDS = {
    "grab": (set(), {"index", "id"}),
    "move": ({"position"}, {"index", "id"}),
    "release": (set(), {"index", "id", "position"}),
    "reset": (set(), set()),
    "train": (set(), set()),
    "pause": (set(), set()),
    "undo": (set(), set()),
    "redo": (set(), set()),
    "ping": ({"t"}, set()),
    "hello": (set(), set()),
    "set": ({"name", "value"}, set()),
}


class IntentError(ValueError):
    """A refused client message; `intent` is its type when that much was readable."""

    def __init__(self, message: str, intent: str | None = None):
        super().__init__(message)
        self.intent = intent


@dataclass(frozen=True)
class Intent:
    type: str
    index: int | None = None
    position: tuple[float, float, float] | None = None
    t: float | None = None
    name: str | None = None
    value: float | bool | None = None
    control_id: int | None = None


# -- intents ---------------------------------------------------------------------------------------------------
def _no_constants(name: str):
    raise ValueError(f"{name} is not allowed")


def _number(value, what: str, kind: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise IntentError(f"{kind}: {what} must be a number, got {json.dumps(value)[:40]}", kind)
    try:
        x = float(value)
    except OverflowError:
        raise IntentError(f"{kind}: {what} is too large", kind) from None
    if not math.isfinite(x):
        raise IntentError(f"{kind}: {what} must be finite", kind)
    return x


def parse_intent(message, n_controls: int) -> Intent:
    """Check one client message (str, or bytes for a binary frame) against the protocol; IntentError if refused."""
    if isinstance(message, (bytes, bytearray, memoryview)):
        raise IntentError("binary messages are not accepted: send JSON text like {\"type\": \"train\"}")
    if not isinstance(message, str):
        raise IntentError(f"unexpected message of type {type(message).__name__}")
    size = len(message.encode("utf-8", "replace"))
    if size > MAX_MESSAGE_BYTES:
        raise IntentError(f"message too long: {size} bytes (the limit is {MAX_MESSAGE_BYTES})")
    try:
        data = json.loads(message, parse_constant=_no_constants)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError is a ValueError; so is a 5000-digit integer
        raise IntentError(f"not valid JSON: {str(exc)[:80]}") from None
    if not isinstance(data, dict):
        raise IntentError("expected a JSON object like {\"type\": \"move\", \"index\": 0, \"position\": [0, 0, 0]}")
    kind = data.get("type")
    if not isinstance(kind, str) or kind not in INTENT_FIELDS:
        shown = json.dumps(kind)[:40] if kind is not None else "missing"
        raise IntentError(f"unknown intent type {shown}; known: {', '.join(INTENT_FIELDS)}")
    required, optional = INTENT_FIELDS[kind]
    fields = set(data) - {"type"}
    extra = sorted(fields - required - optional)
    if extra:
        allowed = ", ".join(sorted(required | optional)) or "none"
        raise IntentError(f"{kind}: unknown field(s) {', '.join(repr(f[:30]) for f in extra)}; allowed: {allowed}",
                          kind)
    missing = sorted(required - fields)
    if missing:
        raise IntentError(f"{kind}: missing field(s) {', '.join(missing)}", kind)
    index = position = t = control_id = None
    if kind in ("grab", "move", "release") and ("index" in data) == ("id" in data):
        raise IntentError(f"{kind}: give the control's \"id\" (or its \"index\"), one of the two", kind)
    if "id" in data:
        control_id = data["id"]
        if isinstance(control_id, bool) or not isinstance(control_id, int) or not 0 <= control_id < 2**31:
            raise IntentError(f"{kind}: id must be a control's id (an integer >= 0), got "
                              f"{json.dumps(control_id)[:40]}", kind)
    if "index" in data:
        index = data["index"]
        if isinstance(index, bool) or not isinstance(index, int):
            raise IntentError(f"{kind}: index must be an integer, got {json.dumps(index)[:40]}", kind)
        if not 0 <= index < n_controls:
            raise IntentError(f"{kind}: control index {index} is out of range (there are {n_controls} controls: "
                              f"0..{n_controls - 1})", kind)
    if "position" in data:
        p = data["position"]
        if not isinstance(p, list) or len(p) != 3:
            raise IntentError(f"{kind}: position must be a list of 3 numbers, got {json.dumps(p)[:60]}", kind)
        xyz = tuple(_number(v, "position", kind) for v in p)
        if max(abs(v) for v in xyz) > MAX_COORDINATE:
            raise IntentError(f"{kind}: position {list(xyz)} is out of bounds (|coordinate| <= {MAX_COORDINATE:g})",
                              kind)
        position = xyz
    if "t" in data:
        t = _number(data["t"], "t", kind)
    name = value = None
    if kind == "set":
        name, value = data["name"], data["value"]
        if not isinstance(name, str) or name not in _parameters.BY_NAME:
            raise IntentError(f"set: unknown parameter {json.dumps(name)[:40]}; known: "
                              f"{', '.join(_parameters.BY_NAME)}", kind)
        declared = _parameters.BY_NAME[name]
        if declared.kind != "bool":
            value = _number(value, name, kind)
        try:
            value = declared.check(value)
        except ValueError as exc:
            raise IntentError(f"set: {exc}", kind) from None
    return Intent(kind, index, position, t, name, value, control_id)


def error_message(message: str, intent: str | None = None) -> str:
    return json.dumps({"type": "error", "message": message, "intent": intent})


def status_message(frame, frames_per_second: float) -> str:
    return json.dumps({"type": "status", "cycle_ms": round(float(frame.cycle_time) * 1e3, 6),
                       "fps": round(float(frames_per_second), 2)})


# -- topology ----------------------------------------------------------------------------------------------------
#: Most display vertices a frame streams: 32,768 x 15 bytes = 0.5 MB a frame, 15 MB/s at 30 frames/s, which a
#: headset's Wi-Fi and a laptop's browser both take. A bigger clay is shown decimated (`decimate_display`).
STREAM_LIMIT = 32768


def decimate_display(points: np.ndarray, triangles: np.ndarray, segments: np.ndarray, limit: int = STREAM_LIMIT):
    """A display mesh of at most `limit` of the nodes, for a clay too big to stream whole: the nodes are clustered on
    a uniform grid over their start positions (one node stands for each occupied cell), and the triangles and
    segments are mapped onto those nodes (the degenerate ones dropped). Every frame then sends the trained
    positions of those nodes. Returns (nodes (m,), triangles (T, 3), segments (E, 2)) over 0..m-1."""
    pts = np.asarray(points, np.float64)
    lo, span = pts.min(axis=0), np.ptp(pts, axis=0)
    span[span <= 0] = 1.0
    cells = max(2, int(round(limit ** (1 / 3))))
    for _ in range(40):  # grow the grid while it keeps under the limit (a surface fills ~cells^2 of cells^3)
        key = np.minimum((pts - lo) / span * cells, cells - 1).astype(np.int64)
        key = (key[:, 0] * cells + key[:, 1]) * cells + key[:, 2]
        _, first, cluster = np.unique(key, return_index=True, return_inverse=True)
        if len(first) > limit:
            cells = max(2, int(cells / 1.15))
            continue
        finer = max(cells + 1, int(cells * min(1.5, (limit / len(first)) ** 0.5)))
        key2 = np.minimum((pts - lo) / span * finer, finer - 1).astype(np.int64)
        if len(np.unique((key2[:, 0] * finer + key2[:, 1]) * finer + key2[:, 2])) > limit:
            break
        cells = finer
    cluster = cluster.ravel()

    def remap(idx: np.ndarray, width: int) -> np.ndarray:
        m = cluster[np.asarray(idx, np.int64).reshape(-1, width)]
        distinct = np.ones(len(m), bool)
        for i in range(width):
            for j in range(i + 1, width):
                distinct &= m[:, i] != m[:, j]
        m = m[distinct]
        return np.unique(np.sort(m, axis=1), axis=0) if width == 2 else m

    return first.astype(np.int64), remap(triangles, 3), remap(segments, 2)


_DISPLAYS: dict[int, tuple] = {}  # id(preset) -> (preset, display): the latest few presets' display geometry


def display_of(session) -> dict:
    """The display geometry of the session's current preset: triangles, segments, points flag, n_vertices, and
    `nodes` (the nodes a frame streams, in order) when the clay is past STREAM_LIMIT and shown decimated. Made once
    per preset (a million-vertex mesh takes seconds to triangulate and decimate), then kept."""
    preset = session.preset
    cached = _DISPLAYS.get(id(preset))
    if cached is not None and cached[0] is preset:
        return cached[1]
    display = _display_geometry(preset)
    if len(_DISPLAYS) >= 4:
        _DISPLAYS.clear()
    _DISPLAYS[id(preset)] = (preset, display)
    return display


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


def control_colours(frame, has_colour: bool) -> np.ndarray:
    """(k_eff, 3) display colours of the effective controls (the palette when the layout has no colour dims)."""
    if has_colour:
        return np.asarray(frame.effective_colours, np.float32)
    return _presets.palette_colours(frame.n_controls, len(frame.effective_controls))[1]


def mirror_axes(session) -> list[bool]:
    """Which position axes (x, y, z) a mirrored copy negates, from the session's mirror dims."""
    from ..model.session import default_mirror

    dims = set(default_mirror(session.preset))
    return [d in dims for d in session.layout.position]


def topology_message(session, frame, client_id: int | None = None) -> dict:
    """The JSON topology message for `frame` (whose generation must be the session's current one)."""
    geo = display_of(session)
    pos, _ = display_arrays(frame, session)
    start = _presets.positions_of(session.preset.weights, session.layout)
    if session.preset.display == "lines":
        start = np.concatenate([start, pos])
    everything = np.concatenate([start, np.asarray(frame.effective_positions, np.float32).reshape(-1, 3)])
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    span = float(np.linalg.norm(hi - lo)) or 1.0
    return {
        "type": "topology", "protocol": PROTOCOL_VERSION, "generation": int(frame.generation),
        "preset": session.preset.name, "title": session.preset.title, "display": geo["display"],
        "n_vertices": int(geo["n_vertices"]), "n_nodes": int(session.topology.n_vertices),
        "triangles": geo["triangles"].ravel().tolist(), "segments": geo["segments"].ravel().tolist(),
        "points": bool(geo["points"]), "n_controls": int(frame.n_controls),
        "n_effective": int(len(frame.effective_controls)), "mirror_axes": mirror_axes(session), "up_axis": 2,
        "bounds": {"min": [float(x) for x in lo], "max": [float(x) for x in hi]},
        "control_radius": 0.035 * span, "colour_space": session.layout.colour_space,
        "feature_names": list(session.layout.names), "max_coordinate": MAX_COORDINATE,
        "max_message_bytes": MAX_MESSAGE_BYTES, "client": client_id,
        "parameters": [p.describe() for p in _parameters.PARAMETERS],
        "control_ids": [int(i) for i in frame.control_ids],
    }


def controls_message(control_ids) -> str:
    """The ids of the controls, in index order: sent before the first frame whose controls they name."""
    return json.dumps({"type": "controls", "ids": [int(i) for i in control_ids]})


# -- frames ----------------------------------------------------------------------------------------------------
def _rgb8(colours: np.ndarray) -> np.ndarray:
    return np.clip(np.round(np.asarray(colours, np.float32) * 255.0), 0, 255).astype(np.uint8)


_encoded: tuple = (None, None, b"")  # (frame, session, bytes): the latest encoding, shared by every view


def encode_frame(frame, session) -> bytes:
    """The binary frame message for `frame` (layout in the module docstring). Encoded once per published frame:
    the websocket hub and every notebook widget of the session get the same bytes."""
    global _encoded
    last = _encoded  # one read of one tuple: a thread that replaces it meanwhile cannot mix two frames
    if last[0] is frame and last[1] is session:
        return last[2]
    data = _encode(frame, session)
    _encoded = (frame, session, data)
    return data


def _encode(frame, session) -> bytes:
    pos, col = display_arrays(frame, session)
    cpos = np.asarray(frame.effective_positions, np.float32).reshape(-1, 3)
    ccol = control_colours(frame, session.layout.colour_space != "none")
    n, k, k_eff = len(pos), int(frame.n_controls), len(cpos)
    undo, redo = frame.history
    flags = (FLAG_RUNNING if frame.running else 0) | (FLAG_PAUSED if frame.paused else 0) | (
        FLAG_MIRRORED if k_eff > k else 0) | (FLAG_CAN_UNDO if undo else 0) | (FLAG_CAN_REDO if redo else 0)
    header = HEADER.pack(MAGIC, PROTOCOL_VERSION, flags, frame.seq & 0xFFFFFFFF, frame.generation & 0xFFFFFFFF,
                         frame.iteration, frame.iterations, n, k, k_eff)
    body = b"".join([header, np.ascontiguousarray(pos, "<f4").tobytes(), np.ascontiguousarray(cpos, "<f4").tobytes(),
                     _rgb8(col).tobytes(), _rgb8(ccol).tobytes()])
    return body + b"\0" * (-len(body) % 4)


def frame_size(n: int, k_eff: int) -> int:
    size = HEADER_SIZE + 15 * (n + k_eff)
    return size + (-size % 4)


def decode_frame(data: bytes) -> dict:
    """Parse a binary frame (for tests and benchmarks): header fields and numpy arrays; ValueError if malformed."""
    if len(data) < HEADER_SIZE:
        raise ValueError(f"frame too short: {len(data)} bytes")
    magic, version, flags, seq, generation, s, S, n, k, k_eff = HEADER.unpack_from(data, 0)
    if magic != MAGIC or version != PROTOCOL_VERSION:
        raise ValueError(f"not a somwidget frame (magic {magic!r}, version {version})")
    if len(data) != frame_size(n, k_eff):
        raise ValueError(f"frame of {len(data)} bytes, expected {frame_size(n, k_eff)} for n={n}, k_eff={k_eff}")
    o = HEADER_SIZE
    pos = np.frombuffer(data, "<f4", 3 * n, o).reshape(n, 3)
    o += 12 * n
    cpos = np.frombuffer(data, "<f4", 3 * k_eff, o).reshape(k_eff, 3)
    o += 12 * k_eff
    col = np.frombuffer(data, np.uint8, 3 * n, o).reshape(n, 3)
    o += 3 * n
    ccol = np.frombuffer(data, np.uint8, 3 * k_eff, o).reshape(k_eff, 3)
    return {"flags": flags, "running": bool(flags & FLAG_RUNNING), "paused": bool(flags & FLAG_PAUSED),
            "can_undo": bool(flags & FLAG_CAN_UNDO), "can_redo": bool(flags & FLAG_CAN_REDO),
            "seq": seq, "generation": generation, "iteration": s, "iterations": S, "n": n, "k": k, "k_eff": k_eff,
            "positions": pos, "control_positions": cpos, "colours": col, "control_colours": ccol}


__all__ = ["PROTOCOL_VERSION", "MAGIC", "HEADER_SIZE", "MAX_MESSAGE_BYTES", "MAX_COORDINATE", "Intent",
           "IntentError", "parse_intent", "error_message", "display_of", "display_arrays", "topology_message",
           "encode_frame", "decode_frame", "frame_size", "mirror_axes"]
