"""The wire messages between a session and its views, declared once, one dataclass each. Validation, the Python
encoders and client/src/protocol.js (`python -m somwidget.frontend.transport.codegen`) are derived from them.

One protocol for every view: the web app's and the XR page over the websocket /view/ws (web/hub.py; /xr/ws is its
old name), the notebook widget over the kernel's comm (notebook/widget.py); both through one `ViewConnection`
(connection.py). Field types and bounds are the wire field types of fields.py.

Server -> client: a `TopologyMessage` once per connection and again at a new preset or mesh; then binary frames
(`FrameHeader` and FRAME_ARRAYS below: the latest state; a slow view skips frames, never lags); then, as things
happen, the other `ServerMessage`s. Over the notebook's comm a frame is a `FrameMessage` whose one buffer is the frame.

Client -> server: JSON text, one `Intent` per message, at most MAX_MESSAGE_BYTES bytes. Anything else is refused with
an `ErrorMessage` sent back (and logged) and changes nothing: binary messages, messages over the size limit, text
that is not JSON (NaN and Infinity included), non-objects, unknown types, unknown or missing fields, and fields that
break their declared type (fields.py). A mirrored copy is moved through its original (the client reflects the point).
"""

from __future__ import annotations

import dataclasses
import json
import struct
from dataclasses import dataclass, field
from typing import Annotated, ClassVar, Literal

from ..model import settings as _settings
from ..model.hands import KINDS as HAND_KINDS
from .fields import (
    MAX_COORDINATE,
    MAX_STROKE_POINTS,
    ControlId,
    ControlIndex,
    IntentError,
    Number,
    OneOf,
    PersonName,
    Point,
    Polyline,
    Radius,
    Value,
    declared_fields,
    finite,
)

PROTOCOL_VERSION = 1
MAGIC = b"SOMF"
#: Frames a second a view is sent at most (the websocket hub and the notebook widget alike).
MAX_FPS = 60.0
#: Seconds between status messages (cycle time, frames/s) while frames flow.
STATUS_PERIOD = 0.5
#: Longest intent message accepted (bytes of UTF-8 text).
MAX_MESSAGE_BYTES = 2048
#: The identity of a symmetry group's maps (3 x 3, row-major): the group "none".
IDENTITY_MAP = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


# -- the settings' part of the schema ------------------------------------------------------------------------------
def settings_schema() -> list[dict]:
    """The settings a view may set by name ("set"), as the topology message lists them ("parameters")."""
    return _settings.wire_schema()


def setting_names() -> tuple[str, ...]:
    return tuple(s.name for s in _settings.settable())


#: A "set" intent's name: a declared setting.
SettingName = Annotated[str, OneOf(setting_names, "parameter")]
#: A "hand" intent's kind: what a view is, as the others see it.
HandKind = Annotated[str, OneOf(lambda: HAND_KINDS, "kind of view")]


def check_setting(name: str, value):
    """`value` checked against the setting `name`'s declaration (type, bounds); ValueError naming the problem."""
    declared = {s.name: s for s in _settings.settable()}[name]
    if declared.kind != "bool":
        value = finite(value, name, "set")
    return _settings.check_set(name, value)


# -- the binary frame ---------------------------------------------------------------------------------------------
def _packed(code: str, doc: str):
    """A header field: its struct code (little-endian) and what it holds."""
    return field(metadata={"struct": code, "doc": doc})


@dataclass(frozen=True)
class FrameHeader:
    """The binary frame's header (little-endian, 32 bytes), followed by FRAME_ARRAYS and zero padding to a multiple
    of 4 bytes. The float arrays come first so they are 4-byte aligned."""

    magic: bytes = _packed("4s", 'b"SOMF"')
    version: int = _packed("H", "the protocol version (PROTOCOL_VERSION)")
    flags: int = _packed("H", "FLAGS: 1 running, 2 paused, 4 mirrored copies present, 8 a step to undo, 16 to redo")
    seq: int = _packed("I", "the session's frame number (one more per published frame)")
    generation: int = _packed("I", "matches the latest topology message")
    iteration: int = _packed("I", "the iteration s")
    iterations: int = _packed("I", "the iterations S")
    n: int = _packed("I", "display vertices")
    k: int = _packed("H", "controls (the originals)")
    k_eff: int = _packed("H", "effective controls (the originals, then the mirrored copies)")


