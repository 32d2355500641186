"""One session, many hands (issue 35), with real clients: two browsers on the view's page, and a browser beside a
headset (Chromium on the XR page with WebXR emulated by npm's `iwer`, as in test_xr_browser.py). People act with
Playwright's mouse and keyboard and the emulated controller; what they see is read from the pages (`somxr`), the
session's state in Python.

- a control one person holds is refused to the other, who is told who holds it, and sees it in the holder's colour;
- every view shows who else is there (desktop, headset: a colour each) and what they hold;
- two drags at once are two undo steps, and each person's Ctrl+Z takes back their own drag first (three views: two
  browsers and a headset, two of them dragging);
- a mouse up (a trigger let go) on a settled clay runs nothing: no cycle, no frame with other positions.

Needs /usr/bin/chromium, Python Playwright and the built client (npm run build).
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import settled_session, skip_unless_browser_and_client, wait_for

pytestmark = pytest.mark.browser

VIEWPORT = {"width": 520, "height": 520}  # small (SwiftShader renders on the CPU), tall enough for the HUD

skip_unless_browser_and_client()


@pytest.fixture(scope="module")
def session():
    yield from settled_session("car")


@pytest.fixture(scope="module")
def server(session):
    from somwidget.frontend.web.standalone import XRServer

    with XRServer(session) as srv:
        yield srv


def open_page(browser, url: str):
    page = browser.new_page(viewport=VIEWPORT)
    page.errors = []
    page.on("pageerror", lambda e: page.errors.append(str(e)))
    page.goto(url)
    page.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=30000)
    return page


def me(page) -> dict:
    """This page's own hand, as the server's presence message names it."""
    page.wait_for_function("somxr.state().presence.some((h) => h.you)", timeout=10000)
    return next(h for h in page.evaluate("somxr.state().presence") if h["you"])


def shown_presence(page) -> str:
    """What the view's corner says of who is on the session (the person reads this)."""
    return page.inner_text(".somview-presence")


def rgb(colour: str) -> np.ndarray:
    return np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])


def press_on(page, index: int) -> tuple[float, float]:
    """The mouse over control `index`, or its mirrored copy where the clay hides the control (dragging either moves
    it), pressed."""
    for j in (index, index + 9):
        x, y = page.evaluate(f"somxr.controlScreen({j})")
        page.mouse.move(x, y)
        try:
            page.wait_for_function(f"somxr.state().hover.some((j) => j % 9 === {index})", timeout=3000)
        except Exception:  # hidden behind the clay: its copy
            continue
        page.mouse.down()
        return x, y
    raise AssertionError(f"neither control {index} nor its copy can be taken with the mouse")


def settled(session) -> bool:
    f = session.frame
    return f.iteration == f.iterations and not f.running


def settled_with(session, index: int, at) -> bool:
    """Settled with control `index` at `at`, both read from one frame: `session.controls` shows a move as soon as it
    is applied, while the frame before it still says settled (under load its cycles then came after the test's read)."""
    f = session.frame
    return (f.iteration == f.iterations and not f.running and f.n_controls == 9
            and np.allclose(f.controls[index][:3], at, atol=1e-4))


