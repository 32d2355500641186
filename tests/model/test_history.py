"""Undo, redo and the history's bounds; shapes kept until the person acts; exact loads (frontend/model/session.py,
frontend/model/history.py). Real sessions on the CPU engine, with their training threads."""

from __future__ import annotations

import time

import numpy as np
import pytest

from somwidget.frontend.model import Session, timeline
from somwidget.frontend.model.history import History, Step


def state_of(session: Session) -> dict:
    """Everything undo promises to put back, read between steps."""
    snap = session.files.snapshot()
    return {"preset": snap["preset"].name, "weights": snap["weights"], "controls": snap["controls"],
            "iteration": snap["iteration"], "parameters": snap["parameters"]}


def assert_same(a: dict, b: dict) -> None:
    assert a["preset"] == b["preset"] and a["iteration"] == b["iteration"]
    np.testing.assert_array_equal(a["weights"], b["weights"])
    np.testing.assert_array_equal(a["controls"], b["controls"])
    assert a["parameters"] == b["parameters"]


def still(session: Session, seconds: float = 0.4) -> dict:
    """The state, checked not to change for a while (nothing trains)."""
    before = state_of(session)
    time.sleep(seconds)
    after = state_of(session)
    assert_same(before, after)
    assert not session.frame.running
    return after


@pytest.fixture
def car():
    s = Session("car", device="cpu")
    assert s.wait_idle(60)
    yield s
    s.close()


def drag(session: Session, index: int, to, steps: int = 8) -> None:
    """A drag as the views make it: press, moves, release."""
    start = session.controls[index, :3].astype(np.float64)
    with session.gesture():
        for t in np.linspace(0, 1, steps + 1)[1:]:
            session.move_control(index, start + t * (np.asarray(to) - start))
            time.sleep(0.01)


def test_undo_and_redo_put_every_step_back_exactly(car):
    a = state_of(car)
    assert car.history == (0, 0) and car.undo() is False and car.redo() is False
    drag(car, 2, [3.0, 0.6, 0.2])
    assert car.wait_idle(60)
    b = state_of(car)
    assert car.history == (1, 0)  # a drag from press to release is one step
    car.set_smoothing(0.1)
    car.set_smoothing(0.15)  # the same parameter again at once joins the step (a slider's drag)
    assert car.wait_idle(60)
    c = state_of(car)
    assert car.history == (2, 0)
    assert car.undo() is True
    assert_same(still(car), b)  # bit for bit, and nothing trains
    assert car.frame.held and car.history == (1, 1)
    assert car.undo() is True
    assert_same(still(car), a)
    assert car.undo() is False
    assert car.redo() is True
    assert_same(still(car), b)
    assert car.redo() is True
    assert_same(still(car), c)
    assert car.redo() is False and car.history == (2, 0)
    # a new step after an undo drops the redo steps; a control placed trains nothing, the next move trains again
    car.undo()
    car.add_control()
    assert car.history == (2, 0)
    assert car.wait_idle(60) and car.frame.held
    assert car.frame.n_controls == 10
    car.move_control(9, car.controls[9, :3] + np.float32([0.0, 0.0, 0.1]))
    assert car.wait_idle(60) and not car.frame.held and car.history == (3, 0)


def test_undo_across_a_preset_and_a_reset(car):
    a = state_of(car)
    car.reset()
    assert car.wait_idle(60)
    car.load_preset("torus")
    assert car.wait_idle(30) and car.preset.name == "torus"
    generation = car.generation
    assert car.undo() is True  # the car as the reset left it
    assert car.preset.name == "car" and car.generation > generation
    assert car.undo() is True
    assert_same(still(car), a)


def test_a_refused_intent_records_no_step(car):
    with pytest.raises(ValueError):
        car.move_control(99, [0, 0, 0])
    with pytest.raises(ValueError):
        car.set_smoothing(3.0)
    assert car.history == (0, 0)


def test_a_radius_sent_again_unchanged_is_no_step(car, monkeypatch):
    """A panel's radius field sends its value on Enter and again when it loses focus (the person pressing on the view
    to drag): the same value again, however late it comes, is no undo step and trains nothing (a loaded machine made
    it a second step of its own, and a drag after it needed two undos)."""
    monkeypatch.setattr(timeline, "PARAMETER_STEP_SECONDS", 0.0)  # the value again comes too late to join its step
    car.set_control_radius(2, 0.4)
    assert car.wait_idle(60) and car.history == (1, 0)
    a = still(car)
    car.set_control_radius(2, 0.4)
    assert car.history == (1, 0)
    assert_same(still(car), a)
    car.set_control_radius(None, 0.4)  # every control's: the others change, so it is a step
    assert car.history == (2, 0)


