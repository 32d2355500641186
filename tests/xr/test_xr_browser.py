"""The WebXR page in a real browser: Debian's Chromium driven by Playwright, on an emulated Meta Quest 3.

The emulator is npm's `iwer` (2.5.0), bundled by the client's own build into /xr/emulator.html (never from a CDN);
the page installs it over Chromium's navigator.xr (`installRuntime({forceInstall: true})`) before the app starts.

Interaction tests act as the person does: Playwright's mouse clicks "Enter AR" and drags controls on the desktop
preview; the emulated controllers and hands are moved, their triggers pulled and their fingers pinched through the
iwer device. What the page shows is read through its read-only `window.somxr` views; the session's state is read in
Python. Nothing here sends an intent itself (test_xr_protocol.py does that, to show the protocol).

The server is the XR route on a small aiohttp server (XRServer) around a real Session; test_xr_serve.py runs the
same page against `somwidget serve`. Needs /usr/bin/chromium, Python Playwright and the built client (npm run build).
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from helpers import CHROMIUM, wait_for

from somwidget.frontend.client import DIST

pytestmark = pytest.mark.browser

VIEWPORT = {"width": 480, "height": 360}  # small: SwiftShader renders on the CPU

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)
if not (DIST / "emulator.html").is_file():  # pragma: no cover
    pytest.skip("the WebXR client is not built (npm ci && npm run build in somwidget/frontend/client)",
                allow_module_level=True)


@pytest.fixture(scope="module")
def session():
    from somwidget.frontend.model import Session

    s = Session("car", device="cpu")
    assert s.wait_idle(120), "the session did not converge"
    yield s
    s.close()


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


def enter_ar(page) -> None:
    """Click "Enter AR" with the mouse, as a person would, and wait for the immersive session."""
    page.wait_for_selector("#enter-ar:not([hidden])", timeout=10000)
    box = page.locator("#enter-ar").bounding_box()
    page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.wait_for_function("somxr.state().presenting && somxr.state().mode === 'immersive-ar'", timeout=15000)
    wait_frames(page, 3)


@pytest.fixture
def ar_page(browser, server):
    page = open_page(browser, server.base + "/xr/emulator.html")
    enter_ar(page)
    yield page
    assert not page.errors, page.errors
    page.close()


def wait_frames(page, n: int = 2, timeout: float = 15000) -> None:
    """Let the emulated headset run `n` more XR frames."""
    start = page.evaluate("somxr.state().xrFrames")
    page.wait_for_function(f"somxr.state().xrFrames >= {start + n}", timeout=timeout)


def device_input(page, kind: str) -> str:
    return f"iwerDevice.{'hands' if kind == 'hand' else 'controllers'}.right"


def input_point(page, hand: bool, key: str = "point") -> np.ndarray:
    """Where the page sees the right controller's tip / the right hand's pinch point (key "point") or index finger
    tip (key "tip"), in world metres."""
    for inp in page.evaluate("somxr.inputs()"):
        if inp["handedness"] == "right" and inp["hand"] == hand and inp[key] is not None:
            return np.array(inp[key])
    seen = page.evaluate("somxr.inputs()")
    raise AssertionError(f"no right {'hand' if hand else 'controller'} seen by the page: {seen}")


def get_position(page, dev: str) -> np.ndarray:
    return np.array(page.evaluate(f"(() => {{ const p = {dev}.position; return [p.x, p.y, p.z]; }})()"))


def set_position(page, dev: str, p) -> None:
    page.evaluate(f"([x, y, z]) => {dev}.position.set(x, y, z)", [float(v) for v in p])


def bring_to(page, dev: str, hand: bool, world, key: str = "point") -> None:
    """Move the emulated input so that its grab point (controller tip / pinch point; key "tip": index finger tip)
    lies at `world`."""
    for _ in range(3):  # the point sits at a fixed offset from the tracked position; refine twice
        offset = input_point(page, hand, key) - get_position(page, dev)
        set_position(page, dev, np.asarray(world) - offset)
        wait_frames(page, 2)
    assert np.linalg.norm(input_point(page, hand, key) - np.asarray(world)) < 2e-3


def glide(page, dev: str, delta, steps: int = 8) -> None:
    """Move the emulated input by `delta` (metres) over several XR frames, as a hand moves."""
    start = get_position(page, dev)
    for s in range(1, steps + 1):
        set_position(page, dev, start + np.asarray(delta) * s / steps)
        wait_frames(page, 2)


def grab_move_release(page, server, session, dev: str, hand: bool, index: int, delta, press, release):
    """The person's gesture: bring the input to control `index`, press, move by `delta`, let go. Returns what the
    test needs to check: the control's world start, the expected model end point and the frames seen."""
    target = np.array(page.evaluate(f"somxr.controlWorld({index})"))
    bring_to(page, dev, hand, target)
    page.wait_for_function(f"somxr.state().hover.includes({index})", timeout=5000)  # hovered before the grab
    before = page.evaluate("somxr.state()")
    page.evaluate(press)
    wait_for(lambda: server.hub.grabs.get(index) is not None, what=f"the server to see control {index} grabbed")
    page.wait_for_function(f"somxr.state().held.includes({index})", timeout=5000)
    look = page.evaluate(f"somxr.controlLook({index})")
    assert look["colour"] == "#ff2020" and look["scale"] > 1.5, look  # the grabbed control: red and enlarged
    mirror_look = page.evaluate(f"somxr.controlLook({index} + somxr.state().k)")
    assert mirror_look["colour"] == "#ff2020", mirror_look  # its mirrored copy too
    glide(page, dev, delta)
    expected = np.array(page.evaluate("(p) => somxr.worldToModel(p)", [float(v) for v in target + delta]))
    page.evaluate(release)
    wait_for(lambda: index not in server.hub.grabs, what=f"control {index} released")
    return target, expected, before


