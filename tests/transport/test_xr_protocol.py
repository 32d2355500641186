"""The views' websocket protocol (/view/ws), shown with Python clients (aiohttp) against the route and a real Session.

These tests send intents themselves: they show the protocol, not the interaction (test_xr_browser.py does that
through an emulated headset). Covered: the topology message and the binary frame layout (decoded and checked
against the session's frames), grab / move / release and who holds what, the shared session between two clients,
a fuzz of bad messages (each refused with an error sent back, none of them touching the session), the flood limit,
and the access token (403 without it).
"""

from __future__ import annotations

import asyncio
import json
import random

import aiohttp
import numpy as np
import pytest

from somwidget.frontend.transport import display as wire_display
from somwidget.frontend.transport import frames as wire_frames
from somwidget.frontend.transport import messages as wire
from somwidget.frontend.web import hub as xr_server
from somwidget.frontend.web.standalone import XRServer


@pytest.fixture(scope="module")
def session():
    from somwidget.frontend.model import Session

    s = Session("car", device="cpu", paused=True)
    yield s
    s.close()


@pytest.fixture(scope="module")
def srv(session):
    with XRServer(session) as server:
        yield server


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 60))


class Client:
    """A websocket client that sorts what arrives into topology, frames and JSON messages."""

    def __init__(self, ws):
        self.ws = ws
        self.topology = None
        self.frames: list[dict] = []
        self.messages: list[dict] = []

    async def receive(self, timeout: float = 10.0):
        msg = await self.ws.receive(timeout=timeout)
        if msg.type == aiohttp.WSMsgType.BINARY:
            f = wire_frames.decode_frame(msg.data)
            f["bytes"] = len(msg.data)
            self.frames.append(f)
            return f
        if msg.type == aiohttp.WSMsgType.TEXT:
            m = json.loads(msg.data)
            if m["type"] == "topology":
                self.topology = m
            else:
                self.messages.append(m)
            return m
        return msg

    async def until(self, predicate, timeout: float = 10.0):
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while True:
            m = await self.receive(timeout=max(0.01, deadline - loop.time()))
            if predicate(m):
                return m

    async def send(self, obj):
        await self.ws.send_str(obj if isinstance(obj, str) else json.dumps(obj))

    async def error_for(self, message):
        """Send `message` (text or bytes) and return the error reply."""
        if isinstance(message, bytes):
            await self.ws.send_bytes(message)
        else:
            await self.send(message)
        return await self.until(lambda m: isinstance(m, dict) and m.get("type") == "error")


def grabs_are(m, *expected) -> bool:
    """A grabs message listing exactly the (index, id, own) of `expected`, each with its holder's name and colour."""
    if not (isinstance(m, dict) and m.get("type") == "grabs"):
        return False
    return ([(g["index"], g["id"], g["own"]) for g in m["grabs"]] == list(expected)
            and all(g["holder"] and g["colour"].startswith("#") for g in m["grabs"]))


async def connect(cs, srv, **kw) -> Client:
    ws = await cs.ws_connect(srv.base + "/view/ws", **kw)
    c = Client(ws)
    await c.until(lambda m: isinstance(m, dict) and "positions" in m)  # topology, then the first frame
    return c


# -- the message layouts -----------------------------------------------------------------------------------------
def test_topology_and_frame_layout(srv, session):
    async def main():
        async with aiohttp.ClientSession() as cs:
            c = await connect(cs, srv)
            await c.ws.close()
            return c

    c = run(main())
    t, f = c.topology, c.frames[0]
    frame = session.frame
    assert t["protocol"] == wire.PROTOCOL_VERSION and t["display"] == "surface" and t["preset"] == "car"
    assert t["n_vertices"] == 602 and t["n_controls"] == 9 and t["n_effective"] == 18
    assert t["mirror_axes"] == [False, True, False] and t["up_axis"] == 2
    tris = np.array(t["triangles"]).reshape(-1, 3)
    assert len(tris) == 1200 and tris.min() == 0 and tris.max() == 601  # 575 quads fanned + 50 pole triangles
    assert len(t["segments"]) == 2 * len(session.topology.edges)
    assert f["n"] == 602 and f["k"] == 9 and f["k_eff"] == 18 and f["bytes"] == wire_frames.frame_size(602, 18)
    assert f["bytes"] == 32 + 15 * (602 + 18) + 0  # 9332: already a multiple of 4
    assert f["seq"] == frame.seq and f["generation"] == frame.generation == t["generation"]
    assert f["paused"] and not f["running"] and f["iterations"] == 1000
    np.testing.assert_array_equal(f["positions"], frame.positions)
    np.testing.assert_array_equal(f["control_positions"], frame.effective_positions)
    np.testing.assert_array_equal(f["colours"], np.clip(np.round(frame.colours * 255), 0, 255).astype(np.uint8))
    np.testing.assert_array_equal(f["control_colours"],
                                  np.clip(np.round(frame.effective_colours * 255), 0, 255).astype(np.uint8))


