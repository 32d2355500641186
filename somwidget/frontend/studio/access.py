"""Who may do what in a studio: three kinds of token, every one compared in constant time.

- the teacher's token: the wall, the list of rooms, every room (to watch, or to take part), making rooms;
- the class token: the lobby, where a person makes a room of their own under a name nobody has taken (it opens no
  room that exists: a taken name is refused);
- a room's token (made with the room, kept in its folder): that room alone. A room's link carries it.

A request shows a token in its URL (?token=), an `Authorization: Bearer` header or a cookie. A page opened with a token
in its URL gets a cookie so that its own assets and websocket need not repeat it: the teacher's cookie for the whole
studio (path /), a room's cookie for that room's pages only (path /r/<name>/, named after the room), each HttpOnly and
SameSite=Strict, Secure over HTTPS. The LAN guard (web/lan.py: the Host and Origin checks, HTTPS beyond loopback)
runs before any of this on every route.
"""

from __future__ import annotations

import hmac
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from aiohttp import web

from ..web import lan

TEACHER = "teacher"
MEMBER = "member"
CLASS = "class"
#: The studio's teacher and class tokens, in its rooms folder (a room's name has no dot: no room is called so).
ACCESS_FILE = "access.json"
REFUSED = ("somwidget studio: this page needs its link's token. A room's link (/r/<name>/?token=...) opens that room "
           "alone; the wall and the other rooms need the teacher's link.\n")


def _same(a: str | None, b: str | None) -> bool:
    return bool(a and b and hmac.compare_digest(a.encode("utf-8", "replace"), b.encode("utf-8")))


def _port(request) -> int:
    try:
        return int(request.url.port or 0)
    except (TypeError, ValueError):
        return 0


def teacher_cookie(request) -> str:
    return f"somwidget_teacher_{_port(request)}"


def room_cookie(request, room: str) -> str:
    return f"somwidget_room_{_port(request)}_{room}"


def _given(request) -> tuple[list[str], bool]:
    """(the tokens a request shows in its URL or header, whether it showed one there)."""
    shown = []
    if request.query.get("token"):
        shown.append(request.query["token"])
    auth = request.headers.get("Authorization", "")
    if auth.lower().startswith("bearer "):
        shown.append(auth[7:].strip())
    return shown, bool(shown)


@dataclass
class StudioAccess:
    """The studio's teacher and class tokens (fresh ones unless given)."""

    teacher: str = field(default_factory=lambda: lan.make_token())
    join: str = field(default_factory=lambda: lan.make_token())

    def __post_init__(self):
        if not self.teacher or not self.join or _same(self.teacher, self.join):
            raise ValueError("the studio's teacher and class tokens must be given and differ")

    @classmethod
    def kept_in(cls, folder) -> StudioAccess:
        """The tokens kept in the rooms `folder` (ACCESS_FILE, readable by this user alone): read, or made and written
        there, so that a restart keeps the wall's and the class's links as it keeps the rooms' own. ValueError naming
        the file when it is not a studio's tokens."""
        path = Path(folder) / ACCESS_FILE
        try:
            kept = json.loads(path.read_text(encoding="utf-8"))
            return cls(teacher=str(kept["teacher"]), join=str(kept["join"]))
        except FileNotFoundError:
            pass
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"{path}: not the studio's tokens ({type(exc).__name__}: {exc}); expected "
                             '{"teacher": "...", "join": "..."}; remove it to make new links') from None
        access = cls()
        path.parent.mkdir(parents=True, exist_ok=True)
        part = path.with_name(ACCESS_FILE + ".part")
        with os.fdopen(os.open(part, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "w", encoding="utf-8") as f:
            json.dump({"teacher": access.teacher, "join": access.join}, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(part, path)
        return access

    def grant(self, request, room: str | None = None, room_token: str | None = None) -> str | None:
        """TEACHER, MEMBER (of `room`, by `room_token`), CLASS, or None: the strongest the request shows."""
        shown, _ = _given(request)
        candidates = [*shown, request.cookies.get(teacher_cookie(request))]
        if room is not None:
            candidates.append(request.cookies.get(room_cookie(request, room)))
        if any(_same(t, self.teacher) for t in candidates):
            return TEACHER
        if room_token and any(_same(t, room_token) for t in candidates):
            return MEMBER
        if any(_same(t, self.join) for t in shown):
            return CLASS
        return None

    def remember(self, request, response, grant: str | None, room: str | None = None, room_token: str | None = None):
        """The cookie for the token the request showed in its URL or header (a page's own requests then need not);
        returns the response."""
        if not _given(request)[1] or not isinstance(response, web.StreamResponse) or response.prepared:
            return response
        options = {"httponly": True, "samesite": "Strict", "secure": request.secure}
        if grant == TEACHER:
            response.set_cookie(teacher_cookie(request), self.teacher, path="/", **options)
        elif grant == MEMBER and room is not None and room_token:
            response.set_cookie(room_cookie(request, room), room_token, path=f"/r/{room}/", **options)
        return response


def refused(reason: str = REFUSED) -> web.Response:
    return web.Response(status=403, text=reason, headers={"Cache-Control": "no-store"})
