"""The front's relay (studio/relay.py) at the byte level: a worker's frames followed through any cut of its bytes into
chunks, the browser's messages sent up masked as a client's must be, and the worker's handshake made by hand against a
real aiohttp websocket server (a message there and back; a refusal passed on with its status)."""

from __future__ import annotations

import asyncio
import struct

import numpy as np
import pytest
from aiohttp import WSMsgType, web

from somwidget.frontend.studio.relay import FrameEnds, Refused, client_frame, close_frame, open_upstream


def server_frame(opcode: int, payload: bytes) -> bytes:
    n = len(payload)
    if n < 126:
        return struct.pack("!BB", 0x80 | opcode, n) + payload
    if n < 1 << 16:
        return struct.pack("!BBH", 0x80 | opcode, 126, n) + payload
    return struct.pack("!BBQ", 0x80 | opcode, 127, n) + payload


def unmask(frame: bytes) -> tuple[int, bytes]:
    """(opcode, payload) of one masked frame, decoded independently of client_frame."""
    assert frame[1] & 0x80, "a client's frame is masked"
    n, at = frame[1] & 0x7F, 2
    if n == 126:
        n, at = struct.unpack_from("!H", frame, 2)[0], 4
    elif n == 127:
        n, at = struct.unpack_from("!Q", frame, 2)[0], 10
    mask, data = frame[at:at + 4], frame[at + 4:]
    assert len(data) == n
    return frame[0] & 0x0F, bytes(b ^ mask[i % 4] for i, b in enumerate(data))


def test_frame_ends_are_found_through_any_cut_of_the_bytes():
    sizes = [0, 5, 125, 126, 300, 65535, 65536, 70000]
    frames = [server_frame(0x2, bytes([i % 251]) * n) for i, n in enumerate(sizes)]
    frames.append(close_frame(1000, b"bye"))
    stream = b"".join(frames)
    ends_at = set(np.cumsum([len(f) for f in frames]).tolist())
    rng = np.random.default_rng(3)
    for _ in range(20):
        cuts = np.sort(rng.choice(np.arange(1, len(stream)), 40, replace=False)).tolist()
        close_head = len(stream) - len(frames[-1]) + 1  # the close frame's header cut in two
        cuts = sorted(set(cuts) | set(rng.choice(sorted(ends_at), 4).tolist()) | {close_head})
        ends, last = FrameEnds(), 0
        for cut in [*cuts, len(stream)]:
            ends.feed(stream[last:cut])
            last = cut
            assert ends.between == (cut in ends_at), cut
            assert ends.closed == (cut >= len(stream) - len(frames[-1]) + 2)  # the close frame's header read


@pytest.mark.parametrize("n", [0, 1, 125, 126, 65535, 65536])
def test_a_browser_message_goes_up_masked(n):
    payload = bytes(np.random.default_rng(n).integers(0, 256, n, dtype=np.uint8))
    assert unmask(client_frame(0x1, payload)) == (0x1, payload)


def test_the_handshake_by_hand_reaches_a_real_websocket_server_and_passes_a_refusal_on():
    async def main():
        async def echo(request):
            if request.headers.get("Authorization") != "Bearer s":
                return web.Response(status=403, text="workers answer the front only")
            ws = web.WebSocketResponse()
            await ws.prepare(request)
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    await ws.send_bytes(msg.data.encode()[::-1])
            return ws

        app = web.Application()
        app.router.add_get("/ws", echo)
        runner = web.AppRunner(app)
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        port = site._server.sockets[0].getsockname()[1]
        try:
            with pytest.raises(Refused) as refused:
                await open_upstream(f"http://127.0.0.1:{port}/ws", {})
            assert refused.value.status == 403 and "front only" in refused.value.text
            reader, writer = await open_upstream(f"http://127.0.0.1:{port}/ws", {"Authorization": "Bearer s"})
            writer.write(client_frame(0x1, b'{"type":"move"}'))
            head = await reader.readexactly(2)
            assert head[0] == 0x82 and not head[1] & 0x80  # a binary frame, unmasked: a browser takes it as it is
            assert await reader.readexactly(head[1]) == b'}"evom":"epyt"{'
            writer.write(client_frame(0x8, struct.pack("!H", 1000)))
            ends = FrameEnds()
            while not ends.closed:
                data = await reader.read(1 << 16)
                assert data, "the server closed without its close frame"
                ends.feed(data)
            writer.close()
        finally:
            await runner.cleanup()

    asyncio.run(main())
