"""A room that lives on a worker process, in Chromium through the front's relay (studio/relay.py): the page draws the
room's frames, a drag with the mouse moves the room's control and is one step of its history; the worker is then
killed (SIGKILL) mid-session: the page says nothing is lost, connects again by itself (the relay closed its socket
with 1012) to the room back on the other worker, shows the drag that was done, and a second drag works there.

Needs /usr/bin/chromium, Python Playwright and the built client (npm run build).
"""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
from helpers import skip_unless_browser_and_client, wait_for
from room_page import drag

import somwidget
from somwidget.frontend.studio.limits import StudioLimits
from somwidget.frontend.studio.serve import StudioServer

pytestmark = pytest.mark.browser

skip_unless_browser_and_client()


def test_a_room_on_a_worker_is_dragged_by_mouse_and_comes_back_to_the_page_after_its_worker_dies(tmp_path, browser):
    with StudioServer(tmp_path / "rooms", device="cpu", workers=2, limits=StudioLimits(park_after=0),
                      rooms=["alice"]) as studio, somwidget.join(studio.room_url("alice")) as room:
        assert room.wait_idle(180)
        k = len(room.control_positions)
        start = room.control_positions.copy()
        assert room.history == (False, False)  # a new room: nothing to undo yet
        page = browser.new_page(viewport={"width": 1000, "height": 700})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(studio.room_url("alice"))
        page.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=30000)
        assert page.inner_text("#title") == "Room alice: Car"  # the person reads which room this is

        drag(page, 3, k)  # through the relay, both ways
        wait_for(lambda: np.linalg.norm(room.control_positions[3] - start[3]) > 0.05, 30, "the drag in the room")
        assert room.wait_idle(180)
        dragged = room.control_positions[3].copy()
        wait_for(lambda: room.history == (True, False), 30, "the drag as a step of the room")
        page.wait_for_function(f"somxr.state().iteration === {room.frame['iterations']} && !somxr.state().running",
                               timeout=30000)
        shown = np.asarray(page.evaluate("somxr.controlModel(3)"), float)
        np.testing.assert_allclose(shown, dragged, atol=1e-5)  # what the page draws is the room's

        dead = studio.front.rooms["alice"].place
        wait_for(lambda: studio.front.rooms["alice"].info.get("saves", 0) > 0, 20, "the room's autosave")
        reconnects = page.evaluate("somxr.state().link.reconnects")
        os.kill(studio.pool.procs[dead].pid, signal.SIGKILL)
        wait_for(lambda: (e := studio.front.rooms["alice"]).place is not dead and e.place is not None
                 and e.info.get("live"), 20, "the room back on the other worker")
        page.wait_for_function(f"somxr.state().link.reconnects > {reconnects} && somxr.state().connected "
                               f"&& somxr.state().link.closeCode === 1012", timeout=30000)
        # the room's controls drawn again on the new connection (its topology came, then a frame)
        page.wait_for_function("somxr.state().frames > 0 && somxr.controlModel(3) !== null", timeout=30000)
        shown = np.asarray(page.evaluate("somxr.controlModel(3)"), float)
        np.testing.assert_allclose(shown, dragged, atol=1e-5)  # the completed drag came back with the room

        with somwidget.join(studio.room_url("alice")) as again:  # the notebook's own link dropped with the worker
            before = again.control_positions.copy()
            drag(page, 3, k)  # the page acts on the room in its new place
            wait_for(lambda: np.linalg.norm(again.control_positions[3] - before[3]) > 0.05, 30,
                     "the second drag in the room's new place")
        assert errors == [], errors
        page.close()
