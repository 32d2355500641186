"""The wall in Chromium (studio/static/wall.js) against a real studio on 127.0.0.1: three rooms modelled by three
designers (each a notebook's `somwidget.join`, a hand of its own room) appear on the wall with their names and who is
in them, and each thumbnail follows its room's changes (its pixels change when that room's clay does, the others'
stay). The teacher then clicks a thumbnail: the room opens to watch, shown read-only, where a drag with the mouse
turns the view and moves nothing; "Take part" opens it to act, where the same drag moves the room's control, and the
wall follows.

Needs /usr/bin/chromium, Python Playwright and the built client (npm run build).
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import skip_unless_browser_and_client, wait_for
from room_page import drag

import somwidget
from somwidget.frontend.studio.limits import StudioLimits
from somwidget.frontend.studio.serve import StudioServer

pytestmark = pytest.mark.browser

skip_unless_browser_and_client()

ROOMS = {"alice": "car", "bob": "sphere", "carol": "torus"}
#: What the wall's person sees of a room: a digest of its thumbnail's pixels.
PIXELS = """(name) => {
  const canvas = document.querySelector(`section.room[data-name="${name}"] canvas`);
  const data = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
  let h = 2166136261, ink = 0;
  for (let i = 0; i < data.length; i += 1) { h = Math.imul(h ^ data[i], 16777619) >>> 0; }
  for (let i = 3; i < data.length; i += 4) { if (data[i] > 0) ink += 1; }
  return [h, ink];
}"""


@pytest.fixture(scope="module")
def studio(tmp_path_factory):
    with StudioServer(tmp_path_factory.mktemp("rooms"), device="cpu", limits=StudioLimits(park_after=0)) as s:
        for name, preset in ROOMS.items():
            s.call(s.front.create(name, preset))
        yield s


def session_of(studio, name):
    return studio.front.places[0].rooms.get(name).session


def settle(studio) -> None:
    for name in ROOMS:
        assert session_of(studio, name).wait_idle(180), f"room {name} did not settle"


@pytest.fixture(scope="module")
def designers(studio):
    joined = {name: somwidget.join(studio.room_url(name)) for name in ROOMS}
    yield joined
    for room in joined.values():
        room.close()


def room_state(page, name) -> dict:
    """Room `name` as the wall shows it ({} while the wall has not listed it yet: a room just made)."""
    return next((r for r in page.evaluate("somwall.state().rooms") if r["name"] == name), {})


def caption(page, name) -> str:
    return page.inner_text(f'section.room[data-name="{name}"] .caption')


def wait_drawn_at(page, studio, name, timeout=20.0):
    """Until the wall drew room `name`'s latest frame; its pixels then."""
    seq = session_of(studio, name).frame.seq
    wait_for(lambda: room_state(page, name).get("seq", -1) >= seq, timeout, f"the wall to draw {name}'s frame {seq}")
    page.wait_for_timeout(50)
    return page.evaluate(PIXELS, name)


def test_three_rooms_on_the_wall_follow_their_designers(studio, designers, browser):
    settle(studio)
    page = browser.new_page(viewport={"width": 1100, "height": 700})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(studio.wall_url)
    page.wait_for_function("somwall.state().rooms.length === 3 && somwall.state().rooms.every((r) => r.drawn > 0)",
                           timeout=30000)
    assert page.inner_text("#summary") == "3 rooms, 3 people"
    for name in ROOMS:  # its name and its designer, as the person reads them
        text = caption(page, name)
        assert name in text and "notebook 1" in text, text
    shown = {name: wait_drawn_at(page, studio, name) for name in ROOMS}
    assert all(ink > 2000 for _, ink in shown.values()), shown  # a clay drawn in each, not an empty canvas
    assert len({h for h, _ in shown.values()}) == 3

    for name, room in designers.items():  # one designer at a time changes their clay
        before = {n: wait_drawn_at(page, studio, n) for n in ROOMS}
        to = room.control_positions[0] + np.float32([0.0, 0.0, 0.25])
        room.move_control(0, to)
        assert room.wait_idle(180)
        settle(studio)
        after = {n: wait_drawn_at(page, studio, n) for n in ROOMS}
        assert after[name][0] != before[name][0], f"{name}'s thumbnail did not follow its change"
        for other in ROOMS:
            if other != name:
                assert after[other] == before[other], f"{other}'s thumbnail changed with {name}'s room"
        page.wait_for_function(f"""document.querySelector('section.room[data-name="{name}"] .state')
                                   .textContent.includes('changed just now')""", timeout=10000)
    assert errors == [], errors
    page.close()


