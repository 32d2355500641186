"""A studio room's autosave while a batch holds its Som (studio/batched.py: `RoomLock.for_save`,
`BatchedRooms.state_to_save`): the save reads the weights and cycle of the batch's last round instead of giving the Som
back (an upload, a read-back and the next round's upload again), and writes exactly what a give-back then a capture
writes: the same step, the same files, the weights bit for bit."""

from __future__ import annotations

import json
import time

import numpy as np

from somwidget.backend import presets
from somwidget.frontend.model import autosave as autosave_module
from somwidget.frontend.model.store import MANIFEST, SessionStore
from somwidget.frontend.studio.batched import BatchedRooms
from somwidget.frontend.studio.limits import StudioLimits
from somwidget.frontend.studio.rooms import Rooms


def _soms(count: int):
    """`count` car Soms at the settled shape, part way into a drag: 30 cycles after a move, the shape anchored."""
    p = presets.get_preset("car")
    settled = p.make_som(device="cpu")
    settled.train()
    soms = []
    for i in range(count):
        som = p.make_som(device="cpu")
        som.restore(settled.weights, som.iterations)
        controls = som.controls
        controls[0, :3] += np.float32(0.03 * (i + 1))
        som.set_controls(controls)
        som.step(30)
        som.anchor()
        soms.append(som)
    return soms


def _round(batches: BatchedRooms, soms, cycles: int) -> None:
    for i, som in enumerate(soms):
        batches.hold(i, som, batches.key(som))
    got = batches.step([(i, cycles) for i in range(len(soms))])
    assert all(not isinstance(v, BaseException) for v in got.values()), got


def test_state_to_save_is_what_a_give_back_leaves_and_gives_nothing_back():
    soms = _soms(3)
    batches = BatchedRooms()
    _round(batches, soms, 5)
    _round(batches, soms, 7)
    # room 0: held, nothing waiting: its row of the last round, without a give-back
    weights, s = batches.state_to_save(0)
    assert batches.holds(0) and batches.given_back == 0
    assert s == soms[0].iteration
    np.testing.assert_array_equal(weights, batches.host(0))
    assert weights is not batches.host(0)  # a copy: the save owns it
    stale = soms[0].parts.state.w.numpy()
    assert np.abs(stale - weights).max() > 1e-4  # the Som's own weights are stale while held: the row is not them
    batches.give_back(0)
    assert batches.given_back == 1
    np.testing.assert_array_equal(soms[0].weights, weights)  # bit for bit what the give-back restored
    assert soms[0].iteration == s
    # room 1: moved from its latest weights, the move put in but not stepped: the row and the Som's new cycle
    moved = soms[1].controls
    moved[0, :3] += np.float32(0.02)
    soms[1].set_controls(moved)
    batches.hold(1, soms[1], batches.key(soms[1]))
    weights, s = batches.state_to_save(1)
    assert batches.holds(1) and batches.given_back == 1
    batches.give_back(1)
    np.testing.assert_array_equal(soms[1].weights, weights)
    assert soms[1].iteration == s
    # room 2: a drag's move from its anchor since the last round (held again or not): the Som's own state is the
    # one to save, so it is given back, as before
    moved = soms[2].controls
    moved[0, :3] -= np.float32(0.02)
    soms[2].set_controls(moved, from_anchor=True)
    assert batches.state_to_save(2) is None
    assert not batches.holds(2) and batches.given_back == 3
    _round(batches, soms[2:], 4)  # held again (as room 0 of this call)
    soms[2].set_controls(moved, from_anchor=True)
    batches.hold(0, soms[2], batches.key(soms[2]))  # the restart from the anchor waits in the batch
    assert batches.state_to_save(0) is None and not batches.holds(0)
    assert batches.state_to_save("never held") is None


def _files(folder) -> tuple[dict, dict]:
    """(the manifest less its time, each file it names -> its arrays)."""
    manifest = json.loads((folder / MANIFEST).read_text())
    manifest.pop("saved")
    names = [r["file"] for r in [manifest["current"], *manifest["undo"], *manifest["redo"]]]
    arrays = {}
    for name in names:
        with np.load(folder / name) as f:
            arrays[name] = {k: f[k] for k in f.files}
    return manifest, arrays