def check_moved(page, session, index: int, expected, before, start_controls):
    """The session's control is where the hand left it, its mirror follows, and new mesh frames arrived."""
    wait_for(lambda: np.allclose(session.controls[index, :3], expected, atol=2e-3), timeout=10,
             what=f"control {index} at {expected} (now {session.controls[index, :3]})")
    moved = np.linalg.norm(session.controls[index, :3] - start_controls[index, :3])
    assert moved > 0.3, f"control {index} moved only {moved}"
    others = np.delete(np.arange(len(start_controls)), index)
    np.testing.assert_allclose(session.controls[others], start_controls[others])  # nothing else moved
    assert session.wait_idle(60)
    frame = session.frame
    k = frame.n_controls
    mirror = frame.effective_positions[k + index]
    np.testing.assert_allclose(mirror, frame.control_positions[index] * np.array([1, -1, 1]), atol=1e-5)
    # the page: new frames with a changed mesh, showing the control (and its mirrored copy) where it now is
    page.wait_for_function(f"somxr.state().seq >= {frame.seq}", timeout=10000)
    after = page.evaluate("somxr.state()")
    assert after["frames"] > before["frames"] and after["digest"] != before["digest"]
    np.testing.assert_allclose(page.evaluate(f"somxr.serverControl({index})"), frame.control_positions[index],
                               atol=1e-5)
    np.testing.assert_allclose(page.evaluate(f"somxr.controlModel({k + index})"), mirror, atol=1e-4)
    shown = np.array(page.evaluate("somxr.positions(602)")).reshape(-1, 3)
    np.testing.assert_allclose(shown, frame.positions, atol=1e-5)
    assert not after["held"] and page.evaluate(f"somxr.controlLook({index})")["colour"] != "#ff2020"


def test_enter_ar_places_clay_in_front(ar_page):
    st = ar_page.evaluate("somxr.state()")
    assert st["mode"] == "immersive-ar" and st["supported"]["ar"] and st["transparent"]  # passthrough shows
    stage = np.array(st["stage"])
    head = np.array(ar_page.evaluate("[iwerDevice.position.x, iwerDevice.position.y, iwerDevice.position.z]"))
    offset = stage - head
    assert 0.3 < -offset[2] < 1.0 and -0.5 < offset[1] < 0.0, offset  # in front of the eyes, a little lower
    radius = ar_page.evaluate("somxr.worldRadius()")
    assert 0.15 < radius < 0.4  # a sensible size in metres
    assert st["k"] == 9 and st["kEff"] == 18