def test_a_general_shape_is_shown_as_it_is_until_the_person_acts():
    s = Session("torus", device="cpu")
    try:
        start = s.preset.weights
        assert s.wait_idle(30)
        f = s.frame
        assert f.iteration == f.iterations and not f.running
        np.testing.assert_array_equal(still(s)["weights"], start)
        # a drag restarts locally: the shape follows near the control and stays elsewhere
        target = s.controls[1, :3] + [0.0, 0.0, 0.12]
        drag(s, 1, target)
        assert s.wait_idle(60)
        after = s.frame.positions
        size = np.linalg.norm(start.max(axis=0) - start.min(axis=0))
        assert np.linalg.norm(after - target, axis=1).min() < 0.01 * size
        far = np.linalg.norm(start - target, axis=1) > 0.25 * size
        assert np.percentile(np.linalg.norm(after[far] - start[far], axis=1), 90) < 0.02 * size
        # Train on a settled shape: one step, a local restart
        s.train()
        assert s.wait_idle(60) and s.history == (2, 0)
    finally:
        s.close()


def test_reset_runs_the_whole_schedule_from_the_start_mesh(car):
    car.pause()
    car.reset()
    assert car.wait_applied(10)
    f = car.frame
    assert f.iteration == 0
    np.testing.assert_array_equal(f.weights, car.preset.weights)
    car.train()
    assert car.wait_idle(60) and car.frame.iteration == 1000


def test_choosing_the_current_preset_again_restores_its_controls(car):
    original = car.controls
    drag(car, 0, [1.6, 1.2, -0.9])
    assert car.wait_idle(60)
    assert not np.array_equal(car.controls, original)
    car.load_preset("car")
    np.testing.assert_array_equal(car.controls, original)
    assert car.undo() is True and not np.array_equal(car.controls, original)


def test_a_loaded_session_is_exactly_as_saved_and_trains_nothing(car, tmp_path):
    car.pause()
    drag(car, 4, [-0.25, 0.5, 1.0])  # a short drag: s0 of the preset's reach (a long one widens it)
    assert car.wait_applied(30)
    saved = state_of(car)
    assert saved["iteration"] == 920  # saved mid-run: restarted at s0, paused there
    car.save(tmp_path / "s.npz")
    car.train()
    car.load_preset("sphere")
    car.load(tmp_path / "s.npz")
    loaded = still(car)
    assert_same({**loaded, "preset": saved["preset"]}, saved)
    assert car.frame.held and car.parameters["reach"] == saved["parameters"]["reach"]
    car.train()  # the run goes on from where it was saved
    assert car.wait_idle(60) and car.frame.iteration == 1000


def test_history_bounds_its_memory_and_keeps_older_steps_on_disk(tmp_path):
    """MAX_STEPS steps at most; weights beyond the memory budget are written to disk and come back exactly."""
    h = History(max_steps=120, memory_bytes=10 * 4096 * 3 * 4, spill_dir=tmp_path)
    steps = [Step(preset=None, controls=np.zeros((1, 3), np.float32), parameters={"i": i},
                  weights=np.full((4096, 3), i, np.float32), iteration=i) for i in range(150)]
    for s in steps:
        h.push(s)
    assert h.undo_count == 120 and h.memory_used <= h.memory_bytes
    spilled = list(tmp_path.rglob("*.npz"))
    assert len(spilled) == 110
    current = Step(preset=None, controls=np.zeros((1, 3), np.float32), parameters={}, weights=np.zeros((4096, 3),
                   np.float32), iteration=0)
    for i in range(149, 29, -1):  # every step back, in order, exactly
        back = h.undo(current)
        assert back.iteration == i and back.parameters == {"i": i}
        np.testing.assert_array_equal(back.weights, np.full((4096, 3), i, np.float32))
        current = back
    assert h.undo(current) is None and h.redo_count == 120
    h.close()
    assert not list(tmp_path.rglob("*.npz"))
