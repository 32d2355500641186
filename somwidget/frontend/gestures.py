"""Who holds which control, and what a client's intent does to the Session: shared by every transport of the clay
view (the websocket of the web app and the XR page, the notebook widget's comm).

A grab begins a gesture (one undo step) and its release ends it; a control is held by one client at a time; a
client that goes away mid-grab ends its gestures. Intents arrive already checked by `protocol.parse_intent`.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Hashable

from . import protocol


class Gestures:
    """The grabs of one transport's clients on one Session; `on_change()` is called when who holds what changes."""

    def __init__(self, session, on_change: Callable[[], None] | None = None):
        self.session = session
        self.on_change = on_change or (lambda: None)
        self.grabs: dict[int, Hashable] = {}  # control index -> client

    def message_for(self, client: Hashable) -> str:
        """The "grabs" message as `client` sees it (own: held by this client)."""
        return json.dumps({"type": "grabs", "grabs": [{"index": i, "own": cid == client}
                                                      for i, cid in sorted(self.grabs.items())]})

    def apply(self, client: Hashable, intent: protocol.Intent) -> dict | None:
        """Do what `intent` asks for `client`; returns a reply to send back to that client alone (a pong), or None.
        ValueError (or the Session's RuntimeError) when the session refuses it."""
        kind, i = intent.type, intent.index
        if kind == "ping":
            return {"type": "pong", "t": intent.t}
        if kind == "grab":
            holder = self.grabs.get(i)
            if holder is not None and holder != client:
                raise ValueError(f"grab: control {i} is held by another client")
            if holder is None:
                self.session.begin_gesture()  # grab to release: one undo step
            self.grabs[i] = client
            self.on_change()
        elif kind in ("move", "release"):
            if self.grabs.get(i) != client:
                raise ValueError(f"{kind}: control {i} is not held by this client; send grab first")
            if intent.position is not None:
                self.session.move_control(i, list(intent.position))
            if kind == "release":
                del self.grabs[i]
                self.on_change()
                self.session.end_gesture()
        elif kind == "set":
            self.session.set_parameter(intent.name, intent.value)
        elif kind == "undo":
            self.session.undo()
        elif kind == "redo":
            self.session.redo()
        elif kind == "reset":
            self.session.reset()
        elif kind == "train":
            self.session.train()
        elif kind == "pause":
            self.session.pause()
        return None

    def drop(self, client: Hashable) -> None:
        """`client` went away: its grabs end, each drag a completed step."""
        released = [i for i, cid in self.grabs.items() if cid == client]
        for i in released:
            del self.grabs[i]
        if released:
            self.on_change()
            self.session.end_gesture()

    def prune(self, n_controls: int) -> None:
        """Controls removed (or a new preset): their grabs end."""
        stale = [i for i in self.grabs if i >= n_controls]
        for i in stale:
            del self.grabs[i]
        if stale:
            self.on_change()
