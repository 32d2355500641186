"""Views of a modelling session: the shared Session (no UI imports) and, imported on demand, the trame web app
(`somwidget.frontend.app`, `somwidget serve`), the notebook's panel and clay widget (`notebook`, `widget`) and the
browser client they all draw with (`xr/`: the clay view and the WebXR page), fed by one protocol (`protocol`)."""

from .session import Frame, Session

__all__ = ["Frame", "Session"]