def test_falls_back_to_vr_without_ar(browser, server):
    """A headset without immersive-ar (emulated: ?modes=vr) gets "Enter VR" only, and an opaque VR scene."""
    page = open_page(browser, server.base + "/xr/emulator.html?modes=vr")
    try:
        page.wait_for_selector("#enter-vr:not([hidden])", timeout=10000)
        assert page.is_hidden("#enter-ar")
        box = page.locator("#enter-vr").bounding_box()
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.wait_for_function("somxr.state().presenting && somxr.state().mode === 'immersive-vr'", timeout=15000)
        wait_frames(page, 3)
        st = page.evaluate("somxr.state()")
        assert not st["transparent"] and st["supported"] == {"ar": False, "vr": True}
        assert 0.15 < page.evaluate("somxr.worldRadius()") < 0.4
        assert not page.errors, page.errors
    finally:
        page.close()


def test_controller_trigger_grabs_moves_and_releases(ar_page, server, session):
    start = session.controls
    dev = device_input(ar_page, "controller")
    delta = np.array([0.04, 0.05, 0.03])
    target, expected, before = grab_move_release(
        ar_page, server, session, dev, False, 2, delta,
        press=f"{dev}.updateButtonValue('trigger', 1)", release=f"{dev}.updateButtonValue('trigger', 0)")
    check_moved(ar_page, session, 2, expected, before, start)
    assert ar_page.evaluate("somxr.state().xr.releases") >= 1


def test_hand_pinch_grabs_moves_and_releases(ar_page, server, session):
    ar_page.evaluate("iwerDevice.primaryInputMode = 'hand'")
    ar_page.wait_for_function("somxr.inputs().some((i) => i.hand && i.handedness === 'right' && i.point)",
                              timeout=10000)
    dev = device_input(ar_page, "hand")
    ar_page.evaluate(f"{dev}.poseId = 'pinch'")  # fingers closing on the way (no pinch event yet)
    wait_frames(ar_page, 2)
    start = session.controls
    delta = np.array([-0.03, 0.04, -0.04])
    target, expected, before = grab_move_release(
        ar_page, server, session, dev, True, 4, delta,
        press=f"{dev}.updatePinchValue(1)", release=f"{dev}.updatePinchValue(0)")
    check_moved(ar_page, session, 4, expected, before, start)


def test_move_and_scale_the_clay(ar_page):
    """Squeeze one controller and move it: the clay follows. Squeeze both and pull them apart: it grows."""
    right, left = "iwerDevice.controllers.right", "iwerDevice.controllers.left"
    stage0 = np.array(ar_page.evaluate("somxr.state().stage"))
    scale0 = ar_page.evaluate("somxr.state().scale")
    ar_page.evaluate(f"{right}.updateButtonValue('squeeze', 1)")
    wait_frames(ar_page, 2)
    delta = np.array([0.1, -0.05, 0.08])
    glide(ar_page, right, delta, steps=5)
    ar_page.evaluate(f"{right}.updateButtonValue('squeeze', 0)")
    wait_frames(ar_page, 2)
    np.testing.assert_allclose(np.array(ar_page.evaluate("somxr.state().stage")) - stage0, delta, atol=1e-3)
    assert ar_page.evaluate("somxr.state().scale") == pytest.approx(scale0)
    # two hands: pull the controllers apart by half their distance -> the clay grows with the distance between
    # their grip points (the controller tips the page draws)
    def tips():
        pts = {i["handedness"]: np.array(i["point"]) for i in ar_page.evaluate("somxr.inputs()") if not i["hand"]}
        return np.linalg.norm(pts["right"] - pts["left"])

    gap = np.linalg.norm(get_position(ar_page, right) - get_position(ar_page, left))
    tips0 = tips()
    ar_page.evaluate(f"{right}.updateButtonValue('squeeze', 1); {left}.updateButtonValue('squeeze', 1)")
    wait_frames(ar_page, 2)
    direction = (get_position(ar_page, right) - get_position(ar_page, left)) / gap
    glide(ar_page, right, 0.25 * gap * direction, steps=4)
    glide(ar_page, left, -0.25 * gap * direction, steps=4)
    ar_page.evaluate(f"{right}.updateButtonValue('squeeze', 0); {left}.updateButtonValue('squeeze', 0)")
    wait_frames(ar_page, 2)
    ratio = tips() / tips0
    assert ratio > 1.4
    assert ar_page.evaluate("somxr.state().scale") == pytest.approx(ratio * scale0, rel=1e-3)
    assert ar_page.evaluate("somxr.state().held") == []  # squeezing moved the clay, not a control


