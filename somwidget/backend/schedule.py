"""Every setting a person or a view can set, declared once; the training schedule they make: the `Schedule` that
holds one set of its settings, and the learning table L[s, d] = alpha(s) * theta(d, s) of the paper's section III.

`SETTINGS` declares each setting: its name, type, bounds, default, help, the panel section it shows in and how.
From it are built the session's settings (frontend/model/settings.py: values, checks, the "set" intent and what
the topology message declares to the views), both panels (web/layout.py, notebook/panel.py), session files
(session_file.py: one member per setting, the default for a member an older file lacks) and the autosave's
manifests (frontend/model/store.py: likewise). A new setting is one line here plus its use in the engine (a
keyword and attribute of `Som` and a field of `Preset` of its name, for a setting of scope "engine": `BatchSom`
takes each of KEYS as it comes).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from . import checks

#: How a smoothing step is taken: the paper's Laplacian step, or Taubin's pair (lambda, then mu: keeps the volume).
SMOOTHING_RULES = ("laplacian", "taubin")

#: The largest S (iterations) anything accepts: a view, a session file, a sweep or the engine.
MAX_ITERATIONS = 1_000_000
#: The neighbourhood radius a restart begins with, as a share of the full radius sigma (som.py, Restarts). Chosen
#: by measurement on the car (BENCHMARKS.md, "Local restarts"): a control moved by 5% of the size is followed to
#: within 1% while the far half of the mesh stays within 2% and nothing collapses, with the least spike at the moved
#: control among the values that do (a smaller reach pulls a narrower, pointier bump; a larger one wears down the
#: neighbourhoods of the other controls).
DEFAULT_REACH = 0.08
#: The largest radius of influence of a control, in model units.
MAX_RADIUS = 1e6

_TRUE, _FALSE = ("true", "on", "1"), ("false", "off", "0")


@dataclass(frozen=True)
class Setting:
    """One setting: what it is called, its type, bounds and default, and how a panel shows it.

    kind: "int", "float", "bool", or "text" (a symmetry group's spec). per: "" (one value), "dim" (one per feature
    dimension) or "control" (one per control). scope: "engine" (a keyword and attribute of Som of this name; a
    change restarts the schedule locally) or "session" (the session's own: the engine never sees it). saved: files
    keep it as a member of its name (False: it follows from what they keep, as the symmetry switch follows the
    group). widget: "field" (a number field; a slider in the notebook), "slider", "switch", "choice" or "table".
    vary: a sweep's range around a value v, (lo, hi, floor, least): max(floor, lo v) to min(high, max(least, hi v)).
    """

    name: str  # the keyword of Som, BatchSom and Session.set_parameter
    label: str  # what a panel and an error message call it
    kind: str
    low: float = 0.0
    high: float = 1.0
    default: Any = 0.0  # a number, a flag or a text, as `kind` says
    low_open: bool = False  # low itself is refused
    slider: tuple[float, float, float] | None = None  # a panel slider's (min, max, step)
    help: str = ""
    section: str = "schedule"  # the panel section it shows in (SECTIONS)
    widget: str = "field"
    short: str = ""  # a narrow panel's label (default: the label)
    per: str = ""
    scope: str = "engine"
    saved: bool = True
    vary: tuple[float, float, float, float] | None = None

    @property
    def by_name(self) -> bool:
        """Set by its name alone (Session.set_parameter, the "set" intent): one number or flag."""
        return not self.per and self.kind != "text"

    def check(self, value, what: str | None = None):
        """The value as the engine keeps it (an int, a float, a bool); ValueError naming `what` (default: the
        label), the value and the bounds."""
        what = self.label if what is None else what
        if self.kind == "bool":
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"{what}: expected true or false, got {value!r}")
            return bool(value)
        if self.kind == "text":
            if not isinstance(value, str):
                raise ValueError(f"{what}: expected a text, got {value!r}")
            return value
        if self.kind == "int":
            return checks.integer(what, value, int(self.low), int(self.high))
        return checks.real(what, value, self.low, self.high, low_open=self.low_open)

    def parse(self, value, what: str | None = None):
        """`check` for a value that may come as a form field sends it ("600", " 1e3 ", a checkbox's "on")."""
        what = self.label if what is None else what
        if self.kind == "int":
            return checks.integer_text(what, value, int(self.low), int(self.high))
        if self.kind == "bool":
            if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)) and value in (0, 1):
                return bool(value)
            if isinstance(value, str) and value.strip().lower() in (*_TRUE, *_FALSE):
                return value.strip().lower() in _TRUE
        return self.check(value, what)

    def slider_range(self) -> tuple[float, float, float]:
        """Its panel slider's (min, max, step); ValueError for a setting declared without one."""
        if self.slider is None:
            raise ValueError(f"{self.name}: declared without a slider, and a panel shows it as one")
        return self.slider

    def range_around(self, value) -> tuple:
        """A sweep's (low, high) around `value` (`vary`)."""
        lo, hi, floor, least = self.vary or (1.0, 1.0, self.low, self.low)
        a, b = max(floor, lo * value), min(self.high, max(least, hi * value))
        return (max(1, int(a)), int(b)) if self.kind == "int" else (a, b)

    def describe(self) -> dict:
        """The declaration as JSON (for the views)."""
        d = asdict(self)
        d["slider"] = list(self.slider) if self.slider else None
        d["vary"] = list(self.vary) if self.vary else None
        return d


