"""A worker's room server: the rooms of one process (rooms.py) behind routes that only the studio's front calls, with
the studio's worker secret on every request (Authorization: Bearer). Browsers never reach it: the front checks their
tokens and relays each room's websocket here (places.py).

    GET  /studio/health                 this worker: its label and load
    GET  /studio/known                  every room with a folder (records, tokens included)
    GET  /studio/rooms                  the rooms of this worker (live and parked)
    POST /studio/rooms                  {"name", "token", "preset"}: a new room
    POST /studio/rooms/{name}/open      bring it back here (or find it live)
    POST /studio/rooms/{name}/park      park it now (?force=1: whatever views it has)
    POST /studio/thumbs                 {"seen": {name: seq or null}}: those rooms' thumbnails newer than those
    GET  /studio/rooms/{name}/ws        the room's view websocket (?watch=1: a view that only watches)

`RoomServer` runs it on an event loop of its own in a daemon thread (a worker process's, or a Dask worker's), parking
idle rooms every PARK_PERIOD seconds.
"""

from __future__ import annotations

import asyncio
import base64
import hmac
import logging
import threading

from aiohttp import web

from ..web import lan
from .limits import StudioFull
from .rooms import RoomBusy, Rooms

#: Seconds a stop waits for the connections still open (the pages' websockets) before it ends them: the worker's
#: room server and the front alike (serve.py).
SHUTDOWN_TIMEOUT = 3.0

log = logging.getLogger(__name__)

#: Seconds between two looks for idle rooms.
PARK_PERIOD = 2.0


def _authorised(request, secret: str) -> bool:
    auth = request.headers.get("Authorization", "")
    return auth.lower().startswith("bearer ") and hmac.compare_digest(auth[7:].strip().encode(), secret.encode())


def error_response(exc: Exception) -> web.Response:
    """A refusal as the front reads it: {"error", "kind"} with a status that says which."""
    kind = {StudioFull: "full", RoomBusy: "busy", KeyError: "missing"}.get(type(exc), "invalid")
    status = {"full": 503, "busy": 409, "missing": 404}.get(kind, 400)
    message = f"no room {exc.args[0]!r}" if isinstance(exc, KeyError) else str(exc)
    return web.json_response({"error": message, "kind": kind}, status=status)


class RoomHost:
    """The routes of the module's docstring over `rooms`."""

    def __init__(self, rooms: Rooms, secret: str):
        if not secret:
            raise ValueError("a room server needs the studio's worker secret")
        self.rooms = rooms
        self.secret = secret

    def app(self) -> web.Application:
        secret = self.secret

        @web.middleware
        async def check(request, handler):
            if not _authorised(request, secret):
                return web.Response(status=403, text="somwidget studio: workers answer the studio's front only\n")
            return await handler(request)

        app = web.Application(middlewares=[lan.request_guard(check_host=False), check], client_max_size=1 << 20)
        r = app.router
        r.add_get("/studio/health", self.health)
        r.add_get("/studio/known", self.known)
        r.add_get("/studio/rooms", self.listing)
        r.add_post("/studio/rooms", self.create)
        r.add_post("/studio/rooms/{name}/open", self.open)
        r.add_post("/studio/rooms/{name}/park", self.park)
        r.add_post("/studio/thumbs", self.thumbs)
        r.add_get("/studio/rooms/{name}/ws", self.socket)
        return app

    async def _run(self, call, *args):
        return await asyncio.get_running_loop().run_in_executor(None, call, *args)

    async def health(self, request):
        return web.json_response({"label": self.rooms.label, "load": self.rooms.load()})

    async def known(self, request):
        return web.json_response([vars(r) for r in await self._run(self.rooms.known)])

    async def listing(self, request):
        return web.json_response(self.rooms.listing())

    async def create(self, request):
        try:
            body = await request.json()
            room = await self._run(self.rooms.create, body["name"], body["token"], body.get("preset", "car"))
        except (ValueError, KeyError, TypeError, RuntimeError) as exc:
            return error_response(exc)
        return web.json_response(room.info())

    async def open(self, request):
        try:
            room = await self._run(self.rooms.open, request.match_info["name"])
        except (ValueError, KeyError, RuntimeError) as exc:
            return error_response(exc)
        return web.json_response(room.info())

    async def park(self, request):
        force = request.query.get("force") == "1"
        try:
            parked = await self._run(self.rooms.park, request.match_info["name"], force)
        except ValueError as exc:
            return error_response(exc)
        return web.json_response({"parked": parked})

    async def thumbs(self, request):
        seen = dict((await request.json()).get("seen", {}))
        out = await self._run(self.rooms.thumbs, seen)
        for item in out:
            item["thumb"] = base64.b64encode(item["thumb"]).decode("ascii")
        return web.json_response(out)

    async def socket(self, request):
        try:
            room = await self._run(self.rooms.open, request.match_info["name"])
        except (ValueError, KeyError, RuntimeError) as exc:
            return error_response(exc)
        return await room.hub.open_socket(request, watch=request.query.get("watch") == "1")


class RoomServer:
    """`RoomHost` on host:port (0: a free one) from a daemon thread; `url` once started."""

    def __init__(self, rooms: Rooms, secret: str, host: str = "127.0.0.1", port: int = 0):
        self.rooms = rooms
        self.host = RoomHost(rooms, secret)
        self.bind = host
        self.port = port
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        shown = f"[{self.bind}]" if ":" in self.bind else self.bind
        return f"http://{shown}:{self.port}"

    def start(self, timeout: float = 30.0) -> RoomServer:
        self._thread = threading.Thread(target=self._run, name="somwidget-room-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout) or self._error is not None:
            raise RuntimeError(f"the room server did not start: {self._error}")
        return self

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)
        try:
            runner = loop.run_until_complete(self._start())
        except BaseException as exc:
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        parking = loop.create_task(self._park_loop())
        try:
            loop.run_forever()
        finally:
            parking.cancel()
            loop.run_until_complete(runner.cleanup())
            loop.close()

    async def _start(self) -> web.AppRunner:
        """Serve on bind:port (the port chosen now where it is 0); the runner, for the cleanup."""
        runner = web.AppRunner(self.host.app(), handle_signals=False, access_log=None,
                               shutdown_timeout=SHUTDOWN_TIMEOUT)
        await runner.setup()
        site = web.TCPSite(runner, self.bind, self.port)
        await site.start()
        self.port = site._server.sockets[0].getsockname()[1]
        return runner

    async def _park_loop(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(PARK_PERIOD)
            try:
                await loop.run_in_executor(None, self.rooms.park_idle)
            except Exception:  # pragma: no cover - parking must not stop the server
                log.exception("studio: parking idle rooms failed")

    def stop(self) -> None:
        """Stop serving and close every room (each saved)."""
        if self._loop is not None and self._loop.is_running():
            self._loop.call_soon_threadsafe(self._loop.stop)
        if self._thread is not None:
            self._thread.join(15)
        self.rooms.close()
