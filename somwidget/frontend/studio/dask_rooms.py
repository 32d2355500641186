"""A studio's rooms on the workers of a Dask cluster (`somwidget serve --studio --scheduler tcp://host:8786`).

Each worker runs a room server of its own (host.py, started in the worker's process by `Client.run`: a thread with its
event loop, on the worker's own address) and the front relays each room's websocket to the worker that holds it
(places.py): the workers' own servers, not actors, because a move reaches its frame sooner that way and frames come
as they are made rather than by polling (BENCHMARKS.md, "Studio": on a LocalCluster of two workers, one room: median
15 ms against 20 ms; two rooms: 27 ms against 61 ms). A GPU worker (dask-cuda: one a GPU, CUDA_VISIBLE_DEVICES set for
it) trains on its GPU, any other on its CPU.

Every second the front asks the scheduler which workers there are: one that came gets a room server, one that went
is dead to the front (front.lost): its rooms come back on the others from their autosaves, which is why the rooms
folder must be one every worker reaches (a shared file system with POSIX locks).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

from .limits import StudioLimits
from .places import RemotePlace

if TYPE_CHECKING:
    from distributed import Client

    from .front import StudioFront

log = logging.getLogger(__name__)

#: Seconds between two looks at the scheduler's workers.
WATCH_PERIOD = 1.0
_SERVERS: dict = {}  # in a worker's process: (rooms folder) -> its RoomServer


def start_room_server(rooms_dir: str, secret: str, limits: dict, frame_rate: float, dask_worker=None) -> str:
    """In a Dask worker's process: its room server (started once), reachable on the worker's own host; its URL."""
    from .host import RoomServer
    from .rooms import Rooms

    server = _SERVERS.get(rooms_dir)
    if server is None:
        host = urlsplit(dask_worker.address.replace("tcp://", "http://", 1)).hostname if dask_worker else "127.0.0.1"
        device = "cuda:0" if os.environ.get("CUDA_VISIBLE_DEVICES") and _has_gpu() else "cpu"
        name = getattr(dask_worker, "name", None)
        name = os.getpid() if name is None else name
        rooms = Rooms(rooms_dir, device=device, limits=StudioLimits(**limits), frame_rate=frame_rate,
                      label=f"Dask worker {name} ({device})")
        server = _SERVERS[rooms_dir] = RoomServer(rooms, secret, host=host, port=0).start()
    return server.url


def _has_gpu() -> bool:
    try:
        import warp as wp

        return wp.get_cuda_device_count() > 0
    except (ImportError, RuntimeError, OSError):
        return False


class DaskRooms:
    """The room servers of a Dask cluster's workers (see the module's docstring)."""

    def __init__(self, scheduler: str, rooms_dir, secret: str, limits: StudioLimits, frame_rate: float):
        self.scheduler = scheduler
        self.rooms_dir = str(rooms_dir)
        self.secret = secret
        self.limits = limits
        self.frame_rate = frame_rate
        self.client: Client | None = None  # connected by start()
        self.places: dict[str, RemotePlace] = {}  # worker address -> its room server
        self._task: asyncio.Task | None = None

    @property
    def connected(self) -> Client:
        """The client of the cluster's scheduler (start() connects it)."""
        if self.client is None:
            raise RuntimeError(f"not connected to the Dask scheduler {self.scheduler} (DaskRooms.start() first)")
        return self.client

    async def start(self) -> list[RemotePlace]:
        try:
            from distributed import Client
        except ImportError:
            raise ValueError("--scheduler needs Dask: pip install somwidget[dask]") from None
        self.client = await Client(self.scheduler, asynchronous=True, timeout="30s")
        await self._join(list((await self.client.scheduler.identity())["workers"]))
        if not self.places:
            raise ValueError(f"the Dask scheduler {self.scheduler} has no workers: start some (docs/studio.md)")
        return list(self.places.values())

    async def _join(self, workers: list[str]) -> list[RemotePlace]:
        """Room servers on `workers` (started where there is none)."""
        if not workers:
            return []
        limits = {"rooms": self.limits.rooms, "nodes": self.limits.nodes, "memory_mb": self.limits.memory_mb,
                  "park_after": self.limits.park_after}
        urls = await self.connected.run(start_room_server, self.rooms_dir, self.secret, limits, self.frame_rate,
                                        workers=workers, on_error="return")
        came = []
        for address, url in urls.items():
            if isinstance(url, BaseException):
                log.error("studio: no room server on %s: %s", address, url)
                continue
            place = RemotePlace(url, self.secret, f"Dask worker {address}")
            with contextlib.suppress(Exception):
                await place.health()
                place.label = (await place.health())["label"]
            self.places[address] = place
            came.append(place)
        return came

    def watch(self, front: StudioFront) -> None:
        """Rooms' servers on the workers that come (front.add_place); the rooms of those that go elsewhere
        (front.lost)."""
        self._task = asyncio.ensure_future(self._watch(front))

    async def _watch(self, front: StudioFront) -> None:
        while True:
            await asyncio.sleep(WATCH_PERIOD)
            try:
                workers = set((await self.connected.scheduler.identity())["workers"])
            except Exception as exc:  # the scheduler is away: the places' own checks go on
                log.warning("studio: cannot reach the Dask scheduler: %s", exc)
                continue
            for address in [a for a in self.places if a not in workers]:
                await front.lost(self.places.pop(address))
            for place in await self._join(sorted(workers - set(self.places))):
                front.add_place(place)

    async def stop_watching(self) -> None:
        """No worker's coming or going is followed from now on (the studio stops)."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None

    async def close(self) -> None:
        await self.stop_watching()
        if self.client is not None:
            with contextlib.suppress(Exception):
                await self.client.close()