#: The panel sections settings show in: (title, what it is about: a note under or beside the title).
SECTIONS: dict[str, tuple[str, str]] = {
    "schedule": ("Schedule", "alpha(s) from l_start to l_end over S cycles"),
    "symmetry": ("Symmetry", "every copy of a control acts together with it"),
    "features": ("Feature dimensions (metric weights)", "the m_j of the winner search"),
    "controls": ("Controls", "each control's radius of influence"),
}

SETTINGS: tuple[Setting, ...] = (
    Setting("iterations", "S (iterations)", "int", 1, MAX_ITERATIONS, 1000, slider=(10, 5000, 10), short="S",
            vary=(0.5, 1.5, 1, 1),
            help="Cycles in a run: the learning rate and the neighbourhood shrink from l_start to l_end over S "
                 "cycles (the paper's S). More cycles settle the shape more finely, and take longer."),
    Setting("l_start", "l_start", "float", 0.0, 1.0, 0.25, low_open=True, slider=(0.001, 1.0, 0.001),
            vary=(0.7, 1.3, 0.01, 0.0),
            help="The learning rate at the first cycle (the paper's l(0)): how far the winner moves toward a "
                 "control at the start of a run."),
    Setting("l_end", "l_end", "float", 0.0, 1.0, 0.03, low_open=True, slider=(0.001, 1.0, 0.001),
            vary=(0.7, 1.3, 0.005, 0.0),
            help="The learning rate at the last cycle (the paper's l(S)): how far the winner moves at the end."),
    Setting("smoothing", "smoothing", "float", 0.0, 1.0, 0.0, slider=(0.0, 1.0, 0.01), vary=(0.0, 2.0, 0.0, 0.05),
            help="One Laplacian step per cycle of this strength pulls each node toward its neighbours' mean "
                 "(0: off). It smooths creases and spikes; too much shrinks the clay."),
    Setting("reach", "reach", "float", 0.0, 1.0, DEFAULT_REACH, low_open=True, slider=(0.01, 1.0, 0.01),
            widget="slider", vary=(0.5, 2.0, 0.01, 0.0),
            help="How far a moved control's pull spreads when the clay follows it: small keeps the rest of your "
                 "shape, 1 regrows the whole mesh."),
    Setting("symmetry", "symmetry (mirror across the xz-plane)", "bool", default=False, section="symmetry",
            widget="switch", short="symmetry", scope="session", saved=False,
            help="Each control gets a mirrored copy across the xz-plane; a control and its copy act as one pair, "
                 "so the shape stays exactly symmetric."),
    Setting("group", "group", "text", default="none", section="symmetry", widget="choice", scope="session",
            saved=False,
            help="The symmetry group: every copy of a control acts together with it. Off, the copies become "
                 "controls of their own and nothing moves; on, images pair up again."),
    Setting("metric_weights", "metric weight", "float", 0.0, 1e6, 1.0, section="features", widget="table",
            per="dim",
            help="How much this feature dimension counts when a control finds its winner (the paper's m_j): 0 "
                 "ignores it, larger makes it matter more than the others."),
    Setting("radius", "radius", "float", 0.0, MAX_RADIUS, 0.0, section="controls", widget="table", per="control",
            help="The control's radius of influence (model units): moving it carries the clay around its nearest "
                 "node with a smooth falloff of about this radius. 0 is the paper's point control, which draws the "
                 "clay to a point."),
)
BY_NAME: dict[str, Setting] = {s.name: s for s in SETTINGS}
#: The engine's schedule: the settings of one value that Som, BatchSom and Preset take by name, in declaration order.
KEYS: tuple[str, ...] = tuple(s.name for s in SETTINGS if s.scope == "engine" and not s.per)
#: The settings the learning table is made of (`learning_table`'s keywords): S and the learning rates.
TABLE_KEYS: tuple[str, ...] = ("iterations", "l_start", "l_end")


@dataclass(frozen=True)
class Schedule:
    """One schedule: S, l_start, l_end, smoothing and reach, each checked against its Setting when made."""

    iterations: int = BY_NAME["iterations"].default
    l_start: float = BY_NAME["l_start"].default
    l_end: float = BY_NAME["l_end"].default
    smoothing: float = BY_NAME["smoothing"].default
    reach: float = BY_NAME["reach"].default

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, BY_NAME[f.name].check(getattr(self, f.name), f.name))

    @classmethod
    def of(cls, values: Mapping | object, **changes) -> Schedule:
        """The schedule of a mapping or an object with these attributes (a Som, a Preset), with `changes`."""
        get = values.get if isinstance(values, Mapping) else lambda k, d=None: getattr(values, k, d)
        base = {k: get(k, BY_NAME[k].default) for k in KEYS}
        return cls(**{**base, **changes})

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in KEYS}

    def learning_table(self, d_max: int, cut: float = 0.0) -> np.ndarray:
        """This schedule's L[s, d] for hop distances up to d_max (`learning_table`)."""
        return learning_table(d_max=d_max, cut=cut, **{k: getattr(self, k) for k in TABLE_KEYS})


