"""One view's connection to a session, whatever carries its bytes: the web hub's websocket clients (web/hub.py) and
the notebook widget (notebook/widget.py) each make one per view and only adapt their pipe and their lifecycle.

A `ViewConnection` sends its view what the session's outbox made for it (`send_latest`: the topology when its
generation is new, the controls when they changed, the frame, the autosave's state, a status line), takes the view's
messages (`receive`: parsed against messages.py, then handed to the intent's handler in HANDLERS, the one dispatch
table), replies (a pong, an error naming what was refused) and holds controls through a `HolderRegistry`.

The pipe is the host's: `send_json(dict)` for a JSON message and `send_frame(bytes)` for a binary frame, both
returning at once (the hub queues; the widget's comm sends). Threads: `send_latest` may run on a sender thread while
`receive` runs on another (the widget's kernel thread); a lock keeps each view's packets in order.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Protocol

from .holders import HolderRegistry
from .messages import (
    AddIntent,
    ControlIntent,
    ErrorMessage,
    GrabIntent,
    HelloIntent,
    Intent,
    INTENTS,
    IntentError,
    MoveIntent,
    PauseIntent,
    PingIntent,
    PongMessage,
    RadiusIntent,
    RedoIntent,
    ReleaseIntent,
    RemoveIntent,
    ResetIntent,
    ServerMessage,
    SetIntent,
    StrokeIntent,
    TrainIntent,
    UndoIntent,
    parse_intent,
)
from .outbox import Peer, outbox_for

log = logging.getLogger(__name__)

#: Refusals logged per connection before only every 100th is.
LOGGED_REFUSALS = 20


class Pipe(Protocol):
    """What a host gives a connection to reach its view."""

    def send_json(self, message: dict) -> None: ...

    def send_frame(self, frame: bytes) -> None: ...


class ViewConnection:
    """One view of `session` through `pipe`, holding controls in `holders` (see the module's docstring).
    `client_id`: the id its topology message carries (None over the notebook's comm); `name`: for the log."""

    def __init__(self, session, holders: HolderRegistry, pipe: Pipe, client_id: int | None = None,
                 name: str = "a view"):
        self.session = session
        self.holders = holders
        self.pipe = pipe
        self.name = name
        self.outbox = outbox_for(session)
        self.peer = Peer(id=client_id)
        self.intents = 0  # intents done
        self.refused = 0  # messages refused
        self._lock = threading.Lock()
        holders.join(self)

    @property
    def client_id(self) -> int | None:
        return self.peer.id

    def open(self) -> None:
        """A view came: the topology and the latest frame, then who holds what."""
        self.send_latest()
        self.send(self.holders.message_for(self))

    def close(self) -> None:
        """The view went: what it held is let go (each drag a completed step)."""
        self.holders.leave(self)

    # -- session -> view ----------------------------------------------------------------------------------------
    def send(self, message: ServerMessage) -> None:
        self.pipe.send_json(message.to_json())

    def send_latest(self, frame=None, again: bool = False) -> bool:
        """Hand the pipe what the outbox made for `frame` (default: the latest) unless this view had it already;
        `again`: the topology and the frame again whatever it had (a new output of the view). Grabs of controls
        the frame no longer has end here. False when there was nothing new."""
        with self._lock:
            frame = self.outbox.latest if frame is None else frame
            if again:
                self.peer.forget()
            elif frame.seq == self.peer.seq:
                return False
            for packet in self.outbox.packets(self.peer, frame):
                if isinstance(packet, bytes):
                    self.pipe.send_frame(packet)
                else:
                    self.send(packet)
        self.holders.prune(frame.control_ids)
        return True

    # -- view -> session ----------------------------------------------------------------------------------------
    def receive(self, message) -> bool:
        """Take one message of the view (JSON text; bytes are refused): do what it asks and reply, or send back an
        ErrorMessage saying why it was refused. False when refused."""
        try:
            intent = parse_intent(message, self.session.n_controls)
        except IntentError as exc:
            self._refuse(exc, exc.intent)
            return False
        try:
            reply = HANDLERS[type(intent)](self, intent)
        except (ValueError, RuntimeError, TypeError) as exc:  # the session's own checks (or a closed session)
            self._refuse(exc, intent.type)
            return False
        self.intents += 1
        if isinstance(reply, ServerMessage):
            self.send(reply)
        return True

    def _refuse(self, exc: Exception, intent: str | None) -> None:
        self.refused += 1
        if self.refused <= LOGGED_REFUSALS or self.refused % 100 == 0:
            log.warning("%s: refused a message (%d so far): %s", self.name, self.refused, exc)
        self.send(ErrorMessage(message=str(exc), intent=intent))

    def control_of(self, intent: ControlIntent) -> int:
        """The id of the control an intent names (by id or by index now); ValueError when it is gone."""
        if intent.id is not None:
            self.session.index_of_control(intent.id)  # ValueError when it is gone
            return intent.id
        ids = self.session.control_ids
        if not 0 <= intent.index < len(ids):
            raise ValueError(f"{intent.type}: control index {intent.index} is out of range")
        return ids[intent.index]


# -- the intents' handlers: (connection, intent) -> a ServerMessage to that view alone (anything else: no reply) ---
def _hello(c: ViewConnection, _: HelloIntent) -> None:
    c.send_latest(again=True)  # the topology again, then the latest frame
    c.send(c.holders.message_for(c))


def _grab(c: ViewConnection, intent: GrabIntent) -> None:
    c.holders.grab(c, c.control_of(intent))


def _move(c: ViewConnection, intent: MoveIntent | ReleaseIntent) -> None:
    cid = intent.id if intent.id is not None else c.control_of(intent)
    c.holders.check(c, cid, intent.type)
    try:
        if intent.position is not None:
            c.session.move_control_id(cid, list(intent.position))
    finally:
        if isinstance(intent, ReleaseIntent):
            c.holders.release(c, cid)


def _remove(c: ViewConnection, intent: RemoveIntent) -> None:
    c.session.remove_control(c.session.index_of_control(c.control_of(intent)))


def _radius(c: ViewConnection, intent: RadiusIntent) -> None:
    c.session.set_control_radius(c.session.index_of_control(c.control_of(intent)), intent.radius)


#: The one dispatch table: each intent's class -> what it does.
HANDLERS: dict[type[Intent], Callable[[ViewConnection, Intent], ServerMessage | None]] = {
    HelloIntent: _hello,
    PingIntent: lambda c, intent: PongMessage(t=intent.t),
    GrabIntent: _grab,
    MoveIntent: _move,
    ReleaseIntent: _move,
    RemoveIntent: _remove,
    RadiusIntent: _radius,
    AddIntent: lambda c, intent: c.session.add_control(list(intent.position), intent.radius),
    StrokeIntent: lambda c, intent: c.session.add_stroke([list(p) for p in intent.points], intent.radius),
    SetIntent: lambda c, intent: c.session.set_parameter(intent.name, intent.value),
    UndoIntent: lambda c, _: c.session.undo(),
    RedoIntent: lambda c, _: c.session.redo(),
    ResetIntent: lambda c, _: c.session.reset(),
    TrainIntent: lambda c, _: c.session.train(),
    PauseIntent: lambda c, _: c.session.pause(),
}
if set(HANDLERS) != set(INTENTS.values()):
    raise TypeError(f"intents without a handler in HANDLERS: {set(INTENTS.values()) - set(HANDLERS)}")