#: The frame header's flag bits.
FLAGS = {"running": 1, "paused": 2, "mirrored": 4, "can_undo": 8, "can_redo": 16}
HEADER_FORMAT = "<" + "".join(f.metadata["struct"] for f in dataclasses.fields(FrameHeader))
HEADER_SIZE = struct.calcsize(HEADER_FORMAT)


@dataclass(frozen=True)
class FrameArray:
    """One array of a frame's body: `rows` rows (a header field) of `width` values of `dtype` (numpy's)."""

    name: str
    dtype: Literal["<f4", "u1"]
    rows: str
    width: int
    doc: str

    @property
    def row_bytes(self) -> int:
        return self.width * (4 if self.dtype == "<f4" else 1)


#: The frame's body after its header, in order.
FRAME_ARRAYS = (
    FrameArray("positions", "<f4", "n", 3, "vertex positions, model units"),
    FrameArray("control_positions", "<f4", "k_eff", 3, "effective control positions"),
    FrameArray("colours", "u1", "n", 3, "vertex colours, RGB"),
    FrameArray("control_colours", "u1", "k_eff", 3, "effective control colours, RGB"),
)


def frame_size(n: int, k_eff: int) -> int:
    """Bytes of a frame of n display vertices and k_eff effective controls (padding included)."""
    rows = {"n": n, "k_eff": k_eff}
    size = HEADER_SIZE + sum(a.row_bytes * rows[a.rows] for a in FRAME_ARRAYS)
    return size + (-size % 4)


# -- server -> client ------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class ServerMessage:
    """A JSON message from the server to a view (its "type", then its fields)."""

    type: ClassVar[str]

    def to_json(self) -> dict:
        out = {"type": self.type}
        for f in dataclasses.fields(self):
            out[f.name] = _plain(getattr(self, f.name))
        return out


def _plain(value):
    """A field's JSON form: dataclasses as objects, tuples as lists; a flat list (a mesh's triangles) as it is."""
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (list, tuple)):
        flat = not any(isinstance(v, (list, tuple)) or dataclasses.is_dataclass(v) for v in value[:1])
        return value if flat and isinstance(value, list) else [_plain(v) for v in value]
    return value


@dataclass(frozen=True, kw_only=True)
class TopologyMessage(ServerMessage):
    """What a view draws, once per connection and again whenever the session's generation changes (a new preset or
    mesh). `n_vertices`: display vertices in each frame (N nodes; 2N for "lines": roots then tips); `triangles`: a
    flat triangle list over them (faces fanned; quads for "lines"); `segments`: a flat segment list (mesh edges;
    root -> tip for "lines"); `points`: draw each vertex as a point; `bounds`: {"min": [x, y, z], "max": [...]} of the
    start mesh and controls; `control_radius`: a control's drawn radius; `off_clay_gap`: past this distance from the
    clay a control gets a line to its nearest node (0: none); `parameters`: the settings a "set" may name.
    The fields after `parameters` are the view's own: its client id (None over the notebook's comm), `watching`
    (the view only watches: its intents other than hello, hand and ping are refused, so it shows itself read-only) and
    the controls as a `ControlsMessage` gives them, with `mirror_axes` (the axes a mirrored copy negates), `n_controls`
    and `n_effective` (originals, then mirrored copies)."""

    type: ClassVar[str] = "topology"
    protocol: int = PROTOCOL_VERSION
    generation: int
    preset: str
    title: str
    display: Literal["surface", "lines", "points"]
    n_vertices: int
    n_nodes: int
    triangles: list[int]
    segments: list[int]
    points: bool
    up_axis: int = 2
    bounds: dict[str, list[float]]
    control_radius: float
    off_clay_gap: float = 0.0
    colour_space: str
    feature_names: list[str]
    max_coordinate: float = MAX_COORDINATE
    max_message_bytes: int = MAX_MESSAGE_BYTES
    parameters: list[dict] = field(default_factory=settings_schema)
    client: int | None = None
    watching: bool = False
    control_ids: list[int] = field(default_factory=list)
    group: str = "none"
    group_maps: list[list[float]] = field(default_factory=lambda: [list(IDENTITY_MAP)])
    mirror_axes: list[bool] = field(default_factory=lambda: [False, False, False])
    n_controls: int = 0
    n_effective: int = 0
    radii: list[float] = field(default_factory=list)
    strokes: list[int] = field(default_factory=list)


