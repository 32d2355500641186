"""Who holds which control of a session, for the views that share one registry (connection.py's `ViewConnection`s).

Controls are held by their stable id (`Session.control_ids`), not by their place: a control removed elsewhere
cannot turn a drag into a drag of another control. A grab begins a gesture (one undo step) and its release ends it;
a control is held by one view at a time; a view that goes away mid-grab ends its gestures; a held control that
disappears ends its grab, and its holder is told (`prune`). Every view of the registry is sent a `GrabsMessage`
whenever who holds what changes.

A view here is anything with `send(ServerMessage)` (a ViewConnection). The web hub keeps one registry for all its
websocket clients, each notebook widget one of its own.
"""

from __future__ import annotations

import threading
from typing import Protocol

from .messages import ErrorMessage, GrabsMessage, HeldControl, ServerMessage


class View(Protocol):
    def send(self, message: ServerMessage) -> None: ...


class HolderRegistry:
    """The grabs of the views of one Session (see the module's docstring)."""

    def __init__(self, session):
        self.session = session
        self._lock = threading.Lock()
        self._views: list[View] = []
        self._holders: dict[int, View] = {}  # control id -> the view holding it

    # -- views ----------------------------------------------------------------------------------------------------
    def join(self, view: View) -> None:
        with self._lock:
            self._views.append(view)

    def leave(self, view: View) -> None:
        """`view` went away: its grabs end, each drag a completed step."""
        with self._lock:
            if view in self._views:
                self._views.remove(view)
            released = [cid for cid, who in self._holders.items() if who is view]
            for cid in released:
                del self._holders[cid]
        if released:
            self._changed()
            self.session.end_gesture()

    # -- grabs ----------------------------------------------------------------------------------------------------
    def grab(self, view: View, control_id: int) -> None:
        """`view` holds the control; ValueError while another view holds it."""
        with self._lock:
            holder = self._holders.get(control_id)
            if holder is not None and holder is not view:
                raise ValueError(f"grab: control {control_id} is held by another client")
            self._holders[control_id] = view
        if holder is None:
            self.session.begin_gesture()  # grab to release: one undo step
        self._changed()

    def check(self, view: View, control_id: int, kind: str) -> None:
        """ValueError unless `view` holds the control (a move or a release)."""
        if self._holders.get(control_id) is not view:
            raise ValueError(f"{kind}: control {control_id} is not held by this client; send grab first")

    def release(self, view: View, control_id: int) -> None:
        with self._lock:
            if self._holders.get(control_id) is not view:
                return
            del self._holders[control_id]
        self._changed()
        self.session.end_gesture()

    def prune(self, control_ids) -> None:
        """Grabs of controls that are gone (removed, or the controls replaced) end; each holder is told."""
        present = set(control_ids)
        with self._lock:
            gone = [(cid, who) for cid, who in self._holders.items() if cid not in present]
            for cid, _ in gone:
                del self._holders[cid]
        if not gone:
            return
        self._changed()
        self.session.end_gesture()
        for cid, who in gone:
            who.send(ErrorMessage(message=f"control {cid} was removed while you held it: the drag ended",
                                  intent="grab"))

    # -- what views are told ------------------------------------------------------------------------------------
    def held(self) -> dict[int, View]:
        """Control index (now) -> the view holding it."""
        ids = self.session.control_ids
        with self._lock:
            return {ids.index(cid): who for cid, who in self._holders.items() if cid in ids}

    def message_for(self, view: View) -> GrabsMessage:
        """The controls held now as `view` sees them (own: held by it), with each control's index now."""
        ids = self.session.control_ids
        with self._lock:
            holders = sorted(self._holders.items(), key=lambda item: item[0])
        return GrabsMessage(grabs=[HeldControl(index=ids.index(cid), id=cid, own=who is view)
                                   for cid, who in holders if cid in ids])

    def _changed(self) -> None:
        with self._lock:
            views = list(self._views)
        for view in views:
            view.send(self.message_for(view))