def _look_along(direction) -> list[float]:
    """The quaternion (x, y, z, w) turning -z onto `direction`."""
    a = np.array([0.0, 0.0, -1.0])
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    axis = np.cross(a, d)
    s = np.linalg.norm(axis)
    angle = math.atan2(s, float(a @ d))
    axis = axis / s if s > 1e-9 else np.array([1.0, 0.0, 0.0])
    return [*(axis * math.sin(angle / 2)), math.cos(angle / 2)]


def point_and_pull(page, dev: str, name: str) -> None:
    """Point the right controller's ray at menu button `name` from 20 cm in front of it and pull the trigger."""
    b = page.evaluate(f"somxr.button('{name}')")
    centre, normal = np.array(b["centre"]), np.array(b["normal"])
    set_position(page, dev, centre + 0.2 * normal)
    page.evaluate("(q) => iwerDevice.controllers.right.quaternion.set(q[0], q[1], q[2], q[3])", _look_along(-normal))
    wait_frames(page, 2)
    page.evaluate(f"{dev}.updateButtonValue('trigger', 1)")
    wait_frames(page, 2)
    page.evaluate(f"{dev}.updateButtonValue('trigger', 0)")
    wait_frames(page, 2)
    page.evaluate("iwerDevice.controllers.right.quaternion.set(0, 0, 0, 1)")


def test_menu_undo_and_redo_take_back_a_grab(ar_page, server, session):
    """Interaction: a controller grab moves a control (one step); pointing at the menu's "Undo" and pulling the
    trigger puts the session back exactly, "Redo" forward again."""
    assert session.wait_idle(60)
    dev = device_input(ar_page, "controller")
    start = session.controls
    before = session.frame.weights.copy()
    steps = session.history[0]
    _, expected, _ = grab_move_release(ar_page, server, session, dev, False, 6, np.array([0.0, 0.05, 0.04]),
                                       f"{dev}.updateButtonValue('trigger', 1)",
                                       f"{dev}.updateButtonValue('trigger', 0)")
    wait_for(lambda: np.allclose(session.controls[6, :3], expected, atol=2e-3), what="the grab's move")
    assert session.wait_idle(60) and session.history == (steps + 1, 0)
    moved = session.frame.weights.copy()
    set_position(ar_page, dev, [0.25, 1.5, -0.4])
    point_and_pull(ar_page, dev, "undo")
    wait_for(lambda: session.history == (steps, 1), what="the undo from the XR menu")
    np.testing.assert_array_equal(session.frame.weights, before)
    np.testing.assert_array_equal(session.controls, start)
    point_and_pull(ar_page, dev, "redo")
    wait_for(lambda: session.history == (steps + 1, 0), what="the redo from the XR menu")
    np.testing.assert_array_equal(session.frame.weights, moved)
    session.undo()  # the module's other tests start from the converged car


def test_menu_pause_reset_train_in_xr(ar_page, session):
    """Point the controller at "Pause" and pull the trigger; touch "Reset" with a finger; point at "Resume"."""
    dev = device_input(ar_page, "controller")

    def point_and_pull_here(name):
        point_and_pull(ar_page, dev, name)

    assert not session.paused
    session.set_iterations(100_000)  # a long run: still training while the menu is used
    ar_page.wait_for_function("somxr.button('train').label === 'Pause'", timeout=10000)
    point_and_pull_here("train")  # labelled "Pause" while training
    wait_for(lambda: session.paused, what="the session paused from the XR menu")
    ar_page.wait_for_function("somxr.button('train').label === 'Resume'", timeout=5000)  # stopped part way

    # reset: touch the button with the right index finger tip
    session.move_control(0, session.controls[0, :3] + np.float32([0.0, 0.0, 0.3]))
    ar_page.evaluate("iwerDevice.primaryInputMode = 'hand'")
    ar_page.wait_for_function("somxr.inputs().some((i) => i.hand && i.handedness === 'right')", timeout=10000)
    wait_frames(ar_page, 2)
    hand = device_input(ar_page, "hand")
    b = ar_page.evaluate("somxr.button('reset')")
    ar_page.evaluate(f"{hand}.poseId = 'point'")  # index finger out
    wait_frames(ar_page, 2)
    # the finger tip 5 cm in front of the button, then pushed through it
    bring_to(ar_page, hand, True, np.array(b["centre"]) + 0.05 * np.array(b["normal"]), key="tip")
    glide(ar_page, hand, -0.07 * np.array(b["normal"]), steps=7)
    wait_for(lambda: "reset" in ar_page.evaluate("somxr.state().pressed"), what="the reset button touched")
    wait_for(lambda: session.frame.iteration == 0, what="the session reset")
    ar_page.evaluate("iwerDevice.primaryInputMode = 'controller'")
    ar_page.wait_for_function("somxr.inputs().some((i) => !i.hand && i.handedness === 'right')", timeout=10000)
    set_position(ar_page, dev, [0.25, 1.5, -0.4])
    wait_frames(ar_page, 2)
    point_and_pull_here("train")
    wait_for(lambda: not session.paused, what="the session training again")
    session.set_iterations(1000)
    session.reset()  # the converged car again, for the module's other tests
    assert session.wait_idle(60)


