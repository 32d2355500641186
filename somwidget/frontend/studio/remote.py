"""A room of a running studio from Python (a notebook, a script): `somwidget.join(url)`.

    room = somwidget.join("https://studio.local:8080/r/alice/?token=...", fingerprint="AB:CD:...")
    room.move_control(0, [0.1, 0.0, 0.3])      # one drag: grab, move, release (one undo step)
    room.set_parameter("smoothing", 0.2); room.undo()
    room.positions                              # the latest frame's positions (N, 3)
    room.show()                                 # the room's clay view in the notebook, a view of its own

A `RoomSession` is one hand of the room, as a page is: its intents and the room's frames travel over the room's view
websocket (/r/<name>/view/ws), in the one protocol of transport/messages.py. The room's own Session lives on the
studio's server; this proxy holds the latest frame (decoded: transport/frames.py), who is there and what they hold.
Intents the room refuses raise ValueError with the room's message. A link under /watch/ joins to watch only.

TLS: a studio on the LAN has a self-signed certificate; pass the fingerprint it printed (`fingerprint=`), or
`verify=False` on a network you trust.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
import time
from typing import Any
from urllib.parse import parse_qs, urlencode, urlsplit, urlunsplit

import numpy as np

from ..transport.frames import decode_frame
from .limits import room_name

#: Seconds after a pong during which a frame may still come that the intents before the ping were made in.
SETTLE = 0.25


def socket_url(url: str) -> tuple[str, str, bool]:
    """(the room's websocket URL, its name, watch only) from a room's link (/r/<name>/, /r/<name>/watch/)."""
    parts = urlsplit(url.strip())
    if parts.scheme not in ("http", "https", "ws", "wss"):
        raise ValueError(f"join: expected a room's link like https://host:8080/r/alice/?token=..., got {url[:80]!r}")
    path = [p for p in parts.path.split("/") if p]
    if len(path) < 2 or path[0] != "r" or (len(path) > 2 and path[2:] not in (["watch"], ["view", "ws"],
                                                                                ["watch", "view", "ws"])):
        raise ValueError(f"join: {parts.path!r} is not a room's path (/r/<name>/)")
    name = room_name(path[1])
    watch = len(path) > 2 and path[2] == "watch"
    token = parse_qs(parts.query).get("token", [""])[0]
    scheme = {"http": "ws", "https": "wss"}.get(parts.scheme, parts.scheme)
    query = urlencode({"token": token}) if token else ""
    return urlunsplit((scheme, parts.netloc, f"/r/{name}/{'watch/' if watch else ''}view/ws", query, "")), name, watch


def ssl_option(fingerprint: str | None, verify: bool):
    """aiohttp's ssl= for a certificate pinned by its SHA-256 fingerprint, not checked, or the system's check."""
    import aiohttp

    if fingerprint:
        digest = bytes.fromhex(fingerprint.replace(":", "").strip())
        if len(digest) != 32:
            raise ValueError("fingerprint: expected the certificate's SHA-256, 32 bytes as hex (AB:CD:...)")
        return aiohttp.Fingerprint(digest)
    return bool(verify)


class RoomSession:
    """A room of a running studio (see the module's docstring). `join(url)` connects and waits for its first frame."""

    def __init__(self, url: str, timeout: float = 30.0, fingerprint: str | None = None, verify: bool = True,
                 kind: str = "notebook"):
        self.url, self.name, self.watch = socket_url(url)
        self.link = url
        self._ssl = ssl_option(fingerprint, verify)
        self.topology: Any = None  # the latest topology message, None until the first comes
        self.frame: Any = None  # the latest frame (a dict of arrays), None until the first comes
        self.presence: list = []
        self.grabs: list = []
        self.errors: list[dict] = []
        self.closed = False
        self._cond = threading.Condition()
        self._pongs: dict[float, float] = {}
        self._t = 0.0
        self._loop = asyncio.new_event_loop()
        self._ws: Any = None  # aiohttp's websocket once connected
        self._thread = threading.Thread(target=self._loop.run_forever, name="somwidget-room", daemon=True)
        self._thread.start()
        try:
            self._call(self._connect(kind), timeout)
        except BaseException:
            self.close()
            raise
        if not self._wait(lambda: self.frame is not None, timeout):
            self.close()
            raise TimeoutError(f"join: no frame from room {self.name!r} within {timeout:g} s")

    @classmethod
    def join(cls, url: str, **options) -> RoomSession:
        return cls(url, **options)

    # -- the connection -----------------------------------------------------------------------------------------
    def _call(self, coroutine, timeout: float = 30.0):
        return asyncio.run_coroutine_threadsafe(coroutine, self._loop).result(timeout)

    async def _connect(self, kind: str) -> None:
        import aiohttp

        self._http = aiohttp.ClientSession()
        try:
            self._ws = await self._http.ws_connect(self.url, ssl=self._ssl, max_msg_size=0, compress=0,
                                                   heartbeat=20.0)
        except aiohttp.WSServerHandshakeError as exc:
            await self._http.close()
            reason = {403: "the studio refused the link's token", 404: "no such room"}.get(exc.status, exc.message)
            raise ValueError(f"join {self.name!r}: {reason} ({exc.status})") from None
        except (aiohttp.ClientError, OSError) as exc:
            await self._http.close()
            raise ValueError(f"join {self.name!r}: cannot reach the studio: {exc}") from None
        if kind != "desktop":
            await self._ws.send_json({"type": "hand", "kind": kind})
        asyncio.ensure_future(self._receive())

    async def _receive(self) -> None:
        import aiohttp

        async for msg in self._ws:
            if msg.type == aiohttp.WSMsgType.BINARY:
                frame = decode_frame(msg.data)
                with self._cond:
                    self.frame = frame
                    self._cond.notify_all()
            elif msg.type == aiohttp.WSMsgType.TEXT:
                self._message(json.loads(msg.data))
        with self._cond:
            self.closed = True
            self._cond.notify_all()

    def _message(self, m: dict) -> None:
        with self._cond:
            kind = m.get("type")
            if kind == "topology":
                self.topology = m
            elif kind == "controls" and self.topology is not None:
                self.topology = dict(self.topology, control_ids=m["ids"], radii=m["radii"])
            elif kind == "presence":
                self.presence = m["hands"]
            elif kind == "grabs":
                self.grabs = m["grabs"]
            elif kind == "error":
                self.errors.append(m)
            elif kind == "pong":
                self._pongs[m["t"]] = time.monotonic()
            self._cond.notify_all()

    def _wait(self, predicate, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0 or self.closed:
                    return bool(predicate())
                self._cond.wait(min(left, 0.1))
            return True

    def _send(self, message: dict) -> None:
        if self.closed or self._ws is None:
            raise RuntimeError(f"room {self.name!r}: the connection is closed")
        self._call(self._ws.send_str(json.dumps(message)))

    def _intent(self, message: dict, timeout: float = 30.0) -> None:
        """Send an intent and wait until the room took it: ValueError with the room's message when it refused."""
        errors = len(self.errors)
        self._send(message)
        self.wait_applied(timeout)
        refused = [e for e in self.errors[errors:] if e.get("intent") == message["type"]]
        if refused:
            raise ValueError(f"room {self.name!r}: {refused[-1]['message']}")

    def wait_applied(self, timeout: float = 30.0) -> bool:
        """Wait until the room took every intent sent so far (its answer to a ping) and the frame after them came
        (the first frame after the answer, or none for SETTLE seconds). False at the timeout."""
        with self._cond:
            self._t += 1.0
            t = self._t
            seq = self.frame["seq"] if self.frame else -1
        self._send({"type": "ping", "t": t})
        if not self._wait(lambda: t in self._pongs, timeout):
            return False
        settle = time.monotonic() + SETTLE
        self._wait(lambda: (self.frame and self.frame["seq"] > seq + 1) or time.monotonic() > settle, SETTLE + 0.05)
        return True

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Wait until the room's training stopped (its schedule done, or paused) after the intents sent so far."""
        return self.wait_applied(timeout) and self._wait(lambda: not self.frame["running"], timeout)

    def close(self) -> None:
        """Leave the room (what this hand holds is let go); the room goes on."""
        async def shut():
            if self._ws is not None:
                await self._ws.close()
            if getattr(self, "_http", None) is not None:
                await self._http.close()

        if self._loop.is_running():
            with contextlib.suppress(Exception):
                self._call(shut(), 10.0)
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(10)
        self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- what the room shows --------------------------------------------------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """(n, 3) the latest frame's display positions (the nodes; roots then tips for the lines preset)."""
        return np.array(self.frame["positions"])

    @property
    def control_positions(self) -> np.ndarray:
        """(k, 3) the controls' positions in the latest frame."""
        return np.array(self.frame["control_positions"][: self.frame["k"]])

    @property
    def control_ids(self) -> list[int]:
        return list(self.topology["control_ids"])

    @property
    def n_controls(self) -> int:
        return int(self.frame["k"])

    @property
    def iteration(self) -> int:
        return int(self.frame["iteration"])

    @property
    def history(self) -> tuple[bool, bool]:
        """(a step to undo, a step to redo)."""
        return bool(self.frame["can_undo"]), bool(self.frame["can_redo"])

    @property
    def people(self) -> list[str]:
        return [h["name"] + (" (you)" if h["you"] else "") for h in self.presence]

    # -- intents ----------------------------------------------------------------------------------------------
    def _id(self, index: int) -> int:
        ids = self.control_ids
        if not 0 <= int(index) < len(ids):
            raise ValueError(f"control index {index} is out of range (the room has {len(ids)} controls)")
        return ids[int(index)]

    def move_control(self, index: int, position, timeout: float = 30.0) -> None:
        """Drag control `index` to `position` (x, y, z): one undo step; returns once a frame shows it there."""
        cid = self._id(index)
        p = [float(v) for v in position]
        if len(p) != 3:
            raise ValueError(f"position: expected x, y, z, got {len(p)} values")
        self._intent({"type": "grab", "id": cid}, timeout)
        self._send({"type": "move", "id": cid, "position": p})
        self._intent({"type": "release", "id": cid}, timeout)
        at = np.asarray(p, dtype=np.float32)
        self._wait(lambda: cid in self.control_ids and np.allclose(
            self.frame["control_positions"][self.control_ids.index(cid)], at, atol=1e-5), timeout)

    def add_control(self, position, radius: float | None = None) -> None:
        message: dict[str, Any] = {"type": "add", "position": [float(v) for v in position]}
        if radius is not None:
            message["radius"] = float(radius)
        self._intent(message)

    def add_stroke(self, points, radius: float | None = None) -> None:
        message: dict[str, Any] = {"type": "stroke", "points": [[float(v) for v in p] for p in points]}
        if radius is not None:
            message["radius"] = float(radius)
        self._intent(message)

    def remove_control(self, index: int) -> None:
        self._intent({"type": "remove", "id": self._id(index)})

    def set_control_radius(self, index: int, radius: float) -> None:
        self._intent({"type": "radius", "id": self._id(index), "radius": float(radius)})

    def set_parameter(self, name: str, value) -> None:
        self._intent({"type": "set", "name": name, "value": value})

    def undo(self) -> None:
        self._intent({"type": "undo"})

    def redo(self) -> None:
        self._intent({"type": "redo"})

    def reset(self) -> None:
        self._intent({"type": "reset"})

    def train(self) -> None:
        self._intent({"type": "train"})

    def pause(self) -> None:
        self._intent({"type": "pause"})

    def show(self, height: int = 520):
        """The room's clay view in a notebook output: a view of its own (another hand), drawn by the browser."""
        from .remote_widget import RoomWidget

        return RoomWidget(self.link, height=height, ssl=self._ssl)


def join(url: str, timeout: float = 30.0, fingerprint: str | None = None, verify: bool = True) -> RoomSession:
    """A room of a running studio by its link (see the module's docstring)."""
    return RoomSession(url, timeout=timeout, fingerprint=fingerprint, verify=verify)
