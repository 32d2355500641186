"""The session's parameters, declared once: name, label, bounds, slider range, help text.

The Session checks values with them (`check`), the web app's and the notebook's panels build their fields and
tooltips from them, and the protocol's "set" intent accepts exactly these (their JSON form goes out in the topology
message). No UI imports here.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from ...backend import checks

#: Bounds the session puts on S coming from a view (the engine has its own, wider checks).
MAX_ITERATIONS = 1_000_000


@dataclass(frozen=True)
class Parameter:
    name: str  # the Session's name for it (`session.set_parameter(name, value)`)
    label: str  # what a panel shows
    kind: str  # "int", "float" or "bool"
    low: float = 0.0
    high: float = 1.0
    low_open: bool = False  # low itself is refused
    slider: tuple[float, float, float] | None = None  # a panel slider's (min, max, step) where it has one
    help: str = ""

    def check(self, value):
        """The value as the session keeps it; ValueError naming the parameter, the value and the bounds."""
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise ValueError(f"{self.label}: expected true or false, got {value!r}")
            return value
        if self.kind == "int":
            return checks.integer_text(self.label, value, int(self.low), int(self.high))
        return checks.real(self.label, value, self.low, self.high, low_open=self.low_open)

    def describe(self) -> dict:
        """The declaration as JSON (the topology message's "parameters")."""
        d = asdict(self)
        d["slider"] = list(self.slider) if self.slider else None
        return d


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("iterations", "S (iterations)", "int", 1, MAX_ITERATIONS, slider=(10, 5000, 10),
              help="Cycles in a run: the learning rate and the neighbourhood shrink from l_start to l_end over S "
                   "cycles (the paper's S). More cycles settle the shape more finely, and take longer."),
    Parameter("l_start", "l_start", "float", 0.0, 1.0, low_open=True, slider=(0.001, 1.0, 0.001),
              help="The learning rate at the first cycle (the paper's l(0)): how far the winner moves toward a "
                   "control at the start of a run."),
    Parameter("l_end", "l_end", "float", 0.0, 1.0, low_open=True, slider=(0.001, 1.0, 0.001),
              help="The learning rate at the last cycle (the paper's l(S)): how far the winner moves at the end."),
    Parameter("smoothing", "smoothing", "float", 0.0, 1.0, slider=(0.0, 1.0, 0.01),
              help="One Laplacian step per cycle of this strength pulls each node toward its neighbours' mean "
                   "(0: off). It smooths creases and spikes; too much shrinks the clay."),
    Parameter("reach", "reach", "float", 0.0, 1.0, low_open=True, slider=(0.01, 1.0, 0.01),
              help="How far a moved control's pull spreads when the clay follows it: small keeps the rest of your "
                   "shape, 1 regrows the whole mesh."),
    Parameter("symmetry", "symmetry (mirror across the xz-plane)", "bool",
              help="Each control gets a mirrored copy across the xz-plane; a control and its copy act as one pair, "
                   "so the shape stays exactly symmetric."),
)
BY_NAME = {p.name: p for p in PARAMETERS}
#: The metric weights (one per feature dimension) are a vector: this is the declaration of each of them.
METRIC_WEIGHT = Parameter("metric_weights", "metric weight", "float", 0.0, 1e6, slider=None,
                          help="How much this feature dimension counts when a control finds its winner (the "
                               "paper's m_j): 0 ignores it, larger makes it matter more than the others.")
#: What a panel shows beside the gaps of the controls table.
GAP_HELP = ("The distance from each control (and its mirrored copy) to its nearest node: small when the clay has "
            "reached the control.")