def test_desktop_preview_mouse_drag_and_headset_sees_it(browser, server, session):
    """Without a headset the page is a desktop preview: drag a control with the mouse. A headset page open at the
    same time sees the move (they share the session), and sees the control held while it is dragged."""
    desk = open_page(browser, server.base + "/xr/")
    headset = open_page(browser, server.base + "/xr/emulator.html")
    try:
        enter_ar(headset)
        st = desk.evaluate("somxr.state()")
        assert not st["presenting"] and st["mode"] is None
        assert desk.is_visible("#no-xr") or desk.is_visible("#enter-vr")  # the page says it is a preview
        start = session.controls
        index = 6
        x, y = desk.evaluate(f"somxr.controlScreen({index})")
        before_seq = session.frame.seq
        desk.mouse.move(x, y)
        # the ray may meet the mirrored copy first (it is nearer the camera): dragging it moves the original too
        desk.wait_for_function(f"somxr.state().hover.some((j) => j % 9 === {index})", timeout=5000)
        desk.mouse.down()
        wait_for(lambda: server.hub.grabs.get(index) is not None, what="the desktop grab")
        headset.wait_for_function(f"somxr.state().held.includes({index})", timeout=5000)  # red on the headset
        for s in range(1, 9):
            desk.mouse.move(x + 8 * s, y - 5 * s)
            desk.wait_for_timeout(40)
        desk.mouse.up()
        wait_for(lambda: index not in server.hub.grabs, what="the desktop release")
        wait_for(lambda: np.linalg.norm(session.controls[index, :3] - start[index, :3]) > 0.2,
                 what="the control to move")
        assert session.wait_idle(60)
        frame = session.frame
        assert frame.seq > before_seq
        for page in (desk, headset):
            page.wait_for_function(f"somxr.state().seq >= {frame.seq}", timeout=10000)
            np.testing.assert_allclose(page.evaluate(f"somxr.serverControl({index})"),
                                       frame.control_positions[index], atol=1e-5)
        assert not desk.errors and not headset.errors, desk.errors + headset.errors
    finally:
        desk.close()
        headset.close()


