"""The modelling session and its parts: no UI package, no network."""

from .session import Frame, Session

__all__ = ["Frame", "Session"]