def sigma_of(d_max: int) -> float:
    """sigma = d_max / sqrt(2 ln 2): theta falls to one half at d_max at the start of a run."""
    return d_max / math.sqrt(2.0 * math.log(2.0))


#: A point control moved across h edges restarts with a neighbourhood c(s0) = reach * sigma of at least MOVE_SPAN * h
#: hops, up to a reach of MOVE_REACH_MOST (`reach_for_move`). Measured on the car (BENCHMARKS.md, "A long move of a
#: point control"): at the default reach, moves of 0.3 to 1.2 units (1.4 to 5.5 median edges) ended with the moved
#: control's winner drawn out to a needle (spike figure 0.38 to 1.30) and up to 0.096 short of it; with these two the
#: spike stayed at most 0.48 (mean 0.27, the trained car's own 0.26), the gap 0.031 and the far half within 2.6% of
#: the size. A wider restart draws the whole car in for a moment, every control's patch with it (its bounding
#: diagonal fell to 0.945 of its size at a reach of 0.18, 0.91 at 0.2, 0.86 at 0.22), and past about a quarter of
#: the schedule regrows it (the far half moved 6-7% at 0.26 to 0.39).
MOVE_SPAN = 1.5
MOVE_REACH_MOST = 0.18


def reach_for_move(reach: float, hops: float, d_max: int) -> float:
    """The reach a local restart takes after a point control moved across `hops` edges (its distance moved over the
    clay's median edge length): `reach`, or wider where the neighbourhood it begins with spans less than MOVE_SPAN
    times the move (up to MOVE_REACH_MOST), so the clay around the control follows it rather than one node drawn out
    to a needle."""
    sigma = sigma_of(d_max)
    if not sigma or not math.isfinite(hops) or hops <= 0:
        return reach
    return max(reach, min(MOVE_REACH_MOST, MOVE_SPAN * hops / sigma))


#: Entries of the table computed at once in float64 (8 MiB a temporary).
TABLE_BLOCK = 1 << 20
#: Past the dense table the neighbourhood is cut where theta(d, s) < NEIGHBOURHOOD_CUT = 2^-24 (half of float32's
#: epsilon): such a rate moves a node by less than 2^-24 of its distance from the control, below the rounding of a
#: coordinate of the control's magnitude. A restart at s0 then touches only the nodes within `reach_hops(table)[s0]`
#: hops of the winners (the CPU's cycle skips the rest: local_path.py); the dense table keeps the paper's exact tail.
NEIGHBOURHOOD_CUT = 2.0**-24


def learning_table(iterations: int, d_max: int, l_start: float = 0.25, l_end: float = 0.03,
                   cut: float = 0.0) -> np.ndarray:
    """(S, d_max + 1) float32 table, computed in float64.

    alpha(s) = l_start * l_end / (l_end + (l_start - l_end) * s / S)        (learning rate)
    c(s) = sigma - sigma * s / S;  theta(d, s) = exp(-d^2 / (2 c(s)^2))     (neighbourhood)
    theta(0, s) = 1 always (also for d_max = 0, where c is 0); theta < cut is taken as 0 (NEIGHBOURHOOD_CUT).
    """
    S = BY_NAME["iterations"].check(iterations, "iterations")
    d_max = checks.integer("d_max", d_max, 0, 2**31 - 2)
    l_start = BY_NAME["l_start"].check(l_start, "l_start")
    l_end = BY_NAME["l_end"].check(l_end, "l_end")
    out = np.empty((S, d_max + 1), np.float32)
    d = np.arange(d_max + 1, dtype=np.float64)[None, :]
    sigma = sigma_of(d_max)
    rows = max(1, TABLE_BLOCK // (d_max + 1))  # float64 temporaries of a block, not of the whole table
    for start in range(0, S, rows):
        s = np.arange(start, min(S, start + rows), dtype=np.float64)[:, None]
        alpha = l_start * l_end / (l_end + (l_start - l_end) * s / S)
        c = sigma - sigma * s / S
        with np.errstate(divide="ignore", invalid="ignore"):
            theta = np.exp(-(d**2) / (2.0 * c**2))
        theta[:, 0] = 1.0
        theta = np.where(np.isfinite(theta) & (theta >= cut), theta, 0.0)
        out[start:start + len(s)] = alpha * theta
    return out


def reach_hops(table: np.ndarray) -> np.ndarray:
    """(S,) int32: the farthest hop count with a non-zero rate at each cycle s (theta falls with d, so the non-zero
    rates of a row are its first reach_hops[s] + 1; c(s) narrows, so it never grows with s). Counted a block of rows
    at a time: no temporary of the table's size."""
    out = np.empty(len(table), np.int32)
    rows = max(1, TABLE_BLOCK // max(1, table.shape[1]))
    for start in range(0, len(table), rows):
        out[start:start + rows] = (table[start:start + rows] > 0).sum(axis=1) - 1
    return out