@pytest.mark.parametrize("preset, display, n", [("lines", "lines", 1204), ("lattice", "points", 512)])
def test_other_displays_encode(preset, display, n):
    from somwidget.frontend.model import Session

    with Session(preset, device="cpu", start=False) as s:
        frame = s.frame
        t = wire_display.topology_message(s, frame).to_json()
        f = wire_frames.decode_frame(wire_frames.encode_frame(frame, s))
    assert t["display"] == display and t["n_vertices"] == n and f["n"] == n
    if display == "lines":  # roots then tips, quads as two triangles, one root -> tip segment per node
        np.testing.assert_array_equal(f["positions"][:602], frame.positions)
        assert len(t["triangles"]) == 6 * len(s.topology.edges) and len(t["segments"]) == 2 * 602
    else:
        assert t["points"] and not t["triangles"] and len(t["segments"]) == 2 * len(s.topology.edges)
        assert len(set(map(tuple, f["control_colours"]))) > 1  # no colour dims: palette colours for controls
    with pytest.raises(ValueError):
        wire_frames.decode_frame(wire_frames.encode_frame(frame, s)[:-4])


# -- intents -----------------------------------------------------------------------------------------------------
BAD_MESSAGES = [
    ("not json", "not valid JSON"),
    ("", "not valid JSON"),
    ("[1, 2, 3]", "expected a JSON object"),
    ('"move"', "expected a JSON object"),
    ("{}", "unknown intent type missing"),
    ('{"type": "explode"}', "unknown intent type"),
    ('{"type": 7}', "unknown intent type"),
    ('{"type": "grab"}', "one of the two"),
    ('{"type": "grab", "index": 0, "id": 0}', "one of the two"),
    ('{"type": "grab", "id": "3"}', "id must be a control's id"),
    ('{"type": "grab", "id": -1}', "id must be a control's id"),
    ('{"type": "move", "id": 77, "position": [0, 0, 0]}', "not held by this client"),
    ('{"type": "grab", "index": 0, "colour": "red"}', "unknown field"),
    ('{"type": "grab", "index": "0"}', "must be an integer"),
    ('{"type": "grab", "index": 1.5}', "must be an integer"),
    ('{"type": "grab", "index": true}', "must be an integer"),
    ('{"type": "grab", "index": 9}', "out of range"),
    ('{"type": "grab", "index": -1}', "out of range"),
    ('{"type": "grab", "index": 99999999999999999999999}', "out of range"),
    ('{"type": "move", "index": 0, "position": [0, 0, NaN]}', "not valid JSON"),
    ('{"type": "move", "index": 0, "position": [Infinity, 0, 0]}', "not valid JSON"),
    ('{"type": "move", "index": 0, "position": [1e400, 0, 0]}', "must be finite"),
    ('{"type": "move", "index": 0, "position": [1e5, 0, 0]}', "out of bounds"),
    ('{"type": "move", "index": 0, "position": [0, 0]}', "list of 3 numbers"),
    ('{"type": "move", "index": 0, "position": [0, 0, 0, 0]}', "list of 3 numbers"),
    ('{"type": "move", "index": 0, "position": {"x": 0}}', "list of 3 numbers"),
    ('{"type": "move", "index": 0, "position": ["1", 0, 0]}', "must be a number"),
    ('{"type": "move", "index": 0, "position": [true, 0, 0]}', "must be a number"),
    ('{"type": "move", "index": 0, "position": [null, 0, 0]}', "must be a number"),
    ('{"type": "move", "index": 0, "position": [1, 2, 3]}', "not held by this client"),
    ('{"type": "release", "index": 0}', "not held by this client"),
    ('{"type": "reset", "now": true}', "unknown field"),
    ('{"type": "ping"}', "missing field"),
    ('{"type": "ping", "t": "soon"}', "must be a number"),
    ("[" * 1000 + "]" * 1000, "not valid JSON"),
    ('{"type": "train", "pad": "' + "x" * 3000 + '"}', "message too long"),
    (b"\x00\x01binary", "binary messages are not accepted"),
    ("1" * 5000, "message too long"),
    ('{"type": "add"}', "missing field"),
    ('{"type": "add", "position": [0, 0]}', "list of 3 numbers"),
    ('{"type": "add", "position": [0, 0, 0], "radius": -1}', "out of bounds"),
    ('{"type": "remove"}', "one of the two"),
    ('{"type": "radius", "id": 0}', "missing field"),
    ('{"type": "radius", "index": 0, "radius": "big"}', "must be a number"),
    ('{"type": "stroke", "points": [[0, 0, 0]]}', "2 to 64 points"),
    ('{"type": "stroke", "points": [[0, 0, 0], [0, 0]]}', "list of 3 numbers"),
    ('{"type": "hand", "kind": "desktop", "name": "' + "x" * 41 + '"}', "1 to 40 printable characters"),
    ('{"type": "hand", "kind": "desktop", "name": "   "}', "1 to 40 printable characters"),
    ('{"type": "hand", "kind": "desktop", "name": "a\\u0000b"}', "1 to 40 printable characters"),
    ('{"type": "hand", "kind": "desktop", "name": 7}', "1 to 40 printable characters"),
]


