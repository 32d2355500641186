"""The studio's front: which rooms there are, where each lives, and placing new and orphaned ones.

The front holds the browsers' connections (routes.py) and a directory of rooms: each room's name, token, preset and
place (places.py: this process, or a worker's room server). A new room goes to the least loaded place: on the GPU
whose workers hold the fewest live rooms for their limits (where several workers share a GPU), then the worker with the
fewest for its limit, then the fewest nodes. Every MONITOR_PERIOD seconds the front asks each place how it is and what
it holds (the wall's list comes from there); a place that fails DEAD_AFTER checks in a row, or that its cluster says has
gone, is dead: its rooms are brought back on the other places from their autosaves (a room's folder is on storage every
worker reaches), the live ones at once, the parked ones when next opened.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import time
from collections.abc import Awaitable, Callable, Collection, Coroutine, Iterable
from dataclasses import dataclass, field

from ..web import lan
from .limits import StudioFull, room_name
from .places import Place, PlaceDown
from .rooms import RoomBusy

log = logging.getLogger(__name__)

#: Seconds between two looks at a place (the places' looks spread over them).
MONITOR_PERIOD = 1.0
#: Failed looks in a row after which a place is dead.
DEAD_AFTER = 2
#: Seconds to keep trying a room whose folder another process still holds (a worker going down lets go of it).
BUSY_WAIT = 8.0


def _logged(task: asyncio.Future) -> None:
    """A task of the front's that failed in a way it does not handle: logged, never left unretrieved."""
    if not task.cancelled() and task.exception() is not None:
        log.error("studio: %s failed", task, exc_info=task.exception())


@dataclass
class Entry:
    """A room as the front knows it."""

    name: str
    token: str
    preset: str = "car"
    place: Place | None = None
    info: dict = field(default_factory=dict)
    slot: int = 0  # its number on the wall


