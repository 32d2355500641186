"""A studio's routes and who may use them (studio/access.py, routes.py), against a real studio on 127.0.0.1 with real
rooms: rooms are private (a room's link opens that room alone), the wall, the list and the other rooms need the
teacher's token, the class token makes new rooms only, the LAN guard (Host, Origin; HTTPS beyond loopback) holds on
every route, and one room's client never reads or changes another room, however it tries."""

from __future__ import annotations

import asyncio
import http.client
import json
import urllib.parse

import aiohttp
import numpy as np
import pytest
from helpers import insecure_context, request

import somwidget
from somwidget.frontend.studio.limits import StudioLimits
from somwidget.frontend.studio.serve import StudioServer
from somwidget.frontend.transport.frames import decode_frame


@pytest.fixture(scope="module")
def studio(tmp_path_factory):
    with StudioServer(tmp_path_factory.mktemp("rooms"), device="cpu", rooms=["alice", "bob"],
                      limits=StudioLimits(park_after=0)) as s:
        for name in ("alice", "bob"):
            assert s.front.places[0].rooms.get(name).session.wait_idle(120)
        yield s


def token_of(studio, name):
    return studio.front.rooms[name].token


def get(studio, path, token=None, headers=None):
    if token is not None:
        path += ("&" if "?" in path else "?") + "token=" + urllib.parse.quote(token)
    return request(studio.base + path, headers)


def session_of(studio, name):
    return studio.front.places[0].rooms.get(name).session


ROOM_PATHS = ["/r/{n}/", "/r/{n}/watch/", "/r/{n}", "/r/{n}/emulator.html"]


def test_a_room_link_opens_that_room_alone(studio):
    alice = token_of(studio, "alice")
    for path in ROOM_PATHS:
        status, body = get(studio, path.format(n="alice"), alice)
        assert status == 200, (path, status, body[:200])
    status, body = get(studio, "/r/alice/", alice)
    assert b"<title>somwidget: alice</title>" in body
    for path in [*ROOM_PATHS, "/r/{n}/assets/x.js"]:
        status, body = get(studio, path.format(n="bob"), alice)
        assert status == 403, (path, status)
        assert b"needs its link's token" in body
    for path in ("/wall", "/api/rooms", "/", "/wall/wall.js", "/r/carol/"):
        assert get(studio, path, alice)[0] == 403, path
    assert "carol" not in studio.front.rooms  # a room's token makes no room


def test_no_token_no_entry(studio):
    for path in ["/", "/wall", "/wall/wall.js", "/api/rooms", *[p.format(n="alice") for p in ROOM_PATHS]]:
        assert get(studio, path)[0] == 403, path
    assert get(studio, "/r/alice/", "not-the-token")[0] == 403


def test_the_teacher_sees_everything(studio):
    teacher = studio.access.teacher
    status, body = get(studio, "/api/rooms", teacher)
    assert status == 200
    rooms = {r["name"]: r for r in json.loads(body)["rooms"]}
    assert set(rooms) >= {"alice", "bob"}
    assert rooms["alice"]["link"] == f"/r/alice/?token={token_of(studio, 'alice')}"
    assert {"people", "last_change", "live", "place"} <= set(rooms["alice"])
    for path in ("/wall", "/wall/wall.js", "/wall/wall.css", "/r/bob/", "/r/bob/watch/", "/"):
        assert get(studio, path, teacher)[0] == 200, path


def test_the_class_token_makes_rooms_and_opens_none(studio):
    join = studio.access.join
    assert get(studio, "/", join)[0] == 200
    assert get(studio, "/api/rooms", join)[0] == 403
    assert get(studio, "/wall", join)[0] == 403
    status, body = get(studio, "/r/alice/", join)  # taken: no way in
    assert status == 403 and b"exists already" in body
    # a name nobody has: the room is made and the person sent on to its own link
    req = urllib.request.Request(f"{studio.base}/r/dora/?token={join}")
    opener = urllib.request.build_opener(NoRedirect)
    with pytest.raises(urllib.error.HTTPError) as err:
        opener.open(req, timeout=60)
    assert err.value.code == 302
    assert err.value.headers["Location"] == f"/r/dora/?token={token_of(studio, 'dora')}"
    status, body = post(studio, "/api/rooms", join, {"name": "eve", "preset": "sphere"})
    assert status == 200 and body["link"] == f"/r/eve/?token={token_of(studio, 'eve')}"
    status, body = post(studio, "/api/rooms", join, {"name": "eve"})
    assert status == 400 and "exists already" in body["error"]
    status, body = post(studio, "/api/rooms", join, {"name": "../x"})
    assert status == 400 and "room name" in body["error"]


class NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *args, **kwargs):
        return None


def post(studio, path, token, body):
    req = urllib.request.Request(f"{studio.base}{path}?token={token}", data=json.dumps(body).encode(),
                                 headers={"Content-Type": "application/json"}, method="POST")
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"{}")


def test_a_cookie_of_one_room_opens_no_other(studio):
    alice = token_of(studio, "alice")
    req = urllib.request.Request(f"{studio.base}/r/alice/?token={alice}")
    with urllib.request.urlopen(req, timeout=60) as r:
        cookie = r.headers["Set-Cookie"]
    assert f"somwidget_room_{studio.port}_alice={alice}" in cookie and "Path=/r/alice/" in cookie
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    pair = cookie.split(";")[0]
    assert get(studio, "/r/alice/assets/none.js", headers={"Cookie": pair})[0] == 404  # let in; no such file
    forged = pair.replace("_alice=", "_bob=")  # alice's token under bob's cookie name
    assert get(studio, "/r/bob/", headers={"Cookie": forged})[0] == 403
    assert get(studio, "/wall", headers={"Cookie": pair})[0] == 403


@pytest.mark.parametrize("path", ["/r/..%2Fbob/", "/r/%2e%2e/", "/r/ALICE%00/", "/r/a%20b/"])
def test_odd_room_names_reach_nothing(studio, path):
    status, _ = get(studio, path, studio.access.teacher)
    assert status in (403, 404), status
    assert set(studio.front.rooms) <= {"alice", "bob", "dora", "eve"}


def test_the_lan_guard_holds_on_every_route(studio):
    teacher = studio.access.teacher
    for path in ("/wall", "/r/alice/", "/api/rooms"):
        status, body = get(studio, path, teacher, headers={"Host": f"evil.example:{studio.port}"})
        assert status == 403 and b"this machine only" in body, path

    async def attempt(headers):
        async with aiohttp.ClientSession() as cs:
            try:
                async with cs.ws_connect(f"{studio.base}/r/alice/view/ws?token={token_of(studio, 'alice')}",
                                         headers=headers):
                    return 101
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    assert asyncio.run(attempt({"Origin": "https://evil.example"})) == 403
    assert asyncio.run(attempt({"Origin": f"http://127.0.0.1:{studio.port}"})) == 101


async def _first_frame(ws) -> dict:
    topology = None
    while True:
        msg = await ws.receive(timeout=60)
        if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data)["type"] == "topology":
            topology = json.loads(msg.data)
        elif msg.type == aiohttp.WSMsgType.BINARY and topology is not None:
            return topology, decode_frame(msg.data)


async def _until_pong(ws, t) -> list[dict]:
    seen = []
    while True:
        msg = await ws.receive(timeout=60)
        if msg.type == aiohttp.WSMsgType.TEXT:
            m = json.loads(msg.data)
            seen.append(m)
            if m == {"type": "pong", "t": t}:
                return seen


