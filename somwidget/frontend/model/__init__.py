"""The modelling session and its parts (no UI package, no network): the Session and the modelling state it shares
with its training thread, its settings, controls, frames, undo history, autosave and files."""

from .frames import Frame
from .session import Session

__all__ = ["Frame", "Session"]
