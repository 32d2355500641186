"""One outbox per session: what the session sends to every view, made once and handed to each transport.

Every view of a session (a `ViewConnection`, connection.py: the web hub's clients, the notebook widgets) sends from
the same outbox: each published frame is encoded once (frames.py), the topology message once per generation
(display.py), and each view (a `Peer`) gets, in order, the topology when its generation is new (else the control ids
when they changed), the frame, the autosave's state when it changed (a save failed, or works again), and a status
line every STATUS_PERIOD seconds. A view that falls behind skips frames: it is only ever handed the latest.

Threads: the session calls `_on_frame` on its training thread, which only keeps the frame and wakes the
subscribers; encoding happens in `packets`, on whichever thread sends (the event loop, a widget's sender).
"""

from __future__ import annotations

import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass, replace

from ..model import Frame, Session
from .display import group_maps, mirror_axes, topology_message
from .frames import encode_frame
from .messages import (
    STATUS_PERIOD,
    AutosaveMessage,
    ControlsMessage,
    ServerMessage,
    StatusMessage,
    TopologyMessage,
)


@dataclass
class Peer:
    """What one view has been sent: its generation, the control ids it knows, when it last had a status line."""

    id: int | None = None  # the client id its topology message carries (None: the notebook widget)
    watching: bool = False  # the view only watches (its topology message says so: the page shows itself read-only)
    generation: int = -1
    control_ids: tuple = ()  # with the group, radii and strokes: the controls it knows
    last_status: float = 0.0
    seq: int = -1  # the latest frame handed to it
    save_error: str | None = None  # the autosave's failure it was told of (None: saves work)

    def forget(self) -> None:
        """Send the topology again with the next frame (a new output on the same connection: a hello)."""
        self.generation = -1


class Outbox:
    """The frames and messages of one session for all its views (see the module's docstring)."""

    def __init__(self, session: Session) -> None:
        self._session = weakref.ref(session)  # the registry below is keyed by the session: no strong way back
        self._lock = threading.Lock()
        self._latest: Frame | None = None
        self._encoded: tuple[int, bytes] = (-1, b"")
        self._topology: tuple[int, TopologyMessage | None] = (-1, None)
        self._subscribers: list[Callable[[], None]] = []
        session.add_listener(self._on_frame, replay=False)

    @property
    def session(self) -> Session:
        session = self._session()
        if session is None:
            raise RuntimeError("outbox: its session is gone (closed and let go)")
        return session

    # -- subscribers -----------------------------------------------------------------------------------------
    def subscribe(self, wake: Callable[[], None]) -> None:
        """Call `wake()` (on the training thread: it must return at once) whenever a new frame is published."""
        with self._lock:
            self._subscribers.append(wake)

    def unsubscribe(self, wake: Callable[[], None]) -> None:
        with self._lock:
            if wake in self._subscribers:
                self._subscribers.remove(wake)

    def _on_frame(self, frame: Frame) -> None:
        with self._lock:
            self._latest = frame
            subscribers = list(self._subscribers)
        for wake in subscribers:
            wake()

    @property
    def latest(self) -> Frame:
        """The newest frame: the latest published, or the session's own when that is newer (a preset installed, not
        yet published)."""
        current = self.session.frame
        with self._lock:
            latest = self._latest
        return current if latest is None or current.seq > latest.seq else latest

    # -- what a view is sent ------------------------------------------------------------------------------------
    def packets(self, peer: Peer, frame: Frame | None = None) -> list[ServerMessage | bytes]:
        """What `peer` should be sent for `frame` (default: the latest), in order: messages, then the frame (bytes),
        then perhaps the autosave's state and a status line. Empty while a newer preset is being installed (its own
        frames follow)."""
        frame = self.latest if frame is None else frame
        session = self.session
        with self._lock:
            if session.generation != frame.generation:
                return []
            kept_generation, topology = self._topology
            if topology is None or kept_generation != frame.generation:
                topology = topology_message(session, frame)
                self._topology = (frame.generation, topology)
            if self._encoded[0] != frame.seq:
                self._encoded = (frame.seq, encode_frame(frame, session))
            data = self._encoded[1]
        out: list[ServerMessage | bytes] = []
        radii = [round(float(r), 6) for r in frame.radii]
        controls = (frame.control_ids, frame.group, tuple(radii), frame.strokes)
        if peer.generation != frame.generation:
            out.append(replace(topology, client=peer.id, watching=peer.watching,
                               control_ids=list(frame.control_ids), group=frame.group,
                               group_maps=group_maps(frame.group), mirror_axes=mirror_axes(frame.group),
                               n_controls=frame.n_controls, n_effective=len(frame.effective_controls), radii=radii,
                               strokes=list(frame.strokes)))
            peer.generation, peer.control_ids = frame.generation, controls
        elif peer.control_ids != controls:  # a control added or removed, a radius, a group: before the frame
            out.append(ControlsMessage(ids=[int(i) for i in frame.control_ids], group=frame.group,
                                       group_maps=group_maps(frame.group), radii=radii,
                                       strokes=[int(n) for n in frame.strokes]))
            peer.control_ids = controls
        out.append(data)
        peer.seq = frame.seq
        if session.save_error != peer.save_error:  # a save failed, or works again: every view says so
            peer.save_error = session.save_error
            out.append(AutosaveMessage.of(peer.save_error))
        now = time.monotonic()
        if now - peer.last_status >= STATUS_PERIOD:
            peer.last_status = now
            out.append(StatusMessage.of(frame.cycle_time, session.frames_per_second))
        return out


_OUTBOXES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_OUTBOXES_LOCK = threading.Lock()


def outbox_for(session: Session) -> Outbox:
    """The session's one outbox, made on first use."""
    with _OUTBOXES_LOCK:
        box = _OUTBOXES.get(session)
        if box is None:
            box = _OUTBOXES[session] = Outbox(session)
        return box
