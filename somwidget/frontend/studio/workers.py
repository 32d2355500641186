"""Worker processes of a studio on this machine: one a GPU (each sees its own GPU alone, through CUDA_VISIBLE_DEVICES),
or several on the CPU; each a `RemotePlace` of the front (places.py). A worker that exits is replaced by a new one on
the same device, its rooms meanwhile brought back on the others (front.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import sys
from typing import TYPE_CHECKING

from .limits import StudioLimits
from .places import RemotePlace
from .worker import ANNOUNCE, SECRET_ENV

if TYPE_CHECKING:
    from .front import StudioFront

log = logging.getLogger(__name__)

#: Seconds a worker may take to start listening.
START_TIMEOUT = 120.0


def gpu_ids() -> list[str]:
    """The GPUs this process may use, as CUDA_VISIBLE_DEVICES names them (or their indices)."""
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None:
        return [g.strip() for g in visible.split(",") if g.strip() and g.strip() != "-1"]
    try:
        import warp as wp

        return [str(i) for i in range(wp.get_cuda_device_count())]
    except (ImportError, RuntimeError, OSError):
        return []


class LocalWorkers:
    """`count` worker processes for the rooms under `rooms_dir` (see the module's docstring). device: "cpu", "cuda"
    or "auto" (the GPUs when there are, one worker a GPU in turn, else the CPU)."""

    def __init__(self, count: int, rooms_dir, secret: str, device: str = "auto", limits: StudioLimits | None = None,
                 frame_rate: float = 30.0):
        if count < 1:
            raise ValueError(f"workers: expected at least 1, got {count}")
        self.count = count
        self.rooms_dir = str(rooms_dir)
        self.secret = secret
        self.limits = limits or StudioLimits()
        self.frame_rate = frame_rate
        gpus = [] if device == "cpu" else gpu_ids()
        if device.startswith("cuda") and not gpus:
            raise ValueError(f"--device {device}: no GPU here (CUDA_VISIBLE_DEVICES, or Warp, reports none)")
        self.gpus = gpus
        self.procs: dict[RemotePlace, asyncio.subprocess.Process] = {}
        self._task: asyncio.Task | None = None

    def gpu_of(self, i: int) -> str | None:
        """The GPU worker i uses (None: the CPU)."""
        return self.gpus[i % len(self.gpus)] if self.gpus else None

    def _device(self, i: int) -> tuple[dict, str, str]:
        """(environment, device, label) of worker i."""
        env = dict(os.environ, **{SECRET_ENV: self.secret})
        gpu = self.gpu_of(i)
        if gpu is None:  # no GPUs
            return env, "cpu", f"CPU worker {i}"
        env["CUDA_VISIBLE_DEVICES"] = gpu
        return env, "cuda:0", f"GPU {gpu}" + (f" worker {i}" if self.count > len(self.gpus) else "")

    async def spawn(self, i: int) -> RemotePlace:
        env, device, label = self._device(i)
        lim = self.limits
        args = [sys.executable, "-m", "somwidget.frontend.studio.worker", "--rooms", self.rooms_dir,
                "--device", device, "--label", label, "--rooms-per-worker", str(lim.rooms),
                "--nodes-per-room", str(lim.nodes), "--park-after", str(lim.park_after),
                "--frame-rate", str(self.frame_rate)]
        if lim.memory_mb is not None:
            args += ["--memory-per-worker", str(lim.memory_mb)]
        # a session of its own: a terminal's Ctrl+C reaches the front alone, which stops its workers in turn (and
        # a front that dies closes their stdin: they stop too)
        proc = await asyncio.create_subprocess_exec(*args, env=env, stdin=asyncio.subprocess.PIPE,
                                                    stdout=asyncio.subprocess.PIPE, start_new_session=True)
        stdout = proc.stdout
        assert stdout is not None  # stdout=PIPE
        try:
            while True:
                line = (await asyncio.wait_for(stdout.readline(), START_TIMEOUT)).decode(errors="replace")
                if not line:
                    raise RuntimeError(f"studio worker {label} exited ({await proc.wait()}) before it listened")
                if line.startswith(ANNOUNCE):
                    break
        except BaseException:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            raise
        place = RemotePlace(line[len(ANNOUNCE):].strip(), self.secret, label)
        place.index = i
        place.gpu = self.gpu_of(i)
        self.procs[place] = proc
        asyncio.ensure_future(self._drain(stdout))
        return place

    @staticmethod
    async def _drain(stdout: asyncio.StreamReader) -> None:
        with contextlib.suppress(Exception):
            while await stdout.readline():
                pass

    async def start(self) -> list[RemotePlace]:
        """Start every worker (at once); their places."""
        return list(await asyncio.gather(*(self.spawn(i) for i in range(self.count))))

    def watch(self, front: StudioFront) -> None:
        """Replace a worker that exits (its rooms come back on the others at once, front.lost)."""
        self._task = asyncio.ensure_future(self._watch(front))

    async def _watch(self, front: StudioFront) -> None:
        while True:
            await asyncio.sleep(0.5)
            for place, proc in list(self.procs.items()):
                if proc.returncode is None:
                    continue
                del self.procs[place]
                log.warning("studio: %s exited (%s); starting another", place.label, proc.returncode)
                await front.lost(place)
                try:
                    assert place.index is not None  # numbered by spawn, as every place of procs
                    front.add_place(await self.spawn(place.index))
                except Exception as exc:  # the others go on
                    log.error("studio: could not start a worker again: %s", exc)

    async def stop_watching(self) -> None:
        """No worker is replaced from now on (the studio stops: its workers' exits are no deaths)."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    async def close(self) -> None:
        await self.stop_watching()
        for proc in self.procs.values():
            if proc.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.terminate()
        for proc in self.procs.values():
            try:
                await asyncio.wait_for(proc.wait(), 20)
            except asyncio.TimeoutError:
                proc.kill()