def test_the_teacher_watches_a_room_then_takes_part(studio, designers, browser):
    settle(studio)
    context = browser.new_context(viewport={"width": 900, "height": 640})
    wall = context.new_page()
    wall.goto(studio.wall_url)
    wall.wait_for_function("somwall.state().rooms.length === 3 && somwall.state().rooms.every((r) => r.drawn > 0)",
                           timeout=30000)
    alice = session_of(studio, "alice")
    k = alice.n_controls
    before, steps = alice.controls.copy(), alice.history[0]

    with context.expect_page() as opened:  # a click on the thumbnail: the room, to watch
        wall.click('section.room[data-name="alice"] canvas')
    watch = opened.value
    watch.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=30000)
    assert watch.title() == "somwidget: alice (watching)"
    assert watch.inner_text("#title") == "Room alice, watching only: Car"  # said on the page, not only in its tab
    assert watch.evaluate("somxr.state().watching") and watch.locator("#reset").is_disabled()  # shown read-only
    x, y = watch.evaluate("somxr.controlScreen(3)")  # a drag from the control turns the view, and sends nothing
    watch.mouse.move(x, y)
    watch.mouse.down()
    for s in range(1, 10):
        watch.mouse.move(x + 8 * s, y - 5 * s)
        watch.wait_for_timeout(40)
    watch.mouse.up()
    watch.wait_for_timeout(300)
    assert watch.evaluate("somxr.state().errors") == [] and watch.evaluate("somxr.state().held") == []
    assert alice.wait_idle(60)
    np.testing.assert_array_equal(alice.controls, before)
    wait_for(lambda: room_state(wall, "alice")["people"] == ["notebook 1"], 10, "the watcher not listed as a designer")
    watch.close()

    pixels = wait_drawn_at(wall, studio, "alice")
    with context.expect_page() as opened:  # "Take part": the teacher's cookie lets them act
        wall.click('section.room[data-name="alice"] a.part')
    part = opened.value
    part.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=30000)
    assert part.title() == "somwidget: alice"
    drag(part, 3, k)
    wait_for(lambda: alice.history[0] == steps + 1, 30, "the teacher's drag as a step of alice's room")
    assert np.linalg.norm(alice.controls[3, :3] - before[3, :3]) > 0.05
    wall.wait_for_function("""document.querySelector('section.room[data-name="alice"] .people').innerText
                              .includes('desktop')""", timeout=10000)
    assert alice.wait_idle(180)
    assert wait_drawn_at(wall, studio, "alice")[0] != pixels  # the wall follows the teacher's change too
    part.close()
    context.close()


def test_the_lobby_checks_a_name_as_it_is_typed_and_a_refusal_goes_when_the_name_changes(studio, browser):
    page = browser.new_page(viewport={"width": 800, "height": 600})
    console = []
    page.on("console", lambda m: console.append(m.text) if m.type == "error" else None)
    page.goto(studio.lobby_url)
    name = page.locator("#name")
    name.click()
    page.keyboard.type("my room")  # a space: the browser's own check says no before anything is sent
    assert page.evaluate("document.getElementById('name').validity.patternMismatch")
    name.fill("")
    page.keyboard.type("alice")  # taken
    assert not page.evaluate("document.getElementById('name').validity.patternMismatch")
    page.click("button[type=submit]")
    page.wait_for_function("document.getElementById('error').textContent.includes('exists already')", timeout=10000)
    name.click()
    page.keyboard.type("2")  # another name: the refusal of the last one goes
    assert page.inner_text("#error") == ""
    # no "not a valid regular expression" for the name's pattern (the refusal's own 400 is logged as a failed load)
    assert [m for m in console if "Failed to load resource" not in m] == [], console
    page.close()


def test_a_student_who_gives_a_name_in_the_lobby_is_named_on_the_wall_and_to_the_others(studio, browser):
    context = browser.new_context(viewport={"width": 900, "height": 640})
    lobby = context.new_page()
    lobby.goto(studio.lobby_url)
    lobby.click("#name")
    lobby.keyboard.type("dave")
    lobby.click("#who")
    lobby.keyboard.type("Dave  Li")
    lobby.click("button[type=submit]")
    lobby.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=60000)
    wall = context.new_page()
    wall.goto(studio.wall_url)
    wall.wait_for_function("""document.querySelector('section.room[data-name="dave"] .people')?.innerText
                              .includes('Dave Li')""", timeout=30000)  # one space: as a name is shown
    other = context.new_page()  # someone else on dave's room sees him by name
    other.goto(studio.room_url("dave"))
    other.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=30000)
    other.wait_for_function("document.querySelector('.somview-presence')?.innerText.includes('Dave Li')",
                            timeout=10000)
    assert "desktop" in other.inner_text(".somview-presence")  # the one who gave no name keeps the view's kind
    context.close()


#: How much of a room's thumbnail is drawn on, and how much of its border (a clay cut by the canvas's edge).
EXTENT = """(name) => {
  const canvas = document.querySelector(`section.room[data-name="${name}"] canvas`);
  const { width: w, height: h } = canvas;
  const data = canvas.getContext('2d').getImageData(0, 0, w, h).data;
  let ink = 0, edge = 0;
  for (let y = 0; y < h; y += 1) {
    for (let x = 0; x < w; x += 1) {
      if (data[4 * (y * w + x) + 3] === 0) continue;
      ink += 1;
      if (x < 2 || y < 2 || x >= w - 2 || y >= h - 2) edge += 1;
    }
  }
  return [ink / (w * h), edge];
}"""


def test_a_room_made_while_the_wall_is_open_is_framed_whole_once_it_has_trained(studio, browser):
    """Its first thumbnail is its clay before training: the wall frames the room anew as the clay outgrows that, so the
    person sees the whole trained clay, not a close-up of it (as a freshly loaded wall shows it)."""
    settle(studio)
    page = browser.new_page(viewport={"width": 1100, "height": 700})
    page.goto(studio.wall_url)
    page.wait_for_function("somwall.state().rooms.length >= 3", timeout=30000)
    studio.call(studio.front.create("dora", "car"))
    assert session_of(studio, "dora").wait_idle(180)
    wait_drawn_at(page, studio, "dora")
    share, edge = page.evaluate(EXTENT, "dora")
    fresh = browser.new_page(viewport={"width": 1100, "height": 700})
    fresh.goto(studio.wall_url)
    fresh.wait_for_function("somwall.state().rooms.some((r) => r.name === 'dora' && r.drawn > 0)", timeout=30000)
    wait_drawn_at(fresh, studio, "dora")
    fresh_share, _ = fresh.evaluate(EXTENT, "dora")
    assert edge == 0 and share < 0.6, (share, edge)  # the whole clay inside its thumbnail
    assert abs(share - fresh_share) < 0.25 * fresh_share, (share, fresh_share)  # framed as a fresh wall frames it
    page.close()
    fresh.close()
