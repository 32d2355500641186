"""The hands of one session (model/hands.py) and their gestures (model/gestures.py) on a real Session: who holds what,
each drag its own undo step whatever else happens meanwhile (another drag, a script's gesture, a setting), steps
recorded in the order they complete, a person's undo taking back their own step first, Python's the whole history,
and grabs let go when their hand goes silent or their control goes. (The views' side, with real clients:
tests/xr/test_many_hands_browser.py, tests/notebook/test_notebook_and_browser.py.)
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from helpers import settled_session

from somwidget.backend import metrics
from somwidget.frontend.model import Session
from somwidget.frontend.model.hands import SILENT_SECONDS


@pytest.fixture
def session():
    yield from settled_session("car")


def drag(session, hand, index, delta, moves=4):
    """`hand` moves control `index` by `delta` in a few moves (it holds it)."""
    cid = session.control_ids[index]
    start = session.controls[index][:3]
    for k in range(1, moves + 1):
        with session.hands.acting(hand, cid):
            session.move_control_id(cid, start + np.float32(delta) * k / moves)


def test_a_held_control_is_refused_to_every_other_hand_with_the_holders_name(session):
    hands = session.hands
    a, b = hands.join("desktop"), hands.join("headset")
    cid = session.control_ids[3]
    hands.grab(a, cid)
    for attempt in (lambda: hands.grab(b, cid), lambda: hands.check_holds(b, cid, "move")):
        with pytest.raises(ValueError, match=f"control 3 is held by desktop {a.id}"):
            attempt()
    with hands.acting(b, cid), pytest.raises(ValueError, match="held by desktop"):
        session.remove_control(3)
    with pytest.raises(ValueError, match=f"change: control 3 is held by desktop {a.id}"):
        session.move_control(3, [0.0, 0.0, 0.0])  # Python too
    with pytest.raises(ValueError, match="held by desktop"):
        session.set_control_radius(3, 0.2)
    assert [(h.name, held) for h, held in hands.present()] == [(f"desktop {a.id}", (cid,)), (f"headset {b.id}", ())]
    hands.release(a, cid)
    hands.grab(b, cid)  # free again
    assert hands.holder(cid) is b


def test_two_drags_a_script_and_a_setting_at_once_are_four_steps_in_the_order_they_complete(session):
    hands = session.hands
    a, b = hands.join("desktop"), hands.join("notebook")
    start, steps = session.controls, session.history[0]
    ids = session.control_ids
    hands.grab(a, ids[1])
    hands.grab(b, ids[2])
    drag(session, a, 1, [0.0, 0.0, 0.1])
    drag(session, b, 2, [0.0, 0.1, 0.0])
    session.set_parameter("smoothing", 0.1)  # a panel's setting meanwhile: a step of its own, done at once
    assert session.history[0] == steps + 2  # the setting, and the open drags' changes so far
    with session.gesture():  # a script meanwhile: its own step; the control it moves is Python's until it ends
        session.move_control(4, start[4][:3] + np.float32([0.1, 0.0, 0.0]))
        assert hands.holder(ids[4]) is hands.python
        with pytest.raises(ValueError, match="held by Python"):
            hands.grab(a, ids[4])
    drag(session, a, 1, [0.0, 0.0, 0.2])
    hands.release(a, ids[1])
    drag(session, b, 2, [0.0, 0.2, 0.0])
    hands.release(b, ids[2])
    assert session.wait_idle(60)
    assert session.history[0] == steps + 4, session.history  # setting, script, A's drag, B's drag
    moved = session.controls

    # B's undo: B's drag (the newest, but cut by A's release) is taken back whole; the rest stays
    assert session.undo(b)
    np.testing.assert_array_equal(session.controls[2], start[2])
    for i in (1, 4):
        np.testing.assert_array_equal(session.controls[i], moved[i])
    assert session.parameters["smoothing"] == pytest.approx(0.1)
    # A's undo: A's drag, older than B's undo, taken back on the clay as it is; A's redo brings it back exactly
    assert session.undo(a)
    np.testing.assert_array_equal(session.controls[1], start[1])
    assert session.redo(a)
    np.testing.assert_array_equal(session.controls[1], moved[1])
    # Python's undo: the whole history, exactly, newest first: A's undo (its redo took it back), then B's undo ...
    assert session.wait_idle(60)
    history = session.history[0]
    for _ in range(history - steps):
        assert session.undo()
    np.testing.assert_array_equal(session.controls, start)
    assert session.parameters["smoothing"] == 0.0


def test_a_silent_hand_and_a_removed_control_let_go(session):
    hands = session.hands
    a, b = hands.join("headset"), hands.join("desktop")
    ids = session.control_ids
    lost = []
    hands.subscribe(lost.extend)
    hands.grab(a, ids[0])
    hands.grab(b, ids[5])
    drag(session, a, 0, [0.1, 0.0, 0.0])
    steps = session.history[0]
    hands.quiet(SILENT_SECONDS)  # heard just now: nothing goes
    assert hands.holder(ids[0]) is a
    hands._heard[a.id] -= SILENT_SECONDS + 1  # as if it said nothing for longer
    hands.heard(b)
    hands.quiet(SILENT_SECONDS)
    assert hands.holder(ids[0]) is None and hands.holder(ids[5]) is b
    assert [(x.hand, x.control_id) for x in lost] == [(a, ids[0])] and "sent nothing for 10 s" in lost[0].why
    assert session.history[0] == steps  # its drag: a completed step (it was counted while open)
    session.control_edits.replace(np.delete(session.controls, 5, axis=0))  # the controls replaced: B's goes
    assert session.wait_applied(30)
    session.hands.prune()
    assert hands.holder(ids[5]) is None and lost[-1].hand is b and "was removed while you held it" in lost[-1].why
    hands.leave(a)
    hands.leave(b)
    assert hands.present() == []


def held(session, controls: tuple, timeout: float = 30.0) -> None:
    """Wait until the Som holds exactly `controls` (a grab or release reaches it on the training thread)."""
    deadline = time.monotonic() + timeout
    while session.modelling.som.held != controls:
        assert time.monotonic() < deadline, f"the Som holds {session.modelling.som.held}, not {controls}"
        time.sleep(0.01)


def test_a_hands_grab_binds_the_clay_it_takes_and_its_release_lets_go():
    """A view's hand pushes the sphere's top control (a radius) straight down into the clay in a few moves: while
    it holds the control the Som holds it too and its node stays the one the grab took (the winner never jumps);
    the clay goes with the hand (the control ends on the clay, the far half stays), and the release lets go."""
    s = Session("sphere", device="cpu", autosave=False)
    try:
        assert s.wait_idle(120)
        som = s.modelling.som
        start = s.frame.positions.copy()
        size = float(np.linalg.norm(start.max(0) - start.min(0)))
        hand, cid = s.hands.join("desktop"), s.control_ids[0]
        c0 = s.controls[0][:3].copy()
        s.hands.grab(hand, cid)
        held(s, (0,))  # the grab is the session's own operation, queued for the training thread
        with s.modelling.som_lock:
            took = int(som.winners()[0])
        for k in range(1, 7):
            with s.hands.acting(hand, cid):
                s.move_control_id(cid, c0 - np.float32([0.0, 0.0, 0.7 * k / 6]))
            assert s.wait_applied(30)
            with s.modelling.som_lock:
                assert int(som.winners()[0]) == took, f"move {k}: the winner jumped"
        s.hands.release(hand, cid)
        held(s, ())
        assert s.wait_idle(120)
        end = s.frame.positions
        target = c0 - np.float32([0.0, 0.0, 0.7])
        assert np.linalg.norm(end - target, axis=1).min() <= 0.03 * size  # the dent followed the hand
        assert metrics.far_half_moved(start, end, c0) <= 0.02
    finally:
        s.close()