@pytest.mark.parametrize("message, reason", [m for m in BAD_MESSAGES if "not held" not in m[1]])
def test_parse_intent_refuses(message, reason):
    """Each malformed message is refused by the parser, with a message that says why."""
    with pytest.raises(wire.IntentError) as info:
        wire.parse_intent(message, n_controls=9)
    assert reason in str(info.value)


def test_parse_intent_accepts():
    assert wire.parse_intent('{"type": "move", "index": 3, "position": [1, -2.5, 0.25]}', 9) == wire.MoveIntent(
        index=3, position=(1.0, -2.5, 0.25))
    assert wire.parse_intent('{"type": "release", "index": 8}', 9).position is None
    assert wire.parse_intent('{"type": "ping", "t": 12.5}', 9).t == 12.5
    assert wire.parse_intent('{"type": "hand", "kind": "desktop", "name": " Dave   Li "}', 9).name == "Dave Li"
    assert wire.parse_intent('{"type": "hand", "kind": "headset"}', 9).name is None
    for kind in ("reset", "train", "pause"):
        assert wire.parse_intent(json.dumps({"type": kind}), 9).type == kind


def test_fuzz_bad_messages_are_refused_and_harmless(srv, session):
    """Every bad message gets an error message back and is logged; the session's controls, parameters and
    training state stay as they were, and the same connection still works afterwards."""
    controls, params, seq = session.controls, session.parameters, session.frame.seq
    refused_before = srv.hub.refused_total
    rng = random.Random(1234)
    values = [None, True, False, 0, -1, 9, 2**70, 1.5, -1e300, 1e308, "", "0", "NaN", [], [0], [0, 0, "0"],
              [1e9, 0, 0], ["a", "b", "c"], {}, {"x": 1}, "\u00e9\u4e2d\U0001f600", "\x00"]
    fuzz = []
    for _ in range(150):  # random objects: mostly bad types, indices, fields and values
        obj = {"type": rng.choice(["grab", "move", "release", "explode", "", None, 3, "MOVE"])}
        for _ in range(rng.randint(0, 3)):
            obj[rng.choice(["index", "position", "t", "extra", "type", "__proto__"])] = rng.choice(values)
        text = json.dumps(obj)
        if rng.random() < 0.2:  # and some broken text
            cut = rng.randint(0, len(text))
            text = text[:cut] + rng.choice(["", "}", "\\", "\ud800", "NaN"]) + text[cut + 1:]
        fuzz.append(text)

    async def main():
        async with aiohttp.ClientSession() as cs:
            c = await connect(cs, srv)
            for message, reason in BAD_MESSAGES:
                err = await c.error_for(message)
                assert reason in err["message"], (message[:60], err)
            answered = 0
            for text in fuzz:
                await c.send(text.encode("utf-8", "surrogatepass").decode("utf-8", "replace"))
            await c.send({"type": "ping", "t": 42})  # the answers come in order: the pong comes last
            while True:
                m = await c.receive()
                if isinstance(m, dict) and m.get("type") == "error":
                    answered += 1
                if isinstance(m, dict) and m.get("type") == "pong":
                    assert m["t"] == 42
                    break
            # the connection still works: grab, move, release a control, then put it back
            await c.send({"type": "grab", "index": 1})
            await c.send({"type": "move", "index": 1, "position": [-1.0, 1.0, -0.5]})
            await c.send({"type": "release", "index": 1, "position": [-1.0, 1.0, -0.6]})
            await c.until(lambda m: isinstance(m, dict) and m.get("type") == "grabs"
                          and all(g["index"] != 1 for g in m["grabs"]))
            await c.ws.close()
            return answered

    answered = run(main())
    assert answered >= 100  # most random messages are bad; the valid ones (e.g. a grab) are simply applied
    assert srv.hub.refused_total - refused_before >= len(BAD_MESSAGES) + answered
    np.testing.assert_allclose(session.controls[1, :3], [-1.0, 1.0, -0.6])
    others = np.delete(np.arange(9), 1)
    np.testing.assert_array_equal(session.controls[others], controls[others])
    assert session.parameters == params and session.paused and session.error is None
    assert np.isfinite(session.frame.positions).all() and session.frame.seq >= seq
    session.control_edits.replace(controls)  # back as it was for the other tests
    assert session.wait_applied(30)


