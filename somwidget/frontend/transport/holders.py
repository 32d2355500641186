"""Who is on a session and who holds which control, for its views: one `HolderRegistry` per session (`holders_for`),
shared by every view of it (the web hub's websocket clients, each notebook widget: connection.py's
`ViewConnection`s) and built on the session's hands (model/hands.py), which Python shares too.

Each view is a hand of its own. Every view is sent who is there (a `PresenceMessage`) and who holds what (a
`GrabsMessage`) whenever that changes, from whichever thread changed it (a view's pipe takes messages from any
thread). A view whose grab ended without its release (the control removed, the view silent for SILENT_SECONDS) is
told why. While the session has views, a watcher thread lets go of the grabs of silent hands once a second.
"""

from __future__ import annotations

import threading
import weakref
from typing import Protocol

from ..model.hands import SILENT_SECONDS, Hand, Hands, Lost
from .messages import ErrorMessage, GrabsMessage, HeldControl, PresenceMessage, PresentHand, ServerMessage

#: Seconds between two looks for silent hands.
WATCH_PERIOD = 1.0


class View(Protocol):
    def send(self, message: ServerMessage) -> None: ...


_REGISTRIES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_REGISTRIES_LOCK = threading.Lock()


def holders_for(session) -> HolderRegistry:
    """The session's one registry of holders (made with its first view)."""
    with _REGISTRIES_LOCK:
        registry = _REGISTRIES.get(session)
        if registry is None:
            registry = _REGISTRIES[session] = HolderRegistry(session)
        return registry


class HolderRegistry:
    """The views of one Session and their hands (see the module's docstring)."""

    def __init__(self, session) -> None:
        # The registry above is keyed by the session: no strong way back to it, not even through its hands (they
        # reach the session through its timeline), else a closed session and its arrays would live on forever.
        self._session = weakref.ref(session)
        self._hands = weakref.ref(session.hands)
        self._lock = threading.Lock()
        self._views: dict[View, Hand] = {}
        self._watcher: threading.Thread | None = None
        self.hands.subscribe(self._changed)

    @property
    def hands(self) -> Hands:
        """The session's hands (model/hands.py); RuntimeError once the session is gone."""
        hands = self._hands()
        if hands is None:
            raise RuntimeError("the session of these views is gone")
        return hands

    # -- views ----------------------------------------------------------------------------------------------------
    def join(self, view: View, kind: str) -> Hand:
        """A view came: its hand (the other views are told; it is told when it opens: `tell`)."""
        hand = self.hands.join(kind)
        with self._lock:
            self._views[view] = hand
        self._watch()
        return hand

    def leave(self, view: View) -> Hand | None:
        """A view went: it is sent nothing more. Its hand is returned for the caller to let go (`Hands.leave`, which
        may wait for the trainer: a server posts it)."""
        with self._lock:
            return self._views.pop(view, None)

    def hand_of(self, view: View) -> Hand | None:
        with self._lock:
            return self._views.get(view)

    def set_kind(self, view: View, kind: str, person: str | None = None) -> None:
        hand = self.hand_of(view)
        if hand is not None:
            self.hands.set_kind(hand, kind, person)

    # -- what views are told ------------------------------------------------------------------------------------
    def held(self) -> dict[int, View | None]:
        """Control index (now) -> the view holding it (None: Python)."""
        ids = self._ids()
        with self._lock:
            views = {hand: view for view, hand in self._views.items()}
        return {ids.index(cid): views.get(hand) for cid, hand in self.hands.held().items() if cid in ids}

    def message_for(self, view: View) -> GrabsMessage:
        """The controls held now as `view` sees them (own: held by it), with each control's index now."""
        ids = self._ids()
        mine = self.hand_of(view)
        return GrabsMessage(grabs=[HeldControl(index=ids.index(cid), id=cid, own=hand is mine, hand=hand.id,
                                               holder=hand.name, colour=hand.colour)
                                   for cid, hand in sorted(self.hands.held().items()) if cid in ids])

    def presence_for(self, view: View) -> PresenceMessage:
        """Who is on the session, as `view` sees it (you: itself)."""
        mine = self.hand_of(view)
        return PresenceMessage(hands=[PresentHand(id=h.id, kind=h.kind, name=h.name, colour=h.colour,
                                                  holds=list(holds), you=h is mine)
                                      for h, holds in self.hands.present()])

    def tell(self, view: View) -> None:
        """Send `view` who holds what and who is there."""
        view.send(self.message_for(view))
        view.send(self.presence_for(view))

    def _ids(self) -> tuple:
        session = self._session()
        return session.control_ids if session is not None else ()

    def _changed(self, lost: list[Lost]) -> None:
        """The hands changed (any thread): every view is told; a view that lost a grab is told why."""
        with self._lock:
            views = dict(self._views)
        for view in views:
            self.tell(view)
        for gone in lost:
            for view, hand in views.items():
                if hand is gone.hand:
                    view.send(ErrorMessage(message=gone.why, intent="grab"))

    # -- silent hands ---------------------------------------------------------------------------------------------
    def _watch(self) -> None:
        """Start the watcher unless it runs."""
        with self._lock:
            if self._watcher is not None and self._watcher.is_alive():
                return
            self._watcher = threading.Thread(target=self._watch_loop, name="somwidget-holders", daemon=True)
            self._watcher.start()

    def _watch_loop(self) -> None:
        stop = threading.Event()
        while not stop.wait(WATCH_PERIOD):
            session = self._session()
            with self._lock:
                if session is None or session.closed or not self._views:
                    self._watcher = None
                    return
            session.hands.quiet(SILENT_SECONDS)
            del session  # not held while it waits
