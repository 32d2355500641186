"""Rooms held in batches (studio/batched.py, rounds.py): alike rooms' states kept in one BatchSom between rounds and
stepped in one launch a round end where the same Soms stepped apart end (the same weights to float tolerance, each
room its own cycles), through moves, drags from an anchor and undos; unlike ones go to batches of their own, and a
studio's rooms really go through one launch."""

from __future__ import annotations

import time

import numpy as np
import pytest

from somwidget.backend import presets
from somwidget.backend.batch import BatchSom
from somwidget.frontend.model import Session
from somwidget.frontend.studio.batched import BatchedRooms, batch_key
from somwidget.frontend.studio.limits import StudioLimits
from somwidget.frontend.studio.rooms import Rooms

ROOMS = 4


def _rooms_soms(preset: str, count: int, seed: int):
    """`count` Soms of `preset`, each a room: restored from the settled shape, its first control moved its own way."""
    p = presets.get_preset(preset)
    settled = p.make_som(device="cpu")
    settled.train()
    shape = settled.weights
    rng = np.random.default_rng(seed)
    soms = []
    for _ in range(count):
        som = p.make_som(device="cpu")
        som.restore(shape, som.iterations)
        controls = som.controls
        controls[0, :3] += rng.normal(0.0, 0.05, 3)
        som.set_controls(controls)  # the local restart a drag makes
        soms.append(som)
    return soms


def _round(batches: BatchedRooms, soms, cycles) -> dict:
    """One round as the worker's loop runs it: every room held (its moved controls and cycle in), one launch a batch."""
    for i, som in enumerate(soms):
        batches.hold(i, som, batches.key(som))
    got = batches.step(list(enumerate(cycles)))
    assert all(not isinstance(v, BaseException) for v in got.values()), got
    return got


@pytest.mark.parametrize("preset", ["car", "lines", "space-grid"])  # the presets of point controls
def test_rooms_stepped_together_equal_the_rooms_stepped_apart(preset):
    apart, together = _rooms_soms(preset, ROOMS, 1), _rooms_soms(preset, ROOMS, 1)
    assert batch_key(together[0], {}) is not None
    batches = BatchedRooms()
    rounds = [[10, 7, 10, 3], [10, 10, 1, 12], [25, 10, 10, 10], [10, 4, 10, 2]]  # each room's pace its own
    rng = np.random.default_rng(5)
    for r, cycles in enumerate(rounds):
        if r == 2:  # rooms 1 and 3 move again while held: only their controls and cycle go in
            for i in (1, 3):
                moved = apart[i].controls
                moved[0, :3] += rng.normal(0.0, 0.05, 3)
                apart[i].set_controls(moved)
                together[i].set_controls(moved)
        for som, k in zip(apart, cycles):
            som.step(k)
        _round(batches, together, cycles)
    for i, (a, t) in enumerate(zip(apart, together)):
        assert t.iteration == a.iteration
        np.testing.assert_allclose(batches.host(i), a.weights, rtol=0, atol=2e-5)  # a frame's weights
        batches.give_back(i)
        np.testing.assert_allclose(t.weights, a.weights, rtol=0, atol=2e-5)  # the Som's, given back
    moved = np.abs(apart[0].weights - _rooms_soms(preset, 1, 1)[0].weights).max()
    assert moved > 1e-3  # the rounds trained: equal weights are not the untouched start
    assert batches.launches == len(rounds) and batches.batched == ROOMS * len(rounds)  # one launch a round


def test_a_drag_from_the_anchor_while_held_equals_it_apart():
    """A drag's moves restart from the shape its grab anchored (Som.set_controls(from_anchor=True)): a held room's
    batch puts its weights back to its anchor's at each move, as the Som alone does."""
    apart, together = _rooms_soms("car", 2, 7), _rooms_soms("car", 2, 7)
    batches = BatchedRooms()
    for som in apart + together:
        som.step(30)
        som.anchor()
    _round(batches, together, [5, 5])  # held from here on, the anchor copied into the batch
    for som in apart:
        som.step(5)
    rng = np.random.default_rng(11)
    for cycles in ([12, 9], [12, 12], [3, 20]):
        for a, t in zip(apart, together):
            moved = a.controls
            moved[0, :3] += rng.normal(0.0, 0.03, 3)
            a.set_controls(moved, from_anchor=True)
            t.set_controls(moved, from_anchor=True)
        for som, k in zip(apart, cycles):
            som.step(k)
        _round(batches, together, cycles)
    for i, (a, t) in enumerate(zip(apart, together)):
        assert t.iteration == a.iteration
        np.testing.assert_allclose(batches.host(i), a.weights, rtol=0, atol=2e-5)
    # a move from the anchor not yet stepped when the room is given back: its Som restarts from its own anchor
    for a, t in zip(apart, together):
        a.set_controls(a.controls, from_anchor=True)
        t.set_controls(t.controls, from_anchor=True)
    _round(batches, together, [0, 0])  # held: the restart waits in the batch
    batches.give_back(0)
    batches.give_back(1)
    for a, t in zip(apart, together):
        np.testing.assert_allclose(t.weights, a.weights, rtol=0, atol=2e-5)