def test_add_radius_stroke_and_remove_intents(srv, session):
    """The intents a view sends when a person places controls (the protocol; test_view_modelling.py and
    test_xr_browser.py show the interaction): "add" puts a control at a point and moves nothing, "radius" sets one's
    radius, "stroke" adds a line as one control, "remove" takes one away; the "controls" message before the next
    frame carries the radii and strokes."""
    assert session.wait_applied(30)
    controls, radii, weights = session.controls, session.control_edits.radii, session.frame.weights.copy()
    point = [float(v) for v in session.frame.positions[10]]

    async def main():
        async with aiohttp.ClientSession() as cs:
            c = await connect(cs, srv)
            await c.send({"type": "add", "position": point, "radius": 0.25})
            msg = await c.until(lambda m: isinstance(m, dict) and m.get("type") == "controls"
                                and len(m["ids"]) == len(controls) + 1)
            added = msg["ids"][-1]
            assert msg["radii"][-1] == 0.25 and msg["strokes"] == [1] * (len(controls) + 1)
            await c.send({"type": "radius", "id": added, "radius": 0.5})
            msg = await c.until(lambda m: isinstance(m, dict) and m.get("type") == "controls"
                                and m["radii"][-1] == 0.5)
            await c.send({"type": "stroke", "points": [[3.0, 0.0, 0.5], [3.0, 0.0, 1.0]], "radius": 0.1})
            msg = await c.until(lambda m: isinstance(m, dict) and m.get("type") == "controls"
                                and len(m["strokes"]) == len(controls) + 2)
            run = msg["strokes"][-1]
            assert run >= 2 and msg["radii"][-run:] == [0.1] * run
            await c.send({"type": "remove", "id": msg["ids"][-1]})  # a sample of the stroke: the stroke goes whole
            await c.send({"type": "remove", "id": added})
            await c.until(lambda m: isinstance(m, dict) and m.get("type") == "controls"
                          and len(m["ids"]) == len(controls))
            await c.ws.close()

    run(main())
    assert session.wait_applied(30)
    np.testing.assert_array_equal(session.controls, controls)
    np.testing.assert_array_equal(session.control_edits.radii, radii)
    np.testing.assert_array_equal(session.frame.weights, weights)  # paused: nothing trained, nothing moved


def test_flood_of_bad_messages_closes_only_that_socket(srv, session, monkeypatch):
    monkeypatch.setattr(xr_server, "MAX_ERRORS", 20)

    async def main():
        async with aiohttp.ClientSession() as cs:
            bad = await connect(cs, srv)
            good = await connect(cs, srv)
            for _ in range(30):
                await bad.send("garbage")
            while True:
                m = await bad.receive()
                if not isinstance(m, dict):
                    assert m.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED)
                    break
            assert bad.ws.close_code == 1008
            await good.send({"type": "ping", "t": 1})
            await good.until(lambda m: isinstance(m, dict) and m.get("type") == "pong")
            await good.ws.close()

    run(main())
    assert session.error is None


