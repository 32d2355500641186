"""somwidget: a self-organizing map as computational clay (after Felbrich et al., IEEE AIVR 2018)."""

from .backend.som import Som
from .backend.topology import Topology

__all__ = ["Som", "Topology"]