def test_unlike_rooms_go_to_batches_of_their_own_and_still_train_right():
    car = _rooms_soms("car", 2, 3)
    other = _rooms_soms("car", 2, 3)
    for som in other:
        som.l_start = 0.3  # another schedule: not the car rooms' batch
    reference = _rooms_soms("car", 2, 3) + _rooms_soms("car", 2, 3)
    for som in reference[2:]:
        som.l_start = 0.3
    batches = BatchedRooms()
    assert batch_key(car[0], {}) != batch_key(other[0], {})
    for _ in range(2):
        _round(batches, car + other, [10] * 4)
        for som in reference:
            som.step(10)
    assert batches.launches == 4 and batches.batched == 8  # a launch a batch a round
    for i, (som, ref) in enumerate(zip(car + other, reference)):
        batches.give_back(i)
        np.testing.assert_allclose(som.weights, ref.weights, rtol=0, atol=2e-5)


def test_a_room_with_a_radius_is_never_batched():
    som = _rooms_soms("car", 1, 4)[0]
    som.radii = np.full(len(som.controls), 0.1)
    assert batch_key(som, {}) is None
    p = presets.get_preset("car")
    with pytest.raises(ValueError, match="point controls"):  # a batch takes no handles at all
        BatchSom(p.topology, p.weights, np.repeat(p.controls[None], 2, axis=0), mirror=p.mirror, device="cpu",
                 radii=np.full(len(p.controls), 0.1))


def test_load_names_a_bad_shape_and_cycle():
    p = presets.get_preset("car")
    batch = BatchSom(p.topology, p.weights, np.repeat(p.controls[None], 2, axis=0), mirror=p.mirror, device="cpu")
    good_w, good_c = np.repeat(p.weights[None], 2, axis=0), np.repeat(p.controls[None], 2, axis=0)
    with pytest.raises(ValueError, match=r"weights: expected shape \(2, 602, 5\)"):
        batch.load(good_w[:1], np.zeros(2, np.int64), good_c)
    with pytest.raises(ValueError, match="iteration: expected 2 whole numbers"):
        batch.load(good_w, np.array([0, p.iterations + 1]), good_c)
    with pytest.raises(ValueError, match=r"controls: expected shape"):
        batch.load(good_w, np.zeros(2, np.int64), good_c[:, :2])


def test_a_studio_steps_its_car_rooms_in_one_launch(tmp_path):
    rooms = Rooms(tmp_path / "rooms", device="cpu", limits=StudioLimits(park_after=0))
    try:
        made = [rooms.create(f"r{i}", f"token-{i}-abcdefgh", "car") for i in range(3)]
        deadline = time.monotonic() + 120
        while rooms.batches.widest < 2 and time.monotonic() < deadline:
            # each room's designer drags on (a room that settled before another's move came steps alone: under
            # load one move each could leave every round with one room)
            for room in made:
                session = room.session
                session.move_control(0, np.asarray(session.controls[0][:3]) + 0.01)
            time.sleep(0.1)
        assert rooms.batches.widest >= 2 and rooms.batches.launches >= 1  # one launch stepped several rooms
        for room in made:
            assert room.session.wait_idle(120)
            assert room.session.error is None
    finally:
        rooms.close()