def test_two_clients_share_the_session_and_grabs(srv, session):
    """What one client moves, the other sees in its frames; a held control is refused to the other; a client
    that goes away lets go of what it held."""
    start = session.controls

    async def main():
        async with aiohttp.ClientSession() as cs:
            a = await connect(cs, srv)
            b = await connect(cs, srv)
            await a.send({"type": "grab", "index": 3})
            m = await b.until(lambda m: grabs_are(m, (3, 3, False)))
            holder = m["grabs"][0]["holder"]
            assert holder.startswith("desktop ")
            err = await b.error_for({"type": "grab", "index": 3})
            assert f"control 3 is held by {holder}" in err["message"]
            err = await b.error_for({"type": "move", "index": 3, "position": [0, 0, 0]})
            assert f"move: control 3 is held by {holder}" in err["message"]
            target = [-2.0, 0.5, 0.4]
            await a.send({"type": "move", "index": 3, "position": target})
            f = await b.until(lambda m: isinstance(m, dict) and "control_positions" in m
                              and np.allclose(m["control_positions"][3], target))
            np.testing.assert_allclose(f["control_positions"][9 + 3], [-2.0, -0.5, 0.4])  # the mirrored copy
            await a.ws.close()  # goes away holding control 3
            await b.until(lambda m: isinstance(m, dict) and m.get("type") == "grabs" and m["grabs"] == [])
            await b.send({"type": "grab", "index": 3})
            await b.until(lambda m: grabs_are(m, (3, 3, True)))
            await b.send({"type": "release", "index": 3})
            await b.until(lambda m: isinstance(m, dict) and m.get("type") == "grabs" and m["grabs"] == [])
            await b.ws.close()

    run(main())
    assert not srv.hub.grabs
    session.control_edits.replace(start)
    assert session.wait_applied(30)


def test_the_old_route_xr_ws_is_the_same_views_socket(srv, session):
    """A headset paired before the route was named /view/ws connects to /xr/ws: it gets the topology and frames and
    shares the grabs with the views on /view/ws."""
    async def main():
        async with aiohttp.ClientSession() as cs:
            a = await connect(cs, srv)
            old = Client(await cs.ws_connect(srv.base + "/xr/ws"))
            await old.until(lambda m: isinstance(m, dict) and "positions" in m)
            assert old.topology["n_vertices"] == a.topology["n_vertices"] == 602
            await a.send({"type": "grab", "index": 5})
            m = await old.until(lambda m: grabs_are(m, (5, session.control_ids[5], False)))
            err = await old.error_for({"type": "grab", "index": 5})
            assert f"control 5 is held by {m['grabs'][0]['holder']}" in err["message"]
            await a.send({"type": "release", "index": 5})
            await old.until(lambda m: isinstance(m, dict) and m.get("type") == "grabs" and m["grabs"] == [])
            await a.ws.close()
            await old.ws.close()

    run(main())
    assert not srv.hub.grabs


def test_train_pause_reset_intents(srv, session):
    async def main():
        async with aiohttp.ClientSession() as cs:
            c = await connect(cs, srv)
            await c.send({"type": "train"})
            await c.until(lambda m: isinstance(m, dict) and "running" in m and m["iteration"] > 0)
            await c.send({"type": "pause"})
            await c.until(lambda m: isinstance(m, dict) and "paused" in m and m["paused"])
            await c.send({"type": "reset"})
            f = await c.until(lambda m: isinstance(m, dict) and "iteration" in m and m["iteration"] == 0)
            np.testing.assert_allclose(f["positions"], session.preset.weights[:, :3])
            await c.ws.close()

    run(main())
    assert session.paused


