"""The one view connection (transport/connection.py), as any host uses it: over a pipe that records what it is
handed (the web hub's pipe is a websocket, the notebook widget's the kernel's comm; tests of those run them for
real). Two views share the session's one registry of holders on a real Session: what each is sent on opening (who
is there), a grab seen by both with its holder, a move of a control held by the other refused with a reason naming
the holder, a hello sending the topology again, a view that goes away letting go of what it held. Intents run on the
session's training thread: `receive` returns a Future of whether the intent was done.
"""

from __future__ import annotations

import gc
import json
import weakref

import numpy as np
import pytest

from somwidget.frontend.model import Session
from somwidget.frontend.transport import frames, messages
from somwidget.frontend.transport.connection import HANDLERS, ViewConnection
from somwidget.frontend.transport.holders import holders_for


class RecordingPipe:
    def __init__(self):
        self.sent: list = []

    def send_json(self, message: dict) -> None:
        self.sent.append(json.loads(json.dumps(message)))  # what a view receives: JSON, nothing else

    def send_frame(self, frame: bytes) -> None:
        self.sent.append(frames.decode_frame(frame))

    def of(self, kind: str) -> list[dict]:
        return [m for m in self.sent if m.get("type") == kind]

    def take(self) -> list:
        out, self.sent = self.sent, []
        return out


@pytest.fixture(scope="module")
def session():
    s = Session("car", device="cpu", paused=True, autosave=False)
    yield s
    s.close()


def test_every_intent_has_one_handler():
    assert set(HANDLERS) == set(messages.INTENTS.values())


def done(connection, message: dict) -> bool:
    """Send one message and wait until it was done (True) or refused (False)."""
    return connection.receive(json.dumps(message)).result(30)


def test_two_views_on_one_registry(session):
    pa, pb = RecordingPipe(), RecordingPipe()
    a = ViewConnection(session, pa, client_id=1)
    b = ViewConnection(session, pb, client_id=2, kind="notebook")
    assert a.holders is b.holders is holders_for(session)  # one registry per session
    assert [m["type"] for m in pa.take()] == ["grabs", "presence"]  # b came
    a.open()
    b.open()
    sent = pa.take()  # the topology, the frame, a status line, who holds what, who is there
    topology, frame = sent[:2]
    assert topology["type"] == "topology" and topology["client"] == 1 and topology["n_controls"] == 9
    assert frame["seq"] == session.frame.seq and frame["n"] == topology["n_vertices"] == 602
    assert [m.get("type") for m in sent[2:]] == ["status", "grabs", "presence"] and sent[-2]["grabs"] == []
    here = sent[-1]["hands"]
    assert [(h["name"], h["kind"], h["you"]) for h in here] == [(f"desktop {a.hand.id}", "desktop", True),
                                                                 (f"notebook {b.hand.id}", "notebook", False)]
    assert here[0]["colour"] != here[1]["colour"] and all(h["holds"] == [] for h in here)
    assert not a.send_latest()  # it has this frame already
    cid = session.control_ids[2]
    pb.take()

    assert done(a, {"type": "grab", "id": cid})
    holder = {"hand": a.hand.id, "holder": f"desktop {a.hand.id}", "colour": a.hand.colour}
    assert pa.of("grabs")[-1]["grabs"] == [{"index": 2, "id": cid, "own": True, **holder}]
    assert pb.of("grabs")[-1]["grabs"] == [{"index": 2, "id": cid, "own": False, **holder}]
    assert [h["holds"] for h in pb.of("presence")[-1]["hands"]] == [[cid], []]
    assert not done(b, {"type": "move", "id": cid, "position": [0, 0, 0]})
    error = pb.of("error")[-1]
    assert error["intent"] == "move" and f"control 2 is held by desktop {a.hand.id}" in error["message"]
    assert not done(b, {"type": "grab", "id": cid})
    assert f"grab: control 2 is held by desktop {a.hand.id}" in pb.of("error")[-1]["message"] and b.refused == 2
    assert not done(b, {"type": "grab", "id": cid, "colour": "red"})
    assert "unknown field" in pb.of("error")[-1]["message"]
    with pytest.raises(ValueError, match=f"held by desktop {a.hand.id}"):  # Python is refused it too
        session.move_control(2, [0.0, 0.0, 0.0])

    target = [float(v) for v in session.controls[2][:3] + np.array([0.0, 0.0, 0.3])]
    steps = session.history[0]
    assert done(a, {"type": "move", "id": cid, "position": target})
    assert done(a, {"type": "ping", "t": 7})
    assert pa.of("pong")[-1] == {"type": "pong", "t": 7.0}
    pa.take()
    assert done(a, {"type": "hello"})
    again = pa.take()
    assert again[0]["type"] == "topology" and "positions" in again[1] and again[-1]["type"] == "presence"
    a.close().result(30)  # gone mid-drag: the drag is a completed step, the other view sees the control free
    assert pb.of("grabs")[-1]["grabs"] == []
    assert [h["name"] for h in pb.of("presence")[-1]["hands"]] == [f"notebook {b.hand.id}"]
    assert session.wait_applied(30)
    np.testing.assert_allclose(session.controls[2][:3], target, atol=1e-6)
    assert session.history[0] == steps + 1
    assert a.intents == 4 and b.intents == 0 and b.refused == 3
    b.close().result(30)


def test_a_release_at_the_last_move_runs_nothing(session):
    """A release ends a drag and nothing more: at the last move's position (an older client's release carries it)
    no cycle runs after it; at another position the control moves there first."""
    pipe = RecordingPipe()
    view = ViewConnection(session, pipe, client_id=3)
    session.train()
    cid = session.control_ids[4]
    start = session.controls[4][:3]
    target = [float(v) for v in start + np.array([0.0, 0.2, 0.0])]
    assert done(view, {"type": "grab", "id": cid}) and done(view, {"type": "move", "id": cid, "position": target})
    assert session.wait_idle(60)
    settled = session.frame
    assert settled.iteration == settled.iterations
    assert done(view, {"type": "release", "id": cid, "position": target})
    assert session.wait_idle(60)
    assert session.frame.iteration == settled.iteration and session.frame.applied == settled.applied
    np.testing.assert_array_equal(session.frame.positions, settled.positions)
    assert pipe.of("grabs")[-1]["grabs"] == []
    further = [float(v) for v in start + np.array([0.0, 0.3, 0.0])]
    assert done(view, {"type": "grab", "id": cid})
    assert done(view, {"type": "release", "id": cid, "position": further})  # elsewhere: it moves there
    assert session.wait_applied(30)
    np.testing.assert_allclose(session.controls[4][:3], further, atol=1e-6)
    view.close().result(30)


def test_a_closed_view_keeps_nothing_of_its_session():
    """Neither the session's registry of holders nor the display geometry kept per preset (both module-wide) holds
    a session, its preset or its topology (with its distance tables) once its last view and the session are closed:
    tests/notebook/test_release.py measures the memory this gives back."""
    s = Session("car", device="cpu", paused=True, autosave=False)
    view = ViewConnection(s, RecordingPipe(), name="a view that goes")
    view.open()  # the topology message: the preset's display geometry is made and kept
    assert s.wait_applied(30)
    gone = [weakref.ref(x) for x in (s, s.preset, s.preset.topology)]
    view.close().result(30)
    s.close()
    del s, view
    gc.collect()
    assert [r() for r in gone] == [None, None, None]