def test_desktop_drag_of_a_radial_copy_moves_its_control_by_the_inverse_rotation(browser):
    """A radial group (radial-4-z) on the sphere: the page shows k controls and 3k copies (ghosts: unnumbered). Dragging
    a copy with the mouse (copy 1: the control turned 90 degrees about z) moves its control to the drag point turned
    back (the inverse map), not to the point itself nor to its mirror image."""
    from somwidget.frontend.model import Session
    from somwidget.frontend.transport.display import group_maps
    from somwidget.frontend.web.standalone import XRServer

    session = Session("sphere", device="cpu")
    try:
        assert session.wait_idle(120), "the session did not converge"
        with XRServer(session) as srv:
            page = open_page(browser, srv.base + "/xr/")
            late = None
            try:
                assert page.evaluate("somxr.state().group") == "none"
                # the group comes in a "controls" message, before the first frame with the copies
                session.settings.set_symmetry("radial-4-z")
                assert session.wait_idle(60)
                assert session.settings.symmetry is not None and session.settings.symmetry.spec == "radial-4-z"
                k = session.frame.n_controls
                assert len(session.frame.effective_controls) == 4 * k
                maps = np.array(group_maps("radial-4-z")).reshape(-1, 3, 3)
                page.wait_for_function(
                    f"(() => {{ const s = somxr.state(); return s.group === 'radial-4-z' && s.k === {k} "
                    f"&& s.kEff === {4 * k} && s.seq >= {session.frame.seq}; }})()", timeout=15000)
                np.testing.assert_allclose(np.array(page.evaluate("somxr.state().groupMaps")).reshape(-1, 3, 3), maps,
                                           atol=1e-12)
                view = "document.getElementById('view').somview"
                page.wait_for_function(f"{view}.describe().numbered.filter((n) => n).length === {k}", timeout=10000)
                assert page.evaluate(f"{view}.describe().group") == "radial-4-z"
                # a page opened now reads the group from its topology message
                late = open_page(browser, srv.base + "/xr/")
                late.wait_for_function(f"somxr.state().group === 'radial-4-z' && somxr.state().kEff === {4 * k}",
                                       timeout=15000)
                late.close()
                late = None

                # a copy under map 1 that is clear on screen and the one the mouse meets
                box = page.locator("#view canvas").bounding_box()
                spots = [page.evaluate(f"somxr.controlScreen({j})") for j in range(4 * k)]
                start = session.controls
                chosen = None
                for j in sorted(range(k, 2 * k), key=lambda j: -min(
                        np.hypot(spots[j][0] - u, spots[j][1] - v) for m, (u, v) in enumerate(spots) if m != j)):
                    x, y = spots[j]
                    if not (box["x"] + 60 < x < box["x"] + box["width"] - 60
                            and box["y"] + 60 < y < box["y"] + box["height"] - 60):
                        continue
                    page.mouse.move(x, y)
                    try:
                        page.wait_for_function(f"somxr.state().hover.length === 1 && somxr.state().hover[0] === {j}",
                                               timeout=2000)
                    except playwright_sync.TimeoutError:
                        continue
                    chosen = j
                    break
                assert chosen is not None, f"no copy under map 1 is clear on screen: {spots}"
                j, i = chosen, chosen % k
                labels = page.evaluate(f"{view}.describe().labels")
                assert str(i) in labels and len(labels) == k, labels  # the control's number, none on its copies
                x, y = spots[j]
                cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
                d = np.array([cx - x, cy - y])
                d = 50 * d / max(np.linalg.norm(d), 1.0) + np.array([0.0, -20.0])
                page.mouse.down()
                wait_for(lambda: srv.hub.grabs.get(i) is not None, what=f"the server to see control {i} grabbed")
                for s in range(1, 11):
                    page.mouse.move(x + d[0] * s / 10, y + d[1] * s / 10)
                    page.wait_for_timeout(30)
                page.wait_for_timeout(100)
                # the copy follows the mouse on screen; its control is drawn at the copy's point turned back
                copy_end = np.array(page.evaluate(f"somxr.controlModel({j})"))
                shown = np.array(page.evaluate(f"somxr.controlScreen({j})"))
                assert np.linalg.norm(shown - [x + d[0], y + d[1]]) < 3, (shown, x + d[0], y + d[1])
                expected = maps[1].T @ copy_end
                np.testing.assert_allclose(page.evaluate(f"somxr.controlModel({i})"), expected, atol=1e-5)
                for g in (2, 3):  # the other copies follow the control
                    np.testing.assert_allclose(page.evaluate(f"somxr.controlModel({g * k + i})"), maps[g] @ expected,
                                               atol=1e-5)
                page.mouse.up()
                wait_for(lambda: i not in srv.hub.grabs, what=f"control {i} released")
                wait_for(lambda: np.allclose(session.controls[i, :3], expected, atol=2e-3), timeout=10,
                         what=f"control {i} at {expected} (now {session.controls[i, :3]})")
                assert np.linalg.norm(session.controls[i, :3] - start[i, :3]) > 0.1, "the control hardly moved"
                # the test tells the maps apart: the point itself or its mirror image is far from where it went
                assert np.linalg.norm(copy_end - expected) > 0.1
                assert np.linalg.norm(copy_end * [1, -1, 1] - expected) > 0.1
                others = np.delete(np.arange(k), i)
                np.testing.assert_allclose(session.controls[others], start[others])
                assert session.wait_idle(60)
                frame = session.frame
                eff = np.asarray(frame.effective_positions).reshape(-1, 3)
                np.testing.assert_allclose(eff[j], maps[1] @ frame.control_positions[i], atol=1e-5)
                page.wait_for_function(f"somxr.state().seq >= {frame.seq}", timeout=10000)
                np.testing.assert_allclose(page.evaluate(f"somxr.serverControl({j})"), eff[j], atol=1e-5)
                assert not page.errors, page.errors
            finally:
                if late is not None:
                    late.close()
                page.close()
    finally:
        session.close()


