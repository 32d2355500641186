"""A room's websocket through the front to its worker: after the handshakes, bytes passed on as they come (RFC 6455).

The browser's websocket ends at the front (its tokens, Host and Origin checked there: routes.py); the front opens one to
the worker's room server for it (its handshake made here, `open_upstream`). After the handshakes nothing is parsed
either way, so that a message costs the front one read and one write:
- up: the browser's frames are masked, as a client's must be, and the worker is the browser's server: they are written
  to the worker's connection as they come (`_BrowserSocket` puts them there instead of aiohttp's websocket reader);
- down: a worker's frames to its client are unmasked, as a browser expects of its server, so they are written to the
  browser's connection as they come (`Upstream`). Only the frames' headers are followed, to know where a frame ends
  (`FrameEnds`).
The worker checks the messages (their size, their kinds) as it would the browser's own. Nothing else writes to either
connection meanwhile (no heartbeat, ping or close of the front's own in between): a frame is never cut by another.
A slow reader: the front stops reading from one side while the other side's connection holds more than HIGH_WATER
bytes unsent, so the worker's hub sees a slow client as it would without the front.

When the worker goes (its connection ends between two frames), the browser's websocket is closed with 1012 (service
restart): its link connects again, to the room's new place; when the worker closes it, the worker's close frame is what
the browser gets; when the front stops, 1001 (going away).
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import os
import struct
from urllib.parse import urlsplit

from aiohttp import web

#: Bytes unsent to one side past which the front stops reading from the other.
HIGH_WATER = 1 << 20
#: Seconds the worker's handshake may take.
HANDSHAKE_TIMEOUT = 10.0
#: Seconds between two looks at a side that was over HIGH_WATER.
_DRAIN_POLL = 0.005
_GUID = b"258EAFA5-E914-47DA-95CA-C5AB0DC85B11"


class Refused(Exception):
    """The worker answered the handshake with an HTTP status (a room it does not have, its limit)."""

    def __init__(self, status: int, text: str):
        super().__init__(text)
        self.status = status
        self.text = text


class Upstream(asyncio.Protocol):
    """The front's connection to a worker's room socket. Until `pipe`, what the worker sends is kept (the handshake's
    answer, then any frames); after, it is written to the browser's connection as it comes (the module's docstring)."""

    def __init__(self) -> None:
        self.transport: asyncio.Transport | None = None
        self.kept = bytearray()
        self.lost = False
        self.ends = FrameEnds()
        self.browser: asyncio.Transport | None = None
        self.finished: asyncio.Future | None = None
        self._waiter: asyncio.Future | None = None

    # -- asyncio.Protocol --------------------------------------------------------------------------------------
    def connection_made(self, transport) -> None:
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        if self.browser is None:
            self.kept += data
            self._wake()
        else:
            self._down(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self.lost = True
        self._wake()
        self.finish("worker")

    # -- the handshake ------------------------------------------------------------------------------------------
    def _wake(self) -> None:
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(None)

    async def take(self, until: bytes | None = None, size: int = 0) -> bytes:
        """The kept bytes up to and with `until`, or the first `size` of them, once they are there."""
        while True:
            if until is None:
                at = size if len(self.kept) >= size else -1
            else:
                at = self.kept.find(until)
                at = at + len(until) if at >= 0 else -1
            if at >= 0:
                break
            if self.lost:
                raise asyncio.IncompleteReadError(bytes(self.kept), None)
            self._waiter = asyncio.get_running_loop().create_future()
            await self._waiter
        out = bytes(self.kept[:at])
        del self.kept[:at]
        return out

    # -- passing the worker's bytes on --------------------------------------------------------------------------
    def pipe(self, browser) -> None:
        """From now on the worker's bytes go to the `browser`'s transport; `finished` (set before) gets what ended it
        first: "worker" (its connection went), "browser", "closed" (the worker's close frame passed) or "stopping"
        (the front stops)."""
        self.browser = browser
        kept, self.kept = bytes(self.kept), bytearray()
        if kept:
            self._down(kept)
        if self.lost:
            self.finish("worker")

    def finish(self, why: str) -> None:
        if self.finished is not None and not self.finished.done():
            self.finished.set_result(why)

    def _down(self, data: bytes) -> None:
        browser = self.browser
        if browser is None or browser.is_closing():
            self.finish("browser")
            return
        self.ends.feed(data)
        browser.write(data)
        if self.ends.closed and self.ends.between:
            self.finish("closed")
        elif browser.get_write_buffer_size() > HIGH_WATER:
            _hold_until_drained(self.transport, browser, self.finished)


def _hold_until_drained(reading, writing, finished: asyncio.Future | None) -> None:
    """Stop reading `reading` until `writing` holds at most HIGH_WATER bytes unsent (or `finished` is done)."""
    reading.pause_reading()

    def look() -> None:
        if finished is not None and finished.done() or reading.is_closing():
            return
        if writing.is_closing() or writing.get_write_buffer_size() <= HIGH_WATER:
            reading.resume_reading()
        else:
            loop.call_later(_DRAIN_POLL, look)

    loop = asyncio.get_running_loop()
    loop.call_later(_DRAIN_POLL, look)


async def open_upstream(url: str, headers: dict) -> Upstream:
    """A websocket to `url` (ws://host:port/path?query, the worker's room socket) with `headers`; Refused when the
    worker answers with anything but 101, OSError / TimeoutError when it cannot be reached."""
    parts = urlsplit(url)
    if parts.hostname is None or parts.port is None:
        raise ValueError(f"a worker's room socket is ws://host:port/path; got {url!r}")
    loop = asyncio.get_running_loop()
    transport, upstream = await asyncio.wait_for(
        loop.create_connection(Upstream, parts.hostname, parts.port), HANDSHAKE_TIMEOUT)
    try:
        key = base64.b64encode(os.urandom(16)).decode()
        target = parts.path + (f"?{parts.query}" if parts.query else "")
        lines = [f"GET {target} HTTP/1.1", f"Host: {parts.hostname}:{parts.port}", "Upgrade: websocket",
                 "Connection: Upgrade", f"Sec-WebSocket-Key: {key}", "Sec-WebSocket-Version: 13",
                 *(f"{k}: {v}" for k, v in headers.items())]
        transport.write(("\r\n".join(lines) + "\r\n\r\n").encode("latin-1"))
        head = (await asyncio.wait_for(upstream.take(b"\r\n\r\n"), HANDSHAKE_TIMEOUT)).decode("latin-1")
        status_line, *fields = head.split("\r\n")
        status = int(status_line.split(" ", 2)[1])
        found = {k.strip().lower(): v.strip() for k, _, v in (f.partition(":") for f in fields if f)}
        if status != 101:
            length = int(found.get("content-length", "0") or 0)
            body = await asyncio.wait_for(upstream.take(size=length), HANDSHAKE_TIMEOUT) if length else b""
            raise Refused(status, body.decode(errors="replace"))
        accept = base64.b64encode(hashlib.sha1(key.encode() + _GUID).digest()).decode()
        if found.get("sec-websocket-accept") != accept:
            raise Refused(502, "the worker's websocket handshake did not match")
    except BaseException:
        transport.close()
        raise
    return upstream


class _BrowserSocket(web.WebSocketResponse):
    """The browser's websocket: its handshake made by aiohttp, then what the browser sends goes to the worker's
    connection as it comes, in place of aiohttp's websocket reader (aiohttp's payload parser: `feed_data` and
    `feed_eof`)."""

    def __init__(self, upstream: Upstream):
        super().__init__(compress=False, autoping=False, autoclose=False)
        self.upstream = upstream
        self.browser = None

    def _post_start(self, request, protocol, writer) -> None:
        self._ws_protocol = protocol
        self._writer = writer
        self.browser = request.transport
        request.protocol.set_parser(self)
        request.protocol.keep_alive(False)

    def feed_data(self, data: bytes) -> tuple[bool, bytes]:
        worker = self.upstream.transport
        if worker is None or worker.is_closing():
            self.upstream.finish("worker")
        else:
            worker.write(data)
            if worker.get_write_buffer_size() > HIGH_WATER:
                _hold_until_drained(self.browser, worker, self.upstream.finished)
        return False, b""

    def feed_eof(self) -> None:
        self.upstream.finish("browser")

    async def write_eof(self) -> None:  # the relay ends both connections itself
        return None


def close_frame(code: int, reason: bytes = b"") -> bytes:
    """An unmasked close frame (a server's) with `code` and `reason` (at most 123 bytes)."""
    payload = struct.pack("!H", code) + reason[:123]
    return struct.pack("!BB", 0x88, len(payload)) + payload


class FrameEnds:
    """Follows a server's frames through the bytes (headers only): whether the bytes so far end between two frames,
    and whether a close frame went by."""

    def __init__(self) -> None:
        self.left = 0  # bytes of the current frame's payload still to come
        self.head = b""  # a header cut between two chunks
        self.closed = False

    @property
    def between(self) -> bool:
        return self.left == 0 and not self.head

    def feed(self, data: bytes) -> None:
        pos, end = 0, len(data)
        while pos < end:
            if self.left:
                step = min(self.left, end - pos)
                self.left -= step
                pos += step
                continue
            head = self.head + data[pos:pos + 14]
            if len(head) < 2:
                self.head, pos = head, end
                continue
            size, need = head[1] & 0x7F, 2
            need += 2 if size == 126 else 8 if size == 127 else 0
            need += 4 if head[1] & 0x80 else 0
            if len(head) < need:
                self.head, pos = head, end
                continue
            if size == 126:
                size = struct.unpack_from("!H", head, 2)[0]
            elif size == 127:
                size = struct.unpack_from("!Q", head, 2)[0]
            if head[0] & 0x0F == 0x8:
                self.closed = True
            pos += need - len(self.head)
            self.head, self.left = b"", size


async def relay(request, upstream: Upstream) -> web.WebSocketResponse:
    """The browser's websocket (`request`, accepted here) and the worker's (`upstream`), until either ends (the
    module's docstring)."""
    browser = _BrowserSocket(upstream)
    finished = asyncio.get_running_loop().create_future()
    upstream.finished = finished  # a browser gone while aiohttp answers it
    try:
        await browser.prepare(request)
        out = request.transport
        upstream.pipe(out)
        first = await finished
    finally:
        if upstream.transport is not None:
            upstream.transport.close()
    if out is not None and not out.is_closing():
        if upstream.ends.between and not upstream.ends.closed:
            if first == "worker":  # the worker went: the room moves
                out.write(close_frame(1012, b"the room moves to another worker"))
            elif first == "stopping":  # the front stops (its pages connect again when it is back)
                out.write(close_frame(1001, b"the studio stops"))
        out.close()
    return browser
