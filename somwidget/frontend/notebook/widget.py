"""The clay view as a Jupyter widget (anywidget): the browser module xr/dist/somview.js drawing one Session's frames.

Frames travel as binary buffers of custom messages over the kernel's comm (the widget protocol), intents come back
the same way, both in the one protocol of protocol.py: no server, no port, no iframe, so it works wherever the
notebook's widgets do (JupyterLab, Notebook 7, VS Code, Colab, marimo). Each output of the widget is its own view
with its own camera; every widget of a session follows it.

Threads: the session calls `_on_frame` on its training thread; a sender thread of the widget encodes the latest
frame and sends it, at most `max_fps` a second (a slow kernel link skips frames, never queues them). Intents arrive
on the kernel's thread (`_on_message`) and go to the Session through `Gestures`, as the websocket's do.
"""

from __future__ import annotations

import base64
import json
import logging
import threading
import time

import anywidget
import traitlets

from ..transport import protocol
from ..transport.gestures import Gestures
from ..client import view_module

log = logging.getLogger(__name__)

PICTURE_PREFIX = "data:image/png;base64,"
#: A bound on the picture a browser may set (a 4K view's PNG is a few MB).
MAX_PICTURE_CHARS = 16 * 1024 * 1024

#: The one client of a widget's gestures (every output of a widget acts as one client).
_CLIENT = "notebook"


class ClayWidget(anywidget.AnyWidget):
    """The live, draggable 3-D view of `session` in a notebook output."""

    height = traitlets.Int(520).tag(sync=True)
    #: The clay as a view last showed it (a PNG data URL its browser takes once the view is still): kept in a saved
    #: notebook's widget state and shown there until a kernel sends frames again.
    picture = traitlets.Unicode("").tag(sync=True)

    @traitlets.validate("picture")
    def _check_picture(self, proposal):
        value = proposal["value"]
        if value and not (value.startswith(PICTURE_PREFIX) and len(value) <= MAX_PICTURE_CHARS):
            raise traitlets.TraitError(f"picture: expected a PNG data URL ({PICTURE_PREFIX}...) of at most "
                                       f"{MAX_PICTURE_CHARS} characters, got {value[:40]!r} ({len(value)} characters)")
        return value

    def picture_png(self) -> bytes | None:
        """The PNG of `picture`, or None before a view has taken one."""
        return base64.b64decode(self.picture[len(PICTURE_PREFIX):]) if self.picture else None

    def __init__(self, session, height: int = 520, max_fps: float = protocol.MAX_FPS, **kwargs):
        super().__init__(_esm=view_module(), height=int(height), **kwargs)
        self.session = session
        self.max_fps = float(max_fps)
        self.gestures = Gestures(session, on_change=self._send_grabs)
        self.frames_sent = 0
        self.intents = 0
        self.refused = 0
        self._latest = None
        self._wake = threading.Condition()
        self._send_lock = threading.Lock()  # the sender thread and the kernel's thread (a hello) both send frames
        self._sent_seq = -1
        self._sent_generation = -1
        self._sent_ids: tuple = ()
        self._last_status = 0.0
        self._closed = False
        self.on_msg(self._on_message)
        self._sender = threading.Thread(target=self._send_loop, name="somwidget-view", daemon=True)
        self._sender.start()
        session.add_listener(self._on_frame)

    # -- session -> browser ------------------------------------------------------------------------------------
    def _on_frame(self, frame) -> None:
        with self._wake:
            self._latest = frame
            self._wake.notify()

    def _send_loop(self) -> None:
        period = 1.0 / self.max_fps
        while True:
            with self._wake:
                while not self._closed and (self._latest is None or self._latest.seq == self._sent_seq):
                    self._wake.wait()
                if self._closed:
                    return
                frame = self._latest
            t = time.monotonic()
            try:
                self._send_frame(frame)
            except Exception:  # a closed comm, an odd frame: the next one tries again
                log.debug("sending a frame to the notebook view failed", exc_info=True)
            self._sent_seq = frame.seq
            rest = period - (time.monotonic() - t)
            if rest > 0:
                time.sleep(rest)

    def _send_frame(self, frame, topology: bool = False) -> None:
        with self._send_lock:
            self._send_frame_locked(frame, topology)

    def _send_frame_locked(self, frame, topology: bool) -> None:
        if self.session.generation != frame.generation:
            return  # a newer preset is being installed; its own frames follow
        if topology or frame.generation != self._sent_generation:
            self.send(protocol.topology_message(self.session, frame))
            self._sent_generation = frame.generation
            self._sent_ids = frame.control_ids
        elif frame.control_ids != self._sent_ids:  # a control added or removed: the ids before the frame
            self.send(json.loads(protocol.controls_message(frame.control_ids)))
            self._sent_ids = frame.control_ids
        self.send({"type": "frame"}, buffers=[protocol.encode_frame(frame, self.session)])
        self.frames_sent += 1
        now = time.monotonic()
        if now - self._last_status >= protocol.STATUS_PERIOD:
            self._last_status = now
            self.send(json.loads(protocol.status_message(frame, self.session.frames_per_second)))
        for _holder, message in self.gestures.prune(frame.control_ids):
            self.send(json.loads(message))

    def _send_grabs(self) -> None:
        self.send(json.loads(self.gestures.message_for(_CLIENT)))

    # -- browser -> session ------------------------------------------------------------------------------------
    def _on_message(self, _widget, content, _buffers) -> None:
        try:
            intent = protocol.parse_intent(json.dumps(content), self.session.n_controls)
            if intent.type == "hello":  # a new output: the topology and the latest frame for it
                self._send_frame(self.session.frame, topology=True)
                self._send_grabs()
                return
            reply = self.gestures.apply(_CLIENT, intent)
            self.intents += 1
            if reply is not None:
                self.send(reply)
        except (ValueError, RuntimeError, TypeError) as exc:  # IntentError is a ValueError
            self.refused += 1
            self.send({"type": "error", "message": str(exc), "intent": getattr(exc, "intent", None)})

    def close(self) -> None:
        """Stop following the session (the session goes on) and close the widget."""
        self.session.remove_listener(self._on_frame)
        self.gestures.drop(_CLIENT)
        with self._wake:
            self._closed = True
            self._wake.notify()
        super().close()