def test_a_held_rooms_save_equals_a_save_after_a_give_back(tmp_path):
    """Rooms dragged (the drag held open, so the save is of a drag not yet released) and settled while their batch
    holds them: the save read through the batch is the save a give-back then a capture makes, to the files."""
    rooms = Rooms(tmp_path / "rooms", device="cpu", limits=StudioLimits(park_after=0))
    try:
        sessions = [rooms.create(f"r{i}", f"token-{i}-abcdefgh", "car").session for i in range(3)]
        for session in sessions:
            assert session.wait_idle(300)
        for session in sessions:
            session.begin_gesture()
        for step in range(4):
            for i, session in enumerate(sessions):
                home = np.asarray(session.controls[0][:3], np.float64)
                session.move_control(0, home + np.array([0.01 * (i + 1), 0.005 * step, 0.0]))
            time.sleep(0.05)
        for session in sessions:
            assert session.wait_idle(300) and session.error is None
        held = [s for s in sessions if rooms.batches.holds(s.trainer)]
        assert len(held) >= 2, "the rooms were not held by a batch: nothing here is tested"
        for n, session in enumerate(held):
            state, autosave = session.modelling, session.autosave
            given = rooms.batches.given_back
            with state.lent.for_save(), state.lock:
                read = autosave.snapshot()
            assert rooms.batches.holds(session.trainer) and rooms.batches.given_back == given  # nothing given back
            with state.som_lock, state.lock:  # the way a save took it before: the Som given back
                after = autosave.snapshot()
            assert not rooms.batches.holds(session.trainer) and rooms.batches.given_back == given + 1
            a, b = read.current, after.current
            np.testing.assert_array_equal(a.weights, b.weights)
            assert a.weights.dtype == b.weights.dtype == np.float32
            np.testing.assert_array_equal(a.weights, session.frame.weights)  # the frame the designer sees
            assert a.iteration == b.iteration and a.parameters == b.parameters and a.strokes == b.strokes
            np.testing.assert_array_equal(a.controls, b.controls)
            np.testing.assert_array_equal(a.radii, b.radii)
            assert a.symmetry == b.symmetry and a.control_ids == b.control_ids and a.preset is b.preset
            assert read.gesture and read.gesture == after.gesture
            assert [s.key for s in read.undo] == [s.key for s in after.undo] and read.redo == after.redo
            for name, saving in (("read", read), ("given", after)):
                SessionStore(tmp_path / f"{name}{n}", "studio").commit(saving)
            (m_read, f_read), (m_given, f_given) = _files(tmp_path / f"read{n}"), _files(tmp_path / f"given{n}")
            assert m_read == m_given and f_read.keys() == f_given.keys()
            for name in f_read:
                for key in ("weights", "controls", "radii"):
                    np.testing.assert_array_equal(f_read[name][key], f_given[name][key])
    finally:
        rooms.close()


def test_a_held_rooms_autosave_during_a_drag_gives_nothing_back(tmp_path, monkeypatch):
    """Rooms dragged on and on while held: their autosave writes every AUTOSAVE_SECONDS and gives no room back (no
    upload, no read-back, the room stays in its batch); released, a room parked and closed saves everything."""
    monkeypatch.setattr(autosave_module, "AUTOSAVE_SECONDS", 0.3)
    rooms = Rooms(tmp_path / "rooms", device="cpu", limits=StudioLimits(park_after=0))
    try:
        sessions = [rooms.create(f"r{i}", f"token-{i}-abcdefgh", "car").session for i in range(3)]
        for session in sessions:
            assert session.wait_idle(300)
        homes = [np.asarray(s.controls[0][:3], np.float64) for s in sessions]
        for session in sessions:
            session.begin_gesture()

        def move(t: float) -> None:
            for i, session in enumerate(sessions):
                session.move_control(0, homes[i] + 0.03 * np.array([np.cos(t + i), np.sin(t + i), 0.0]))

        deadline = time.monotonic() + 60
        t = 0.0
        while t < 0.5 or (not all(rooms.batches.holds(s.trainer) for s in sessions) and time.monotonic() < deadline):
            t += 0.1
            move(t)
            time.sleep(1 / 30)
        # held again after the drags' first moves gave them back (their boundary recorded: undo steps)
        assert all(rooms.batches.holds(s.trainer) for s in sessions), "the rooms were not held: nothing is tested"
        given, saves = rooms.batches.given_back, [s.autosave.writer.saves for s in sessions]
        batched = rooms.batches.batched
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            t += 0.1
            move(t)
            time.sleep(1 / 30)
        for session in sessions:
            assert session.autosave.writer.flush(30)
        assert rooms.batches.batched > batched  # the drag went on in the batch
        wrote = [s.autosave.writer.saves - n for s, n in zip(sessions, saves)]
        assert all(n >= 2 for n in wrote), wrote  # the drag was saved as it went
        assert rooms.batches.given_back == given  # and no save took a room back
        for session in sessions:
            session.end_gesture()
        for session in sessions:
            assert session.wait_idle(300) and session.error is None
            assert session.autosave.flush(30)
            with session.modelling.som_lock:  # given back: the Som's own state, the last frame's
                np.testing.assert_array_equal(session.modelling.som.weights, session.frame.weights)
    finally:
        rooms.close()


def test_the_saves_of_rooms_dragged_together_drift_apart():
    """Each wait for a drag's next save is drawn within AUTOSAVE_JITTER of AUTOSAVE_SECONDS: the rooms of a worker
    whose drags began in the same moment do not all write in the same round, every two seconds (that lockstep made a
    periodic tail of slow frames: BENCHMARKS.md, "The tail at four GPUs")."""
    seconds, jitter = autosave_module.AUTOSAVE_SECONDS, autosave_module.AUTOSAVE_JITTER
    assert 0.1 <= jitter <= 0.5
    now = time.monotonic()
    waits = np.array([autosave_module.next_due() for _ in range(400)]) - now
    assert waits.min() >= seconds * (1 - jitter) - 1e-3 and waits.max() <= seconds * (1 + jitter) + 0.1
    # spread over the band: two rooms that saved together are a tenth of a second apart or more, most times
    assert waits.min() < seconds * (1 - jitter / 2) and waits.max() > seconds * (1 + jitter / 2)
    pairs = np.abs(waits[::2] - waits[1::2])
    assert np.mean(pairs > 0.1) > 0.5, np.sort(pairs)[:10]