@dataclass(frozen=True, kw_only=True)
class ControlsMessage(ServerMessage):
    """Each control's stable id in index order, the symmetry group (its maps of a position, 3 x 3 row-major, the
    identity first: effective control j is control j mod k under map j // k), each control's radius of influence
    (model units) and the runs of controls that act as one (a stroke's samples). Sent before the frame whenever one
    of them changes."""

    type: ClassVar[str] = "controls"
    ids: list[int]
    group: str = "none"
    group_maps: list[list[float]] = field(default_factory=lambda: [list(IDENTITY_MAP)])
    radii: list[float] = field(default_factory=list)
    strokes: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class HeldControl:
    """A control held now: its index now, its id, whether the view it is sent to holds it, and who does (the
    holder's hand id, name and colour, as a `PresenceMessage` lists them)."""

    index: int
    id: int
    own: bool
    hand: int
    holder: str
    colour: str


@dataclass(frozen=True, kw_only=True)
class GrabsMessage(ServerMessage):
    """The controls held now, as the view it is sent to sees them."""

    type: ClassVar[str] = "grabs"
    grabs: list[HeldControl]


@dataclass(frozen=True)
class PresentHand:
    """One hand on the session: a view ("desktop", "notebook", "headset") or "python" (while it holds something),
    its name and colour, the ids of the controls it holds, and whether it is the view this is sent to."""

    id: int
    kind: str
    name: str
    colour: str
    holds: list[int]
    you: bool


@dataclass(frozen=True, kw_only=True)
class PresenceMessage(ServerMessage):
    """Who is on the session now, in the order they came: sent to every view whenever someone comes, goes, grabs or
    lets go."""

    type: ClassVar[str] = "presence"
    hands: list[PresentHand]


@dataclass(frozen=True, kw_only=True)
class ErrorMessage(ServerMessage):
    """A refused intent: why, and its type when that much was readable."""

    type: ClassVar[str] = "error"
    message: str
    intent: str | None = None


@dataclass(frozen=True, kw_only=True)
class PongMessage(ServerMessage):
    """The answer to a ping, with its `t`."""

    type: ClassVar[str] = "pong"
    t: float | None


@dataclass(frozen=True, kw_only=True)
class StatusMessage(ServerMessage):
    """The engine's time per cycle (ms) and the frames published a second, every STATUS_PERIOD while frames flow."""

    type: ClassVar[str] = "status"
    cycle_ms: float
    fps: float

    @classmethod
    def of(cls, cycle_time: float, frames_per_second: float) -> StatusMessage:
        return cls(cycle_ms=round(float(cycle_time) * 1e3, 6), fps=round(float(frames_per_second), 2))


@dataclass(frozen=True, kw_only=True)
class AutosaveMessage(ServerMessage):
    """The autosave cannot write (`ok` false: what and where; it tries again every second), shown until a message
    with `ok` true says a save is on disk again."""

    type: ClassVar[str] = "autosave"
    ok: bool
    message: str

    @classmethod
    def of(cls, error: str | None) -> AutosaveMessage:
        return cls(ok=error is None, message=error or "autosave works again: all is on disk")


@dataclass(frozen=True, kw_only=True)
class FrameMessage(ServerMessage):
    """Over the notebook's comm only: a binary frame travels as this message with the frame as its one buffer (a
    websocket sends the frame bare)."""

    type: ClassVar[str] = "frame"


#: Server -> client JSON messages by their "type" (the frame's envelope aside: the view's pipe opens it).
SERVER_MESSAGES: dict[str, type[ServerMessage]] = {
    m.type: m for m in (TopologyMessage, GrabsMessage, PresenceMessage, ControlsMessage, ErrorMessage, PongMessage,
                        StatusMessage, AutosaveMessage)
}