def test_two_browsers_refusal_presence_two_steps_and_own_undo(browser, server, session):
    a = open_page(browser, server.base + "/xr/")
    b = open_page(browser, server.base + "/xr/")
    try:
        ha, hb = me(a), me(b)
        assert ha["kind"] == hb["kind"] == "desktop" and ha["colour"] != hb["colour"]
        for page, other in ((a, hb), (b, ha)):  # each view shows the other, in its colour
            page.wait_for_function(f"document.querySelector('.somview-presence').innerText.includes('{other['name']}')",
                                   timeout=10000)
            assert "(you)" in shown_presence(page)
        start = session.controls
        steps = session.history[0]

        # A holds control 2; B sees it held in A's colour, with A's name beside it
        xa, ya = press_on(a, 2)
        wait_for(lambda: server.hub.grabs.get(2) is not None, what="A's grab")
        b.wait_for_function(f"document.querySelector('.somview-presence').innerText.includes("
                            f"'{ha['name']} \u00b7 holds 2')", timeout=10000)
        look = b.evaluate("somxr.controlLook(2)")
        assert np.abs(rgb(look["colour"]) - rgb(ha["colour"])).max() <= 2 and look["scale"] > 1.5, look
        # B tries to drag the same control: refused, told who holds it; the control stays A's
        xb, yb = press_on(b, 2)
        for s in range(1, 5):
            b.mouse.move(xb - 6 * s, yb + 4 * s)
            b.wait_for_timeout(40)
        b.mouse.up()
        b.wait_for_function(f"(somxr.state().lastError || '').includes('control 2 is held by {ha['name']}')",
                            timeout=10000)
        assert f"held by {ha['name']}" in b.inner_text("#error")  # on screen, in the panel
        np.testing.assert_array_equal(session.controls[2], start[2])

        # two drags at once: A goes on with control 2 while B drags control 1; A lets go first
        xb, yb = press_on(b, 1)
        wait_for(lambda: server.hub.grabs.get(1) is not None, what="B's grab")
        for s in range(1, 9):
            a.mouse.move(xa + 7 * s, ya - 4 * s)
            b.mouse.move(xb - 5 * s, yb + 4 * s)
            a.wait_for_timeout(30)
        a.mouse.up()
        for s in range(9, 13):
            b.mouse.move(xb - 5 * s, yb + 4 * s)
            b.wait_for_timeout(30)
        b.mouse.up()
        wait_for(lambda: not server.hub.grabs, what="both released")
        assert session.wait_idle(60)
        moved = session.controls
        assert np.linalg.norm(moved[2, :3] - start[2, :3]) > 0.2 and np.linalg.norm(moved[1, :3] - start[1, :3]) > 0.2
        assert session.history[0] == steps + 2, session.history  # two drags, two steps: no more, no fewer

        # B's Ctrl+Z takes back B's drag (the newest step, but cut by A's release), A's drag stays
        b.keyboard.press("Control+z")
        wait_for(lambda: np.array_equal(session.controls[1], start[1]), what="B's control back where it was")
        np.testing.assert_array_equal(session.controls[2], moved[2])
        # A's Ctrl+Z takes back A's own drag, though B's undo came after it
        a.keyboard.press("Control+z")
        wait_for(lambda: np.array_equal(session.controls[2], start[2]), what="A's control back where it was")
        np.testing.assert_array_equal(session.controls[1], start[1])
        assert a.errors == [] and b.errors == [], a.errors + b.errors
    finally:
        a.close()
        b.close()
    wait_for(lambda: not session.hands.present(), what="both hands gone")


def test_a_mouse_up_on_a_settled_clay_runs_nothing(browser, server, session):
    """Drag, hold still until the clay has settled, let go: the iteration counter stays at S and no frame with other
    positions comes (it used to re-run the last move: 80 cycles, the clay jumping back towards the drag's start)."""
    page = open_page(browser, server.base + "/xr/")
    frames = []
    try:
        assert session.wait_idle(60)
        x, y = press_on(page, 4)
        for s in range(1, 9):
            page.mouse.move(x + 6 * s, y - 5 * s)
            page.wait_for_timeout(30)
        held_at = np.asarray(page.evaluate("somxr.controlModel(4)"), float)[:3]  # where the drag left it
        wait_for(lambda: settled_with(session, 4, held_at), timeout=60, what="settled on the drag's last move")
        page.wait_for_function(f"somxr.state().seq >= {session.frame.seq}", timeout=10000)
        before = session.frame
        shown = np.array(page.evaluate("somxr.positions(602)")).reshape(-1, 3)
        np.testing.assert_array_equal(shown, before.positions)
        control = session.controls[4]
        session.add_listener(frames.append, replay=False)
        page.mouse.up()
        wait_for(lambda: not server.hub.grabs, what="the release")
        page.wait_for_timeout(1500)  # time for any cycle the release would run
        assert session.wait_idle(60)
        after = session.frame
        np.testing.assert_array_equal(session.controls[4], control)
        assert after.iteration == before.iteration == before.iterations
        assert all(f.iteration == before.iteration and f.step_cycles == 0 for f in frames), [
            (f.iteration, f.step_cycles) for f in frames]
        np.testing.assert_array_equal(after.positions, before.positions)
        assert all(np.array_equal(f.positions, before.positions) for f in frames)
        page.wait_for_function(f"somxr.state().seq >= {after.seq}", timeout=10000)
        assert page.evaluate("somxr.state().iteration") == before.iterations
        np.testing.assert_array_equal(np.array(page.evaluate("somxr.positions(602)")).reshape(-1, 3), shown)
        assert page.errors == []
    finally:
        session.remove_listener(frames.append)
        page.close()


# -- a browser beside a headset (iwer) ----------------------------------------------------------------------------
def enter_ar(page) -> None:
    page.wait_for_selector("#enter-ar:not([hidden])", timeout=10000)
    box = page.locator("#enter-ar").bounding_box()
    page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.wait_for_function("somxr.state().presenting && somxr.state().mode === 'immersive-ar'", timeout=15000)
    wait_frames(page, 3)


def wait_frames(page, n: int = 2) -> None:
    start = page.evaluate("somxr.state().xrFrames")
    page.wait_for_function(f"somxr.state().xrFrames >= {start + n}", timeout=15000)


RIGHT = "iwerDevice.controllers.right"


def tip(page) -> np.ndarray:
    for inp in page.evaluate("somxr.inputs()"):
        if inp["handedness"] == "right" and not inp["hand"] and inp["point"] is not None:
            return np.array(inp["point"])
    raise AssertionError("no right controller seen by the page")


