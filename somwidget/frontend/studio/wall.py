"""The wall's feed: every room's list entry and thumbnail, once a second, to every wall page open (the websocket
/wall/ws; nothing is made while no wall is open).

Each WALL_PERIOD the feed asks each room's place for its thumbnail when newer than the one it has (thumbs.py: a room's
clay at most THUMB_NODES nodes, about 7 KB for the car, made only when its frame changed; a room without a place,
parked before the studio restarted, is read from its folder by any place) and sends the wall pages, in order:

    {"type": "rooms", "rooms": [...]}                    the list (front.listing), when it changed
    {"type": "shape", "slot", "name", "generation", "shape"}   a room's shape, when its generation is new
    binary: THUMB_HEADER (b"SOMT", slot, seq, n), then n float32 x, y, z and n RGB bytes

A page that opens gets the list and every shape and thumbnail kept so far at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import struct
from collections.abc import Callable

from aiohttp import WSMsgType, web

from .front import StudioFront
from .places import PlaceDown

log = logging.getLogger(__name__)

#: Seconds between two updates of the wall.
WALL_PERIOD = 1.0
THUMB_HEADER = struct.Struct("<4sIII")
THUMB_MAGIC = b"SOMT"


class WallFeed:
    """The feed of the module's docstring over a `StudioFront`; `links(name)`: the links a wall shows for a room."""

    def __init__(self, front: StudioFront, links: Callable[[str], dict]):
        self.front = front
        self.links = links
        self.pages: set[web.WebSocketResponse] = set()
        self.kept: dict[str, tuple[int, int, dict, bytes]] = {}  # name -> (generation, seq, shape, thumbnail)
        self._listing = ""
        self._task: asyncio.Task | None = None

    def start(self) -> None:
        self._task = asyncio.ensure_future(self._run())

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        for ws in list(self.pages):
            await ws.close(code=1001, message=b"server shutdown")

    def rooms_message(self) -> str:
        rooms = [dict(info, **self.links(info["name"])) for info in self.front.listing()]
        return json.dumps({"type": "rooms", "rooms": rooms})

    def _packets(self, name: str, kept, new_shape: bool) -> list:
        entry = self.front.rooms.get(name)
        if entry is None:
            return []
        generation, seq, shape, data = kept
        out = []
        if new_shape:
            out.append(json.dumps({"type": "shape", "slot": entry.slot, "name": name, "generation": generation,
                                   "shape": shape}))
        out.append(THUMB_HEADER.pack(THUMB_MAGIC, entry.slot, seq, shape["n"]) + data)
        return out

    async def socket(self, request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=4096, compress=False)
        await ws.prepare(request)
        self.pages.add(ws)
        try:
            await ws.send_str(self.rooms_message())
            for name, kept in list(self.kept.items()):
                for packet in self._packets(name, kept, True):
                    await (ws.send_str(packet) if isinstance(packet, str) else ws.send_bytes(packet))
            if self._task is not None:
                await self.tick()
            async for msg in ws:  # a wall sends nothing; it is read until it goes
                if msg.type == WSMsgType.ERROR:
                    break
        finally:
            self.pages.discard(ws)
        return ws

    async def _run(self) -> None:
        while True:
            await asyncio.sleep(WALL_PERIOD)
            if self.pages:
                try:
                    await self.tick()
                except Exception:  # pragma: no cover - a wall must not stop the studio
                    log.exception("studio: updating the wall failed")

    def _asks(self) -> dict:
        """place -> {name: the seq the wall has, or None}: each room asked of its place; a room without one (parked
        before the studio restarted, or its place gone) of the first live place, which reads it from its folder."""
        alive = self.front.alive()
        asks: dict = {}
        for entry in list(self.front.rooms.values()):
            place = entry.place if entry.place is not None and entry.place.alive else (alive[0] if alive else None)
            if place is not None:
                kept = self.kept.get(entry.name)
                asks.setdefault(place, {})[entry.name] = kept[1] if kept is not None else None
        return asks

    async def tick(self) -> None:
        """One update of every wall page."""
        packets: list = []
        listing = self.rooms_message()
        if listing != self._listing:
            self._listing = listing
            packets.append(listing)
        for place, seen in self._asks().items():
            try:
                updates = await place.thumbs(seen)
            except PlaceDown:
                continue
            for item in updates:
                name = item["name"]
                before = self.kept.get(name)
                kept = (item["generation"], item["seq"], item["shape"], item["thumb"])
                self.kept[name] = kept
                # a new generation, or the same number on another worker (a room brought back) with another shape
                packets += self._packets(name, kept, before is None or before[0] != kept[0] or before[2] != kept[2])
        for ws in list(self.pages):
            try:
                for packet in packets:
                    await (ws.send_str(packet) if isinstance(packet, str) else ws.send_bytes(packet))
            except (ConnectionError, RuntimeError):
                self.pages.discard(ws)
