"""somwidget: a self-organizing map as computational clay (after Felbrich et al., IEEE AIVR 2018).

Compute lives in somwidget.backend (numpy + warp only); the views in somwidget.frontend.
"""

from .backend import presets
from .backend.som import Som
from .backend.topology import Topology

__all__ = ["Som", "Topology", "presets"]