def test_a_grab_is_one_step_that_undo_and_redo_intents_take_back(srv, session):
    """Protocol: grab, several moves, release make one undo step; "undo" puts the session back exactly and the
    frames say a redo is there; "redo" brings the move back."""
    before_controls = session.controls
    before = session.frame.weights.copy()
    steps = session.history[0]

    async def main():
        async with aiohttp.ClientSession() as cs:
            c = await connect(cs, srv)
            await c.send({"type": "grab", "index": 4})
            for z in (1.0, 1.1, 1.2):
                await c.send({"type": "move", "index": 4, "position": [-0.3, 0.45, z]})
            await c.send({"type": "release", "index": 4})
            await c.until(lambda m: isinstance(m, dict) and m.get("type") == "grabs" and m["grabs"] == [])
            f = await c.until(lambda m: isinstance(m, dict) and "can_undo" in m and m["can_undo"]
                              and np.allclose(m["control_positions"][4], [-0.3, 0.45, 1.2]))
            assert not f["can_redo"]
            await c.send({"type": "undo"})
            f = await c.until(lambda m: isinstance(m, dict) and "can_redo" in m and m["can_redo"])
            np.testing.assert_allclose(f["control_positions"][:9], before_controls[:, :3])
            await c.send({"type": "redo"})
            await c.until(lambda m: isinstance(m, dict) and "can_redo" in m and not m["can_redo"]
                          and np.allclose(m["control_positions"][4], [-0.3, 0.45, 1.2]))
            await c.ws.close()

    run(main())
    assert session.history[0] == steps + 1
    assert session.undo()
    np.testing.assert_array_equal(session.frame.weights, before)
    np.testing.assert_array_equal(session.controls, before_controls)


# -- the access token ----------------------------------------------------------------------------------------
def test_token_required(session):
    token = "s3cret-token_value"
    with XRServer(session, token=token) as srv:
        async def main():
            async with aiohttp.ClientSession() as cs:
                for url in ("/xr/", "/xr", "/xr/emulator.html", "/xr/status", "/xr/assets/x.js"):
                    async with cs.get(srv.base + url, allow_redirects=False) as r:
                        assert r.status == 403, url
                        assert "token" in await r.text()
                for bad in ("?token=wrong", "?token=", f"?token={token}x"):
                    async with cs.get(srv.base + "/xr/" + bad) as r:
                        assert r.status == 403, bad
                with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                    await cs.ws_connect(srv.base + "/view/ws")
                assert info.value.status == 403
                with pytest.raises(aiohttp.WSServerHandshakeError):
                    await cs.ws_connect(srv.base + "/view/ws?token=nope")
                async with cs.get(srv.base + "/xr/status", headers={"Authorization": f"Bearer {token}"}) as r:
                    assert r.status == 200
            # with the token in the URL: the page, a cookie for the rest, and the websocket
            async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as cs:
                async with cs.get(srv.base + f"/xr/?token={token}") as r:
                    assert r.status == 200 and "somwidget" in await r.text()
                async with cs.get(srv.base + "/xr/status") as r:  # the cookie alone is enough now
                    assert r.status == 200
                c = await connect(cs, srv)
                assert c.topology["n_vertices"] == 602
                await c.ws.close()
            async with aiohttp.ClientSession() as cs:
                c = await connect(cs, srv, params={"token": token})
                await c.ws.close()

        run(main())


def test_new_preset_sends_a_new_topology():
    """When the desktop loads another preset, every XR client gets the new topology before its frames."""
    from somwidget.frontend.model import Session

    with Session("car", device="cpu", paused=True) as session, XRServer(session) as srv:
        async def main():
            async with aiohttp.ClientSession() as cs:
                c = await connect(cs, srv)
                g = c.topology["generation"]
                await asyncio.get_running_loop().run_in_executor(None, session.load_preset, "lattice")
                f = await c.until(lambda m: isinstance(m, dict) and "positions" in m and m["generation"] > g)
                assert c.topology["generation"] == f["generation"] and c.topology["preset"] == "lattice"
                assert f["n"] == c.topology["n_vertices"] == 512 and c.topology["display"] == "points"
                await c.ws.close()

        run(main())


