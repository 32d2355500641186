"""The wire messages between a session and its views, declared once: what a server sends every view, what it accepts
from one, and how it checks it.

One protocol for every view: the web app's page and the XR page over the websocket /xr/ws (web/hub.py), the
notebook widget over the kernel's comm (notebook/widget.py; a frame there is a custom message {"type": "frame"}
whose one binary buffer is the frame below). Binary frames are encoded in frames.py, the topology message's
geometry in display.py; both send through outbox.py. The JavaScript twin is client/src/protocol.js (a test keeps the
two in step).

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
    "mirror_axes": [bool, bool, bool]  the position axes a mirrored copy negates (a mirror group)
    "group": "radial-8-z",      the symmetry group of the controls ("none": each control alone)
    "group_maps": [[9 floats], ...]  the group's maps of a position (3 x 3, row-major), the identity first: effective
                                control j is control j mod k under map j // k
    "up_axis": 2,               the model's up axis (z; x forward, y sideways)
    "bounds": {"min": [x, y, z], "max": [x, y, z]}  start mesh and controls, for placing the clay
    "control_radius": r,        the drawn radius of a control (model units)
    "radii": [r, ...], "strokes": [n, ...]  each control's radius of influence and the runs that act as one (as in
                                the "controls" message)
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
   {"type": "controls", "ids": [c, ...], "group": g,               each control's stable id, in index order, and
    "group_maps": [...], "radii": [r, ...], "strokes": [n, ...]}   the group (as in the topology), each control's
                                                                   radius of influence (model units) and the runs of
                                                                   controls that act as one (a stroke's samples):
                                                                   sent (before the frame) whenever they change (a
                                                                   control added or removed, a radius, new controls,
                                                                   a group on or off)
   {"type": "error", "message": "...", "intent": "move" | null}     a refused message (see below)
   {"type": "pong", "t": t}                                        the answer to a ping
   {"type": "status", "cycle_ms": c, "fps": f}                     the engine's time per cycle and the frames
                                                                   published per second (about twice a second
                                                                   while frames flow)
   {"type": "autosave", "ok": false, "message": "..."}             the autosave cannot write (what and where; it
                                                                   tries again every second): shown until a message
                                                                   with "ok": true says a save is on disk again

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
   {"type": "add", "position": [x, y, z], "radius": r}   a new control there (its other features the nearest
                                                         node's; radius optional: the preset's); it moves nothing
                                                         until it is dragged
   {"type": "remove", "id": c}                           remove a control (a stroke goes whole)
   {"type": "radius", "id": c, "radius": r}              a control's radius of influence (model units, >= 0); the
                                                         same control's radius again within a moment joins its step
   {"type": "stroke", "points": [[x, y, z], ...],        a polyline of 2 to MAX_STROKE_POINTS points as one control
    "radius": r}                                         (its samples act as one); radius optional
   {"type": "set", "name": n, "value": v}                set a parameter declared in model/parameters.py (the topology
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
from dataclasses import dataclass

from ..model import settings as _parameters

PROTOCOL_VERSION = 1
MAGIC = b"SOMF"
#: The binary frame's header: magic, version, flags, seq, generation, s, S, n, k, k_eff (frames.py packs it).
HEADER_FORMAT = "<4sHHIIIIIHH"
HEADER_SIZE = 32
#: The frame header's flag bits.
FLAGS = {"running": 1, "paused": 2, "mirrored": 4, "can_undo": 8, "can_redo": 16}
#: Frames a second a view is sent at most (the websocket hub and the notebook widget alike).
MAX_FPS = 60.0
#: Seconds between status messages (cycle time, frames/s) while frames flow.
STATUS_PERIOD = 0.5
#: Longest intent message accepted (bytes of UTF-8 text).
MAX_MESSAGE_BYTES = 2048
#: Largest |coordinate| a move may carry (model units; the presets span a few units, meshes are normalised).
MAX_COORDINATE = 1e4

#: Client -> server: each intent's type -> (required fields, optional fields) besides "type".
INTENTS = {
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
    "add": ({"position"}, {"radius"}),
    "remove": (set(), {"index", "id"}),
    "radius": ({"radius"}, {"index", "id"}),
    "stroke": ({"points"}, {"radius"}),
}
#: Intents that name one control (by "id", or by "index").
CONTROL_INTENTS = ("grab", "move", "release", "remove", "radius")
#: Most points a stroke intent carries (the session samples the line again, MAX_STROKE_SAMPLES at most).
MAX_STROKE_POINTS = 64

#: Server -> client JSON messages (besides binary frames), by their "type".
SERVER_MESSAGES = ("topology", "grabs", "controls", "error", "pong", "status", "autosave")


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
    radius: float | None = None
    points: tuple[tuple[float, float, float], ...] | None = None


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
    if not isinstance(kind, str) or kind not in INTENTS:
        shown = json.dumps(kind)[:40] if kind is not None else "missing"
        raise IntentError(f"unknown intent type {shown}; known: {', '.join(INTENTS)}")
    required, optional = INTENTS[kind]
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
    if kind in CONTROL_INTENTS and ("index" in data) == ("id" in data):
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
        position = _point(data["position"], "position", kind)
    if "t" in data:
        t = _number(data["t"], "t", kind)
    radius = points = None
    if "radius" in data:
        radius = _number(data["radius"], "radius", kind)
        if not 0.0 <= radius <= MAX_COORDINATE:
            raise IntentError(f"{kind}: radius {radius:g} is out of bounds (0 <= radius <= {MAX_COORDINATE:g})", kind)
    if "points" in data:
        pts = data["points"]
        if not isinstance(pts, list) or not 2 <= len(pts) <= MAX_STROKE_POINTS:
            raise IntentError(f"{kind}: points must be a list of 2 to {MAX_STROKE_POINTS} points [x, y, z], got "
                              f"{json.dumps(pts)[:60]}", kind)
        points = tuple(_point(p, "points", kind) for p in pts)
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
    return Intent(kind, index, position, t, name, value, control_id, radius, points)


def _point(p, what: str, kind: str) -> tuple[float, float, float]:
    """Three finite numbers within +-MAX_COORDINATE (a position, a stroke's point)."""
    if not isinstance(p, list) or len(p) != 3:
        raise IntentError(f"{kind}: {what} must be a list of 3 numbers, got {json.dumps(p)[:60]}", kind)
    xyz = tuple(_number(v, what, kind) for v in p)
    if max(abs(v) for v in xyz) > MAX_COORDINATE:
        raise IntentError(f"{kind}: {what} {list(xyz)} is out of bounds (|coordinate| <= {MAX_COORDINATE:g})", kind)
    return xyz


def error_message(message: str, intent: str | None = None) -> dict:
    return {"type": "error", "message": message, "intent": intent}


def status_message(cycle_time: float, frames_per_second: float) -> dict:
    return {"type": "status", "cycle_ms": round(float(cycle_time) * 1e3, 6), "fps": round(float(frames_per_second), 2)}


def autosave_message(error: str | None) -> dict:
    """The autosave's state: `error` (what and where) while saves fail, None once one is on disk again."""
    return {"type": "autosave", "ok": error is None, "message": error or "autosave works again: all is on disk"}


def controls_message(control_ids, group: str = "none", maps: list | None = None, radii=(), strokes=()) -> dict:
    """The ids of the controls, in index order, their symmetry group, radii and strokes: sent before the first frame
    whose controls they name."""
    return {"type": "controls", "ids": [int(i) for i in control_ids], "group": group,
            "group_maps": maps if maps is not None else [[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]],
            "radii": [round(float(r), 6) for r in radii], "strokes": [int(n) for n in strokes]}


def grabs_message(grabs: list[dict]) -> dict:
    """The controls held now: [{"index": i, "id": c, "own": bool}, ...] as one client sees them."""
    return {"type": "grabs", "grabs": grabs}


def pong_message(t: float | None) -> dict:
    return {"type": "pong", "t": t}
