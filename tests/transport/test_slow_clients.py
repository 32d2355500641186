"""Slow and passive clients (issue 17, item 3), as the attack: at once, a client that never reads its socket, a
client bursting 90 intents a second and a normal client. The server's memory stays bounded (one pending frame per
client, a bounded queue of replies), the passive client is dropped once a send stalls, the bursty one is not cut
off and gets its replies promptly, and the normal one keeps its frame rate."""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import time

import helpers
import pytest

pytest.importorskip("aiohttp")


def passive_socket(port: int) -> socket.socket:
    """A websocket handshake by hand, then nothing read, ever: the server's sends to it stall once buffers fill."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # before connecting: a small window
    s.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET /view/ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
    return s


async def normal_client(base: str, seconds: float, out: dict) -> None:
    import aiohttp

    async with aiohttp.ClientSession() as cs, cs.ws_connect(base.replace("http", "ws") + "/view/ws") as ws:
        frames, pongs, t0 = 0, [], time.perf_counter()
        sent = {}

        async def pinger():
            for i in range(int(seconds * 4)):
                sent[i] = time.perf_counter()
                await ws.send_json({"type": "ping", "t": i})
                await asyncio.sleep(0.25)

        task = asyncio.create_task(pinger())
        while time.perf_counter() - t0 < seconds:
            try:
                msg = await ws.receive(timeout=1.0)
            except asyncio.TimeoutError:
                continue
            if msg.type == aiohttp.WSMsgType.BINARY:
                frames += 1
            elif msg.type == aiohttp.WSMsgType.TEXT and '"pong"' in msg.data:
                i = json.loads(msg.data)["t"]
                pongs.append(time.perf_counter() - sent[int(i)])
            elif msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED):
                out["closed"] = True
                break
        task.cancel()
        out.update(frames_per_s=frames / seconds, pongs=pongs)


async def bursty_client(base: str, seconds: float, out: dict) -> None:
    import aiohttp

    async with aiohttp.ClientSession() as cs, cs.ws_connect(base.replace("http", "ws") + "/view/ws") as ws:
        t0, sent, answered, closed = time.perf_counter(), {}, [], False

        async def reader():
            nonlocal closed
            async for msg in ws:
                if msg.type == aiohttp.WSMsgType.TEXT and '"pong"' in msg.data:
                    i = int(json.loads(msg.data)["t"])
                    answered.append(time.perf_counter() - sent[i])
            closed = True

        task = asyncio.create_task(reader())
        i = 0
        await ws.send_json({"type": "grab", "index": 3})
        while time.perf_counter() - t0 < seconds:
            sent[i] = time.perf_counter()
            await ws.send_json({"type": "ping", "t": i})
            await ws.send_json({"type": "move", "index": 3, "position": [0.5 + 0.001 * (i % 50), 0.3, 0.2]})
            i += 1
            await asyncio.sleep(1 / 45)  # 90 intents a second
        await ws.send_json({"type": "release", "index": 3})
        await asyncio.sleep(0.5)
        task.cancel()
        out.update(closed=closed or ws.closed, pongs=answered, sent=i)


def test_a_passive_a_bursty_and_a_normal_client_at_once():
    import numpy as np

    serve = helpers.Serve("--preset", "space-grid")  # 61 kB frames: a passive client's buffers fill in seconds
    try:
        serve.idle()
        alone: dict = {}
        serve_port = serve.port
        asyncio.run(normal_client(serve.base, 3.0, alone))
        before = helpers.proc_status_mb(serve.proc.pid, "VmRSS")
        passive = [passive_socket(serve_port) for _ in range(3)]
        seconds = 14.0

        async def together():
            normal, bursty = {}, {}
            await asyncio.gather(normal_client(serve.base, seconds, normal), bursty_client(serve.base, seconds, bursty))
            return normal, bursty

        normal, bursty = asyncio.run(together())
        grown = helpers.proc_status_mb(serve.proc.pid, "VmRSS") - before
        status = json.loads(serve.get("/xr/status")[1])
        for s in passive:
            s.close()
        assert grown < 60, f"the server grew by {grown:.0f} MB"
        assert not bursty["closed"], "the bursty client was cut off"
        assert np.median(bursty["pongs"]) < 0.2, f"bursty pongs: median {np.median(bursty['pongs']):.3f} s"
        assert not normal.get("closed")
        assert normal["frames_per_s"] > 0.6 * alone["frames_per_s"] or normal["frames_per_s"] > 20, (alone, normal)
        assert np.median(normal["pongs"]) < 0.2, f"normal pongs: median {np.median(normal['pongs']):.3f} s"
        # the passive clients were dropped once their sends stalled
        assert len(status["clients"]) <= 1, status
    finally:
        serve.stop()