def controller_to(page, world) -> None:
    """The right controller's tip at `world` (metres)."""
    for _ in range(3):
        here = np.array(page.evaluate(f"(() => {{ const p = {RIGHT}.position; return [p.x, p.y, p.z]; }})()"))
        target = np.asarray(world) - (tip(page) - here)
        page.evaluate(f"([x, y, z]) => {RIGHT}.position.set(x, y, z)", [float(v) for v in target])
        wait_frames(page, 2)


def test_two_browsers_and_a_headset(browser, server, session):
    """Three views: a desktop page, a second one, and a headset. Each lists the three; the headset's grab is refused
    to the desktop and shown in both; the second desktop drags another control meanwhile (a step of its own); the
    headset lets go on a settled clay and nothing runs."""
    desk = open_page(browser, server.base + "/xr/")
    desk2 = open_page(browser, server.base + "/xr/")
    headset = open_page(browser, server.base + "/xr/emulator.html")
    frames = []
    try:
        enter_ar(headset)
        hh, hd, hd2 = me(headset), me(desk), me(desk2)
        wait_for(lambda: me(headset)["kind"] == "headset", what="the headset to say it is one")
        hh = me(headset)
        for page in (desk, desk2):
            page.wait_for_function(f"document.querySelector('.somview-presence').innerText.includes('{hh['name']}')",
                                   timeout=10000)
            assert len(page.evaluate("somxr.state().presence")) == 3
        assert hh["name"].startswith("headset ") and len({hh["colour"], hd["colour"], hd2["colour"]}) == 3
        headset.wait_for_function(f"somxr.state().menuStatus.includes('with {hd['name']}')", timeout=10000)
        assert hd2["name"] in headset.evaluate("somxr.state().menuStatus")
        assert session.wait_idle(60)
        start, steps = session.controls, session.history[0]

        # the headset's trigger holds control 2: the desktop sees it held in the headset's colour, and is refused it
        target = np.array(headset.evaluate("somxr.controlWorld(2)"))
        controller_to(headset, target)
        headset.wait_for_function("somxr.state().hover.includes(2)", timeout=5000)
        headset.evaluate(f"{RIGHT}.updateButtonValue('trigger', 1)")
        wait_for(lambda: server.hub.grabs.get(2) is not None, what="the headset's grab")
        desk.wait_for_function(f"document.querySelector('.somview-presence').innerText.includes("
                               f"'{hh['name']} \u00b7 holds 2')", timeout=10000)
        assert np.abs(rgb(desk.evaluate("somxr.controlLook(2)")["colour"]) - rgb(hh["colour"])).max() <= 2
        x, y = press_on(desk, 2)
        desk.mouse.move(x + 10, y + 10)
        desk.mouse.up()
        desk.wait_for_function(f"(somxr.state().lastError || '').includes('control 2 is held by {hh['name']}')",
                               timeout=10000)
        desk2.wait_for_function(f"document.querySelector('.somview-presence').innerText.includes("
                                f"'{hh['name']} \u00b7 holds 2')", timeout=10000)
        x, y = press_on(desk2, 5)  # the second desktop drags control 5 meanwhile
        for s in range(1, 7):  # the headset moves control 2, the second desktop control 5
            controller_to(headset, target + np.array([0.01, 0.008, 0.0]) * s)
            desk2.mouse.move(x - 6 * s, y + 4 * s)
        desk2.mouse.up()
        # the second desktop's release applied (its moves before it, in order), so no move of its is still on its way
        wait_for(lambda: set(server.hub.grabs) == {2}, timeout=30, what="the second desktop's release")
        held_at = np.asarray(headset.evaluate("somxr.controlModel(2)"), float)[:3]  # where the headset has it
        wait_for(lambda: settled_with(session, 2, held_at), timeout=60, what="settled, the trigger held")
        before = session.frame
        session.add_listener(frames.append, replay=False)
        headset.evaluate(f"{RIGHT}.updateButtonValue('trigger', 0)")  # let go: nothing runs
        wait_for(lambda: not server.hub.grabs, what="the headset's release")
        headset.wait_for_timeout(1500)
        assert session.wait_idle(60)
        assert session.frame.iteration == before.iterations and all(f.step_cycles == 0 for f in frames)
        np.testing.assert_array_equal(session.frame.positions, before.positions)
        assert np.linalg.norm(session.controls[2, :3] - start[2, :3]) > 0.05
        assert np.linalg.norm(session.controls[5, :3] - start[5, :3]) > 0.1
        assert session.history[0] == steps + 2  # the two drags, a step each
        desk.wait_for_function("!document.querySelector('.somview-presence').innerText.includes('holds')",
                               timeout=10000)
        assert desk.errors == [] and desk2.errors == [] and headset.errors == []
    finally:
        session.remove_listener(frames.append)
        for page in (desk, desk2, headset):
            page.close()
