"""Small inputs cannot exhaust memory (issue 17, item 1), each written as the attack: a small GLB placing one mesh
thousands of times, a session archive of many members or with an S past the cap, and a 12-byte chunk header on the
page's websocket claiming 256 MB. Each is refused with a clear message within 10 s and at most 100 MB of extra peak
memory, measured in a process of its own, and a served session carries on."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
import zipfile

import helpers
import msgpack
import numpy as np
import pytest

LIMIT_MB = 100
LIMIT_S = 10.0

# Runs one loader in a fresh interpreter: the peak memory it added (VmHWM) and the time, or the message it gave.
PROBE = """
import json, resource, sys, time
import trimesh
from somwidget.backend import io, session_file
from somwidget.backend.schedule import MAX_ITERATIONS
kind, path = sys.argv[1], sys.argv[2]
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.perf_counter()
try:
    if kind == "mesh":
        io.load_mesh(path, max_vertices=16384)
    else:
        session_file.load_session(path, max_vertices=16384, max_iterations=MAX_ITERATIONS)
    message = None
except ValueError as exc:
    message = str(exc)
print(json.dumps({"message": message, "seconds": time.perf_counter() - t,
                  "extra_mb": (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) / 1024}))
"""


def probe(kind: str, path) -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE, kind, str(path)], capture_output=True, text=True,
                         timeout=300, cwd=helpers.ROOT, env={**os.environ, "PYTHONPATH": str(helpers.ROOT)})
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def refused_quickly(result: dict, words: str) -> None:
    assert result["message"] is not None, "the input was accepted"
    assert words in result["message"], result["message"]
    assert result["seconds"] < LIMIT_S, result
    assert result["extra_mb"] < LIMIT_MB, result


def test_a_small_glb_placing_one_mesh_thousands_of_times_is_refused_before_it_is_flattened(tmp_path):
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=3)  # 642 vertices
    scene = trimesh.Scene()
    scene.add_geometry(ball, geom_name="ball", node_name="n0")
    for i in range(1, 8000):  # 5.1 million vertices once placed
        matrix = np.eye(4)
        matrix[:3, 3] = [i % 20, (i // 20) % 20, i // 400]
        scene.graph.update(frame_to=f"n{i}", frame_from=scene.graph.base_frame, matrix=matrix, geometry="ball")
    path = tmp_path / "instanced.glb"
    path.write_bytes(scene.export(file_type="glb"))
    assert path.stat().st_size < 1_000_000
    refused_quickly(probe("mesh", path), "places its meshes 8,000 times")


def _saved_session(tmp_path):
    from somwidget.backend import presets, session_file

    path = tmp_path / "car.npz"
    session_file.save_session(path, session_file.session_state(presets.get_preset("car")))
    return path


def test_a_session_archive_of_many_members_is_refused_unread(tmp_path):
    good = _saved_session(tmp_path)
    bad = tmp_path / "many.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            dst.writestr(info, src.read(info))
        zeros = np.zeros(4_000_000, np.uint8).tobytes()  # each member well under the per-member limit
        for i in range(60):  # 240 MB unpacked from a few hundred KB
            dst.writestr(f"extra{i}.npy", zeros)
    assert bad.stat().st_size < 2_000_000
    refused_quickly(probe("session", bad), "not part of a somwidget session")
    # the same bytes under the format's own names: the total is bounded too
    renamed = tmp_path / "big-members.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(renamed, "w", zipfile.ZIP_DEFLATED) as dst:
        names = [i.filename for i in src.infolist()]
        for info in src.infolist():
            data = src.read(info)
            if info.filename in ("weights.npy", "start_weights.npy", "edges.npy", "face_indices.npy"):
                data = data + np.zeros(8_000_000, np.uint8).tobytes()
            dst.writestr(info.filename, data)
    assert "weights.npy" in names
    refused_quickly(probe("session", renamed), "more than")


def test_a_session_archive_with_s_past_the_cap_is_refused_before_its_table_is_built(tmp_path):
    good = _saved_session(tmp_path)
    bad = tmp_path / "long.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "iterations.npy":
                import io as _bytes

                buf = _bytes.BytesIO()
                np.save(buf, np.int64(2_000_000))
                data = buf.getvalue()
            dst.writestr(info.filename, data)
    refused_quickly(probe("session", bad), "S = 2,000,000 is more than this session allows")


def test_the_learning_table_is_built_without_float64_copies_of_the_whole_table():
    code = """
import resource, time
from somwidget.backend.schedule import learning_table
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = learning_table(1_000_000, 45)
extra = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) / 1024
print(t.nbytes / 2**20, extra)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         cwd=helpers.ROOT, env={**os.environ, "PYTHONPATH": str(helpers.ROOT)})
    assert out.returncode == 0, out.stderr
    table_mb, extra_mb = (float(x) for x in out.stdout.split())
    assert extra_mb < table_mb + 60, (table_mb, extra_mb)  # the float32 table and one block, not 4 x float64


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads the server's peak memory from /proc")
def test_a_chunk_header_claiming_256_mb_on_the_page_websocket_allocates_nothing():
    import aiohttp

    serve = helpers.Serve()
    try:
        serve.idle()
        before = helpers.proc_status_mb(serve.proc.pid, "VmHWM")

        async def attack():
            async with aiohttp.ClientSession() as cs, cs.ws_connect(serve.base.replace("http", "ws") + "/ws",
                                                                    headers={"Origin": serve.base}) as ws:
                hello = msgpack.packb({"wslink": "1.0", "id": "system:c0:0", "method": "wslink.hello",
                                       "args": [{"secret": "wslink-secret"}], "kwargs": {}})
                await ws.send_bytes(helpers.wslink_chunk(1, hello))
                reply = await ws.receive(timeout=10)
                assert reply.type == aiohttp.WSMsgType.BINARY
                t = time.perf_counter()
                closed = False
                try:
                    for mid in range(2, 10):  # eight headers, 256 MB each, no content
                        await ws.send_bytes(helpers.wslink_chunk(mid, total=256 * 2**20))
                except aiohttp.ClientConnectionResetError:  # the server closed the socket before the last ones
                    return True, time.perf_counter() - t
                try:
                    while True:
                        msg = await ws.receive(timeout=5)
                        if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                            closed = True
                            break
                except asyncio.TimeoutError:
                    pass
                return closed, time.perf_counter() - t

        closed, seconds = asyncio.run(attack())
        time.sleep(0.5)
        extra = helpers.proc_status_mb(serve.proc.pid, "VmHWM") - before
        assert extra < LIMIT_MB, f"the server's peak memory grew by {extra:.0f} MB"
        assert closed and seconds < LIMIT_S, (closed, seconds)
        # the session carries on: a move from the views' websocket is applied
        st = serve.state()
        assert st["session"]["preset"] == "car" and serve.proc.poll() is None
    finally:
        serve.stop()
