"""Intents on a session's parameters: a schedule parameter (backend/schedule.py), both learning rates at once,
symmetry, the metric weights. Each is checked in the caller's thread against its declaration (parameters.py),
changes the session's view at once and queues the change for the Som; a schedule change restarts the schedule
locally from the latest weights. Setting the same parameter again within a moment joins its undo step (timeline.py).
"""

from __future__ import annotations

from ...backend import checks
from ...backend.schedule import MAX_ITERATIONS
from ...backend.som import _MAX_TABLE_ENTRIES
from .clay import Clay
from .controls import MAX_ABS_VALUE, check_count
from .operations import SetMetricWeights, SetMirror, SetParameter
from .parameters import BY_NAME, METRIC_WEIGHT, SYMMETRY
from .timeline import Timeline
from .trainer import Trainer

#: The engine's cap on its learning table, S x (d_max + 1) float32 entries (2 GiB): backend/som.py, _build_table.
MAX_TABLE_ENTRIES = _MAX_TABLE_ENTRIES


class ParameterEdits:
    """The parameter intents of one session (see the module's docstring)."""

    def __init__(self, clay: Clay, timeline: Timeline, trainer: Trainer):
        self.clay = clay
        self.timeline = timeline
        self.trainer = trainer

    @property
    def max_iterations(self) -> int:
        d_max = int(self.clay.preset.topology.d_max)  # the Som's own d_max: sessions keep the dense table
        return min(MAX_ITERATIONS, MAX_TABLE_ENTRIES // (d_max + 1))

    def set(self, name: str, value) -> None:
        name = "iterations" if name == "S" else name
        if name == "symmetry":
            return self.set_symmetry(value)
        if name == "metric_weights":
            return self.set_metric_weights(value)
        if name not in BY_NAME:
            raise ValueError(f"unknown parameter {name!r}; known: {', '.join((*BY_NAME, 'metric_weights'))}")
        x = BY_NAME[name].parse(value)
        with self.timeline.step(f"parameter:{name}"), self.clay.lock:
            if name == "iterations" and x > self.max_iterations:
                d_max = int(self.clay.preset.topology.d_max)
                raise ValueError(f"S (iterations): {x} is more than this mesh allows: at most {self.max_iterations}, "
                                 f"since the learning table S x (d_max + 1) = {x} x {d_max + 1} may hold at most "
                                 f"{MAX_TABLE_ENTRIES} entries")
            self.clay.params[name] = x
            self.trainer.enqueue(SetParameter(name, x))

    def set_learning_rates(self, l_start, l_end) -> None:
        a, b = BY_NAME["l_start"].parse(l_start), BY_NAME["l_end"].parse(l_end)
        with self.timeline.step("parameter:rates"), self.clay.lock:
            self.clay.params["l_start"], self.clay.params["l_end"] = a, b
            self.trainer.enqueue(SetParameter("l_start", a))
            self.trainer.enqueue(SetParameter("l_end", b))

    def set_symmetry(self, value) -> None:
        on = SYMMETRY.parse(value)
        clay = self.clay
        with self.timeline.step("parameter:symmetry"), clay.lock:
            check_count(clay.controls, on)
            clay.params["symmetry"] = on
            self.trainer.enqueue(SetMirror(clay.mirror_dims if on else ()))

    def set_metric_weights(self, value) -> None:
        clay = self.clay
        with self.timeline.step("parameter:metric_weights"), clay.lock:
            m = checks.finite_vector("metric_weights", value, clay.layout.n_dims, MAX_ABS_VALUE)
            if (m < 0).any():
                raise ValueError(f"metric_weights: weights must be >= 0, got {m.tolist()}")
            if not (m > 0).any():
                raise ValueError("metric_weights: at least one weight must be positive")
            clay.params["metric_weights"] = [float(x) for x in m]
            self.trainer.enqueue(SetMetricWeights(m))

    def set_metric_weight(self, dim: int, value) -> None:
        clay = self.clay
        with clay.lock:
            d = checks.integer_text("feature dimension", dim, 0, clay.layout.n_dims - 1)
            m = list(clay.params["metric_weights"])
            m[d] = METRIC_WEIGHT.check(value, f"{METRIC_WEIGHT.label} of {clay.layout.names[d]}")
        self.set_metric_weights(m)