def test_strokes_and_radii_in_the_headset(ar_page, server, session):
    """Point at the menu's "Stroke" and pull the trigger: the tool is on (the button now says "Grab"). The thumbstick
    pushed up makes the stroke's radius ball larger; the trigger held while the controller moves draws a line, and
    letting go adds it as one control of that radius. With hands: a pinch draws, a pinch with the other hand turns
    it into a spread that sets the radius. With the tool off, the thumbstick while a control is held sets its
    radius."""
    assert session.wait_idle(60)
    steps, k0 = session.history[0], len(session.controls)
    dev = device_input(ar_page, "controller")
    set_position(ar_page, dev, [0.25, 1.5, -0.4])
    point_and_pull(ar_page, dev, "stroke")
    ar_page.wait_for_function("somxr.state().tools.on && somxr.button('stroke').label === 'Grab'", timeout=5000)
    r0 = ar_page.evaluate("somxr.state().tools.radius")
    ar_page.evaluate(f"{dev}.updateAxes('thumbstick', 0, -1)")  # pushed up: larger
    wait_frames(ar_page, 12)
    ar_page.evaluate(f"{dev}.updateAxes('thumbstick', 0, 0)")
    wait_frames(ar_page, 2)
    r1 = ar_page.evaluate("somxr.state().tools.radius")
    assert r1 > 1.05 * r0, (r0, r1)
    start = np.array(ar_page.evaluate("somxr.controlWorld(2)")) + np.array([0.0, 0.03, 0.0])
    bring_to(ar_page, dev, False, start)
    ar_page.evaluate(f"{dev}.updateButtonValue('trigger', 1)")
    wait_frames(ar_page, 2)
    glide(ar_page, dev, [-0.12, 0.02, 0.0], steps=10)
    ar_page.evaluate(f"{dev}.updateButtonValue('trigger', 0)")
    edits = session.control_edits
    wait_for(lambda: len(edits.strokes) and edits.strokes[-1] >= 2 and len(session.controls) > k0,
             what="the stroke added")
    run = session.control_edits.strokes[-1]
    np.testing.assert_allclose(session.control_edits.radii[-run:], r1, rtol=1e-3)  # the ball's radius
    first = np.array(ar_page.evaluate("(p) => somxr.worldToModel(p)", [float(v) for v in start]))
    assert np.linalg.norm(session.controls[-run, :3] - first) < 0.05 * 2 * ar_page.evaluate("somxr.worldRadius()") \
        / ar_page.evaluate("somxr.state().scale")  # it begins where the trigger was pulled
    assert session.wait_idle(120) and session.history[0] == steps + 1  # one step

    # hands: the right hand pinches (draws), the left pinches too: a spread of 16 cm is a ball 8 cm in radius
    ar_page.evaluate("iwerDevice.primaryInputMode = 'hand'")
    ar_page.wait_for_function("somxr.inputs().filter((i) => i.hand && i.point).length === 2", timeout=10000)
    right, left = device_input(ar_page, "hand"), "iwerDevice.hands.left"
    for h in (right, left):
        ar_page.evaluate(f"{h}.poseId = 'pinch'")
    wait_frames(ar_page, 2)
    centre = np.array(ar_page.evaluate("somxr.state().stage"))
    bring_to(ar_page, right, True, centre + [0.05, 0.35, 0.0])
    ar_page.evaluate(f"{right}.updatePinchValue(1)")
    wait_frames(ar_page, 3)
    assert ar_page.evaluate("somxr.state().tools.drawing")
    pts = {i["handedness"]: np.array(i["point"]) for i in ar_page.evaluate("somxr.inputs()") if i["hand"]}
    set_position(ar_page, left, get_position(ar_page, left) + (pts["right"] + [-0.16, 0, 0]) - pts["left"])
    wait_frames(ar_page, 2)
    ar_page.evaluate(f"{left}.updatePinchValue(1)")
    wait_frames(ar_page, 3)
    tools = ar_page.evaluate("somxr.state().tools")
    scale = ar_page.evaluate("somxr.state().scale")
    assert tools["spreading"] and not tools["drawing"]
    assert tools["radius"] * scale == pytest.approx(0.08, rel=0.05)
    for h in (right, left):
        ar_page.evaluate(f"{h}.updatePinchValue(0)")
    wait_frames(ar_page, 3)
    assert len(session.controls) == k0 + run, "a spread adds nothing"

    # the tool off; a controller holds control 3 and the thumbstick makes its radius larger
    ar_page.evaluate("iwerDevice.primaryInputMode = 'controller'")
    ar_page.wait_for_function("somxr.inputs().some((i) => !i.hand && i.handedness === 'right')", timeout=10000)
    set_position(ar_page, dev, [0.25, 1.5, -0.4])
    point_and_pull(ar_page, dev, "stroke")
    ar_page.wait_for_function("!somxr.state().tools.on && somxr.button('stroke').label === 'Stroke'", timeout=5000)
    bring_to(ar_page, dev, False, np.array(ar_page.evaluate("somxr.controlWorld(3)")))
    ar_page.evaluate(f"{dev}.updateButtonValue('trigger', 1)")
    wait_for(lambda: server.hub.grabs.get(3) is not None, what="control 3 held")
    ar_page.evaluate(f"{dev}.updateAxes('thumbstick', 0, -1)")
    wait_frames(ar_page, 12)
    ar_page.evaluate(f"{dev}.updateAxes('thumbstick', 0, 0); {dev}.updateButtonValue('trigger', 0)")
    wait_for(lambda: session.control_edits.radii[3] > 0, what="control 3's radius from the thumbstick")
    assert session.wait_idle(120)
    while session.history[0] > steps:  # the module's other tests start from the converged car
        session.undo()


