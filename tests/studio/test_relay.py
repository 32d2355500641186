"""The front's relay (studio/relay.py): a worker's frames followed through any cut of its bytes into chunks; the
worker's handshake made by hand against a real aiohttp websocket server (a message there and back; a refusal passed on
with its status); and a real browser-side client through a real front to a real worker: messages of every length both
ways unchanged, the close codes passed on, a worker gone closing the browser's socket with 1012, and a browser that
reads nothing holding the worker back instead of filling the front's memory."""

from __future__ import annotations

import asyncio
import json
import os
import struct
import subprocess
import sys

import aiohttp
import numpy as np
import pytest
from aiohttp import WSMsgType, web
from helpers import ROOT

from somwidget.frontend.studio import relay
from somwidget.frontend.studio.relay import FrameEnds, Refused, close_frame, open_upstream


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
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


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
            upstream = await open_upstream(f"http://127.0.0.1:{port}/ws", {"Authorization": "Bearer s"})
            upstream.transport.write(client_frame(0x1, b'{"type":"move"}'))
            head = await upstream.take(size=2)
            assert head[0] == 0x82 and not head[1] & 0x80  # a binary frame, unmasked: a browser takes it as it is
            assert await upstream.take(size=head[1]) == b'}"evom":"epyt"{'
            upstream.transport.write(client_frame(0x8, struct.pack("!H", 1000)))
            ends = FrameEnds()
            while not ends.closed:
                data = await upstream.take(size=1)
                ends.feed(data)
            upstream.transport.close()
        finally:
            await runner.cleanup()

    asyncio.run(main())


async def start(app: web.Application) -> tuple[web.AppRunner, int]:
    runner = web.AppRunner(app)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    return runner, site._server.sockets[0].getsockname()[1]


async def front_to(worker_port: int, seen: list) -> tuple[web.AppRunner, int]:
    """A front of one route, relaying to the worker at `worker_port` as `RemotePlace.socket` does; `seen` gets each
    browser connection's transport."""
    async def ws(request):
        seen.append(request.transport)
        upstream = await open_upstream(f"ws://127.0.0.1:{worker_port}/ws", {})
        return await relay.relay(request, upstream)

    app = web.Application()
    app.router.add_get("/ws", ws)
    return await start(app)


def test_messages_of_every_length_pass_both_ways_unchanged_and_the_close_codes_too():
    sizes = [0, 1, 125, 126, 127, 65535, 65536, 200_000]
    closed_with: list = []

    async def main():
        async def echo(request):  # each message back reversed, of the same kind
            ws = web.WebSocketResponse(max_msg_size=0)
            await ws.prepare(request)
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    await ws.send_str(msg.data[::-1])
                elif msg.type == WSMsgType.BINARY:
                    await ws.send_bytes(msg.data[::-1])
            closed_with.append(ws.close_code)
            return ws

        app = web.Application()
        app.router.add_get("/ws", echo)
        worker, worker_port = await start(app)
        front, port = await front_to(worker_port, [])
        rng = np.random.default_rng(5)
        try:
            async with aiohttp.ClientSession() as http, http.ws_connect(f"ws://127.0.0.1:{port}/ws",
                                                                        max_msg_size=0) as ws:
                for n in sizes:
                    data = bytes(rng.integers(0, 256, n, dtype=np.uint8))
                    await ws.send_bytes(data)
                    text = "".join(chr(c) for c in rng.integers(32, 0x24F, n))
                    await ws.send_str(text)
                    got = await ws.receive(timeout=10)
                    assert got.type == WSMsgType.BINARY and got.data == data[::-1], n
                    got = await ws.receive(timeout=10)
                    assert got.type == WSMsgType.TEXT and got.data == text[::-1], n
                await ws.close(code=4000, message=b"done here")
                assert ws.closed and ws.close_code == 1000  # the worker's answer (aiohttp's: 1000) came back
            for _ in range(100):
                if closed_with:
                    break
                await asyncio.sleep(0.02)
            assert closed_with == [4000]
        finally:
            await front.cleanup()
            await worker.cleanup()

    asyncio.run(main())


def test_a_worker_gone_between_frames_closes_the_browsers_socket_with_1012():
    async def main():
        async def worker_that_dies(request):
            ws = web.WebSocketResponse()
            await ws.prepare(request)
            await ws.send_bytes(b"a frame")
            async for msg in ws:
                if msg.type == WSMsgType.TEXT and msg.data == "die":
                    request.transport.abort()  # the process gone: no close frame
                    break
            return ws

        app = web.Application()
        app.router.add_get("/ws", worker_that_dies)
        worker, worker_port = await start(app)
        front, port = await front_to(worker_port, [])
        try:
            async with aiohttp.ClientSession() as http, http.ws_connect(f"ws://127.0.0.1:{port}/ws") as ws:
                assert (await ws.receive(timeout=10)).data == b"a frame"
                await ws.send_str("die")
                got = await ws.receive(timeout=10)
                assert got.type == WSMsgType.CLOSE and got.data == 1012, got
                assert "moves" in got.extra
        finally:
            await front.cleanup()
            await worker.cleanup()

    asyncio.run(main())


def test_a_browser_that_reads_nothing_holds_the_worker_back_and_then_gets_every_frame():
    frame, count = 1_000_000, 40  # 40 MB: far past HIGH_WATER (1 MB) and what the sockets buffer

    async def main():
        sent = []

        async def flood(request):
            ws = web.WebSocketResponse()
            await ws.prepare(request)
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    for i in range(count):
                        await ws.send_bytes(i.to_bytes(4, "big") * (frame // 4))
                        sent.append(i)
            return ws

        app = web.Application()
        app.router.add_get("/ws", flood)
        worker, worker_port = await start(app)
        seen: list = []
        front, port = await front_to(worker_port, seen)
        try:
            async with aiohttp.ClientSession() as http:
                ws = await http.ws_connect(f"ws://127.0.0.1:{port}/ws", max_msg_size=0)
                reader = ws._response.connection.transport
                reader.pause_reading()  # the browser reads nothing for a while
                await ws.send_str("go")
                most = 0
                for _ in range(100):
                    await asyncio.sleep(0.01)
                    most = max(most, seen[0].get_write_buffer_size())
                assert 0 < len(sent) < count, f"the worker was held back (its sends wait): {len(sent)} sent"
                assert most <= relay.HIGH_WATER + (1 << 20), most  # the front held about HIGH_WATER, not all of it
                reader.resume_reading()
                for i in range(count):
                    got = await ws.receive(timeout=10)
                    assert got.type == WSMsgType.BINARY and got.data[:4] == i.to_bytes(4, "big")
                    assert len(got.data) == frame
                await ws.close()
        finally:
            await front.cleanup()
            await worker.cleanup()

    asyncio.run(main())


def test_the_relay_benchmark_counts_the_frames_the_relay_passed(tmp_path):
    """benchmarks/bench_relay.py at its smallest: every designer's moves come back as frames through the real relay,
    and the relay process's CPU is counted."""
    out = tmp_path / "relay.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_relay.py"), "--designers", "2", "--seconds",
                    "1.5", "--rate", "20", "--json", str(out)], check=True, timeout=120, capture_output=True)
    (row,) = json.loads(out.read_text())
    assert row["designers"] == 2 and 20 <= row["frames_per_s"] <= 45, row  # two designers at 20 moves a second
    assert row["front_cpu_ms_a_frame"] > 0 and row["p95_ms"] is not None, row
