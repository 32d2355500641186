"""The training schedule, declared once: its parameters (S, l_start, l_end, smoothing, reach) with their bounds,
defaults and help, the `Schedule` that holds one set of them, and the learning table L[s, d] = alpha(s) * theta(d, s)
of the paper's section III that they make.

`Som`, `BatchSom`, the variants, the session files (io.py) and every panel take their checks, defaults and labels
from `SETTINGS`: a new schedule parameter is declared here and implemented in the engine, nothing else.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from collections.abc import Mapping

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


@dataclass(frozen=True)
class Setting:
    """One schedule parameter: what it is called, its bounds and default, and how a panel shows it."""

    name: str  # the keyword of Som, BatchSom and Session.set_parameter
    label: str  # what a panel and an error message call it
    kind: str  # "int" or "float"
    low: float
    high: float
    default: float
    low_open: bool = False  # low itself is refused
    slider: tuple[float, float, float] | None = None  # a panel slider's (min, max, step)
    help: str = ""

    def check(self, value, what: str | None = None):
        """The value as the engine keeps it (an int or a float); ValueError naming `what` (default: the label), the
        value and the bounds."""
        what = self.label if what is None else what
        if self.kind == "int":
            return checks.integer(what, value, int(self.low), int(self.high))
        return checks.real(what, value, self.low, self.high, low_open=self.low_open)

    def parse(self, value, what: str | None = None):
        """`check` for a value that may come as text, as a form field sends it ("600", " 1e3 ")."""
        if self.kind == "int":
            return checks.integer_text(self.label if what is None else what, value, int(self.low), int(self.high))
        return self.check(value, what)

    def describe(self) -> dict:
        """The declaration as JSON (for the views)."""
        d = asdict(self)
        d["slider"] = list(self.slider) if self.slider else None
        return d


SETTINGS: tuple[Setting, ...] = (
    Setting("iterations", "S (iterations)", "int", 1, MAX_ITERATIONS, 1000, slider=(10, 5000, 10),
            help="Cycles in a run: the learning rate and the neighbourhood shrink from l_start to l_end over S "
                 "cycles (the paper's S). More cycles settle the shape more finely, and take longer."),
    Setting("l_start", "l_start", "float", 0.0, 1.0, 0.25, low_open=True, slider=(0.001, 1.0, 0.001),
            help="The learning rate at the first cycle (the paper's l(0)): how far the winner moves toward a "
                 "control at the start of a run."),
    Setting("l_end", "l_end", "float", 0.0, 1.0, 0.03, low_open=True, slider=(0.001, 1.0, 0.001),
            help="The learning rate at the last cycle (the paper's l(S)): how far the winner moves at the end."),
    Setting("smoothing", "smoothing", "float", 0.0, 1.0, 0.0, slider=(0.0, 1.0, 0.01),
            help="One Laplacian step per cycle of this strength pulls each node toward its neighbours' mean "
                 "(0: off). It smooths creases and spikes; too much shrinks the clay."),
    Setting("reach", "reach", "float", 0.0, 1.0, DEFAULT_REACH, low_open=True, slider=(0.01, 1.0, 0.01),
            help="How far a moved control's pull spreads when the clay follows it: small keeps the rest of your "
                 "shape, 1 regrows the whole mesh."),
)
BY_NAME: dict[str, Setting] = {s.name: s for s in SETTINGS}
#: The schedule's parameter names, in declaration order.
KEYS: tuple[str, ...] = tuple(BY_NAME)


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


def sigma_of(d_max: int) -> float:
    """sigma = d_max / sqrt(2 ln 2): theta falls to one half at d_max at the start of a run."""
    return d_max / math.sqrt(2.0 * math.log(2.0))


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
