"""The rooms of one worker (studio/rooms.py) with real Sessions on the CPU: each room its own clay, controls, settings,
undo history and autosave folder; an idle room parked (saved, its session gone) and back on open within a second as it
was; limits refusing a new room with a message that names the limit; room names checked."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from somwidget.frontend.studio.limits import StudioFull, StudioLimits, room_name
from somwidget.frontend.studio.rooms import RoomRecord, Rooms
from somwidget.frontend.studio.thumbs import THUMB_FILE, thumbnail


@pytest.fixture
def rooms(tmp_path):
    r = Rooms(tmp_path / "rooms", device="cpu", limits=StudioLimits(rooms=3, nodes=1000, park_after=0.3))
    yield r
    r.close()


def drag(session, index: int, by) -> np.ndarray:
    """A drag of control `index` by `by` as Python makes one (one undo step); the position it ends at."""
    to = session.controls[index][:3] + np.float32(by)
    with session.gesture():
        session.move_control(index, to)
    assert session.wait_idle(120)
    return to


def test_a_parked_rooms_last_thumbnail_is_read_from_its_folder_by_a_worker_that_never_held_it(rooms, tmp_path):
    room = rooms.create("alice", "t", "sphere")
    assert room.session.wait_idle(120)
    frame = room.session.frame
    assert rooms.park("alice")
    other = Rooms(tmp_path / "rooms", device="cpu")  # as after a restart, or another worker of the studio
    try:
        (got,) = other.thumbs({"alice": None, "nobody": None})
        assert got["name"] == "alice" and got["seq"] == frame.seq and got["shape"]["n"] == len(frame.positions)
        # the bytes of the frame the room parked with: its float32 positions, then its colours as RGB bytes
        assert got["thumb"] == thumbnail(frame, {"nodes": None})
        assert other.thumbs({"alice": frame.seq}) == []  # the wall has it already
        assert not other.live()  # read without bringing the room back
        (tmp_path / "rooms" / "alice" / THUMB_FILE).write_bytes(b"SOMTHUMB1\n\x05\x00\x00\x00{}")
        assert other.thumbs({"alice": None}) == []  # a broken file shows nothing (and is logged), nothing crashes
    finally:
        other.close()


def test_each_room_is_its_own_session(rooms, tmp_path):
    a = rooms.create("alice", "token-a", "car")
    b = rooms.create("bob", "token-b", "car")
    assert a.session is not b.session
    assert a.session.wait_idle(120) and b.session.wait_idle(120)
    b_before = b.session.frame.positions.copy()
    to = drag(a.session, 0, [0.0, 0.0, 0.1])
    a.session.set_parameter("smoothing", 0.3)
    assert a.session.wait_idle(120)
    np.testing.assert_array_equal(a.session.controls[0][:3], to)
    assert a.session.history[0] == 2 and b.session.history[0] == 0
    assert b.session.parameters["smoothing"] != 0.3
    np.testing.assert_array_equal(b.session.frame.positions, b_before)  # bob's clay did not move
    assert a.session.autosave.path == tmp_path / "rooms" / "alice" / "session"
    assert b.session.autosave.path == tmp_path / "rooms" / "bob" / "session"
    assert RoomRecord.read(tmp_path / "rooms" / "alice").token == "token-a"
    with pytest.raises(ValueError, match="exists already"):
        rooms.create("Alice", "t", "car")  # names fold to lower case


def test_an_idle_room_is_parked_and_back_within_a_second(rooms):
    room = rooms.create("alice", "t", "car")
    session = room.session
    assert session.wait_idle(120)
    to = drag(session, 1, [0.05, 0.0, -0.08])
    undo_steps = session.history[0]
    shown = session.frame.positions.copy()
    room.last_active = time.monotonic() - 1.0  # no view for a second, past park_after
    assert rooms.park_idle() == ["alice"]
    assert not room.live and session.closed
    assert room.info()["live"] is False and room.latest_thumb() is not None  # the wall keeps its picture
    t0 = time.perf_counter()
    again = rooms.open("alice")
    took = time.perf_counter() - t0
    assert took < 1.0, f"a parked room took {took:.2f} s to come back"
    back = again.session
    assert back is not session
    np.testing.assert_array_equal(back.controls[1][:3], to)
    np.testing.assert_array_equal(back.frame.positions, shown)
    assert back.history[0] == undo_steps
    assert back.undo() and back.wait_idle(60)
    assert not np.array_equal(back.controls[1][:3], to)  # the drag's undo step came back with it


def test_a_room_with_views_is_not_parked(rooms):
    room = rooms.create("alice", "t", "car")
    room.last_active = time.monotonic() - 10
    room.views = lambda: ["a view"]
    assert rooms.park_idle() == [] and room.live
    assert rooms.park("alice") is False


def test_limits_refuse_a_new_room_with_a_clear_message(rooms, tmp_path):
    for name in ("a", "b", "c"):
        rooms.create(name, "t", "car")
    with pytest.raises(StudioFull, match=r"holds 3 rooms, its limit \(--rooms-per-worker 3\)"):
        rooms.create("d", "t", "car")
    assert not (tmp_path / "rooms" / "d").exists()
    rooms.park("a", force=True)
    with pytest.raises(StudioFull, match=r"4,096 nodes is past the studio's limit of 1,000 nodes"):
        rooms.create("grid", "t", "space-grid")
    small = Rooms(tmp_path / "other", device="cpu", limits=StudioLimits(memory_mb=1))
    with pytest.raises(StudioFull, match=r"past its 1 MB \(--memory-per-worker\)"):
        small.create("x", "t", "car")


@pytest.mark.parametrize("bad", ["", "../bob", "a b", "x" * 41, "-lead", "room/1", "ü", None])
def test_room_names(bad):
    with pytest.raises(ValueError, match="room name"):
        room_name(bad)
    assert room_name(" Group-3_b ") == "group-3_b"


def test_a_rooms_slow_call_does_not_hold_up_the_other_rooms(rooms):
    """A preset switch (a slow call: here it also waits 3 s, as a large preset's build on a busy host would) runs off
    the worker's stepping loop: another room's move is shown while it is still under way, and the switch lands."""
    a = rooms.create("alice", "t", "car")
    b = rooms.create("bob", "t", "car")
    assert a.session.wait_idle(120) and b.session.wait_idle(120)
    started = threading.Event()

    def switch():
        started.set()
        a.session.load_preset("sphere")
        time.sleep(3.0)

    call = a.session.submit(switch)
    assert started.wait(60)
    shown: list[tuple[np.ndarray, bool]] = []  # bob's frames: control 0 where, alice's call still running
    b.session.add_listener(lambda f: shown.append((f.control_positions[0].copy(), not call.done())), replay=False)
    to = b.session.controls[0][:3] + np.float32([0.0, 0.0, 0.05])
    b.session.move_control(0, to)
    deadline = time.monotonic() + 2.5
    while time.monotonic() < deadline and not any(np.array_equal(p, to) for p, _ in shown):
        time.sleep(0.01)
    during = [running for p, running in shown if np.array_equal(p, to)]
    assert during and during[0], "bob's move waited for alice's preset switch"
    call.result(60)
    assert a.session.wait_idle(120) and a.session.preset.name == "sphere"
    assert b.session.preset.name == "car"


def test_a_worker_reports_how_long_its_rounds_take(rooms):
    """The load a worker reports (the front's looks, bench_studio.py) carries its latest rounds: how many, their median,
    95th percentile and longest, each within the time the rounds had."""
    began = time.monotonic()
    assert rooms.load()["round"] == {"rounds": 0}  # no room: no round timed
    room = rooms.create("alice", "token-a", "car")
    assert room.session.wait_idle(120)
    drag(room.session, 0, [0.0, 0.0, 0.1])
    took_ms = 1e3 * (time.monotonic() - began)
    r = rooms.load()["round"]
    assert 2 <= r["rounds"] <= rooms.rounds.rounds, r
    assert 0 < r["median_ms"] <= r["p95_ms"] <= r["max_ms"] < took_ms, (r, took_ms)


def test_a_live_rooms_thumbnail_is_kept_in_its_folder_without_a_wall(tmp_path, monkeypatch):
    """No wall open and no parking: the worker's look at its rooms keeps a changing room's thumbnail in its folder at
    most every THUMB_SAVE_PERIOD seconds, so that after its worker dies (here: another worker reads the folder, as a
    studio restarted does) the wall shows the room's clay as it was then."""
    from somwidget.frontend.studio import rooms as rooms_module

    monkeypatch.setattr(rooms_module, "THUMB_SAVE_PERIOD", 30.0)
    rooms = Rooms(tmp_path / "rooms", device="cpu", limits=StudioLimits(park_after=0))  # never parked
    room = rooms.create("alice", "t", "sphere")
    assert room.session.wait_idle(120)
    kept = tmp_path / "rooms" / "alice" / THUMB_FILE
    rooms.park_idle()  # the worker's look (every PARK_PERIOD seconds)
    assert kept.is_file(), "no thumbnail kept for a live room without a wall"
    first = kept.stat().st_mtime_ns
    drag(room.session, 0, [0.0, 0.0, 0.1])
    rooms.park_idle()  # changed, but within the period: not written again yet
    assert kept.stat().st_mtime_ns == first
    monkeypatch.setattr(rooms_module, "THUMB_SAVE_PERIOD", 0.0)  # the period over
    rooms.park_idle()
    frame = room.session.frame
    other = Rooms(tmp_path / "rooms", device="cpu")  # the room's worker gone without parking it
    try:
        (got,) = other.thumbs({"alice": None})
        assert got["seq"] == frame.seq and got["thumb"] == thumbnail(frame, {"nodes": None})  # the dragged clay
        assert room.live  # never parked: the worker's look kept it
    finally:
        other.close()
        rooms.close()
