"""A studio room's clay view in a notebook (`RoomSession.show()`): the notebook widget's own module (ClayWidget's),
its messages relayed to and from the room's view websocket. The kernel holds the websocket, so the browser needs no
route to the studio; the room sees one more hand, a notebook.
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
from typing import Any

import anywidget

from ..client import view_module
from ..notebook.widget import FRAME_ENVELOPE, ClayWidget
from .remote import socket_url

log = logging.getLogger(__name__)


class RoomWidget(ClayWidget):
    """The live view of a studio room at `link` (see the module's docstring)."""

    def __init__(self, link: str, height: int = 520, ssl=None):
        anywidget.AnyWidget.__init__(self, _esm=view_module(), height=int(height))  # no local session to follow
        self.url, self.room, _ = socket_url(link)
        self.frames_sent = 0
        self._ssl = ssl
        self._ws: Any = None  # aiohttp's websocket once connected
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="somwidget-room-view", daemon=True)
        self._thread.start()
        asyncio.run_coroutine_threadsafe(self._connect(), self._loop).result(30)
        self.on_msg(self._on_message)

    async def _connect(self) -> None:
        import aiohttp

        self._http = aiohttp.ClientSession()
        self._ws = await self._http.ws_connect(self.url, ssl=self._ssl, max_msg_size=0, compress=0, heartbeat=20.0)
        await self._ws.send_json({"type": "hand", "kind": "notebook"})
        asyncio.ensure_future(self._relay())

    async def _relay(self) -> None:
        import aiohttp

        async for msg in self._ws:
            try:
                if msg.type == aiohttp.WSMsgType.BINARY:
                    self.send(FRAME_ENVELOPE, buffers=[msg.data])
                    self.frames_sent += 1
                elif msg.type == aiohttp.WSMsgType.TEXT:
                    self.send(json.loads(msg.data))
            except Exception:  # a closed comm: the next message tries again
                log.debug("relaying to the notebook view failed", exc_info=True)

    def _on_message(self, _widget, content, _buffers) -> None:
        if self._ws is not None and not self._ws.closed:
            asyncio.run_coroutine_threadsafe(self._ws.send_str(json.dumps(content)), self._loop)

    @property
    def intents(self) -> int:
        return 0

    @property
    def refused(self) -> int:
        return 0

    def close(self) -> None:
        """Leave the room (the room goes on) and close the widget."""
        async def shut():
            if self._ws is not None:
                await self._ws.close()
            await self._http.close()

        if self._loop.is_running():
            try:
                asyncio.run_coroutine_threadsafe(shut(), self._loop).result(10)
            except Exception:  # pragma: no cover - closing goes on
                pass
            self._loop.call_soon_threadsafe(self._loop.stop)
        anywidget.AnyWidget.close(self)
