"""What one worker of a studio (a process, a GPU) takes: rooms, nodes a room, memory; a new room past them is
refused with a message that says which limit and what to do, instead of slowing every room down.

Memory is checked before a room is made: what the process uses now (its resident memory, and on a GPU the device's
memory in use) plus what the new room will take (`room_bytes`: its dense distance table, N x N uint16, and a measured
base) must stay within `memory_mb`, and on a GPU within the device's free memory.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

#: Room names: a letter or digit, then letters, digits, "-" or "_" (40 at most); folded to lower case.
ROOM_NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,39}")
#: A room's memory beyond its distance table (the Session, its threads, history, frames), CPU, measured for the car
#: on the CPU (BENCHMARKS.md, "Studio": memory a room).
ROOM_BASE_BYTES = 12 << 20
#: The device memory a GPU keeps free for the rooms already there (their drags, undo steps).
GPU_HEADROOM_BYTES = 512 << 20


class StudioFull(ValueError):
    """A new room refused: a limit of the worker it would go to (the message names it)."""


def room_name(text) -> str:
    """A room's name, folded to lower case; ValueError naming what is wrong."""
    if not isinstance(text, str):
        raise ValueError(f"room name: expected text, got {type(text).__name__}")
    name = text.strip().lower()
    if not ROOM_NAME.fullmatch(name):
        raise ValueError(f"room name {text[:60]!r}: use 1 to 40 letters, digits, '-' or '_', starting with a letter "
                         "or a digit (e.g. alice, group-3)")
    return name


@dataclass(frozen=True)
class StudioLimits:
    """rooms: live rooms a worker holds (parked ones do not count); nodes: a room's largest mesh (a preset, an upload,
    a refine); memory_mb: memory a worker's rooms may use (None: only the machine's and the GPU's own); park_after:
    seconds a room with no view stays live before it is parked (0: never)."""

    rooms: int = 64
    nodes: int = 65536
    memory_mb: float | None = None
    park_after: float = 300.0

    def __post_init__(self):
        if int(self.rooms) < 1:
            raise ValueError(f"rooms per worker: expected at least 1, got {self.rooms}")
        if int(self.nodes) < 4:
            raise ValueError(f"nodes per room: expected at least 4, got {self.nodes}")
        if self.memory_mb is not None and float(self.memory_mb) <= 0:
            raise ValueError(f"memory per worker: expected a positive number of MB, got {self.memory_mb}")
        if float(self.park_after) < 0:
            raise ValueError(f"park after: expected seconds >= 0, got {self.park_after}")


def room_bytes(n_nodes: int) -> int:
    """What a room of `n_nodes` nodes takes, roughly: its dense distance table and a base."""
    return 2 * int(n_nodes) ** 2 + ROOM_BASE_BYTES


def resident_bytes() -> int:
    """This process's resident memory (bytes; 0 where it cannot be read)."""
    try:
        with open(f"/proc/{os.getpid()}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        import resource

        return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024
    except (ImportError, OSError):  # pragma: no cover
        return 0


def device_free_bytes(device: str) -> int | None:
    """Free memory of a CUDA device (bytes), None on the CPU."""
    if not str(device).startswith("cuda"):
        return None
    import warp as wp

    return int(wp.get_device(device).free_memory)


def device_used_bytes(device: str) -> int:
    """Memory in use on a CUDA device (by every process on it; bytes), 0 on the CPU."""
    if not str(device).startswith("cuda"):
        return 0
    import warp as wp

    d = wp.get_device(device)
    return int(d.total_memory - d.free_memory)


def check_new_room(limits: StudioLimits, live: int, n_nodes: int, device: str, where: str) -> None:
    """StudioFull unless a room of `n_nodes` fits beside the `live` rooms of the worker `where` on `device`."""
    if live >= limits.rooms:
        raise StudioFull(f"the studio is full: {where} holds {live} rooms, its limit (--rooms-per-worker "
                         f"{limits.rooms}); a room is parked after {limits.park_after:g} s without a view, or ask "
                         "whoever runs the studio for more workers")
    if n_nodes > limits.nodes:
        raise StudioFull(f"a room of {n_nodes:,} nodes is past the studio's limit of {limits.nodes:,} nodes a room "
                         "(--nodes-per-room); choose a smaller preset or mesh")
    need = room_bytes(n_nodes)
    if limits.memory_mb is not None:
        used = resident_bytes()
        if used + need > limits.memory_mb * 2**20:
            raise StudioFull(f"the studio is full: {where} uses {used / 2**20:,.0f} MB and a room of {n_nodes:,} "
                             f"nodes needs about {need / 2**20:,.0f} MB more, past its {limits.memory_mb:,.0f} MB "
                             "(--memory-per-worker)")
    free = device_free_bytes(device)
    if free is not None and free < need + GPU_HEADROOM_BYTES:
        raise StudioFull(f"the studio is full: {device} of {where} has {free / 2**20:,.0f} MB free and a room of "
                         f"{n_nodes:,} nodes needs about {need / 2**20:,.0f} MB (with {GPU_HEADROOM_BYTES >> 20} MB "
                         "kept for the rooms there)")