class StudioFront:
    """The directory of rooms over `places` (see the module's docstring). `preset`: what a new room starts from."""

    def __init__(self, places: Iterable[Place], preset: str = "car"):
        self.places: list[Place] = list(places)
        self.preset = preset
        self.rooms: dict[str, Entry] = {}
        self.moved: list[tuple[str, str, str, float]] = []  # (room, from, to, seconds): rooms brought back elsewhere
        self._slots = itertools.count(1)
        self._locks: dict[str, asyncio.Lock] = {}
        self._task: asyncio.Task | None = None
        self._tasks: set[asyncio.Task] = set()

    # -- start and stop ---------------------------------------------------------------------------------------
    async def start(self) -> None:
        """Read the rooms there are (from the rooms folder, through a place) and which place has which live."""
        await self.discover()
        self._task = asyncio.ensure_future(self._monitor())

    async def discover(self) -> None:
        for place in self.alive():  # their loads, for placing rooms
            with contextlib.suppress(PlaceDown):
                await place.health()
        for place in self.alive():
            try:
                for record in await place.known():
                    entry = self._entry(record["name"], record["token"], record.get("preset", "car"))
                    # when it last changed, as its folder says (a parked room's place reports nothing of it)
                    entry.info.setdefault("last_change", float(record.get("last_change", 0.0)))
                break
            except PlaceDown:
                continue
        for place in self.alive():
            with contextlib.suppress(PlaceDown):
                self._note(place, await place.listing())

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        for task in list(self._tasks):
            task.cancel()
        for place in self.places:
            with contextlib.suppress(Exception):
                await place.close()

    def _entry(self, name: str, token: str, preset: str) -> Entry:
        entry = self.rooms.get(name)
        if entry is None:
            entry = self.rooms[name] = Entry(name, token, preset, slot=next(self._slots))
        return entry

    # -- places -----------------------------------------------------------------------------------------------
    def alive(self) -> list[Place]:
        return [p for p in self.places if p.alive]

    def add_place(self, place: Place) -> None:
        """A worker that came (a Dask worker joining the cluster, a worker process started again): rooms that were live
        on a dead worker and found no place then come back now."""
        self.places.append(place)
        log.info("studio: a place for rooms came: %s", place.label)
        for entry in [e for e in self.rooms.values() if e.place is None and e.info.get("live")]:
            self._later(self._bring_back(entry, "a worker that went"))

    def _later(self, coroutine: Coroutine[object, object, None]) -> asyncio.Task:
        """`coroutine` run as a task of the front's (ended when it closes); a failure it does not handle is logged."""
        task = asyncio.ensure_future(coroutine)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        task.add_done_callback(_logged)
        return task

    def choose(self, exclude: Collection[Place] = ()) -> Place:
        """The least loaded live place with room for one more; StudioFull when every one is full."""
        open_places = [p for p in self.alive() if p not in exclude and p.load.get("rooms", 0) < p.load.get("limit", 1)]
        if not open_places:
            alive = self.alive()
            held = sum(p.load.get("rooms", 0) for p in alive)
            raise StudioFull(f"the studio is full: {held} live rooms on {len(alive)} worker(s), each at its limit "
                             "(--rooms-per-worker); rooms without a view are parked after a while, or add workers"
                             if alive else "the studio has no worker for rooms now; try again in a moment")
        # GPU -> (its workers' rooms, their limits): the least loaded GPU first
        gpus: dict[str | None, tuple[int, int]] = {}
        for p in self.alive():
            gpu = p.gpu
            if gpu is not None:
                rooms, limit = gpus.get(gpu, (0, 0))
                gpus[gpu] = (rooms + p.load.get("rooms", 0), limit + max(1, p.load.get("limit", 1)))

        def load(p: Place) -> tuple:
            rooms, limit = gpus.get(p.gpu, (0, 1))
            return (rooms / limit, p.load.get("rooms", 0) / max(1, p.load.get("limit", 1)), p.load.get("nodes", 0))

        place = min(open_places, key=load)
        place.load = dict(place.load, rooms=place.load.get("rooms", 0) + 1)  # until its next report
        return place

    async def lost(self, place: Place) -> None:
        """`place` is dead: its live rooms come back elsewhere now, its parked ones when next opened."""
        if not place.alive:
            return
        place.alive = False
        orphans = [e for e in self.rooms.values() if e.place is place]
        log.warning("studio: %s is gone; bringing back its %d room(s) elsewhere", place.label, len(orphans))
        for entry in orphans:
            entry.place = None
        for entry in [e for e in orphans if e.info.get("live")]:  # in tasks of their own: a caller may hold a lock
            self._later(self._bring_back(entry, place.label))

    async def _failed(self, place: Place) -> None:
        """A call to `place` failed: it is lost unless it still answers a health check. A call that outlasts its
        timeout on a busy worker is no death: the next place takes the room, and the monitor's looks decide."""
        try:
            await place.health()
        except PlaceDown:
            await self.lost(place)
        else:
            log.warning("studio: %s answers, but too slowly for a room's call; the next place is tried", place.label)

    async def _bring_back(self, entry: Entry, was: str) -> None:
        t0 = time.monotonic()
        try:
            await self.open(entry.name)
        except Exception as exc:  # it comes back when next opened
            log.warning("studio: room %s could not come back yet: %s", entry.name, exc)
            return
        seconds = time.monotonic() - t0
        assert entry.place is not None  # open() leaves the room on a place (it raises where none takes it)
        self.moved.append((entry.name, was, entry.place.label, seconds))
        log.info("studio: room %s is back on %s (%.2f s)", entry.name, entry.place.label, seconds)

    # -- rooms ------------------------------------------------------------------------------------------------
    def _lock(self, name: str) -> asyncio.Lock:
        return self._locks.setdefault(name, asyncio.Lock())

    async def create(self, name: str, preset: str | None = None) -> Entry:
        """A new room (ValueError: a taken name, an unknown preset; StudioFull)."""
        name = room_name(name)
        preset = preset or self.preset
        async with self._lock(name):
            if name in self.rooms:
                raise ValueError(f"a room named {name!r} exists already; choose another name")
            token = lan.make_token()
            place, info = await self._place(lambda p: p.create(name, token, preset))
            entry = self._entry(name, token, preset)
            entry.place, entry.info = place, info
        return entry

    async def open(self, name: str) -> Entry:
        """The room live on its place (brought back there, or elsewhere when its place is gone). KeyError: no such
        room; StudioFull; RoomBusy when its folder stays held."""
        entry = self.rooms[room_name(name)]
        async with self._lock(entry.name):
            place = entry.place
            if place is not None and place.alive:
                try:
                    entry.info = await place.open(entry.name)
                    return entry
                except PlaceDown:
                    await self._failed(place)
            entry.place, entry.info = await self._place(lambda p: p.open(entry.name))
            return entry

    async def _place(self, action: Callable[[Place], Awaitable[dict]]) -> tuple[Place, dict]:
        """(place, what `action(place)` answered) on the least loaded place that takes it: a place that is down, or
        refuses for its own limit, passes it on to the next; a room still held by a worker going down is tried again
        for BUSY_WAIT seconds. StudioFull (the last place's own words) when none takes it."""
        tried: list[Place] = []
        refusal: StudioFull | None = None
        deadline = time.monotonic() + BUSY_WAIT
        fresh = False
        while True:
            try:
                place = self.choose(exclude=tried)
            except StudioFull:
                if refusal is not None:
                    raise refusal from None
                if fresh:
                    raise
                fresh = True  # the loads as the places say now (a room parked since their last report)
                await asyncio.gather(*(p.health() for p in self.alive()), return_exceptions=True)
                continue
            try:
                return place, await action(place)
            except PlaceDown:
                await self._failed(place)
                tried.append(place)
            except StudioFull as exc:
                refusal = exc
                tried.append(place)
            except RoomBusy:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.25)

    async def park(self, name: str, force: bool = False) -> bool:
        entry = self.rooms[room_name(name)]
        if entry.place is None or not entry.place.alive:
            return False
        parked = await entry.place.park(entry.name, force)
        if parked:
            entry.info = dict(entry.info, live=False, people=[], watchers=0)
        return parked

    def listing(self) -> list[dict]:
        """Every room: its place's latest report (people, last change, live or parked), its slot and place."""
        out = []
        for entry in sorted(self.rooms.values(), key=lambda e: e.name):
            info = {"name": entry.name, "preset": entry.preset, "title": entry.preset, "people": [], "watchers": 0,
                    "last_change": 0.0, "live": False, "nodes": None, **entry.info}
            place = entry.place if entry.place is not None and entry.place.alive else None
            info.update(slot=entry.slot, place=place.label if place is not None else None,
                        live=bool(info["live"]) and place is not None)
            out.append(info)
        return out

    # -- watching the places ----------------------------------------------------------------------------------
    def _note(self, place: Place, listing: list[dict]) -> None:
        for item in listing:
            name = item.get("name")
            entry = self.rooms.get(name) if isinstance(name, str) else None  # the rooms are named by text
            if entry is None:
                continue
            if item.get("live") and entry.place is not place:
                entry.place = place
            if entry.place is place:
                entry.info = item

    async def check(self, place: Place) -> None:
        """One look at `place`: its load and rooms; DEAD_AFTER failures in a row make it dead."""
        try:
            await place.health()
            self._note(place, await place.listing())
            await place.park_idle()
            place.failures = 0
        except PlaceDown as exc:
            place.failures += 1
            log.warning("studio: %s (%d in a row)", exc, place.failures)
            if place.failures >= DEAD_AFTER:
                await self.lost(place)

    async def _monitor(self) -> None:
        """Each place looked at once a MONITOR_PERIOD, the looks spread over the period: all at once, the replies of
        thirty workers arrived together and held up the relaying of every room's moves and frames for tens of ms
        (BENCHMARKS.md, "The tail at four GPUs"). A place whose last look is still under way is skipped."""
        looking: dict[int, asyncio.Task] = {}
        while True:
            places = self.alive()
            if not places:
                await asyncio.sleep(MONITOR_PERIOD)
            for place in places:
                await asyncio.sleep(MONITOR_PERIOD / len(places))
                last = looking.get(id(place))
                if not place.alive or (last is not None and not last.done()):
                    continue
                looking[id(place)] = self._later(self.check(place))
            looking = {key: look for key, look in looking.items() if not look.done()}
