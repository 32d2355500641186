"""The studio's routes for browsers and notebooks (every one behind the LAN guard, web/lan.py, and a token, access.py):

    /                        the lobby: make a room of your own (class or teacher token)
    GET  /api/rooms          every room: people, last change, place, links (teacher)
    POST /api/rooms          {"name", "preset"}: a new room; its link comes back (class or teacher)
    /wall                    every room as a live thumbnail (teacher); /wall/ws its feed (wall.py)
    /r/<name>/               the room's page: the clay view with its bar, on a desktop or in a headset (the room's
                             token or the teacher's; a name nobody has taken makes the room, for the class or teacher
                             token, and a class token is sent on to the room's own link)
    /r/<name>/watch/         the same page, watching only (the room's token or the teacher's)
    /r/<name>/view/ws        the room's view websocket (also under watch/): the browser's page, a notebook's
                             `somwidget.join(url)`
    /r/<name>/assets/...     the page's scripts and style (also under watch/)

A room's routes reach that room alone: the websocket is bound to the room of its path when it opens, and a token of
one room opens no other.
"""

from __future__ import annotations

import logging
from pathlib import Path

from aiohttp import web

from ...backend import presets as _presets
from ..client import BUILD_HINT, DIST
from .access import CLASS, MEMBER, TEACHER, StudioAccess, refused
from .front import StudioFront
from .limits import StudioFull, room_name
from .places import PlaceDown
from .rooms import RoomBusy
from .wall import WallFeed

log = logging.getLogger(__name__)

STATIC = Path(__file__).resolve().parent / "static"
NOT_BUILT = ('<!doctype html><meta charset="utf-8"><title>somwidget: the client is not built</title>'
             f"<p>The browser client is not built: {BUILD_HINT}. Then reload.</p>")
_ASSET = "{file:[A-Za-z0-9_.-]+}"
_PAGE = "{page:[A-Za-z0-9_-]+\\.html}"


def _text(status: int, message: str) -> web.Response:
    return web.Response(status=status, text=f"somwidget studio: {message}\n", headers={"Cache-Control": "no-store"})


def failure(exc: Exception) -> web.Response:
    """A refusal of the studio as a response that says what happened."""
    if isinstance(exc, StudioFull):
        return _text(503, str(exc))
    if isinstance(exc, RoomBusy):
        return _text(409, str(exc))
    if isinstance(exc, PlaceDown):
        return _text(503, f"{exc}; try again in a moment")
    if isinstance(exc, KeyError):
        return _text(404, "no such room")
    return _text(400, str(exc))


