"""Bounded memory and logs (issue 27, item 5), each written as the fault and measured as peak RSS (VmHWM) of a fresh
process: a valid `set iterations` intent on an 8,192-vertex strip (it took the server from 375 MB to 4,461 MB: the
learning table held twice over, old and new at once); six page-websocket clients each sending 50 MB of unfinished
messages (1.24 GB held, then kept until a garbage collection, and a 25-line traceback per refused chunk); a 200 KB
GLB placing one mesh thousands of times at a GPU session's vertex limit (8.9 s and 1.84 GB before it was refused)."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time

import helpers
import msgpack
import numpy as np
import pytest

pytestmark = pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads peak memory from /proc")


def peak_from_now(pid) -> float:
    """Reset a process's peak RSS (VmHWM) to its RSS now (Linux 4.0+: clear_refs 5); returns that RSS in MB."""
    with open(f"/proc/{pid}/clear_refs", "w") as f:
        f.write("5")
    return helpers.proc_status_mb(pid, "VmHWM")


def strip_obj(path, n: int = 4096) -> None:
    """A 2 x n grid strip of quads (2n vertices, grid diameter n)."""
    lines = [f"v {i} {j} 0" for j in range(2) for i in range(n)]
    lines += [f"f {i + 1} {i + 2} {n + i + 2} {n + i + 1}" for i in range(n - 1)]
    path.write_text("\n".join(lines) + "\n")


async def _set(base: str, name: str, value) -> None:
    import aiohttp

    async with aiohttp.ClientSession() as cs, cs.ws_connect(base.replace("http", "ws") + "/view/ws") as ws:
        await ws.send_json({"type": "set", "name": name, "value": value})  # 54 bytes
        await ws.send_json({"type": "ping", "t": 1})
        while True:
            msg = await ws.receive(timeout=120)
            assert '"error"' not in str(msg.data), msg.data
            if msg.type == aiohttp.WSMsgType.TEXT and '"pong"' in msg.data:
                return


def test_an_s_change_costs_at_most_one_learning_table(tmp_path):
    strip_obj(tmp_path / "strip.obj")
    srv = helpers.Serve("--mesh", str(tmp_path / "strip.obj"), timeout=300)
    try:
        st = srv.idle(120)
        assert st["session"]["n_vertices"] == 8192
        before = peak_from_now(srv.proc.pid)
        S, d_max = 25_000, 4096
        table_mb = S * (d_max + 1) * 4 / 2**20  # 391 MiB
        asyncio.run(_set(srv.base, "iterations", S))
        srv.wait(lambda s: s["session"]["frame"]["iterations"] == S, 120, "the engine to take S")
        peak = helpers.proc_status_mb(srv.proc.pid, "VmHWM") - before
        now = helpers.proc_status_mb(srv.proc.pid, "VmRSS")
        assert peak < table_mb + 64, f"an S change cost {peak:.0f} MB of peak memory; one table is {table_mb:.0f} MB"
        print(f"S change to {S:,} (table {table_mb:.0f} MiB): peak +{peak:.0f} MB, RSS {now:.0f} MB")
    finally:
        srv.stop()


