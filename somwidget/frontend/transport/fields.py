"""The wire field types of the intents (messages.py): what a JSON value must be to pass, and the message that says why
it did not; `declared_fields` reads a message class's fields with their wire types. A field declares its type as
`Annotated[python type, WireType]`; `parse_intent` calls each field's `check`, and the code generator reads `js` for the
browser's JSDoc.
"""

from __future__ import annotations

import dataclasses
import json
import math
import typing
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Annotated

#: Largest |coordinate| a position may carry (model units; the presets span a few units, meshes are normalised).
MAX_COORDINATE = 1e4
#: Most points a stroke intent carries (the session samples the line again, MAX_STROKE_SAMPLES at most).
MAX_STROKE_POINTS = 64
#: Control ids are below this (a u31: what a JavaScript number and a JSON integer both hold exactly).
MAX_CONTROL_ID = 2**31


class IntentError(ValueError):
    """A refused client message; `intent` is its type when that much was readable."""

    def __init__(self, message: str, intent: str | None = None) -> None:
        super().__init__(message)
        self.intent = intent


def _shown(value, limit: int = 40) -> str:
    return json.dumps(value)[:limit]


def finite(value, name: str, kind: str) -> float:
    """A finite JSON number (not true / false) as a float; IntentError naming the intent and the field."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise IntentError(f"{kind}: {name} must be a number, got {_shown(value)}", kind)
    try:
        x = float(value)
    except OverflowError:
        raise IntentError(f"{kind}: {name} is too large", kind) from None
    if not math.isfinite(x):
        raise IntentError(f"{kind}: {name} must be finite", kind)
    return x


class WireType:
    """A field's type on the wire: `check(value, name, kind, n_controls)` returns the value as Python uses it or
    raises IntentError naming the intent, the field and what was expected."""

    js = "*"

    def check(self, value, name: str, kind: str, n_controls: int):
        raise NotImplementedError


@dataclass(frozen=True)
class Number(WireType):
    """A finite JSON number (not true / false), within [low, high] where given."""

    low: float | None = None
    high: float | None = None
    js = "number"

    def check(self, value, name: str, kind: str, n_controls: int = 0) -> float:
        x = finite(value, name, kind)
        if (self.low is not None and x < self.low) or (self.high is not None and x > self.high):
            raise IntentError(f"{kind}: {name} {x:g} is out of bounds ({self.low:g} <= {name} <= {self.high:g})",
                              kind)
        return x


@dataclass(frozen=True)
class Identifier(WireType):
    """A control's stable id: an integer in [0, MAX_CONTROL_ID)."""

    js = "number"

    def check(self, value, name: str, kind: str, n_controls: int = 0) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < MAX_CONTROL_ID:
            raise IntentError(f"{kind}: {name} must be a control's id (an integer >= 0), got {_shown(value)}", kind)
        return value


@dataclass(frozen=True)
class Place(WireType):
    """A control's index now: an integer in [0, n_controls)."""

    js = "number"

    def check(self, value, name: str, kind: str, n_controls: int = 0) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise IntentError(f"{kind}: {name} must be an integer, got {_shown(value)}", kind)
        if not 0 <= value < n_controls:
            raise IntentError(f"{kind}: control index {value} is out of range (there are {n_controls} controls: "
                              f"0..{n_controls - 1})", kind)
        return value


@dataclass(frozen=True)
class Coordinates(WireType):
    """A point [x, y, z]: three finite numbers within +-MAX_COORDINATE (model units)."""

    js = "number[]"

    def check(self, value, name: str, kind: str, n_controls: int = 0) -> tuple[float, float, float]:
        if not isinstance(value, list) or len(value) != 3:
            raise IntentError(f"{kind}: {name} must be a list of 3 numbers, got {_shown(value, 60)}", kind)
        xyz = (finite(value[0], name, kind), finite(value[1], name, kind), finite(value[2], name, kind))
        if max(abs(v) for v in xyz) > MAX_COORDINATE:
            raise IntentError(f"{kind}: {name} {list(xyz)} is out of bounds (|coordinate| <= {MAX_COORDINATE:g})",
                              kind)
        return xyz


