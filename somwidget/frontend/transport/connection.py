"""One view's connection to a session, whatever carries its bytes: the web hub's websocket clients (web/hub.py) and
the notebook widget (notebook/widget.py) each make one per view and only adapt their pipe and their lifecycle.

A `ViewConnection` sends its view what the session's outbox made for it (`send_latest`: the topology when its
generation is new, the controls when they changed, the frame, the autosave's state, a status line), takes the view's
messages (`receive`: parsed against messages.py, then handed to the intent's handler in HANDLERS, the one dispatch
table), replies (a pong, an error naming what was refused) and is one hand of the session (model/hands.py) in the
session's one `HolderRegistry` (holders.py): who is there, who holds what.

Intents run on the session's training thread (`Session.submit`), in the order they came, so the thread that
receives them (a server's event loop) never waits for the Som; a view's moves of one control still waiting there
collapse into the latest. A ping is answered there too while intents of its view wait there (a view that has its
pong knows the intents before it were taken), else at once, as are a hello and a hand (they touch nothing of the
clay): a view that only watches is never held up by another's intents.

The pipe is the host's: `send_json(dict)` for a JSON message and `send_frame(bytes)` for a binary frame, both
returning at once and callable from any thread (the hub queues on its loop; the widget's comm sends). A lock keeps
each view's packets in order.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, Protocol

import numpy as np

from .holders import holders_for
from .messages import (
    INTENTS,
    AddIntent,
    ControlIntent,
    ErrorMessage,
    GrabIntent,
    HandIntent,
    HelloIntent,
    Intent,
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
    RevolveIntent,
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
    """One view of `session` through `pipe`, a hand of kind `kind` (see the module's docstring). `client_id`: the id
    its topology message carries (None over the notebook's comm); `name`: for the log."""

    def __init__(self, session, pipe: Pipe, client_id: int | None = None, name: str = "a view",
                 kind: str = "desktop", watch: bool = False) -> None:
        self.session = session
        self.pipe = pipe
        self.name = name
        self.watch = watch  # a view that only watches (a studio's wall opens rooms so): WATCHING intents alone
        self.outbox = outbox_for(session)
        self.peer = Peer(id=client_id, watching=watch)
        self.intents = 0  # intents done
        self.refused = 0  # messages refused
        self._lock = threading.Lock()
        self._moves: dict = {}  # control -> its latest move still waiting for the training thread
        self._moves_lock = threading.Lock()
        self._waiting = 0  # intents posted to the training thread and not done yet
        self.holders = holders_for(session)
        self.hand = self.holders.join(self, kind)

    @property
    def client_id(self) -> int | None:
        return self.peer.id

    def open(self) -> None:
        """A view came: the topology and the latest frame, then who holds what and who is there."""
        self.send_latest()
        self.holders.tell(self)

    def close(self) -> Future:
        """The view went: it is sent nothing more, and what it held is let go (each drag a completed step) on the
        training thread."""
        hand = self.holders.leave(self)
        hands = self.holders.hands
        return self.session.submit(lambda: hands.leave(hand) if hand is not None else None)

    # -- session -> view ----------------------------------------------------------------------------------------
    def send(self, message: ServerMessage) -> None:
        self.pipe.send_json(message.to_json())

    def send_latest(self, frame=None, again: bool = False) -> bool:
        """Hand the pipe what the outbox made for `frame` (default: the latest) unless this view had it already;
        `again`: the topology and the frame again whatever it had (a new output of the view). False when there was
        nothing new."""
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
        return True

    # -- view -> session ----------------------------------------------------------------------------------------
    def receive(self, message) -> Future:
        """Take one message of the view (JSON text; bytes are refused): its intent runs on the training thread (a
        hello, a hand here and now), with a reply, or an ErrorMessage saying why it was refused. Returns a
        Future of True (done) or False (refused)."""
        self.holders.hands.heard(self.hand)
        try:
            intent = parse_intent(message, self.session.n_controls)
        except IntentError as exc:
            self._refuse(exc, exc.intent)
            return _done(False)
        if self.watch and type(intent) not in WATCHING:
            self._refuse(ValueError(f"{intent.type}: this view only watches the session; to take part, open its own "
                                    "link (in a studio: Take part, on the wall)"), intent.type)
            return _done(False)
        if type(intent) in AT_ONCE or (isinstance(intent, PingIntent) and not self._waiting):
            return _done(self._handle(intent))
        if isinstance(intent, MoveIntent):
            key = (intent.id, intent.index)
            with self._moves_lock:
                waiting = key in self._moves
                self._moves[key] = intent
            if waiting:  # the move waiting there takes this position
                self.intents += 1
                return _done(True)
            return self._submit(lambda: self._handle(self._latest_move(key)), quick=True)
        return self._submit(lambda: self._handle(intent), quick=isinstance(intent, QUICK))

    def _latest_move(self, key) -> MoveIntent:
        with self._moves_lock:
            return self._moves.pop(key)

    def _submit(self, call: Callable[[], bool], quick: bool = False) -> Future:
        done: Future = Future()
        with self._moves_lock:
            self._waiting += 1

        def finish(future: Future) -> None:
            with self._moves_lock:
                self._waiting -= 1
            exc = future.exception()
            if exc is None:
                done.set_result(future.result())
            else:  # a closed session
                self._refuse(exc, None)
                done.set_result(False)

        self.session.submit(call, quick).add_done_callback(finish)
        return done

    def _handle(self, intent: Intent) -> bool:
        try:
            with self.holders.hands.acting(self.hand):
                reply = HANDLERS[type(intent)](self, intent)
        except (ValueError, RuntimeError, TypeError) as exc:  # the session's own checks (or a closed session)
            self._refuse(exc, intent.type)
            return False
        self.intents += 1
        if isinstance(reply, ServerMessage):
            self.send(reply)
        return True

    def _refuse(self, exc: BaseException, intent: str | None) -> None:
        self.refused += 1
        if self.refused <= LOGGED_REFUSALS or self.refused % 100 == 0:
            log.warning("%s: refused a message (%d so far): %s", self.name, self.refused, exc)
        self.send(ErrorMessage(message=str(exc), intent=intent))

    def control_of(self, intent: ControlIntent) -> int:
        """The id of the control an intent names (by id or by index now); ValueError when it is gone."""
        if intent.id is not None:
            self.session.index_of_control(intent.id)  # ValueError when it is gone
            return intent.id
        ids, index = self.session.control_ids, intent.index
        if index is None:  # parse_intent refuses an intent with neither
            raise ValueError(f"{intent.type}: give the control's id or its index")
        if not 0 <= index < len(ids):
            raise ValueError(f"{intent.type}: control index {index} is out of range")
        return ids[index]


def _done(value) -> Future:
    future: Future = Future()
    future.set_result(value)
    return future


# -- the intents' handlers: (connection, intent) -> a ServerMessage to that view alone (anything else: no reply) ---
def _hello(c: ViewConnection, _: HelloIntent) -> None:
    c.send_latest(again=True)  # the topology again, then the latest frame
    c.holders.tell(c)


def _hand(c: ViewConnection, intent: HandIntent) -> None:
    c.holders.set_kind(c, intent.kind, intent.name)


def _grab(c: ViewConnection, intent: GrabIntent) -> None:
    c.holders.hands.grab(c.hand, c.control_of(intent))


def _move(c: ViewConnection, intent: MoveIntent | ReleaseIntent) -> None:
    """A move of a held control; a release lets go (after its position, where it differs from the last move)."""
    hands = c.holders.hands
    cid = intent.id if intent.id is not None else c.control_of(intent)
    hands.check_holds(c.hand, cid, intent.type)
    try:
        if intent.position is not None and (isinstance(intent, MoveIntent) or _moved(c.session, cid, intent.position)):
            with hands.acting(c.hand, cid):
                c.session.move_control_id(cid, list(intent.position))
    finally:
        if isinstance(intent, ReleaseIntent):
            hands.release(c.hand, cid)


def _moved(session, control_id: int, position) -> bool:
    """A release's position differs from where the control is (its last move)."""
    at = session.controls[session.index_of_control(control_id)][list(session.layout.position)]
    return not np.array_equal(at, np.asarray(position, np.float32))


def _remove(c: ViewConnection, intent: RemoveIntent) -> None:
    cid = c.control_of(intent)
    with c.holders.hands.acting(c.hand, cid):
        c.session.remove_control(c.session.index_of_control(cid))


def _radius(c: ViewConnection, intent: RadiusIntent) -> None:
    cid = c.control_of(intent)
    with c.holders.hands.acting(c.hand, cid):  # the radius of a control it drags joins the drag
        c.session.set_control_radius(c.session.index_of_control(cid), intent.radius)


def _revolve(c: ViewConnection, intent: RevolveIntent) -> None:
    """Lathe about the radial group's axis with its copies (none in effect: the z-axis, 16 copies)."""
    group = c.session.settings.symmetry
    radial = group is not None and group.kind == "radial"
    c.session.revolve([list(p) for p in intent.points], group.axis if radial else "z", group.n if radial else 16,
                      intent.radius)


#: The one dispatch table: each intent's class -> what it does (on the training thread, but for AT_ONCE); a handler
#: takes the intent of its own class (Any: no type says "the class of the key"), and a ServerMessage it returns is sent.
HANDLERS: dict[type[Intent], Callable[[ViewConnection, Any], object]] = {
    HelloIntent: _hello,
    PingIntent: lambda c, intent: PongMessage(t=intent.t),
    HandIntent: _hand,
    GrabIntent: _grab,
    MoveIntent: _move,
    ReleaseIntent: _move,
    RemoveIntent: _remove,
    RadiusIntent: _radius,
    AddIntent: lambda c, intent: c.session.add_control(list(intent.position), intent.radius),
    StrokeIntent: lambda c, intent: c.session.add_stroke([list(p) for p in intent.points], intent.radius),
    RevolveIntent: _revolve,
    SetIntent: lambda c, intent: c.session.set_parameter(intent.name, intent.value),
    UndoIntent: lambda c, _: c.session.undo(c.hand),
    RedoIntent: lambda c, _: c.session.redo(c.hand),
    ResetIntent: lambda c, _: c.session.reset(),
    TrainIntent: lambda c, _: c.session.train(),
    PauseIntent: lambda c, _: c.session.pause(),
}
#: Intents answered on the thread that receives them: they touch nothing of the clay.
AT_ONCE = frozenset({HelloIntent, HandIntent})
#: What a view that only watches may send.
WATCHING = frozenset({HelloIntent, HandIntent, PingIntent})
#: Intents that take no time: a studio's loop runs them in its round, any other off it (studio/rounds.py)
QUICK = (MoveIntent, GrabIntent, ReleaseIntent, PingIntent, HandIntent, HelloIntent)
if set(HANDLERS) != set(INTENTS.values()):
    raise TypeError(f"intents without a handler in HANDLERS: {set(INTENTS.values()) - set(HANDLERS)}")
