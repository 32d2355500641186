"""`somwidget serve --studio`: many rooms on one server, each a session of its own (rooms.py), the wall of every room
(wall.py), on this process, on worker processes of this machine (one a GPU: workers.py) or on the workers of a Dask
cluster (dask_rooms.py); the front (front.py, routes.py) holds the browsers' connections.

    with StudioServer(rooms_dir, port=0) as studio:      # tests, benchmarks: served from a thread
        print(studio.wall_url, studio.lobby_url)
    run_studio(...)                                     # the command: served until interrupted

Beyond loopback it is served over HTTPS (web/lan.py's certificate); every route needs a token (access.py) and passes
the LAN guard (Host, Origin). Imports no UI package: aiohttp, numpy and warp are all it needs.
"""

from __future__ import annotations

import asyncio
import logging
import secrets
import signal
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from aiohttp import web

from ..model.storage import data_dir
from ..web import lan
from .access import StudioAccess
from .front import StudioFront
from .host import SHUTDOWN_TIMEOUT
from .limits import StudioLimits, room_name
from .places import LocalPlace, Place
from .rooms import FRAME_RATE, Rooms
from .routes import StudioRoutes

if TYPE_CHECKING:
    from .dask_rooms import DaskRooms
    from .workers import LocalWorkers

log = logging.getLogger(__name__)


def default_rooms_dir() -> Path:
    return data_dir() / "studio"