def test_a_room_client_cannot_touch_another_room(studio):
    """Alice's websocket names bob's controls (by bob's ids, by index), sends bob's name and token in intents, and
    tries bob's websocket with alice's token: bob's room never changes, and alice's frames are alice's clay only."""
    alice, bob = session_of(studio, "alice"), session_of(studio, "bob")
    bob_controls, bob_positions, bob_steps = bob.controls.copy(), bob.frame.positions.copy(), bob.history[0]
    bob_ids = list(bob.control_ids)

    async def go():
        url = f"{studio.base}/r/alice/view/ws?token={token_of(studio, 'alice')}"
        async with aiohttp.ClientSession() as cs, cs.ws_connect(url) as ws:
            topology, frame = await _first_frame(ws)
            assert topology["n_nodes"] == alice.preset.n_vertices
            np.testing.assert_allclose(frame["control_positions"][: frame["k"]], alice.controls[:, :3], atol=1e-6)
            attempts = [{"type": "grab", "id": i} for i in bob_ids if i not in alice.control_ids]
            attempts += [{"type": "remove", "id": 10_000}, {"type": "set", "name": "smoothing", "value": 0.5,
                                                             "room": "bob"},
                         {"type": "move", "id": bob_ids[0], "position": [9, 9, 9], "token": token_of(studio, "bob")},
                         {"type": "undo"}, {"type": "reset"}]
            for attempt in attempts:
                await ws.send_str(json.dumps(attempt))
            await ws.send_str(json.dumps({"type": "ping", "t": 7}))
            return await _until_pong(ws, 7)

    seen = asyncio.run(go())
    errors = [m["message"] for m in seen if m["type"] == "error"]
    assert any("unknown field(s) 'room'" in e for e in errors) and any("unknown field(s) 'token'" in e for e in errors)

    async def bob_with_alices_token():
        async with aiohttp.ClientSession() as cs:
            with pytest.raises(aiohttp.WSServerHandshakeError) as err:
                await cs.ws_connect(f"{studio.base}/r/bob/view/ws?token={token_of(studio, 'alice')}")
            return err.value.status

    assert asyncio.run(bob_with_alices_token()) == 403
    assert alice.wait_idle(120) and bob.wait_idle(120)
    np.testing.assert_array_equal(bob.controls, bob_controls)
    np.testing.assert_array_equal(bob.frame.positions, bob_positions)
    assert bob.history[0] == bob_steps and bob.parameters["smoothing"] == 0.0


def test_a_watching_view_changes_nothing(studio):
    alice = session_of(studio, "alice")
    assert alice.wait_idle(120)
    before, steps = alice.controls.copy(), alice.history

    async def go():
        url = f"{studio.base}/r/alice/watch/view/ws?token={studio.access.teacher}"
        async with aiohttp.ClientSession() as cs, cs.ws_connect(url) as ws:
            topology, _ = await _first_frame(ws)
            cid = topology["control_ids"][0]
            for m in ({"type": "grab", "id": cid}, {"type": "move", "id": cid, "position": [1, 1, 1]},
                      {"type": "undo"}, {"type": "add", "position": [0, 0, 0]}):
                await ws.send_str(json.dumps(m))
            await ws.send_str(json.dumps({"type": "ping", "t": 3}))
            return await _until_pong(ws, 3)

    seen = asyncio.run(go())
    refused = [m for m in seen if m["type"] == "error"]
    assert len(refused) == 4 and all("only watches" in m["message"] for m in refused)
    assert alice.wait_idle(60)
    np.testing.assert_array_equal(alice.controls, before)
    assert alice.history == steps


def test_https_beyond_loopback(tmp_path):
    from somwidget.frontend.web import lan

    cfg = lan.prepare_lan("127.0.0.1", directory=tmp_path / "cert")
    # the room on a worker process: its websocket goes through the front's relay, over TLS to the browser
    with StudioServer(tmp_path / "rooms", device="cpu", workers=1, lan_config=cfg, rooms=["alice"]) as s:
        assert s.base.startswith("https://")
        ctx = insecure_context()
        with urllib.request.urlopen(s.room_url("alice"), timeout=60, context=ctx) as r:
            assert r.status == 200
        assert [p.label for p in s.front.places] == ["CPU worker 0"]
        with somwidget.join(s.room_url("alice"), verify=False) as room:
            to = room.control_positions[0] + np.float32([0.0, 0.0, 0.1])
            room.move_control(0, to)
            np.testing.assert_allclose(room.control_positions[0], to, atol=1e-6)
            assert room.wait_idle(60)  # the frames came back through the relay
            assert room.frame["iteration"] == room.frame["iterations"]
        status, _ = request(s.base + "/r/alice/")
        assert status == 403
        with pytest.raises((OSError, http.client.HTTPException)):  # plain HTTP to the TLS port: no answer read
            urllib.request.urlopen(s.room_url("alice").replace("https://", "http://"), timeout=10)
    with pytest.raises(ValueError, match="reachable from other machines"):
        StudioServer(tmp_path / "rooms", host="0.0.0.0")