def test_pending_bytes_are_bounded_across_clients_and_a_refused_client_logs_one_line():
    import aiohttp

    from somwidget.frontend.transport import limits

    srv = helpers.Serve()
    try:
        srv.idle()
        base_hwm = peak_from_now(srv.proc.pid)
        chunk = 4_000_000  # wslink's chunks are at most 4 MiB a websocket message
        per_client = 48_000_000

        async def client(i: int, out: dict) -> None:
            async with aiohttp.ClientSession() as cs, cs.ws_connect(
                    srv.base.replace("http", "ws") + "/ws", headers={"Origin": srv.base},
                    max_msg_size=0) as ws:
                hello = msgpack.packb({"wslink": "1.0", "id": f"system:c{i}:0", "method": "wslink.hello",
                                       "args": [{"secret": "wslink-secret"}], "kwargs": {}})
                await ws.send_bytes(helpers.wslink_chunk(1, hello))
                await ws.receive(timeout=20)
                payload = os.urandom(chunk)
                out[i] = "held"
                try:  # a message of 60 MB of which 48 MB come, then nothing: held until the client goes
                    for offset in range(0, per_client, chunk):
                        await ws.send_bytes(helpers.wslink_chunk(2, payload, total=60_000_000, offset=offset))
                        await asyncio.sleep(0.01)
                    deadline = time.monotonic() + 3  # the held ones stay a while: the others are refused meanwhile
                    while time.monotonic() < deadline:
                        try:
                            msg = await ws.receive(timeout=deadline - time.monotonic())
                        except (asyncio.TimeoutError, TimeoutError):
                            break
                        if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                            out[i] = f"closed {ws.close_code}"
                            break
                except ConnectionError:  # closed while it was still sending
                    out[i] = "closed"

        async def six():
            out: dict = {}
            await asyncio.gather(*(client(i, out) for i in range(6)))
            return out

        t = time.perf_counter()
        out = asyncio.run(six())
        seconds = time.perf_counter() - t
        peak = helpers.proc_status_mb(srv.proc.pid, "VmHWM") - base_hwm
        held = sorted(v for v in out.values())
        assert held.count("held") == limits.MAX_TOTAL_PENDING_BYTES // per_client, out  # 3 fit in the budget
        assert all(v == "held" or v.startswith("closed") for v in out.values()), out  # 1009, or cut while sending
        budget_mb = limits.MAX_TOTAL_PENDING_BYTES / 1e6
        assert peak < budget_mb + 100, f"six clients took the server's peak memory up by {peak:.0f} MB"
        log = srv.output()
        refusals = [line for line in log.splitlines() if "refused the page websocket's client" in line]
        assert len(refusals) == 3, log[-3000:]
        assert "Traceback" not in log, log[-3000:]
        srv.state()  # the session carries on
        print(f"six clients of 48 MB each: 3 held, 3 refused in {seconds:.1f} s; peak +{peak:.0f} MB")
    finally:
        srv.stop()


PROBE = """
import json, resource, sys, time
import trimesh
from somwidget.backend import io
def status(field):
    return next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith(field + ":")) / 1024
open("/proc/self/clear_refs", "w").write("5")  # the peak from here on
base = status("VmHWM")
t = time.perf_counter()
try:
    io.load_mesh(sys.argv[1], max_vertices=int(sys.argv[2]))
    message = None
except ValueError as exc:
    message = str(exc)
print(json.dumps({"message": message, "seconds": time.perf_counter() - t, "extra_mb": status("VmHWM") - base}))
"""


def test_a_gpu_sized_import_is_counted_before_it_is_expanded(tmp_path):
    import trimesh

    from somwidget.frontend.model.state import GPU_MAX_VERTICES

    ball = trimesh.creation.icosphere(subdivisions=4)  # 2,562 vertices
    scene = trimesh.Scene()
    scene.add_geometry(ball, geom_name="ball", node_name="n0")
    for i in range(1, 1700):  # 4.4 million vertices once placed
        matrix = np.eye(4)
        matrix[:3, 3] = [i % 20, (i // 20) % 20, i // 400]
        scene.graph.update(frame_to=f"n{i}", frame_from=scene.graph.base_frame, matrix=matrix, geometry="ball")
    path = tmp_path / "instanced.glb"
    path.write_bytes(scene.export(file_type="glb"))
    size_kb = path.stat().st_size / 1000
    assert size_kb < 300
    out = subprocess.run([sys.executable, "-c", PROBE, str(path), str(GPU_MAX_VERTICES)], capture_output=True,
                         text=True, timeout=300, cwd=helpers.ROOT, env={**os.environ, "PYTHONPATH": str(helpers.ROOT)})
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["message"] and "places its meshes 1,700 times" in result["message"], result
    assert result["seconds"] < 1.0 and result["extra_mb"] < 100, result
    print(f"{size_kb:.0f} KB GLB at {GPU_MAX_VERTICES:,} vertices: refused in {result['seconds']:.2f} s, "
          f"+{result['extra_mb']:.0f} MB")