# -- client -> server ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Intent:
    """A view's request, one JSON object per message. A field without a default is required; a field whose
    metadata says browser=False is for older clients (the browser's builders leave it out)."""

    type: ClassVar[str]
    #: Fields of which exactly one must be given.
    one_of: ClassVar[tuple[str, ...]] = ()

    def checked(self) -> Intent:
        """Checks across fields, once each field passed its own (IntentError); the intent, perhaps refined."""
        return self

    def to_json(self) -> dict:
        """The message a client sends (fields left at None are left out)."""
        out = {"type": self.type}
        for f in dataclasses.fields(self):
            if getattr(self, f.name) is not None:
                out[f.name] = _plain(getattr(self, f.name))
        return out


#: A control by its place now (older clients; the browser names controls by id).
_BY_PLACE = {"browser": False}


@dataclass(frozen=True, kw_only=True)
class ControlIntent(Intent):
    """An intent that names one control: by its stable id (the topology's "control_ids", then "controls" messages),
    or by its index now."""

    one_of: ClassVar[tuple[str, ...]] = ("id", "index")
    id: ControlId | None = None
    index: ControlIndex | None = field(default=None, metadata=_BY_PLACE)


@dataclass(frozen=True, kw_only=True)
class GrabIntent(ControlIntent):
    """Hold a control; refused while another view holds it. A grab to its release is one undo step (a gesture)."""

    type: ClassVar[str] = "grab"


@dataclass(frozen=True, kw_only=True)
class MoveIntent(ControlIntent):
    """Move a held control to `position` (model units)."""

    type: ClassVar[str] = "move"
    position: Point


@dataclass(frozen=True, kw_only=True)
class ReleaseIntent(ControlIntent):
    """Let go of a held control: the drag ends, nothing more. A last `position` (older clients) moves it first only
    where it differs from the last move. A held control removed elsewhere ends the grab, with an error message to the
    view that held it."""

    type: ClassVar[str] = "release"
    position: Point | None = None


@dataclass(frozen=True, kw_only=True)
class RemoveIntent(ControlIntent):
    """Remove a control (a stroke goes whole)."""

    type: ClassVar[str] = "remove"


@dataclass(frozen=True, kw_only=True)
class RadiusIntent(ControlIntent):
    """A control's radius of influence (model units); the same control's radius again within a moment joins its
    step."""

    type: ClassVar[str] = "radius"
    radius: Radius


@dataclass(frozen=True, kw_only=True)
class AddIntent(Intent):
    """A new control at `position` (its other features the nearest node's; radius left out: the preset's); it moves
    nothing until it is dragged."""

    type: ClassVar[str] = "add"
    position: Point
    radius: Radius | None = None


@dataclass(frozen=True, kw_only=True)
class StrokeIntent(Intent):
    """A polyline of 2 to MAX_STROKE_POINTS points as one control (its samples act as one); radius optional."""

    type: ClassVar[str] = "stroke"
    points: Polyline
    radius: Radius | None = None


@dataclass(frozen=True, kw_only=True)
class RevolveIntent(Intent):
    """A profile of 2 to MAX_STROKE_POINTS points drawn beside the axis of the radial group in effect (none: the
    z-axis, 16 copies): the clay is lathed around it and the profile becomes its stroke control (Session.revolve);
    radius optional."""

    type: ClassVar[str] = "revolve"
    points: Polyline
    radius: Radius | None = None


@dataclass(frozen=True, kw_only=True)
class SetIntent(Intent):
    """Set a setting by name (the topology message lists them: "parameters"), checked against its declaration."""

    type: ClassVar[str] = "set"
    name: SettingName
    value: Value

    def checked(self) -> SetIntent:
        try:
            return dataclasses.replace(self, value=check_setting(self.name, self.value))
        except IntentError:
            raise
        except ValueError as exc:
            raise IntentError(f"set: {exc}", "set") from None


@dataclass(frozen=True, kw_only=True)
class PingIntent(Intent):
    """Answered at once with a `PongMessage` carrying the same `t`."""

    type: ClassVar[str] = "ping"
    t: Annotated[float, Number()]


@dataclass(frozen=True, kw_only=True)
class HelloIntent(Intent):
    """Send the topology and the latest frame again (a new output of the same connection: a notebook's)."""

    type: ClassVar[str] = "hello"


@dataclass(frozen=True, kw_only=True)
class HandIntent(Intent):
    """What this view is, as the others see it (a `PresenceMessage`): "desktop" (a view's connection starts as one;
    a notebook's as "notebook"), or "headset" while the page is in its immersive session; `name`: the person's name
    as they gave it (a studio's lobby), shown in place of "desktop 2" to the others and on the wall."""

    type: ClassVar[str] = "hand"
    kind: HandKind
    name: PersonName | None = None


