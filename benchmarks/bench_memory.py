"""Memory of the faults of issue 27, item 5, as peak RSS (VmHWM, reset with /proc/PID/clear_refs) of a fresh
`somwidget serve` or interpreter, against the source tree given (default: this checkout), so that a tree from before
a change can be measured the same way:

    python benchmarks/bench_memory.py [--root DIR]

1. a valid `set iterations` intent (54 bytes) on an 8,192-vertex strip (2 x 4096 quads, grid diameter 4096), S 1,000
   to 25,000 and to 100,000: the learning table is 410 MB and 1,639 MB;
2. six clients of the page's websocket each sending 48 MB of one unfinished 60 MB message, twice;
3. a 272 KB GLB placing a 2,562-vertex sphere 1,700 times, loaded at a GPU session's limit (4,194,304 vertices);
4. the autosave: the time to write a completed step (Session.flush_autosave) of the car and of a 16,384-vertex grid.
Linux only (/proc).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import msgpack

HERE = Path(__file__).resolve().parent


def status_mb(pid: int, field: str) -> float:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field + ":")) / 1024


def reset_peak(pid: int) -> float:
    with open(f"/proc/{pid}/clear_refs", "w") as f:
        f.write("5")
    return status_mb(pid, "VmHWM")


class Server:
    def __init__(self, root: Path, *args: str):
        self.log = Path(tempfile.mkdtemp()) / "serve.log"
        env = {**os.environ, "PYTHONPATH": str(root), "SOMWIDGET_DATA_DIR": tempfile.mkdtemp()}
        with open(self.log, "w") as out:
            self.proc = subprocess.Popen([sys.executable, "-m", "somwidget.cli", "serve", "--port", "0", "--device",
                                          "cpu", "--fresh", *args], cwd=root, env=env, stdout=out,
                                         stderr=subprocess.STDOUT)
        while not (m := re.search(r"at http://127.0.0.1:(\d+)/", self.log.read_text())):
            if self.proc.poll() is not None:
                raise SystemExit(self.log.read_text()[-2000:])
            time.sleep(0.2)
        self.base = f"http://127.0.0.1:{m.group(1)}"

    def state(self) -> dict:
        import urllib.request

        with urllib.request.urlopen(self.base + "/api/state", timeout=30) as r:
            return json.loads(r.read())["session"]

    def idle(self) -> None:
        while (s := self.state())["frame"]["running"] or s["pending_intents"]:
            time.sleep(0.2)

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(60)


def chunk(mid: int, payload: bytes = b"", total: int | None = None, offset: int = 0) -> bytes:
    total = len(payload) if total is None else total
    return mid.to_bytes(4, "little") + offset.to_bytes(4, "little") + total.to_bytes(4, "little") + payload


def s_change(root: Path, folder: Path) -> None:
    n = 4096
    lines = [f"v {i} {j} 0" for j in range(2) for i in range(n)]
    lines += [f"f {i + 1} {i + 2} {n + i + 2} {n + i + 1}" for i in range(n - 1)]
    (folder / "strip.obj").write_text("\n".join(lines) + "\n")
    for S in (25_000, 100_000):
        srv = Server(root, "--mesh", str(folder / "strip.obj"))
        try:
            srv.idle()
            before = reset_peak(srv.proc.pid)

            async def send(srv=srv, S=S):
                import aiohttp

                url = srv.base.replace("http", "ws") + "/view/ws"
                async with aiohttp.ClientSession() as cs, cs.ws_connect(url) as ws:
                    await ws.send_json({"type": "set", "name": "iterations", "value": S})

            t = time.perf_counter()
            asyncio.run(send())
            while srv.state()["frame"]["iterations"] != S:
                time.sleep(0.1)
            peak = status_mb(srv.proc.pid, "VmHWM")
            print(f"S 1,000 -> {S:,} (table {S * (n + 1) * 4 / 1e6:,.0f} MB): RSS {before:,.0f} MB before, peak "
                  f"{peak:,.0f} MB (+{peak - before:,.0f}), {status_mb(srv.proc.pid, 'VmRSS'):,.0f} MB after; "
                  f"{time.perf_counter() - t:.1f} s", flush=True)
        finally:
            srv.stop()


def six_clients(root: Path) -> None:
    import aiohttp

    srv = Server(root)
    try:
        srv.idle()
        before = reset_peak(srv.proc.pid)

        async def client(i: int, out: dict) -> None:
            async with aiohttp.ClientSession() as cs, cs.ws_connect(srv.base.replace("http", "ws") + "/ws",
                                                                    headers={"Origin": srv.base}) as ws:
                hello = msgpack.packb({"wslink": "1.0", "id": f"system:c{i}:0", "method": "wslink.hello",
                                       "args": [{"secret": "wslink-secret"}], "kwargs": {}})
                await ws.send_bytes(chunk(1, hello))
                await ws.receive(timeout=20)
                payload = os.urandom(4_000_000)
                out[i] = "held"
                try:
                    for offset in range(0, 48_000_000, 4_000_000):
                        await ws.send_bytes(chunk(2, payload, total=60_000_000, offset=offset))
                        await asyncio.sleep(0.01)
                    deadline = time.monotonic() + 3
                    while time.monotonic() < deadline:
                        try:
                            msg = await ws.receive(timeout=deadline - time.monotonic())
                        except asyncio.TimeoutError:
                            break
                        if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED):
                            out[i] = "closed"
                            break
                except ConnectionError:
                    out[i] = "closed"

        async def six() -> dict:
            out: dict = {}
            await asyncio.gather(*(client(i, out) for i in range(6)))
            return out

        for round_ in (1, 2):  # the second round: memory freed by the first is used again, nothing more held
            out = asyncio.run(six())
            peak = status_mb(srv.proc.pid, "VmHWM")
            time.sleep(1)
            log = srv.log.read_text()
            print(f"six clients of 48 MB, round {round_}: {list(out.values()).count('held')} held, "
                  f"{list(out.values()).count('closed')} closed; RSS {before:,.0f} MB before, peak {peak:,.0f} MB "
                  f"(+{peak - before:,.0f}), {status_mb(srv.proc.pid, 'VmRSS'):,.0f} MB when they are gone; log: "
                  f"{len(log.splitlines())} lines, {log.count('Traceback')} tracebacks", flush=True)
    finally:
        srv.stop()


PROBE = """
import json, sys, time
from somwidget.backend import io
def status(field):
    return next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith(field + ":")) / 1024
