"""Views of a modelling session: the shared Session (no UI imports) and, imported on demand, the trame web app
(`somwidget.frontend.app`, `somwidget serve`) and its pyvista scene (`somwidget.frontend.view`)."""

from .session import Frame, Session

__all__ = ["Frame", "Session"]