def test_a_controllers_and_a_hands_grab_bind_the_clay_as_the_mouse_does(ar_page, server, session):
    """Controls with a radius (handles): the controller's trigger and the hand's pinch each bind the clay the control
    takes, as a mouse's grab does: while held the Som holds the control and its node stays the one the grab took
    (the winner never jumps), and letting go lets go."""
    assert session.wait_idle(60)
    steps = session.history[0]
    p = session.frame.positions
    size = float(np.linalg.norm(p.max(0) - p.min(0)))
    som = session.modelling.som
    for index, kind in ((2, "controller"), (4, "hand")):
        session.set_control_radius(index, 0.1 * size)
        assert session.wait_idle(120)
        if kind == "hand":
            ar_page.evaluate("iwerDevice.primaryInputMode = 'hand'")
            ar_page.wait_for_function("somxr.inputs().some((i) => i.hand && i.handedness === 'right' && i.point)",
                                      timeout=10000)
        dev = device_input(ar_page, kind)
        if kind == "hand":
            ar_page.evaluate(f"{dev}.poseId = 'pinch'")
            wait_frames(ar_page, 2)
        bring_to(ar_page, dev, kind == "hand", np.array(ar_page.evaluate(f"somxr.controlWorld({index})")))
        ar_page.wait_for_function(f"somxr.state().hover.includes({index})", timeout=5000)
        ar_page.evaluate(f"{dev}.updatePinchValue(1)" if kind == "hand" else f"{dev}.updateButtonValue('trigger', 1)")
        wait_for(lambda index=index: som.held == (index,), what=f"the Som to hold control {index} ({kind})")
        with session.modelling.som_lock:
            took = int(som.winners()[index])
        before = session.controls[index].copy()
        glide(ar_page, dev, [0.0, -0.04, 0.0])
        wait_for(lambda: np.abs(session.controls[index] - before).max() > 0.01, what="the move")  # noqa: B023
        assert session.wait_applied(30)
        assert som.held == (index,)
        with session.modelling.som_lock:
            assert int(som.winners()[index]) == took, f"{kind}: the winner jumped while held"
        ar_page.evaluate(f"{dev}.updatePinchValue(0)" if kind == "hand" else f"{dev}.updateButtonValue('trigger', 0)")
        wait_for(lambda: som.held == (), what=f"the Som to let go of control {index} ({kind})")
        assert session.wait_idle(120)
    while session.history[0] > steps:  # the module's other tests start from the converged car
        session.undo()
