"""The clay view as a Jupyter widget (anywidget): the browser client's module (client/dist/somview.js) drawing one
Session's frames.

Frames travel as binary buffers of custom messages over the kernel's comm (the widget protocol), intents come back
the same way, both in the one protocol of transport/messages.py: no server, no port, no iframe, so it works wherever
the notebook's widgets do (JupyterLab, Notebook 7, VS Code, Colab, marimo). Each output of the widget is its own view
with its own camera (the outputs of one widget act as one view); every widget of a session follows it.

The widget is the pipe and the lifecycle of one `ViewConnection` (transport/connection.py), as each websocket client
of the web hub is: a JSON message is a custom message, a frame a custom message {"type": "frame"} with the frame as
its one buffer. Threads: the session's outbox (transport/outbox.py) wakes the widget on the training thread; a sender
thread of the widget hands the connection the latest frame, at most `max_fps` a second (a slow kernel link skips
frames, never queues them). Intents arrive on the kernel's thread (`_on_message`) and run on the session's training
thread; its replies, and news of the session's other hands (holders.py), come from there.
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
from ..transport.connection import ViewConnection

log = logging.getLogger(__name__)

PICTURE_PREFIX = "data:image/png;base64,"
#: A bound on the picture a browser may set (a 4K view's PNG is a few MB).
MAX_PICTURE_CHARS = 16 * 1024 * 1024
#: A frame's envelope over the comm (its one buffer is the frame).
FRAME_ENVELOPE = messages.FrameMessage().to_json()


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

    def __init__(self, session, height: int = 520, max_fps: float = messages.MAX_FPS, **kwargs) -> None:
        super().__init__(_esm=view_module(), height=int(height), **kwargs)
        self.session = session
        self.max_fps = float(max_fps)
        self.frames_sent = 0
        self.connection = ViewConnection(session, self, name="the notebook view", kind="notebook")
        self.outbox = self.connection.outbox
        self._fresh = True  # a frame came that is not sent yet
        self._wake = threading.Condition()
        self._closed = False
        self.on_msg(self._on_message)
        self._sender = threading.Thread(target=self._send_loop, name="somwidget-view", daemon=True)
        self._sender.start()
        self.outbox.subscribe(self._on_frame)

    @property
    def intents(self) -> int:
        return self.connection.intents

    @property
    def refused(self) -> int:
        return self.connection.refused

    # -- the pipe -----------------------------------------------------------------------------------------------
    def send_json(self, message: dict) -> None:
        self.send(message)

    def send_frame(self, frame: bytes) -> None:
        self.send(FRAME_ENVELOPE, buffers=[frame])
        self.frames_sent += 1

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
                self.connection.send_latest()
            except Exception:  # a closed comm, an odd frame: the next one tries again
                log.debug("sending a frame to the notebook view failed", exc_info=True)
            rest = period - (time.monotonic() - t)
            if rest > 0:
                time.sleep(rest)

    # -- browser -> session ------------------------------------------------------------------------------------
    def _on_message(self, _widget, content, _buffers) -> None:
        self.connection.receive(json.dumps(content))

    def close(self) -> None:
        """Stop following the session (the session goes on) and close the widget. Once: a closed widget's own
        collection (ipywidgets' __del__) closes it again, perhaps after its session has gone."""
        if not hasattr(self, "outbox") or self._closed:  # __init__ stopped before it followed the session
            return super().close()  # (ClientNotBuilt), or closed already
        self.outbox.unsubscribe(self._on_frame)
        self.connection.close()
        with self._wake:
            self._closed = True
            self._wake.notify()
        super().close()
