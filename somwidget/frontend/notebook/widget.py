"""The clay view as a Jupyter widget (anywidget): the browser client's module (client/dist/somview.js) drawing one
Session's frames.

Frames travel as binary buffers of custom messages over the kernel's comm (the widget protocol), intents come back
the same way, both in the one protocol of transport/messages.py: no server, no port, no iframe, so it works wherever
the notebook's widgets do (JupyterLab, Notebook 7, VS Code, Colab, marimo). Each output of the widget is its own view
with its own camera; every widget of a session follows it.

Threads: the session's outbox (transport/outbox.py) wakes the widget on the training thread; a sender thread of the
widget takes what the outbox made for it and sends it, at most `max_fps` a second (a slow kernel link skips frames,
never queues them). Intents arrive on the kernel's thread (`_on_message`) and go to the Session through `Gestures`,
as the websocket's do.
"""

from __future__ import annotations

import base64
import json
import logging
import threading
import time

import anywidget
import traitlets

from ..client import view_module
from ..transport import messages
from ..transport.gestures import Gestures
from ..transport.outbox import Peer, outbox_for

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

    def __init__(self, session, height: int = 520, max_fps: float = messages.MAX_FPS, **kwargs):
        super().__init__(_esm=view_module(), height=int(height), **kwargs)
        self.session = session
        self.max_fps = float(max_fps)
        self.gestures = Gestures(session, on_change=self._send_grabs)
        self.frames_sent = 0
        self.intents = 0
        self.refused = 0
        self.outbox = outbox_for(session)
        self._peer = Peer()
        self._fresh = True  # a frame came that is not sent yet
        self._wake = threading.Condition()
        self._send_lock = threading.Lock()  # the sender thread and the kernel's thread (a hello) both send frames
        self._closed = False
        self.on_msg(self._on_message)
        self._sender = threading.Thread(target=self._send_loop, name="somwidget-view", daemon=True)
        self._sender.start()
        self.outbox.subscribe(self._on_frame)

    # -- session -> browser ------------------------------------------------------------------------------------
    def _on_frame(self) -> None:
        with self._wake:
            self._fresh = True
            self._wake.notify()

    def _send_loop(self) -> None:
        period = 1.0 / self.max_fps
        while True:
            with self._wake:
                while not self._closed and not self._fresh:
                    self._wake.wait()
                if self._closed:
                    return
                self._fresh = False
            t = time.monotonic()
            try:
                self._send_frame()
            except Exception:  # a closed comm, an odd frame: the next one tries again
                log.debug("sending a frame to the notebook view failed", exc_info=True)
            rest = period - (time.monotonic() - t)
            if rest > 0:
                time.sleep(rest)

    def _send_frame(self, topology: bool = False) -> None:
        with self._send_lock:
            frame = self.outbox.latest
            if frame.seq == self._peer.seq and not topology:
                return
            if topology:
                self._peer.forget()
            for packet in self.outbox.packets(self._peer, frame):
                if isinstance(packet, bytes):
                    self.send({"type": "frame"}, buffers=[packet])
                    self.frames_sent += 1
                else:
                    self.send(packet)
            for _holder, message in self.gestures.prune(frame.control_ids):
                self.send(message)

    def _send_grabs(self) -> None:
        self.send(self.gestures.message_for(_CLIENT))

    # -- browser -> session ------------------------------------------------------------------------------------
    def _on_message(self, _widget, content, _buffers) -> None:
        try:
            intent = messages.parse_intent(json.dumps(content), self.session.n_controls)
            if intent.type == "hello":  # a new output: the topology and the latest frame for it
                self._send_frame(topology=True)
                self._send_grabs()
                return
            reply = self.gestures.apply(_CLIENT, intent)
            self.intents += 1
            if reply is not None:
                self.send(reply)
        except (ValueError, RuntimeError, TypeError) as exc:  # IntentError is a ValueError
            self.refused += 1
            self.send(messages.error_message(str(exc), getattr(exc, "intent", None)))

    def close(self) -> None:
        """Stop following the session (the session goes on) and close the widget."""
        if not hasattr(self, "outbox"):  # __init__ stopped before it followed the session (ClientNotBuilt)
            return super().close()
        self.outbox.unsubscribe(self._on_frame)
        self.gestures.drop(_CLIENT)
        with self._wake:
            self._closed = True
            self._wake.notify()
        super().close()
