"""Where a studio's rooms live, as the front sees them: a `LocalPlace` (rooms of the front's own process) or a
`RemotePlace` (a worker's room server, host.py: another process on this machine, or a Dask worker). Both answer the
same coroutines; the front routes each room to its place.

A remote room's websocket is relayed (relay.py): the browser's websocket ends at the front (its tokens, Host and Origin
checked there), which opens one to the worker's room server for it and passes the worker's bytes on as they come, the
browser's messages up (frames are the latest state already: the worker's hub keeps one slot a view, so a slow browser
skips frames). When the worker goes, the front closes the browser's websocket with 1012 (service restart): its link
connects again, to the room's new place.
"""

from __future__ import annotations

import asyncio
import base64
import logging
from typing import Protocol

import aiohttp
from aiohttp import web

from . import relay
from .limits import StudioFull
from .rooms import RoomBusy, Rooms

log = logging.getLogger(__name__)

#: Seconds a call to a worker may take before it counts as a failure.
CALL_TIMEOUT = 10.0
#: Seconds a health check may take.
HEALTH_TIMEOUT = 2.0


class PlaceDown(RuntimeError):
    """A worker that does not answer."""


class Place(Protocol):
    """What the front (front.py, routes.py, wall.py) asks of a place: `LocalPlace` and `RemotePlace` answer it.

    label: the place as messages name it; alive: False once the front found it dead (front.lost); failures: failed
    looks in a row; load: its latest report ({"rooms", "nodes", "limit", ...}); gpu: the GPU it shares with other
    places (None: it shares none). A remote place raises PlaceDown when its worker does not answer."""

    label: str
    alive: bool
    failures: int
    load: dict
    gpu: str | None

    async def health(self) -> dict: ...

    async def known(self) -> list[dict]: ...

    async def listing(self) -> list[dict]: ...

    async def create(self, name: str, token: str, preset: str) -> dict: ...

    async def open(self, name: str) -> dict: ...

    async def park(self, name: str, force: bool = False) -> bool: ...

    async def park_idle(self) -> list[str]: ...

    async def thumbs(self, seen: dict) -> list[dict]:
        """The thumbnails of the rooms named in `seen` ({name: seq the wall has, or None}) newer than it has: the
        rooms live or parked here, and any other from its folder (Rooms.thumbs)."""
        ...

    async def socket(self, request: web.Request, name: str, watch: bool) -> web.StreamResponse: ...

    async def close(self) -> None: ...


class LocalPlace:
    """The rooms of this process."""

    def __init__(self, rooms: Rooms):
        self.rooms = rooms
        self.label = rooms.label
        self.gpu: str | None = None  # shares no GPU with another place
        self.alive = True
        self.failures = 0
        self.load = rooms.load()

    async def _run(self, call, *args):
        return await asyncio.get_running_loop().run_in_executor(None, call, *args)

    async def health(self) -> dict:
        self.load = self.rooms.load()
        return {"label": self.label, "load": self.load}

    async def known(self) -> list[dict]:
        return [vars(r) for r in await self._run(self.rooms.known)]

    async def listing(self) -> list[dict]:
        return self.rooms.listing()

    async def create(self, name: str, token: str, preset: str) -> dict:
        return (await self._run(self.rooms.create, name, token, preset)).info()

    async def open(self, name: str) -> dict:
        return (await self._run(self.rooms.open, name)).info()

    async def park(self, name: str, force: bool = False) -> bool:
        return await self._run(self.rooms.park, name, force)

    async def park_idle(self) -> list[str]:
        return await self._run(self.rooms.park_idle)

    async def thumbs(self, seen: dict) -> list[dict]:
        return await self._run(self.rooms.thumbs, seen)

    async def socket(self, request: web.Request, name: str, watch: bool) -> web.StreamResponse:
        room = await self._run(self.rooms.open, name)
        return await room.hub.open_socket(request, watch=watch)

    async def close(self) -> None:
        await self._run(self.rooms.close)