def test_a_clay_past_the_streaming_limit_streams_a_decimated_mesh_on_its_trained_nodes():
    """62,500 nodes (a 250 x 250 grid) are more than a frame streams whole: the display mesh keeps at most
    DECIMATED_NODES nodes, every triangle and segment joins kept nodes, it still covers the grid, and a frame carries
    exactly the trained positions of those nodes."""
    from types import SimpleNamespace

    n = 250
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    idx = ii * n + jj
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    pts = np.stack([ii.ravel() / (n - 1), jj.ravel() / (n - 1), 0.1 * np.sin(ii.ravel() / 20.0)], 1)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    edges = np.unique(np.sort(np.concatenate([quads[:, [0, 1]], quads[:, [1, 2]]]), axis=1), axis=0)
    nodes, t, e = wire_display.decimate_display(pts, tris, edges)
    assert 0.25 * wire_display.DECIMATED_NODES < len(nodes) <= wire_display.DECIMATED_NODES < len(pts)
    assert len(np.unique(nodes)) == len(nodes) and nodes.max() < len(pts)
    assert t.max() < len(nodes) and e.max() < len(nodes) and len(t) > len(nodes)  # a surface, not a cloud
    assert (t[:, 0] != t[:, 1]).all() and (t[:, 1] != t[:, 2]).all() and (t[:, 0] != t[:, 2]).all()
    kept = pts[nodes]
    assert np.allclose(kept.min(axis=0)[:2], 0, atol=0.03) and np.allclose(kept.max(axis=0)[:2], 1, atol=0.03)
    # the display mesh's triangles are small: no face spans more than a few grid cells of the decimated grid
    side = np.linalg.norm(kept[t[:, 0]] - kept[t[:, 1]], axis=1)
    assert side.max() < 0.05
    # a frame of that session streams those nodes' trained positions
    class StandIn(SimpleNamespace):  # a preset's stand-in: display.py keeps its geometry by a weak reference
        pass

    session = SimpleNamespace(preset=StandIn(display="surface", weights=pts.astype(np.float32),
                                             layout=SimpleNamespace(position=(0, 1, 2)),
                                             topology=SimpleNamespace(n_vertices=len(pts), edges=edges,
                                                                      faces=quads.tolist())))
    geo = wire_display.display_of(session)
    assert geo["n_vertices"] == len(geo["nodes"]) <= wire_display.DECIMATED_NODES
    trained = pts + 0.01
    frame = SimpleNamespace(positions=trained.astype(np.float32), colours=np.zeros_like(trained, np.float32))
    pos, col = wire_display.display_arrays(frame, session)
    np.testing.assert_array_equal(pos, trained.astype(np.float32)[geo["nodes"]])


def test_a_control_removed_elsewhere_does_not_redirect_a_held_drag(srv, session):
    """The attack of issue 17 (item 4): a headset holds control 3 (by its id, as the clients send it); the desktop
    removes control 0. The headset's next move moves the same control (now at index 2), never the one that slid
    into index 3; the held control itself is refused to the desktop; when the controls are replaced, the grab ends
    with a message."""
    async def main():
        async with aiohttp.ClientSession() as cs:
            a = await connect(cs, srv)
            ids = list(session.control_ids)
            held_id = ids[3]
            await a.send({"type": "grab", "id": held_id})
            await a.until(lambda m: isinstance(m, dict) and m.get("type") == "grabs" and m["grabs"]
                          and m["grabs"][0]["id"] == held_id)
            before = session.controls.copy()
            session.remove_control(0)  # the desktop, meanwhile
            session.wait_idle(30)
            await a.until(lambda m: m.get("type") == "controls" and m["ids"].index(held_id) == 2)
            target = [-1.5, 0.4, 0.6]
            await a.send({"type": "move", "id": held_id, "position": target})
            await a.until(lambda m: "control_positions" in m and np.allclose(m["control_positions"][2], target))
            after = session.controls
            np.testing.assert_allclose(after[2, :3], target, atol=1e-6)  # the held control, at its new place
            np.testing.assert_array_equal(after[3], before[4])  # the one that slid into index 3: untouched
            # an old client naming the place instead of the id is refused, not redirected
            err = await a.error_for({"type": "move", "index": 3, "position": [0, 0, 0]})
            assert "not held by this client" in err["message"]
            with pytest.raises(ValueError, match="control 2 is held by desktop"):
                session.remove_control(2)  # the held control itself: refused to every other hand
            session.control_edits.replace(np.delete(session.controls, 2, axis=0))  # the controls replaced: it goes
            m = await a.until(lambda m: m.get("type") == "error" and "was removed while you held" in m["message"])
            assert str(held_id) in m["message"]
            assert {"type": "grabs", "grabs": []} in a.messages  # and every client saw the grab end

    run(main())
