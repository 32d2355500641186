"""The session's parameters as the views show them: the schedule's (declared in backend/schedule.py), symmetry, and
one metric weight per feature dimension. The panel model builds every panel's fields and tooltips from this list,
the Session checks values with it, and the protocol's "set" intent accepts exactly these (their JSON form goes out
in the topology message). No UI imports here.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ...backend.schedule import MAX_ITERATIONS, SETTINGS, Setting


@dataclass(frozen=True)
class Toggle:
    """An on / off parameter."""

    name: str
    label: str
    help: str = ""
    kind: str = "bool"
    low: float = 0.0
    high: float = 1.0
    default: bool = False
    low_open: bool = False
    slider: tuple | None = None

    def check(self, value, what: str | None = None) -> bool:
        """True or False; ValueError for anything else."""
        if not isinstance(value, bool):
            raise ValueError(f"{what or self.label}: expected true or false, got {value!r}")
        return value

    def parse(self, value, what: str | None = None) -> bool:
        """`check`, also taking 0 / 1 and a checkbox's text ("true", "off"...)."""
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        if isinstance(value, (int, np.integer)) and int(value) in (0, 1):
            return bool(value)
        if isinstance(value, str) and value.strip().lower() in ("true", "false", "on", "off", "1", "0"):
            return value.strip().lower() in ("true", "on", "1")
        raise ValueError(f"{what or self.name}: expected true or false, got {value!r}")

    def describe(self) -> dict:
        return asdict(self)


SYMMETRY = Toggle("symmetry", "symmetry (mirror across the xz-plane)",
                  help="Each control gets a mirrored copy across the xz-plane; a control and its copy act as one pair, "
                       "so the shape stays exactly symmetric.")
#: Every parameter a view can set by name, in panel order.
PARAMETERS: tuple[Setting | Toggle, ...] = (*SETTINGS, SYMMETRY)
BY_NAME = {p.name: p for p in PARAMETERS}
#: The metric weights (one per feature dimension) are a vector: this is the declaration of each of them.
METRIC_WEIGHT = Setting("metric_weights", "metric weight", "float", 0.0, 1e6, 1.0,
                        help="How much this feature dimension counts when a control finds its winner (the paper's "
                             "m_j): 0 ignores it, larger makes it matter more than the others.")
#: The line every panel shows under its reach slider.
REACH_HELP = BY_NAME["reach"].help
#: What a panel shows beside each control's radius.
RADIUS_HELP = ("The control's radius of influence (model units): moving it carries the clay around its nearest node "
               "with a smooth falloff of about this radius. 0 is the paper's point control, which draws the clay to "
               "a point.")
#: What a panel shows beside the gaps of the controls table.
GAP_HELP = ("The distance from each control (and its mirrored copy) to its nearest node: small when the clay has "
            "reached the control.")

__all__ = ["MAX_ITERATIONS", "PARAMETERS", "BY_NAME", "METRIC_WEIGHT", "SYMMETRY", "REACH_HELP", "GAP_HELP",
           "RADIUS_HELP", "Toggle"]