def _raise_refusal(status: int, body: dict) -> None:
    message = body.get("error", f"status {status}")
    kind = body.get("kind")
    if kind == "full":
        raise StudioFull(message)
    if kind == "busy":
        raise RoomBusy(message)
    if kind == "missing":
        raise KeyError(message)
    raise ValueError(message)


class RemotePlace:
    """A worker's room server at `url` (http://host:port), called with the studio's worker `secret`."""

    def __init__(self, url: str, secret: str, label: str | None = None):
        self.url = url.rstrip("/")
        self.secret = secret
        self.label = label or self.url
        self.index: int | None = None  # its number among a machine's worker processes (workers.py)
        self.gpu: str | None = None  # the GPU it steps its rooms on, where several workers share one (workers.py)
        self.alive = True
        self.failures = 0
        self.load: dict = {"rooms": 0, "nodes": 0, "limit": 1}
        self._http: aiohttp.ClientSession | None = None
        self._relays: set[relay.Upstream] = set()  # the browsers' websockets relayed to this worker now

    @property
    def headers(self) -> dict:
        return {"Authorization": f"Bearer {self.secret}"}

    def _client(self) -> aiohttp.ClientSession:
        if self._http is None or self._http.closed:
            self._http = aiohttp.ClientSession(headers=self.headers)
        return self._http

    async def _call(self, method: str, path: str, body=None, timeout: float = CALL_TIMEOUT):
        try:
            async with self._client().request(method, self.url + path, json=body,
                                              timeout=aiohttp.ClientTimeout(total=timeout)) as r:
                data = await r.json(content_type=None)
        except (aiohttp.ClientError, OSError, asyncio.TimeoutError, ValueError) as exc:
            raise PlaceDown(f"the worker at {self.url} does not answer: {exc or type(exc).__name__}") from None
        if r.status >= 400:
            _raise_refusal(r.status, data if isinstance(data, dict) else {})
        return data

    async def health(self) -> dict:
        data = await self._call("GET", "/studio/health", timeout=HEALTH_TIMEOUT)
        self.load = data["load"]
        return data

    async def known(self) -> list[dict]:
        return await self._call("GET", "/studio/known")

    async def listing(self) -> list[dict]:
        return await self._call("GET", "/studio/rooms")

    async def create(self, name: str, token: str, preset: str) -> dict:
        return await self._call("POST", "/studio/rooms", {"name": name, "token": token, "preset": preset})

    async def open(self, name: str) -> dict:
        return await self._call("POST", f"/studio/rooms/{name}/open")

    async def park(self, name: str, force: bool = False) -> bool:
        return (await self._call("POST", f"/studio/rooms/{name}/park" + ("?force=1" if force else "")))["parked"]

    async def park_idle(self) -> list[str]:
        return []  # the worker parks its own (host.py)

    async def thumbs(self, seen: dict) -> list[dict]:
        out = await self._call("POST", "/studio/thumbs", {"seen": seen})
        for item in out:
            item["thumb"] = base64.b64decode(item["thumb"])
        return out

    async def socket(self, request: web.Request, name: str, watch: bool) -> web.StreamResponse:
        """The browser's websocket relayed to the room's on the worker, the bytes passed on both ways as they come
        (relay.py)."""
        url = self.url + f"/studio/rooms/{name}/ws" + ("?watch=1" if watch else "")
        try:
            upstream = await relay.open_upstream(url, self.headers)
        except relay.Refused as exc:
            return web.Response(status=exc.status, text=f"somwidget studio: the room's worker refused: {exc.text}\n")
        except (OSError, asyncio.TimeoutError, asyncio.IncompleteReadError, ValueError) as exc:
            raise PlaceDown(f"the worker at {self.url} does not answer: {exc or type(exc).__name__}") from None
        self._relays.add(upstream)
        try:
            return await relay.relay(request, upstream)
        finally:
            self._relays.discard(upstream)

    async def close(self) -> None:
        """The browsers' websockets to this worker closed (1001: the studio stops; their pages connect again when it
        is back), then the front's own connection."""
        for upstream in list(self._relays):
            upstream.finish("stopping")
        if self._http is not None:
            await self._http.close()
