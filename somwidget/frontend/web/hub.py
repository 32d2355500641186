"""The clay view's server side on an aiohttp app: the websocket /view/ws that feeds every browser view of a Session
(the web app's page, the XR page; /xr/ws is the same route under the name headsets paired before it had), the XR page
at /xr/ and the view's module at /xr/somview.js.

`attach(server, session, token=None)` adds the routes to a running trame/wslink server (call it from
`ctrl.on_server_bind`, whose argument is the wslink server) or to any aiohttp `web.Application`. One `ViewHub` per
app holds the connected clients, each a `ViewConnection` (transport/connection.py) over its websocket and a hand in
the session's one registry of holders (transport/holders.py, shared with its notebook widgets and Python); every
client shares the one `Session`, so a desktop tab, the trame panel and a headset all see each other's moves.

Threads: the session's outbox (transport/outbox.py) calls `ViewHub._on_frame` on the training thread; that only
wakes the event loop. Encoding and sending happen on the event loop's thread; intents run on the session's training
thread (the loop never waits for the Som), whose replies and news come back through the client's pipe, which hands
them to the loop. Each client has a slot for the latest frame and a bounded queue of JSON messages, sent first: a
slow client gets the latest frame, never a backlog, and its replies never wait behind frames. A client whose queue
overflows, or that stops reading (a send that does not finish within SEND_TIMEOUT), is dropped.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import logging
import threading
import time
from pathlib import Path

from aiohttp import WSMsgType, web

from ..client import BUILD_HINT, DIST
from ..transport import messages
from ..transport.connection import ViewConnection
from ..transport.holders import holders_for
from ..transport.outbox import outbox_for
from . import lan
from .loop_calls import calls_for

log = logging.getLogger(__name__)

#: The websocket every view connects to, and the older name of the same route (headsets paired before).
VIEW_SOCKET = "/view/ws"
OLD_VIEW_SOCKET = "/xr/ws"
#: Refused messages a client may send within ERROR_WINDOW seconds before the server closes its socket.
MAX_ERRORS = 200
ERROR_WINDOW = 10.0
#: JSON messages waiting for one client beyond which it is dropped as too slow (frames do not queue: one slot).
MAX_TEXTS = 512
#: Seconds one send may take before the client counts as not reading and is dropped.
SEND_TIMEOUT = 5.0
NOT_BUILT = ('<!doctype html><meta charset="utf-8"><title>somwidget: the client is not built</title>'
             f"<p>The browser client is not built: {BUILD_HINT}. Then reload.</p>")


class _Client:
    """One websocket client: the pipe of its ViewConnection (a queue of JSON texts, sent first, and a slot for the
    latest frame; from another thread both are handed to the loop) and its counters."""

    connection: ViewConnection  # set by the hub as the client is made (the connection sends through this client)

    def __init__(self, cid: int, ws: web.WebSocketResponse, remote: str | None) -> None:
        self.id = cid
        self.ws = ws
        self.remote = remote
        self.loop = asyncio.get_running_loop()
        self.calls = calls_for(self.loop)  # one wake of the loop for the calls of every client (loop_calls.py)
        self.texts: collections.deque = collections.deque()  # JSON messages, sent before any frame
        self.frame: bytes | None = None  # the latest frame not yet sent (a newer one replaces it)
        self.wake = asyncio.Event()
        self.errors: collections.deque = collections.deque()
        self.frames_sent = 0
        self.bytes_sent = 0
        self.closed = False
        self.close_reason = b""
        self.transport = None  # the connection, to cut when the client stops reading

    @property
    def refused(self) -> int:
        return self.connection.refused

    def send_json(self, message: dict) -> None:
        if not self.closed:
            self._on_loop(self._push, json.dumps(message))

    def _push(self, text: str) -> None:
        if self.closed:
            return
        if len(self.texts) >= MAX_TEXTS:  # it does not read what it asked for: drop it, keep no more
            self.drop(b"too slow")
            return
        self.texts.append(text)
        self.wake.set()

    def send_frame(self, data: bytes) -> None:
        self._on_loop(self._take_frame, data)

    def _take_frame(self, data: bytes) -> None:
        self.frame = data  # not sent yet: the newer frame replaces it
        self.wake.set()

    def _on_loop(self, call, arg) -> None:
        """`call(arg)` on the loop's thread, in the order handed, whichever thread hands it (a reply made on the
        training thread stays before a pong answered later on the loop); the calls of every client of the loop share
        its wakes (loop_calls.py)."""
        self.calls.call(call, arg)

    def drop(self, reason: bytes) -> None:
        self.closed = True
        self.close_reason = self.close_reason or reason
        self.texts.clear()
        self.frame = None
        self.wake.set()


class ViewHub:
    """The view's routes (/view/ws, /xr/...) and their websocket clients, for one Session."""

    def __init__(self, session, token: str | None = None, dist: Path | None = None, max_fps: float = messages.MAX_FPS):
        self.session = session
        self.token = token or None
        self.dist = Path(dist) if dist is not None else DIST
        self.max_fps = float(max_fps)
        self.clients: dict[int, _Client] = {}
        self.holders = holders_for(session)
        self.outbox = outbox_for(session)
        self.refused_total = 0
        self.intents_total = 0
        self._next_id = 1
        self._loop: asyncio.AbstractEventLoop | None = None
        self._scheduled = False
        self._scheduled_lock = threading.Lock()
        self.outbox.subscribe(self._on_frame)

    # -- routes ----------------------------------------------------------------------------------------------
    def add_routes(self, router) -> None:
        router.add_get("/xr", self._redirect)
        router.add_get("/xr/", self._index)
        router.add_get(VIEW_SOCKET, self._websocket)
        router.add_get(OLD_VIEW_SOCKET, self._websocket)
        router.add_get("/xr/status", self._status)
        router.add_get("/xr/somview.js", self._view_module)
        router.add_get("/xr/{name:[A-Za-z0-9_.-]+\\.html}", self._page)
        if (self.dist / "assets").is_dir():
            router.add_static("/xr/assets/", self.dist / "assets", append_version=False)
        else:
            router.add_get("/xr/assets/{tail:.*}", self._not_built)

    def _allowed(self, request) -> bool:
        return lan.token_ok(request, self.token)

    def _cookie(self, request, response):
        return lan.set_token_cookie(request, response, self.token)

    async def _redirect(self, request):
        if not self._allowed(request):
            return lan.forbidden()
        qs = f"?{request.query_string}" if request.query_string else ""
        raise web.HTTPFound(f"/xr/{qs}")

    async def _index(self, request):
        return await self._serve_page(request, "index.html")

    async def _page(self, request):
        return await self._serve_page(request, request.match_info["name"])

    async def _serve_page(self, request, name: str):
        if not self._allowed(request):
            return lan.forbidden()
        path = self.dist / name
        if not self.dist.is_dir():
            return web.Response(status=503, text=NOT_BUILT, content_type="text/html")
        if not path.is_file():
            raise web.HTTPNotFound(text=f"no page {name!r} under /xr/")
        response = web.FileResponse(path, headers={"Cache-Control": "no-cache"})
        return self._cookie(request, response)

    async def _view_module(self, request):
        if not self._allowed(request):
            return lan.forbidden()
        path = self.dist / "somview.js"
        if not path.is_file():
            return web.Response(status=503, text=NOT_BUILT, content_type="text/html")
        response = web.FileResponse(path, headers={"Cache-Control": "no-cache",
                                                   "Content-Type": "text/javascript; charset=utf-8"})
        return self._cookie(request, response)

    async def _not_built(self, request):
        if not self._allowed(request):
            return lan.forbidden()
        return web.Response(status=503, text=NOT_BUILT, content_type="text/html")

    async def _status(self, request):
        """JSON: the connected views, grabs, counters (for tests and benchmarks)."""
        if not self._allowed(request):
            return lan.forbidden()
        body = {"clients": [{"id": c.id, "frames_sent": c.frames_sent, "bytes_sent": c.bytes_sent,
                             "refused": c.refused} for c in self.clients.values()],
                "grabs": {str(i): cid for i, cid in self.grabs.items()}, "refused_total": self.refused_total,
                "intents_total": self.intents_total, "built": (self.dist / "index.html").is_file()}
        return web.json_response(body, headers={"Cache-Control": "no-store"})

    # -- frames ---------------------------------------------------------------------------------------------------
    def _on_frame(self) -> None:
        """Training thread: the newest frame's broadcast handed to the loop once (the rooms of a studio worker share
        the loop's wakes: loop_calls.py)."""
        with self._scheduled_lock:
            if self._scheduled or not self.clients or self._loop is None:
                return
            self._scheduled = True
        calls_for(self._loop).call(self._broadcast)

    def _send_frame(self, client: _Client, frame=None) -> None:
        try:
            client.connection.send_latest(frame)
        except Exception:  # never let one odd frame stop the stream
            log.exception("encoding a frame for view client %d failed", client.id)

    def _broadcast(self) -> None:
        with self._scheduled_lock:
            self._scheduled = False
        frame = self.outbox.latest
        for client in list(self.clients.values()):
            self._send_frame(client, frame)

    @property
    def grabs(self) -> dict[int, int | None]:
        """Control index (now) -> the id of the client holding it (None: another view, or Python)."""
        return {index: getattr(view, "client_id", None) for index, view in self.holders.held().items()}

    async def _sender(self, client: _Client) -> None:
        """Sends the client's JSON messages first, then its latest frame at most max_fps a second; a send that
        does not finish within SEND_TIMEOUT drops the client (it stopped reading)."""
        period = 1.0 / self.max_fps if self.max_fps > 0 else 0.0
        last_frame = 0.0
        ws = client.ws
        try:
            while not ws.closed and not client.closed:
                await client.wake.wait()
                client.wake.clear()
                while not ws.closed and not client.closed and (client.texts or client.frame is not None):
                    if client.texts:
                        text = client.texts.popleft()
                        await asyncio.wait_for(ws.send_str(text), SEND_TIMEOUT)
                        client.bytes_sent += len(text)
                        continue
                    wait = last_frame + period - time.monotonic()
                    if wait > 0:  # paced; a reply that comes meanwhile goes out at once
                        client.wake.clear()
                        with contextlib.suppress(asyncio.TimeoutError):
                            await asyncio.wait_for(client.wake.wait(), wait)
                        continue
                    data, client.frame = client.frame, None
                    if data is None:  # cannot be: texts go out first (above), then the frame that is waiting
                        continue
                    await asyncio.wait_for(ws.send_bytes(data), SEND_TIMEOUT)
                    last_frame = time.monotonic()
                    client.frames_sent += 1
                    client.bytes_sent += len(data)
        except asyncio.TimeoutError:
            log.warning("view client %d stopped reading (a send took over %g s); dropping it", client.id, SEND_TIMEOUT)
            client.drop(b"not reading")
            if client.transport is not None:  # a close frame would wait behind the unread data: cut it
                client.transport.abort()
            return
        except (ConnectionError, RuntimeError, asyncio.CancelledError):
            pass
        if client.closed and not ws.closed:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(ws.close(code=1008, message=client.close_reason), SEND_TIMEOUT)

    # -- websocket -----------------------------------------------------------------------------------------------
    async def _websocket(self, request):
        return await self.open_socket(request)

    async def open_socket(self, request, watch: bool = False):
        """A view's websocket on this hub (its route's handler; a studio's room routes call it after their own
        checks). `watch`: the view only watches (connection.py: WATCHING)."""
        if not self._allowed(request):
            log.info("refused a view websocket from %s: no valid token", request.remote)
            return lan.forbidden()
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=64 * 1024, compress=False)
        await ws.prepare(request)
        if self._loop is None:
            self._loop = asyncio.get_running_loop()
        client = _Client(self._next_id, ws, request.remote)
        client.transport = request.transport
        client.connection = ViewConnection(self.session, client, client_id=client.id, name=f"view client {client.id}",
                                           watch=watch)
        self._next_id += 1
        self.clients[client.id] = client
        log.info("view client %d connected from %s (%s)", client.id, request.remote, request.path)
        sender = asyncio.ensure_future(self._sender(client))
        try:
            client.connection.open()
            async for msg in ws:
                if msg.type in (WSMsgType.TEXT, WSMsgType.BINARY):
                    self._receive(client, msg.data)
                elif msg.type == WSMsgType.ERROR:
                    break
                if client.closed:
                    log.warning("view client %d dropped: %s", client.id, client.close_reason.decode())
                    await ws.close(code=1008, message=client.close_reason)
                    break
        finally:
            self.clients.pop(client.id, None)
            client.connection.close()  # a client gone mid-grab: its drag is a completed step
            client.wake.set()
            sender.cancel()
            log.info("view client %d disconnected (%d frames, %d bytes sent, %d refused)", client.id,
                     client.frames_sent, client.bytes_sent, client.refused)
        return ws

    def _receive(self, client: _Client, data) -> None:
        """One message of a client to its connection (its intent runs on the training thread, then is counted
        here)."""
        done = client.connection.receive(data)
        if done.done():
            self._counted(client, done.result())
        else:
            done.add_done_callback(lambda f: client._on_loop(lambda ok: self._counted(client, ok), f.result()))

    def _counted(self, client: _Client, ok: bool) -> None:
        """A client refused more than MAX_ERRORS times within ERROR_WINDOW seconds is dropped."""
        if ok:
            self.intents_total += 1
            return
        self.refused_total += 1
        now = time.monotonic()
        client.errors.append(now)
        while client.errors and now - client.errors[0] > ERROR_WINDOW:
            client.errors.popleft()
        if len(client.errors) > MAX_ERRORS:
            client.drop(b"too many refused messages")

    async def close(self, *_) -> None:
        for c in list(self.clients.values()):
            await c.ws.close(code=1001, message=b"server shutdown")

    def detach(self) -> None:
        self.outbox.unsubscribe(self._on_frame)


def attach(server, session, token: str | None = None, dist=None) -> ViewHub:
    """Serve the clay view's routes on `server`: a wslink server (what `ctrl.on_server_bind` passes), an aiohttp
    `web.Application` or its router. Adds the websocket /view/ws (and /xr/ws, the same), GET /xr/ (the XR page;
    /xr redirects), /xr/<page>.html, /xr/assets/..., /xr/somview.js and /xr/status. With `token`, every one of them
    answers 403 unless the request carries it (?token=, the cookie, or Authorization: Bearer). Returns the hub."""
    app = getattr(server, "app", server)
    router = getattr(app, "router", app)
    if not hasattr(router, "add_get"):
        raise TypeError(f"attach: expected a wslink server, an aiohttp Application or a router, got {server!r}")
    hub = ViewHub(session, token=token, dist=dist)
    hub.add_routes(router)
    if isinstance(app, web.Application) and not app.frozen:
        app.on_shutdown.append(hub.close)
    return hub


__all__ = ["ViewHub", "attach", "DIST", "VIEW_SOCKET", "OLD_VIEW_SOCKET"]