def test_rooms_that_drag_and_undo_while_batched_end_as_a_session_alone(tmp_path):
    """Three car rooms dragged at once (their steps batched, their states held between rounds), undone and dragged
    again, each show what a session of its own shows: the same weights at each settled state."""
    rooms = Rooms(tmp_path / "rooms", device="cpu", limits=StudioLimits(park_after=0))
    alone = Session("car", device="cpu", autosave=False)
    try:
        sessions = [rooms.create(f"r{i}", f"token-{i}-abcdefgh", "car").session for i in range(3)] + [alone]
        home = np.asarray(alone.controls[0][:3], np.float64)

        def drag(offsets) -> None:
            for session in sessions:
                session.begin_gesture()
            for offset in offsets:
                for session in sessions:
                    session.move_control(0, home + offset)
                time.sleep(0.05)  # the rooms train between the moves: later moves reach held rooms
            for session in sessions:
                session.end_gesture()
            settled()

        def settled() -> None:
            for session in sessions:
                assert session.wait_idle(300) and session.error is None
            want = alone.frame.weights
            for session in sessions[:-1]:
                assert session.frame.iteration == alone.frame.iteration
                np.testing.assert_allclose(session.frame.weights, want, rtol=0, atol=5e-5)

        settled()  # the car grows from its start mesh first: each drag's anchor is the settled shape
        drag([np.array([0.05, 0.0, 0.0]), np.array([0.08, 0.02, 0.0]), np.array([0.1, 0.03, -0.02])])
        held = rooms.batches.batched
        assert rooms.batches.widest >= 2 and held >= 2  # the rooms trained in shared launches
        before = alone.frame.weights
        for session in sessions:
            assert session.undo()
        settled()
        assert np.abs(alone.frame.weights - before).max() > 1e-3  # the undo changed the shape
        drag([np.array([-0.04, 0.05, 0.0]), np.array([-0.06, 0.05, 0.03])])
        assert rooms.batches.batched > held  # held again after the undo gave the states back
        for session in sessions[:-1]:  # the Soms' own weights, given back, are the frames'
            with session.modelling.som_lock:
                np.testing.assert_allclose(session.modelling.som.weights, session.frame.weights, atol=1e-6)
    finally:
        alone.close()
        rooms.close()


def test_a_lent_states_moves_wait_for_its_give_back_and_a_run_meanwhile_takes_them_first():
    """While a batch holds a room's Som state its moves' controls wait (SomState.lend): given back, or stepped while
    still lent, the Som steps with its latest controls, bit for bit as a Som never lent."""
    p = presets.get_preset("car")
    settled = p.make_som(device="cpu")
    settled.train()
    soms = []
    for _ in range(3):
        som = p.make_som(device="cpu")
        som.restore(settled.weights, som.iterations)
        soms.append(som)
    never, given_back, stepped_lent = soms
    moves = [never.controls + np.float32(0.01 * (i + 1)) for i in range(3)]
    given_back.parts.state.lend(True)
    stepped_lent.parts.state.lend(True)
    for c in moves:
        for som in soms:
            som.set_controls(c)
    assert given_back.parts.state._waiting is not None  # nothing written to its own rows yet
    given_back.parts.state.lend(False)
    for som in soms:
        som.step(7)
    np.testing.assert_array_equal(given_back.weights, never.weights)
    np.testing.assert_array_equal(stepped_lent.weights, never.weights)
    assert stepped_lent.parts.state._waiting is None


def test_a_rounds_node_colours_made_for_every_room_at_once_equal_each_rooms_own():
    """BatchedRooms.colours: the nodes' colours of every room a round stepped, made in one call, are each room's own
    colours of its row of the round's copy, bit for bit; a room the round did not step gets none (made on its own)."""
    layout = presets.get_preset("car").layout
    soms = _rooms_soms("car", ROOMS, 3)
    batches = BatchedRooms()
    _round(batches, soms, [10, 7, 3, 10])
    for i in range(ROOMS):
        mine = presets.colours_of(batches.host(i), layout)
        got = batches.colours(i, layout)
        assert not got.flags.writeable
        np.testing.assert_array_equal(got, mine)
    for i in range(3):  # room 3 sits this round out: its row is the last round's, its colours are not made here
        batches.hold(i, soms[i], batches.key(soms[i]))
    batches.step([(i, 5) for i in range(3)])
    assert batches.colours(3, layout) is None
    np.testing.assert_array_equal(batches.colours(1, layout), presets.colours_of(batches.host(1), layout))
    assert not np.array_equal(batches.colours(1, layout), presets.colours_of(soms[1].start_weights, layout))