class StudioRoutes:
    """The routes of the module's docstring over a front and its tokens."""

    def __init__(self, front: StudioFront, access: StudioAccess, dist: Path | None = None):
        self.front = front
        self.access = access
        self.dist = Path(dist) if dist is not None else DIST
        self.wall = WallFeed(front, self.links)

    def add_routes(self, router) -> None:
        router.add_get("/", self.lobby)
        router.add_get("/api/rooms", self.api_rooms)
        router.add_post("/api/rooms", self.api_create)
        router.add_get("/wall", self.wall_page)
        router.add_get("/wall/ws", self.wall_socket)
        router.add_get("/wall/{file:wall\\.(?:js|css)}", self.wall_static)
        for watch in ("", "/watch"):
            router.add_get("/r/{name}" + watch, self.room_redirect)
            router.add_get("/r/{name}" + watch + "/", self.room_page)
            router.add_get("/r/{name}" + watch + "/" + _PAGE, self.room_page)
            router.add_get("/r/{name}" + watch + "/assets/" + _ASSET, self.room_asset)
            router.add_get("/r/{name}" + watch + "/view/ws", self.room_socket)

    def links(self, name: str) -> dict:
        entry = self.front.rooms[name]
        return {"watch": f"/r/{name}/watch/", "part": f"/r/{name}/", "link": f"/r/{name}/?token={entry.token}"}

    # -- the lobby and the list ---------------------------------------------------------------------------------
    async def lobby(self, request):
        grant = self.access.grant(request)
        if grant not in (TEACHER, CLASS):
            return refused()
        html = (STATIC / "lobby.html").read_text(encoding="utf-8")
        options = "".join(f'<option value="{name}"{" selected" if name == self.front.preset else ""}>{name}</option>'
                          for name in _presets.PRESETS)
        html = html.replace("<!--presets-->", options).replace("<!--wall-->", '<a href="/wall">The wall</a>'
                                                               if grant == TEACHER else "")
        return self.access.remember(request, web.Response(text=html, content_type="text/html",
                                                          headers={"Cache-Control": "no-store"}), grant)

    async def api_rooms(self, request):
        if self.access.grant(request) != TEACHER:
            return refused()
        rooms = [dict(info, **self.links(info["name"])) for info in self.front.listing()]
        return web.json_response({"rooms": rooms}, headers={"Cache-Control": "no-store"})

    async def api_create(self, request):
        if self.access.grant(request) not in (TEACHER, CLASS):
            return refused()
        try:
            body = await request.json()
            if not isinstance(body, dict):
                raise ValueError('expected a JSON object like {"name": "alice", "preset": "car"}')
            entry = await self.front.create(body.get("name"), body.get("preset"))
        except (ValueError, StudioFull, PlaceDown) as exc:
            status = 400 if type(exc) is ValueError else 503
            return web.json_response({"error": str(exc)}, status=status)
        return web.json_response({"name": entry.name, "link": self.links(entry.name)["link"]})

    # -- the wall -----------------------------------------------------------------------------------------------
    async def wall_page(self, request):
        grant = self.access.grant(request)
        if grant != TEACHER:
            return refused()
        response = web.FileResponse(STATIC / "wall.html", headers={"Cache-Control": "no-cache"})
        return self.access.remember(request, response, grant)

    async def wall_static(self, request):
        if self.access.grant(request) != TEACHER:
            return refused()
        return web.FileResponse(STATIC / request.match_info["file"], headers={"Cache-Control": "no-cache"})

    async def wall_socket(self, request):
        if self.access.grant(request) != TEACHER:
            return refused()
        return await self.wall.socket(request)

    # -- a room -------------------------------------------------------------------------------------------------
    async def _gate(self, request, page: bool):
        """(entry, grant) for a request to a room's route, or the response that refuses it. A page of a name nobody
        has taken makes the room (teacher or class token)."""
        try:
            name = room_name(request.match_info["name"])
        except ValueError as exc:
            return _text(404, str(exc))
        entry = self.front.rooms.get(name)
        grant = self.access.grant(request, name, entry.token if entry is not None else None)
        if entry is None and page and grant in (TEACHER, CLASS) and not _watching(request):
            try:
                entry = await self.front.create(name, request.query.get("preset"))
            except (ValueError, StudioFull, PlaceDown) as exc:
                return failure(exc)
            if grant == CLASS:  # the person's link is their room's from now on
                raise web.HTTPFound(f"/r/{name}/?token={entry.token}")
        if entry is None or grant not in (TEACHER, MEMBER):
            if grant == CLASS:
                return _text(403, f"a room named {name!r} exists already: choose another name in the lobby")
            return refused()
        return entry, grant

    async def room_redirect(self, request):
        gate = await self._gate(request, page=False)
        if isinstance(gate, web.StreamResponse):
            return gate
        qs = f"?{request.query_string}" if request.query_string else ""
        raise web.HTTPFound(f"/r/{gate[0].name}{'/watch' if _watching(request) else ''}/{qs}")

    async def room_page(self, request):
        gate = await self._gate(request, page=True)
        if isinstance(gate, web.StreamResponse):
            return gate
        entry, grant = gate
        watch = _watching(request)
        page = request.match_info.get("page", "index.html")
        path = self.dist / page
        if not path.is_file():
            return web.Response(status=503, text=NOT_BUILT, content_type="text/html") if page == "index.html" else \
                _text(404, f"no page {page!r}")
        try:
            await self.front.open(entry.name)  # parked: brought back now, so the page shows it at once
        except (KeyError, StudioFull, RoomBusy, PlaceDown) as exc:
            return failure(exc)
        title = f"somwidget: {entry.name}" + (" (watching)" if watch else "")
        html = path.read_text(encoding="utf-8").replace("somwidget XR</title>", f"{title}</title>")
        heading = f"Room {entry.name}" + (", watching only" if watch else "")  # the view adds ": <the clay's title>"
        html = html.replace('<div id="title">somwidget XR</div>', f'<div id="title">{heading}</div>')
        response = web.Response(text=html, content_type="text/html", headers={"Cache-Control": "no-cache"})
        return self.access.remember(request, response, grant, entry.name, entry.token)

    async def room_asset(self, request):
        gate = await self._gate(request, page=False)
        if isinstance(gate, web.StreamResponse):
            return gate
        path = self.dist / "assets" / request.match_info["file"]
        if not path.is_file():
            return _text(404, "no such file")
        return web.FileResponse(path, headers={"Cache-Control": "no-cache"})

    async def room_socket(self, request):
        gate = await self._gate(request, page=False)
        if isinstance(gate, web.StreamResponse):
            return gate
        entry, _ = gate
        try:
            entry = await self.front.open(entry.name)
            assert entry.place is not None  # open() leaves the room on a place (it raises where none takes it)
            return await entry.place.socket(request, entry.name, _watching(request))
        except (KeyError, StudioFull, RoomBusy, PlaceDown) as exc:
            return failure(exc)


def _watching(request) -> bool:
    parts = request.path.split("/")
    return len(parts) > 3 and parts[3] == "watch"