@dataclass(frozen=True)
class Points(WireType):
    """A list of `least` to `most` points [x, y, z] (each as `Coordinates`)."""

    least: int
    most: int
    js = "number[][]"

    def check(self, value, name: str, kind: str, n_controls: int = 0) -> tuple[tuple[float, float, float], ...]:
        if not isinstance(value, list) or not self.least <= len(value) <= self.most:
            raise IntentError(f"{kind}: {name} must be a list of {self.least} to {self.most} points [x, y, z], got "
                              f"{_shown(value, 60)}", kind)
        point = Coordinates()
        return tuple(point.check(p, name, kind) for p in value)


@dataclass(frozen=True)
class OneOf(WireType):
    """A string among `choices()` (called at each check: the list may grow); `what` names one in messages."""

    choices: Callable[[], Iterable[str]]
    what: str
    js = "string"

    def check(self, value, name: str, kind: str, n_controls: int = 0) -> str:
        known = tuple(self.choices())
        if not isinstance(value, str) or value not in known:
            raise IntentError(f"{kind}: unknown {self.what} {_shown(value)}; known: {', '.join(known)}", kind)
        return value


@dataclass(frozen=True)
class Words(WireType):
    """A short line of printable text (a person's name): 1 to `most` characters once its runs of spaces are one."""

    most: int
    js = "string"

    def check(self, value, name: str, kind: str, n_controls: int = 0) -> str:
        text = " ".join(value.split()) if isinstance(value, str) else ""
        if not text or len(text) > self.most or not text.isprintable():
            raise IntentError(f"{kind}: {name} must be 1 to {self.most} printable characters, got {_shown(value, 60)}",
                              kind)
        return text


@dataclass(frozen=True)
class Scalar(WireType):
    """A number or true / false, as it came: the intent checks it against what it names (`Intent.checked`)."""

    js = "number|boolean"

    def check(self, value, name: str, kind: str, n_controls: int = 0):
        return value


#: The field types the intents use.
ControlId = Annotated[int, Identifier()]
ControlIndex = Annotated[int, Place()]
Point = Annotated[tuple[float, float, float], Coordinates()]
Polyline = Annotated[tuple[tuple[float, float, float], ...], Points(2, MAX_STROKE_POINTS)]
Radius = Annotated[float, Number(0.0, MAX_COORDINATE)]
Value = Annotated[float | bool, Scalar()]
#: Longest name a person gives themselves (shown to the others and on a studio's wall).
MAX_PERSON_NAME = 40
PersonName = Annotated[str, Words(MAX_PERSON_NAME)]


@dataclass(frozen=True)
class Declared:
    """One field of a message as declared: its name, Python type, wire type (intents), and whether it is required."""

    name: str
    hint: object
    wire: WireType | None
    required: bool
    browser: bool

    def wire_type(self) -> WireType:
        """The field's wire type (every intent's field has one: checked as this module loads)."""
        if self.wire is None:
            raise TypeError(f"{self.name}: no wire type (declare it as Annotated[type, WireType], fields.py)")
        return self.wire


def declared_fields(cls) -> tuple[Declared, ...]:
    """The fields of a message class with their types resolved (what validation and the code generator read)."""
    hints = typing.get_type_hints(cls, include_extras=True)
    out = []
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        out.append(Declared(f.name, hint, _wire_type(hint), f.default is dataclasses.MISSING
                            and f.default_factory is dataclasses.MISSING, f.metadata.get("browser", True)))
    return tuple(out)


def _wire_type(hint) -> WireType | None:
    """The WireType in an Annotated hint (also inside `X | None`)."""
    for arg in (hint, *typing.get_args(hint)):
        for meta in getattr(arg, "__metadata__", ()):
            if isinstance(meta, WireType):
                return meta
    return None
