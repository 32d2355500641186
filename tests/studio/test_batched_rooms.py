"""Rooms stepped together (studio/batched.py): alike rooms' Soms stepped in one BatchSom launch a round end where
the same Soms stepped apart end (the same weights to float tolerance, each room its own cycles), unlike ones step
by themselves, and a studio's rooms really go through one launch."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from somwidget.backend import presets
from somwidget.backend.batch import BatchSom
from somwidget.frontend.studio.batched import BatchedSteps, batch_key
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


def _together(steps: BatchedSteps, soms, cycles) -> None:
    """Each Som stepped from a thread of its own (as the rooms' training threads do), all at once."""
    barrier = threading.Barrier(len(soms))
    errors = []

    def room(som, k):
        barrier.wait()
        try:
            steps.step(som, k)
        except Exception as exc:  # noqa: BLE001 - the test reports it
            errors.append(exc)

    threads = [threading.Thread(target=room, args=(s, k)) for s, k in zip(soms, cycles)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors, errors


@pytest.mark.parametrize("preset", ["car", "lines", "space-grid"])  # the presets of point controls
def test_rooms_stepped_together_equal_the_rooms_stepped_apart(preset):
    apart, together = _rooms_soms(preset, ROOMS, 1), _rooms_soms(preset, ROOMS, 1)
    assert batch_key(together[0], {}) is not None
    # on this shared machine: wait long enough for every room's thread, and remember rooms across the slow rounds
    steps = BatchedSteps(window=2.0, recent=600.0)
    rounds = [[10, 7, 10, 3], [10, 10, 1, 12], [25, 10, 10, 10], [10, 4, 10, 2]]  # each room's pace its own
    for cycles in rounds:
        for som, k in zip(apart, cycles):
            som.step(k)
        _together(steps, together, cycles)
    for a, t in zip(apart, together):
        assert t.iteration == a.iteration
        np.testing.assert_allclose(t.weights, a.weights, rtol=0, atol=2e-5)
    moved = np.abs(apart[0].weights - _rooms_soms(preset, 1, 1)[0].weights).max()
    assert moved > 1e-3  # the rounds trained: equal weights are not the untouched start
    # every round after the first (whose leader knew of no other room yet) was one launch for every room
    assert steps.launches >= len(rounds) - 1 and steps.batched >= ROOMS * (len(rounds) - 1)


def test_unlike_rooms_step_by_themselves_and_still_train_right():
    car, other = _rooms_soms("car", 2, 3)
    other.l_start = 0.3  # another schedule: not the car rooms' batch
    reference = _rooms_soms("car", 2, 3)
    reference[1].l_start = 0.3
    steps = BatchedSteps(window=0.5)
    assert batch_key(car, {}) != batch_key(other, {})
    for _ in range(2):
        _together(steps, [car, other], [10, 10])
        for som in reference:
            som.step(10)
    assert steps.batched == 0 and steps.alone == 4
    for som, ref in zip([car, other], reference):
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
        for room in made:  # each room's designer drags: its session trains again
            session = room.session
            session.move_control(0, np.asarray(session.controls[0][:3]) + 0.05)
        deadline = time.monotonic() + 120
        while rooms.steps.batched == 0 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert rooms.steps.batched >= 2 and rooms.steps.launches >= 1
        for room in made:
            assert room.session.wait_idle(120)
            assert room.session.error is None
    finally:
        rooms.close()