@dataclass(frozen=True, kw_only=True)
class ResetIntent(Intent):
    """Train the whole schedule again from the start mesh."""

    type: ClassVar[str] = "reset"


@dataclass(frozen=True, kw_only=True)
class TrainIntent(Intent):
    """Resume training."""

    type: ClassVar[str] = "train"


@dataclass(frozen=True, kw_only=True)
class PauseIntent(Intent):
    """Pause training."""

    type: ClassVar[str] = "pause"


@dataclass(frozen=True, kw_only=True)
class UndoIntent(Intent):
    """Take back this view's own latest step (others' steps after it stay), else the last step."""

    type: ClassVar[str] = "undo"


@dataclass(frozen=True, kw_only=True)
class RedoIntent(Intent):
    """Bring back the step last undone (after this view's undo of an older step of its own: that step)."""

    type: ClassVar[str] = "redo"


#: Client -> server intents by their "type", in the order the browser's builders list them.
INTENTS: dict[str, type[Intent]] = {
    i.type: i for i in (GrabIntent, MoveIntent, ReleaseIntent, ResetIntent, TrainIntent, PauseIntent, UndoIntent,
                        RedoIntent, PingIntent, HelloIntent, SetIntent, AddIntent, RemoveIntent, RadiusIntent,
                        StrokeIntent, HandIntent, RevolveIntent)
}


_DECLARED = {kind: declared_fields(cls) for kind, cls in INTENTS.items()}
for _kind, _fields in _DECLARED.items():
    if any(f.wire is None for f in _fields):
        raise TypeError(f"intent {_kind!r}: every field needs a wire type (fields.py), as Annotated[type, WireType]")


def _no_constants(name: str):
    raise ValueError(f"{name} is not allowed")


def parse_intent(message, n_controls: int) -> Intent:
    """Check one client message (str, or bytes for a binary frame) against its declaration; IntentError if refused."""
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
        raise IntentError("expected a JSON object like {\"type\": \"move\", \"id\": 0, \"position\": [0, 0, 0]}")
    kind = data.get("type")
    if not isinstance(kind, str) or kind not in INTENTS:
        shown = json.dumps(kind)[:40] if kind is not None else "missing"
        raise IntentError(f"unknown intent type {shown}; known: {', '.join(INTENTS)}")
    cls, declared = INTENTS[kind], _DECLARED[kind]
    names = {f.name for f in declared}
    given = set(data) - {"type"}
    extra = sorted(given - names)
    if extra:
        allowed = ", ".join(sorted(names)) or "none"
        raise IntentError(f"{kind}: unknown field(s) {', '.join(repr(f[:30]) for f in extra)}; allowed: {allowed}",
                          kind)
    missing = sorted(f.name for f in declared if f.required and f.name not in given)
    if missing:
        raise IntentError(f"{kind}: missing field(s) {', '.join(missing)}", kind)
    if cls.one_of and sum(name in given for name in cls.one_of) != 1:
        raise IntentError(f"{kind}: give {' or '.join(json.dumps(n) for n in cls.one_of)}, one of the two", kind)
    values = {f.name: f.wire_type().check(data[f.name], f.name, kind, n_controls) for f in declared if f.name in given}
    return cls(**values).checked()


__all__ = ["PROTOCOL_VERSION", "MAGIC", "MAX_FPS", "STATUS_PERIOD", "MAX_MESSAGE_BYTES", "MAX_COORDINATE",
           "MAX_STROKE_POINTS", "FLAGS", "HEADER_FORMAT", "HEADER_SIZE", "FrameHeader", "FrameArray", "FRAME_ARRAYS",
           "frame_size", "ServerMessage", "TopologyMessage", "ControlsMessage", "HeldControl", "GrabsMessage",
           "PresentHand", "PresenceMessage", "HandIntent",
           "ErrorMessage", "PongMessage", "StatusMessage", "AutosaveMessage", "FrameMessage", "SERVER_MESSAGES",
           "Intent", "ControlIntent", "INTENTS", "IntentError", "parse_intent", "declared_fields", "settings_schema",
           "check_setting"]
