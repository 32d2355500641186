"""Rooms beyond the front's process, with real worker processes on the CPU standing in for GPUs: rooms placed on the
least loaded worker, a worker's limit refusing a room with its message, rooms reached through the front's relay (a
notebook's `somwidget.join`), and a worker killed (SIGKILL) with its rooms back on another worker within 10 s, nothing
completed lost: worker processes of this machine (workers.py) and a Dask LocalCluster of two workers (dask_rooms.py)."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest
from helpers import wait_for

import somwidget
from somwidget.frontend.studio.limits import StudioFull, StudioLimits
from somwidget.frontend.studio.places import PlaceDown
from somwidget.frontend.studio.serve import StudioServer

#: How long a dead worker's rooms may take to be back (issue 37).
BACK_WITHIN = 10.0


def drag_and_wait_saved(studio, name: str) -> np.ndarray:
    """A drag in room `name` through the front (a notebook's join); returns where the control is once the room's
    autosave has it (the listing's save count went up)."""
    with somwidget.join(studio.room_url(name)) as room:
        saves = studio.front.rooms[name].info["saves"]
        to = room.control_positions[0] + np.float32([0.0, 0.0, 0.1])
        room.move_control(0, to)
        np.testing.assert_allclose(room.control_positions[0], to, atol=1e-6)
        wait_for(lambda: studio.front.rooms[name].info.get("saves", 0) > saves, 20, "the drag's save")
        return to


def back_elsewhere(studio, name: str, dead) -> float:
    t0 = time.monotonic()
    wait_for(lambda: (e := studio.front.rooms[name]).place is not None and e.place is not dead and e.place.alive
             and e.info.get("live"), BACK_WITHIN + 5, f"room {name} back on another worker")
    return time.monotonic() - t0


def test_worker_processes_place_rooms_and_take_over_a_dead_ones(tmp_path):
    limits = StudioLimits(rooms=2, park_after=0)
    with StudioServer(tmp_path / "rooms", device="cpu", workers=2, limits=limits,
                      rooms=["a", "b", "c"]) as studio:
        places = studio.front.places
        assert len(places) == 2 and {p.label for p in places} == {"CPU worker 0", "CPU worker 1"}
        on = {name: e.place for name, e in studio.front.rooms.items()}
        assert on["a"] is not on["b"], "the second room went to the busier worker"
        assert sorted(len([n for n in on if on[n] is p]) for p in places) == [1, 2]
        studio.call(studio.front.create("d"))  # 2 + 2: both full now
        with pytest.raises(StudioFull, match=r"the studio is full: .*--rooms-per-worker"):
            studio.call(studio.front.create("e"))

        to = drag_and_wait_saved(studio, "a")
        dead = studio.front.rooms["a"].place
        pid = studio.pool.procs[dead].pid
        moved_away = [n for n, e in studio.front.rooms.items() if e.place is dead]
        studio.call(studio.front.park(next(n for n, e in studio.front.rooms.items()
                                           if e.place is not dead), force=True))  # room for them elsewhere
        os.kill(pid, signal.SIGKILL)
        took = back_elsewhere(studio, "a", dead)
        assert took < BACK_WITHIN, f"the dead worker's room took {took:.1f} s to come back"
        with somwidget.join(studio.room_url("a")) as room:
            np.testing.assert_allclose(room.control_positions[0], to, atol=1e-6)  # the completed drag is there
            assert room.history == (True, False)
        assert len(moved_away) == 2
        wait_for(lambda: len(studio.front.alive()) == 2, 60, "a new worker in place of the dead one")


@pytest.fixture
def cluster():
    distributed = pytest.importorskip("distributed", reason="Dask is not installed (pip install somwidget[dask])")
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = {"PYTHONPATH": here, "SOMWIDGET_DATA_DIR": os.environ["SOMWIDGET_DATA_DIR"]}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  env=env) as c:
        yield c


def test_dask_workers_hold_rooms_and_a_killed_one_s_come_back(tmp_path, cluster):
    from distributed import Client

    with StudioServer(tmp_path / "rooms", device="cpu", scheduler=cluster.scheduler_address,
                      rooms=["alice", "bob", "carol", "dan"], limits=StudioLimits(park_after=0)) as studio:
        places = {e.place for e in studio.front.rooms.values()}
        assert len(places) == 2 and all(p.label.startswith("Dask worker") for p in places)
        to = drag_and_wait_saved(studio, "alice")
        dead = studio.front.rooms["alice"].place
        with Client(cluster.scheduler_address) as client:
            pids = client.run(os.getpid)
        address = next(a for a, p in studio.pool.places.items() if p is dead)
        orphans = [n for n, e in studio.front.rooms.items() if e.place is dead]
        os.kill(pids[address], signal.SIGKILL)
        took = max(back_elsewhere(studio, name, dead) for name in orphans)
        assert took < BACK_WITHIN, f"the killed worker's rooms took {took:.1f} s to come back"
        with somwidget.join(studio.room_url("alice")) as room:
            np.testing.assert_allclose(room.control_positions[0], to, atol=1e-6)
            assert room.history == (True, False)


class _Place:
    """A place as the front's placing reads it: its GPU and its last load report."""

    def __init__(self, gpu: str, rooms: int, limit: int = 10):
        self.gpu, self.alive, self.label = gpu, True, f"GPU {gpu}"
        self.load = {"rooms": rooms, "limit": limit, "nodes": 0}


def test_a_new_room_goes_to_the_least_loaded_gpu_then_its_least_loaded_worker():
    from somwidget.frontend.studio.front import StudioFront

    # GPU 0's two workers hold 3 rooms (one worker none), GPU 1's two hold 2: the room goes to GPU 1
    places = [_Place("0", 3), _Place("0", 0), _Place("1", 2), _Place("1", 0)]
    front = StudioFront(places)
    assert front.choose() is places[3]
    assert front.choose() is places[1]  # 3 against 3: GPU 0's empty worker, then by turns
    chosen = [front.choose().gpu for _ in range(6)]
    assert sorted(chosen) == ["0", "0", "0", "1", "1", "1"]
    places[2].alive = False  # a worker gone: its GPU's other worker carries that GPU's share
    loads = {g: sum(p.load["rooms"] for p in places if p.alive and p.gpu == g) for g in "01"}
    assert front.choose().gpu == min(loads, key=lambda g: loads[g] / (20 if g == "0" else 10))


class _CallingPlace(_Place):
    """A place whose calls fail the way a worker's do: `slow` answers its health check but not a room's call in
    time, `dead` answers neither; a sound one makes the room."""

    def __init__(self, gpu: str, rooms: int, kind: str):
        super().__init__(gpu, rooms)
        self.kind, self.made = kind, []

    async def health(self) -> dict:
        if self.kind == "dead":
            raise PlaceDown(f"{self.label} does not answer")
        return {"load": self.load}

    async def create(self, name: str, token: str, preset: str) -> dict:
        if self.kind != "sound":
            raise PlaceDown(f"{self.label} does not answer in time")
        self.made.append(name)
        return {"name": name, "live": True}


def test_a_worker_too_slow_for_one_call_stays_in_service_and_a_silent_one_is_lost():
    import asyncio

    from somwidget.frontend.studio.front import StudioFront

    slow, dead, sound = _CallingPlace("0", 0, "slow"), _CallingPlace("1", 1, "dead"), _CallingPlace("2", 2, "sound")
    front = StudioFront([slow, dead, sound])
    entry = asyncio.run(front.create("alice", "car"))
    assert entry.place is sound and sound.made == ["alice"]  # tried the least loaded first, in turn
    assert slow.alive, "a worker that answers its health check was taken for dead after one slow call"
    assert not dead.alive


def test_a_worker_warms_its_kernels_before_it_announces_and_keeps_no_room_of_it(tmp_path):
    from somwidget.frontend.studio.rooms import Rooms

    rooms = Rooms(tmp_path, device="cpu")
    rooms.warm()
    assert rooms.rooms() == [] and list(tmp_path.iterdir()) == []
    assert rooms.batches.launches == 0  # its own batch, not the worker's


class _LookedAtPlace(_Place):
    """A place that notes when the front looks at it (its health check, its rooms, its idle rooms)."""

    def __init__(self, gpu: str, looks: list):
        super().__init__(gpu, 0)
        self.looks = looks

    async def health(self) -> dict:
        import time

        self.looks.append((time.monotonic(), self.label))
        return {"load": self.load}

    async def known(self) -> list[dict]:
        return []

    async def listing(self) -> list[dict]:
        return []

    async def park_idle(self) -> list[str]:
        return []


def test_the_front_spreads_its_looks_at_the_places_over_the_period(monkeypatch):
    """Eight places looked at once a period each, one after another: never all in the same moment (their replies
    arriving together held up every room's relaying), and none left out."""
    import asyncio

    from somwidget.frontend.studio import front as front_module

    period = 0.4
    monkeypatch.setattr(front_module, "MONITOR_PERIOD", period)
    looks: list = []
    places = [_LookedAtPlace(str(i), looks) for i in range(8)]

    async def watch():
        front = front_module.StudioFront(places)
        await front.start()
        looks.clear()  # the start's one look at each place, together: then the monitor's
        await asyncio.sleep(3 * period + 0.05)
        await front.close()

    asyncio.run(watch())
    assert {label for _, label in looks} == {p.label for p in places}  # every place looked at
    times = sorted(t for t, _ in looks)
    assert len(times) >= 2 * len(places), len(times)  # once a period each, or about
    gaps = [b - a for a, b in zip(times, times[1:])]
    # spread: about period / 8 apart (0.05 s); all at once they were microseconds apart
    assert min(gaps) > 0.3 * period / len(places), gaps
