"""The modelling session and its parts (no UI package, no network): the Session and the clay it shares with its
training thread, frames, undo history, autosave and files."""

from .frames import Frame
from .session import Session

__all__ = ["Frame", "Session"]
