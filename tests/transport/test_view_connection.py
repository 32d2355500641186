"""The one view connection (transport/connection.py), as any host uses it: over a pipe that records what it is
handed (the web hub's pipe is a websocket, the notebook widget's the kernel's comm; tests of those run them for
real). Two views share a registry of holders on a real Session: what each is sent on opening, a grab seen by both,
a move of a control held by the other refused with a reason, a hello sending the topology again, a view that goes
away letting go of what it held.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from somwidget.frontend.model import Session
from somwidget.frontend.transport import frames, messages
from somwidget.frontend.transport.connection import HANDLERS, ViewConnection
from somwidget.frontend.transport.holders import HolderRegistry


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


def test_two_views_on_one_registry(session):
    holders = HolderRegistry(session)
    pa, pb = RecordingPipe(), RecordingPipe()
    a = ViewConnection(session, holders, pa, client_id=1)
    b = ViewConnection(session, holders, pb, client_id=2)
    a.open()
    b.open()
    sent = pa.take()  # the topology, the frame, a status line, who holds what
    topology, frame = sent[:2]
    assert topology["type"] == "topology" and topology["client"] == 1 and topology["n_controls"] == 9
    assert frame["seq"] == session.frame.seq and frame["n"] == topology["n_vertices"] == 602
    assert [m.get("type") for m in sent[2:]] == ["status", "grabs"] and sent[-1]["grabs"] == []
    assert not a.send_latest()  # it has this frame already
    cid = session.control_ids[2]
    pb.take()

    assert a.receive(json.dumps({"type": "grab", "id": cid}))
    assert pa.of("grabs")[-1]["grabs"] == [{"index": 2, "id": cid, "own": True}]
    assert pb.of("grabs")[-1]["grabs"] == [{"index": 2, "id": cid, "own": False}]
    assert not b.receive(json.dumps({"type": "move", "id": cid, "position": [0, 0, 0]}))
    error = pb.of("error")[-1]
    assert error["intent"] == "move" and "not held by this client" in error["message"] and b.refused == 1
    assert not b.receive(json.dumps({"type": "grab", "id": cid, "colour": "red"}))
    assert "unknown field" in pb.of("error")[-1]["message"]

    target = [float(v) for v in session.controls[2][:3] + np.array([0.0, 0.0, 0.3])]
    steps = session.history[0]
    assert a.receive(json.dumps({"type": "move", "id": cid, "position": target}))
    assert a.receive(json.dumps({"type": "ping", "t": 7}))
    assert pa.of("pong")[-1] == {"type": "pong", "t": 7.0}
    pa.take()
    assert a.receive(json.dumps({"type": "hello"}))
    again = pa.take()
    assert again[0]["type"] == "topology" and "positions" in again[1] and again[-1]["type"] == "grabs"
    a.close()  # gone mid-drag: the drag is a completed step, the other view sees the control free
    assert pb.of("grabs")[-1]["grabs"] == []
    assert session.wait_applied(30)
    np.testing.assert_allclose(session.controls[2][:3], target, atol=1e-6)
    assert session.history[0] == steps + 1
    assert a.intents == 4 and b.intents == 0 and b.refused == 2
    b.close()