class StudioServer:
    """A studio (see the module's docstring). rooms_dir: its rooms' folders (default: <data dir>/studio; on a cluster
    a folder every worker reaches); workers: worker processes on this machine (0: rooms in this process);
    scheduler: a Dask scheduler's address whose workers hold the rooms; rooms: names of rooms to have at start;
    lan_config: web/lan.py's, to serve over HTTPS."""

    def __init__(self, rooms_dir=None, host: str = "127.0.0.1", port: int = 0, device: str = "auto",
                 workers: int = 0, limits: StudioLimits | None = None, preset: str = "car",
                 frame_rate: float = FRAME_RATE, access: StudioAccess | None = None, lan_config=None,
                 scheduler: str | None = None, rooms=(), dist=None):
        self.rooms_dir = Path(rooms_dir) if rooms_dir is not None else default_rooms_dir()
        self.host = lan.normalise_host(host) or "127.0.0.1"
        if not lan.is_loopback(self.host) and lan_config is None:
            raise ValueError(f"host {self.host!r} is reachable from other machines: serve it with a LAN configuration "
                             "(HTTPS and tokens: web/lan.py prepare_lan)")
        self.port = port
        self.device = device
        self.workers = int(workers)
        self.limits = limits or StudioLimits()
        self.preset = preset
        self.frame_rate = frame_rate
        self.access = access or StudioAccess.kept_in(self.rooms_dir)
        self.lan_config = lan_config
        self.scheduler = scheduler
        self.initial_rooms = [room_name(n) for n in rooms]
        self.dist = dist
        self.secret = secrets.token_urlsafe(24)  # the front's, for its workers
        self.front: StudioFront | None = None
        self.routes: StudioRoutes | None = None
        self.pool: LocalWorkers | DaskRooms | None = None
        self._runner: web.AppRunner | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._error: BaseException | None = None

    # -- addresses ----------------------------------------------------------------------------------------------
    @property
    def base(self) -> str:
        shown = self.lan_config.host if self.lan_config is not None else self.host
        shown = f"[{shown}]" if ":" in shown else shown
        return f"{'https' if self.lan_config is not None else 'http'}://{shown}:{self.port}"

    @property
    def wall_url(self) -> str:
        return f"{self.base}/wall?token={self.access.teacher}"

    @property
    def lobby_url(self) -> str:
        return f"{self.base}/?token={self.access.join}"

    def room_url(self, name: str, watch: bool = False) -> str:
        if self.front is None:
            raise RuntimeError("the studio is not started: its rooms have no links yet (start() first)")
        entry = self.front.rooms[room_name(name)]
        return f"{self.base}/r/{entry.name}/{'watch/' if watch else ''}?token={entry.token}"

    # -- running ------------------------------------------------------------------------------------------------
    async def _places(self) -> Sequence[Place]:
        if self.scheduler:
            from .dask_rooms import DaskRooms

            self.pool = DaskRooms(self.scheduler, self.rooms_dir, self.secret, self.limits, self.frame_rate)
            return await self.pool.start()
        if self.workers:
            from .workers import LocalWorkers

            self.pool = LocalWorkers(self.workers, self.rooms_dir, self.secret, self.device, self.limits,
                                     self.frame_rate)
            return await self.pool.start()
        rooms = Rooms(self.rooms_dir, device=self.device, limits=self.limits, frame_rate=self.frame_rate)
        rooms.label = "this process (" + ("CPU" if rooms.device == "cpu" else rooms.device) + ")"
        return [LocalPlace(rooms)]

    async def start_async(self) -> None:
        self.rooms_dir.mkdir(parents=True, exist_ok=True)
        self.front = StudioFront(await self._places(), preset=self.preset)
        await self.front.start()
        if self.pool is not None:
            self.pool.watch(self.front)
        self.routes = StudioRoutes(self.front, self.access, self.dist)
        app = web.Application(middlewares=[lan.request_guard(check_host=lan.is_loopback(self.host))])
        self.routes.add_routes(app.router)
        self.routes.wall.start()
        self._runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=SHUTDOWN_TIMEOUT)
        await self._runner.setup()
        ssl = self.lan_config.ssl_context() if self.lan_config is not None else None
        site = web.TCPSite(self._runner, self.lan_config.bind if self.lan_config else self.host, self.port,
                           ssl_context=ssl)
        await site.start()
        self.port = site._server.sockets[0].getsockname()[1]
        for name in self.initial_rooms:
            if name not in self.front.rooms:
                await self.front.create(name)

    async def stop_async(self) -> None:
        if self.pool is not None:
            await self.pool.stop_watching()  # the workers' exits from now on are the stop's, not deaths
        if self.routes is not None:
            await self.routes.wall.close()
        if self.front is not None:
            await self.front.close()  # no more looks at the places; the relays closed; this process's rooms saved
        if self.pool is not None:
            await self.pool.close()  # the workers' rooms saved as they stop
        if self._runner is not None:
            await self._runner.cleanup()

    async def _main(self) -> None:
        self._stop = asyncio.Event()
        try:
            await self.start_async()
        except BaseException as exc:
            self._error = exc
            self._ready.set()
            await self.stop_async()
            raise
        self._ready.set()
        try:
            await self._stop.wait()
        finally:
            await self.stop_async()

    def start(self, timeout: float = 180.0) -> StudioServer:
        """Serve from a daemon thread (tests, benchmarks); returns once it listens."""
        def run():
            self._loop = asyncio.new_event_loop()
            try:
                self._loop.run_until_complete(self._main())
            except BaseException:  # start() reports it
                pass
            finally:
                self._loop.close()

        self._thread = threading.Thread(target=run, name="somwidget-studio", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise RuntimeError("the studio did not start")
        if self._error is not None:
            raise RuntimeError(f"the studio did not start: {self._error}") from self._error
        return self

    def stop(self, timeout: float = 60.0) -> None:
        if self._loop is not None and self._stop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._stop.set)
        if self._thread is not None:
            self._thread.join(timeout)

    def call(self, coroutine, timeout: float = 60.0):
        """Run a coroutine on the studio's loop from another thread (tests)."""
        if self._loop is None:
            raise RuntimeError("the studio is not started: it has no event loop to run on (start() first)")
        return asyncio.run_coroutine_threadsafe(coroutine, self._loop).result(timeout)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def run(self) -> None:
        """Serve in this thread until SIGINT or SIGTERM (every room saved)."""
        async def main():
            loop = asyncio.get_running_loop()
            task = asyncio.ensure_future(self._main())
            await asyncio.sleep(0)
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, lambda: self._stop.set())
            while not self._ready.is_set() and not task.done():
                await asyncio.sleep(0.05)
            if self._error is None:
                print(self.announcement(), flush=True)
            await task

        asyncio.run(main())

    def announcement(self) -> str:
        where = {0: "in this process"}.get(self.workers, f"on {self.workers} worker processes")
        if self.scheduler:
            where = f"on the workers of {self.scheduler}"
        park = self.limits.park_after
        parking = f"a room with no view is parked after {park:g} s" if park else "rooms are never parked"
        lines = [f"somwidget serving the studio at {self.base}/ (rooms {where}, device {self.device}; {parking})",
                 f"  the wall and every room (teacher): {self.wall_url}",
                 f"  the class (each person makes a room of their own): {self.lobby_url}"]
        lines += [f"  room {name}: {self.room_url(name)}" for name in self.initial_rooms]
        if self.lan_config is not None:
            lines += [f"  desktop: {self.lobby_url}",
                      f"  certificate SHA-256: {lan.certificate_fingerprint(self.lan_config.cert)}",
                      "  The browser warns about the certificate once: accept it (see README, 'AR headsets')."]
        lines.append(f"  rooms are kept in {self.rooms_dir}")
        return "\n".join(line for line in lines if line)


def run_studio(host: str | None = None, port: int = 8080, device: str = "auto", lan_mode: bool = False,
               workers: int | None = None, limits: StudioLimits | None = None, preset: str = "car",
               rooms_dir=None, rooms=(), scheduler: str | None = None) -> None:
    """`somwidget serve --studio`: serve until interrupted (see StudioServer). workers None: one worker process a
    GPU where there are two or more, else the rooms in this process."""
    host = lan.normalise_host(host)
    lan_config = None
    if lan_mode or not lan.is_loopback(host):
        lan_config = lan.prepare_lan(host)
        host = lan_config.bind
    if workers is None:
        from .workers import gpu_ids

        gpus = [] if device == "cpu" else gpu_ids()
        workers = len(gpus) if len(gpus) >= 2 and not scheduler else 0
    StudioServer(rooms_dir, host or "127.0.0.1", port, device, workers, limits, preset, lan_config=lan_config,
                 scheduler=scheduler, rooms=rooms).run()
