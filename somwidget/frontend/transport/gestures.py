"""Who holds which control, and what a client's intent does to the Session: shared by every transport of the clay
view (the websocket of the web app and the XR page, the notebook widget's comm).

Controls are held by their stable id (`Session.control_ids`), not by their place: a control removed elsewhere
cannot turn a drag into a drag of another control. A grab begins a gesture (one undo step) and its release ends
it; a control is held by one client at a time; a client that goes away mid-grab ends its gestures; a held control
that disappears ends its grab, and the holder is told (`prune`). Intents arrive checked by `messages.parse_intent`.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable

from .messages import Intent, error_message, grabs_message, pong_message


#: Intents that are a Session method of the same name, without arguments.
SESSION_ACTIONS = ("undo", "redo", "reset", "train", "pause")


class Gestures:
    """The grabs of one transport's clients on one Session; `on_change()` is called when who holds what changes."""

    def __init__(self, session, on_change: Callable[[], None] | None = None):
        self.session = session
        self.on_change = on_change or (lambda: None)
        self.grabs: dict[int, Hashable] = {}  # control id -> client

    def message_for(self, client: Hashable) -> dict:
        """The "grabs" message as `client` sees it (own: held by this client), with each control's index now."""
        ids = self.session.control_ids
        held = [{"index": ids.index(cid), "id": cid, "own": who == client}
                for cid, who in sorted(self.grabs.items()) if cid in ids]
        return grabs_message(held)

    def _control_of(self, intent: Intent) -> int:
        if intent.control_id is not None:
            self.session.index_of_control(intent.control_id)  # ValueError when it is gone
            return intent.control_id
        ids = self.session.control_ids
        if not 0 <= intent.index < len(ids):
            raise ValueError(f"{intent.type}: control index {intent.index} is out of range")
        return ids[intent.index]

    def apply(self, client: Hashable, intent: Intent) -> dict | None:
        """Do what `intent` asks for `client`; returns a reply to send back to that client alone (a pong), or None.
        ValueError (or the Session's RuntimeError) when the session refuses it."""
        kind = intent.type
        if kind == "ping":
            return pong_message(intent.t)
        if kind == "grab":
            cid = self._control_of(intent)
            holder = self.grabs.get(cid)
            if holder is not None and holder != client:
                raise ValueError(f"grab: control {cid} is held by another client")
            if holder is None:
                self.session.begin_gesture()  # grab to release: one undo step
            self.grabs[cid] = client
            self.on_change()
        elif kind in ("move", "release"):
            cid = intent.control_id if intent.control_id is not None else self._control_of(intent)
            if self.grabs.get(cid) != client:
                raise ValueError(f"{kind}: control {cid} is not held by this client; send grab first")
            try:
                if intent.position is not None:
                    self.session.move_control_id(cid, list(intent.position))
            finally:
                if kind == "release":
                    del self.grabs[cid]
                    self.on_change()
                    self.session.end_gesture()
        elif kind == "set":
            self.session.set_parameter(intent.name, intent.value)
        elif kind == "add":
            self.session.add_control(list(intent.position), intent.radius)
        elif kind == "remove":
            self.session.remove_control(self.session.index_of_control(self._control_of(intent)))
        elif kind == "radius":
            self.session.set_control_radius(self.session.index_of_control(self._control_of(intent)), intent.radius)
        elif kind == "stroke":
            self.session.add_stroke([list(p) for p in intent.points], intent.radius)
        elif kind in SESSION_ACTIONS:
            getattr(self.session, kind)()
        return None

    def drop(self, client: Hashable) -> None:
        """`client` went away: its grabs end, each drag a completed step."""
        released = [cid for cid, who in self.grabs.items() if who == client]
        for cid in released:
            del self.grabs[cid]
        if released:
            self.on_change()
            self.session.end_gesture()

    def prune(self, control_ids) -> list[tuple[Hashable, dict]]:
        """Grabs of controls that are gone (removed, or the controls replaced) end; returns (client, message)
        for each client whose held control went, to tell it."""
        present = set(control_ids)
        gone = [(cid, who) for cid, who in self.grabs.items() if cid not in present]
        for cid, _ in gone:
            del self.grabs[cid]
        if gone:
            self.on_change()
            self.session.end_gesture()
        return [(who, error_message(f"control {cid} was removed while you held it: the drag ended",
                                             "grab")) for cid, who in gone]