open("/proc/self/clear_refs", "w").write("5")
base = status("VmHWM")
t = time.perf_counter()
try:
    io.load_mesh(sys.argv[1], max_vertices=4194304)
    message = None
except ValueError as exc:
    message = str(exc)
print(json.dumps({"message": message, "seconds": time.perf_counter() - t, "extra_mb": status("VmHWM") - base}))
"""


def instanced_glb(root: Path, folder: Path) -> None:
    import numpy as np
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=4)
    scene = trimesh.Scene()
    scene.add_geometry(ball, geom_name="ball", node_name="n0")
    for i in range(1, 1700):
        m = np.eye(4)
        m[:3, 3] = [i % 20, (i // 20) % 20, i // 400]
        scene.graph.update(frame_to=f"n{i}", frame_from=scene.graph.base_frame, matrix=m, geometry="ball")
    path = folder / "instanced.glb"
    path.write_bytes(scene.export(file_type="glb"))
    out = subprocess.run([sys.executable, "-c", PROBE, str(path)], capture_output=True, text=True, cwd=root,
                         env={**os.environ, "PYTHONPATH": str(root)})
    r = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"{path.stat().st_size / 1000:.0f} KB instanced GLB at 4,194,304 vertices: {r['seconds']:.2f} s, peak "
          f"+{r['extra_mb']:,.0f} MB: {r['message'][len(str(path)) + 2:][:90]}...", flush=True)


SAVES = """
import os, tempfile, time
os.environ["SOMWIDGET_DATA_DIR"] = tempfile.mkdtemp()
from somwidget.frontend.model import Session
n = 128
grid = os.path.join(tempfile.mkdtemp(), "grid.obj")
with open(grid, "w") as f:
    f.write("".join(f"v {i} {j} 0\\n" for j in range(n) for i in range(n)))
    f.write("".join(f"f {j * n + i + 1} {j * n + i + 2} {(j + 1) * n + i + 2} {(j + 1) * n + i + 1}\\n"
                    for j in range(n - 1) for i in range(n - 1)))
for name in ("car", grid):
    s = Session("car", device="cpu", start=False)
    if name != "car":
        s.load_mesh(name)
    assert s.autosave.flush(60)
    times = []
    for i in range(5):
        s.settings.set("reach", 0.1 + 0.01 * i)
        t = time.perf_counter()
        assert s.autosave.flush(60)
        times.append(time.perf_counter() - t)
    print(f"autosave of a completed step, {s.preset.name} ({s.preset.n_vertices:,} nodes): median "
          f"{1e3 * sorted(times)[2]:.1f} ms", flush=True)
    s.close()
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=HERE.parent, help="the source tree to measure")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp())
    s_change(args.root, folder)
    six_clients(args.root)
    instanced_glb(args.root, folder)
    if (args.root / "somwidget" / "frontend" / "model" / "store.py").exists():
        subprocess.run([sys.executable, "-c", SAVES], cwd=args.root, env={**os.environ, "PYTHONPATH": str(args.root)})


if __name__ == "__main__":
    main()
