"""A room's websocket through the front to its worker, the worker's bytes passed on as they come (RFC 6455).

The browser's websocket ends at the front (its tokens, Host and Origin checked there: routes.py); the front opens one to
the worker's room server for it (its handshake made here, `open_upstream`). Frames, the bulk of the traffic, are not
parsed on the way down: a worker's frames to its client are unmasked, as a browser expects of its server, so the bytes
the worker sends are written to the browser's connection as they are (only the frames' headers are followed, to know
where a frame ends: `FrameEnds`). The browser's messages (small: moves, grabs) are read as messages and sent up masked,
as a client's must be; its pongs and pings go up too, so that the worker's heartbeat sees the browser. Nothing else
writes to the browser's connection meanwhile (no heartbeat, ping or close of the front's own in between): a frame is
never cut by another. A slow browser: the front stops reading from the worker while the browser's connection holds more
than HIGH_WATER bytes unsent, so the worker's hub sees a slow client as it would without the front.

When the worker goes (its connection ends between two frames), the browser's websocket is closed with 1012 (service
restart): its link connects again, to the room's new place; when the worker closes it, the worker's close frame is what
the browser gets.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import hashlib
import os
import struct
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web

#: Bytes unsent to a browser past which the front stops reading its room's frames from the worker.
HIGH_WATER = 1 << 20
#: Seconds the worker's handshake may take.
HANDSHAKE_TIMEOUT = 10.0
_GUID = b"258EAFA5-E914-47DA-95CA-C5AB0DC85B11"
_OPCODES = {WSMsgType.TEXT: 0x1, WSMsgType.BINARY: 0x2, WSMsgType.PING: 0x9, WSMsgType.PONG: 0xA}


class Refused(Exception):
    """The worker answered the handshake with an HTTP status (a room it does not have, its limit)."""

    def __init__(self, status: int, text: str):
        super().__init__(text)
        self.status = status
        self.text = text


async def open_upstream(url: str, headers: dict) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """A websocket to `url` (ws://host:port/path?query, the worker's room socket) with `headers`; Refused when the
    worker answers with anything but 101, OSError / TimeoutError when it cannot be reached."""
    parts = urlsplit(url)
    reader, writer = await asyncio.wait_for(asyncio.open_connection(parts.hostname, parts.port), HANDSHAKE_TIMEOUT)
    try:
        key = base64.b64encode(os.urandom(16)).decode()
        target = parts.path + (f"?{parts.query}" if parts.query else "")
        lines = [f"GET {target} HTTP/1.1", f"Host: {parts.hostname}:{parts.port}", "Upgrade: websocket",
                 "Connection: Upgrade", f"Sec-WebSocket-Key: {key}", "Sec-WebSocket-Version: 13",
                 *(f"{k}: {v}" for k, v in headers.items())]
        writer.write(("\r\n".join(lines) + "\r\n\r\n").encode("latin-1"))
        head = (await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HANDSHAKE_TIMEOUT)).decode("latin-1")
        status_line, *fields = head.split("\r\n")
        status = int(status_line.split(" ", 2)[1])
        found = {k.strip().lower(): v.strip() for k, _, v in (f.partition(":") for f in fields if f)}
        if status != 101:
            length = int(found.get("content-length", "0") or 0)
            body = await asyncio.wait_for(reader.readexactly(length), HANDSHAKE_TIMEOUT) if length else b""
            raise Refused(status, body.decode(errors="replace"))
        accept = base64.b64encode(hashlib.sha1(key.encode() + _GUID).digest()).decode()
        if found.get("sec-websocket-accept") != accept:
            raise Refused(502, "the worker's websocket handshake did not match")
    except BaseException:
        writer.close()
        raise
    return reader, writer


def client_frame(opcode: int, payload: bytes) -> bytes:
    """One masked frame (a client's, RFC 6455 5.2) of `payload`."""
    n = len(payload)
    if n < 126:
        head = struct.pack("!BB", 0x80 | opcode, 0x80 | n)
    elif n < 1 << 16:
        head = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, n)
    else:
        head = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, n)
    mask = os.urandom(4)
    if not n:
        return head + mask
    masked = int.from_bytes(payload, "little") ^ int.from_bytes((mask * (n // 4 + 1))[:n], "little")
    return head + mask + masked.to_bytes(n, "little")


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


async def relay(request, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> web.WebSocketResponse:
    """The browser's websocket (`request`, accepted here) and the worker's (`reader`, `writer`), until either ends
    (the module's docstring)."""
    browser = web.WebSocketResponse(max_msg_size=64 * 1024, compress=False, autoping=False, autoclose=False)
    await browser.prepare(request)
    out = request.transport
    ends = FrameEnds()

    async def down() -> str:
        while True:
            data = await reader.read(1 << 16)
            if not data:
                return "worker"
            ends.feed(data)
            if out is None or out.is_closing():
                return "browser"
            out.write(data)
            if ends.closed and ends.between:
                return "closed"
            while out.get_write_buffer_size() > HIGH_WATER and not out.is_closing():
                await asyncio.sleep(0.005)

    async def up() -> str:
        async for msg in browser:
            opcode = _OPCODES.get(msg.type)
            if opcode is not None:
                payload = msg.data.encode() if msg.type == WSMsgType.TEXT else bytes(msg.data or b"")
                writer.write(client_frame(opcode, payload))
            elif msg.type == WSMsgType.CLOSE:
                code = msg.data if isinstance(msg.data, int) else 1000
                writer.write(client_frame(0x8, struct.pack("!H", code) + (msg.extra or "").encode()[:123]))
                return "browser"
            else:
                return "browser"
            if writer.transport.get_write_buffer_size() > HIGH_WATER:
                await writer.drain()
        return "browser"

    tasks = [asyncio.ensure_future(down()), asyncio.ensure_future(up())]
    try:
        done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        first = next(iter(done)).result() if done and not next(iter(done)).exception() else "worker"
        if first == "browser" and not tasks[0].done():  # the worker's close frame back, for a moment
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(asyncio.shield(tasks[0]), 2.0)
    finally:
        for task in tasks:
            task.cancel()
        writer.close()
    if out is not None and not out.is_closing():
        if first == "worker" and ends.between and not ends.closed:  # the worker went: the room moves
            out.write(close_frame(1012, b"the room moves to another worker"))
        out.close()
    return browser
