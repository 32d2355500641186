"""The web app in a real browser: Debian's Chromium driven by Playwright against `somwidget serve`.

Interaction tests act as the person does: Playwright's mouse drags a control's sphere on the server-rendered view.
Server-side state is read through the app's read-only debug route GET /api/state; nothing here sets it directly.
Needs /usr/bin/chromium, Python Playwright and EGL/Mesa for headless VTK (scripts/setup.sh installs them).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import datetime
import io
import itertools
import os
import tempfile
import time

import helpers
import numpy as np
import pytest
from helpers import CHROMIUM, Serve, wave_mesh

from somwidget.backend.schedule import MOVE_REACH_MOST

pytestmark = pytest.mark.browser

VIEWPORT = {"width": 1200, "height": 800}

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)


@pytest.fixture(scope="module")
def server():
    srv = Serve()
    yield srv
    srv.stop()


VIEW = "document.getElementById('clay-view')?.somview"


def open_page(browser, server):
    """A tab on the app, once its clay view has drawn a frame."""
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(server.url)
    page.wait_for_function(f"() => {{ const v = {VIEW}; return v && v.describe().painted > 0; }}", timeout=30000)
    return page


def view_state(page) -> dict:
    return page.evaluate(f"() => {VIEW}.describe()")


def shows(page, st: dict, timeout: float = 15000) -> None:
    """Wait until the page's view has drawn the session's frame of `st` (or a later one)."""
    seq = st["session"]["frame"]["seq"]
    page.wait_for_function(f"() => {{ const d = {VIEW}.describe(); return d.seq >= {seq} && d.painted > 0; }}",
                           timeout=timeout)
    page.wait_for_timeout(100)  # the next animation frame has painted it


def view_image(page) -> np.ndarray:
    from PIL import Image

    png = page.locator("#clay-view canvas").screenshot()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def not_blank(img: np.ndarray) -> float:
    """Share of pixels that differ clearly from the most common (background) colour."""
    flat = img.reshape(-1, 3)
    values, counts = np.unique(flat[:: max(1, len(flat) // 20000)], axis=0, return_counts=True)
    bg = values[np.argmax(counts)]
    return float((np.abs(flat - bg).sum(axis=1) > 30).mean())


def control_on_screen(page, index: int) -> tuple[float, float]:
    """Where the view draws effective control `index`, in page pixels."""
    x, y = page.evaluate(f"() => {VIEW}.controlScreen({index})")
    return float(x), float(y)


def canvas_box(page) -> dict:
    return page.locator("#clay-view canvas").bounding_box()


def pick_control(page, prefer=(2, 5, 3, 6, 4, 0, 1, 7, 8), margin: float = 90.0, exclude=()) -> int:
    """A control whose sphere is on screen, not hidden by the clay, away from the view's edges and from the other
    spheres."""
    box = canvas_box(page)
    page.wait_for_timeout(350)  # the view has looked again which controls the clay hides
    state = view_state(page)
    spots = [control_on_screen(page, j) for j in range(state["kEff"])]
    best, best_clear = None, 0.0
    for i in prefer:
        if i in exclude or i >= len(spots) or i in state["behind"]:
            continue
        x, y = spots[i]
        inside = box["x"] + margin < x < box["x"] + box["width"] - margin and \
            box["y"] + margin < y < box["y"] + box["height"] - margin
        clear = min(np.hypot(x - u, y - v) for j, (u, v) in enumerate(spots) if j != i)
        if inside and clear > 45:
            return i
        if inside and clear > max(best_clear, 24):
            best, best_clear = i, clear
    if best is not None:
        return best
    raise AssertionError(f"no control sphere is clear on screen: {spots}")


def toward_centre(page, start, length: float = 80.0) -> tuple[float, float]:
    """A drag vector of `length` pixels from `start` toward the middle of the view (so it stays on screen)."""
    box = canvas_box(page)
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    v = np.array([cx - start[0], cy - start[1]])
    n = float(np.linalg.norm(v))
    v = v / n if n > 1 else np.array([0.0, -1.0])
    # turn by 30 degrees so the control does not slide along the view direction only
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    v = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])
    return float(v[0] * length), float(v[1] * length)


def mouse_drag(page, start, delta, steps: int = 24, pause: float = 0.03, release: bool = True):
    """A real mouse drag: press on `start`, move by `delta` in `steps`, release."""
    x0, y0 = start
    page.mouse.move(x0, y0)
    page.mouse.down()
    for i in range(1, steps + 1):
        page.mouse.move(x0 + delta[0] * i / steps, y0 + delta[1] * i / steps)
        time.sleep(pause)
    if release:
        page.mouse.up()


def held(st: dict) -> list[int]:
    """The controls the views hold now (grabbed by a mouse or a hand)."""
    return sorted(int(i) for i in st["views"]["grabs"])


def nearest(positions, p) -> float:
    return float(np.sqrt(((np.asarray(positions) - np.asarray(p)) ** 2).sum(axis=1)).min())


def test_page_loads_on_the_car_and_renders(browser, server):
    page = open_page(browser, server)
    try:
        st = server.idle()
        assert st["session"]["preset"] == "car"
        assert st["session"]["frame"]["iteration"] == 1000
        page.wait_for_function("() => document.querySelector('#iteration-text').innerText"
                               ".startsWith('iteration 1000 / 1000')", timeout=10000)
        shows(page, st)
        img = view_image(page)
        assert not_blank(img) > 0.05, "the 3-D view looks blank"
        assert st["clients"] >= 1 and st["views"]["clients"] >= 1
        v = view_state(page)
        # drawn by the browser from the streamed frames: the labels match the panel's control table (0..8; the
        # mirrored copies are ghosts without numbers), the status line shows the iteration
        assert v["k"] == 9 and v["kEff"] == 18
        assert sorted(v["labels"], key=int) == [str(i) for i in range(9)]
        assert v["numbered"] == [True] * 9 + [False] * 9
        assert v["status"].startswith("iteration 1000 / 1000")
        # and the server's own figures, sent four times a second to every view: the cycle's time in ms
        page.wait_for_function(f"() => / cycle \\d+\\.\\d{{3}} ms/.test({VIEW}.describe().status)", timeout=10000)
        np.testing.assert_allclose(np.array([page.evaluate(f"() => {VIEW}.controlModel({j})") for j in range(9)]),
                                   np.array(st["session"]["controls"])[:, :3], atol=1e-5)
    finally:
        page.close()


def test_mouse_drag_moves_control_and_clay_follows(browser, server):
    page = open_page(browser, server)
    try:
        st0 = server.idle()
        shows(page, st0)
        before_img = view_image(page)
        i = pick_control(page)  # the car's nose (2) unless it is hidden
        c0 = np.array(st0["session"]["controls"][i][:3])
        start = control_on_screen(page, i)
        page.mouse.move(*start)  # hovering highlights the sphere
        page.wait_for_function(f"() => {VIEW}.describe().hover.includes({i})", timeout=5000)
        mouse_drag(page, start, toward_centre(page, start, 130), release=False)
        mid = server.state(positions=True)  # still holding the button: the clay follows during the drag
        look = page.evaluate(f"() => {VIEW}.controlLook({i})")
        page.mouse.up()
        assert held(mid) == [i]
        assert look["colour"] == "#ff2020" and look["scale"] > 1.4  # the held one: red and enlarged
        c_mid = np.array(mid["session"]["controls"][i][:3])
        assert np.linalg.norm(c_mid - c0) > 0.2, "the control did not follow the mouse"
        assert mid["session"]["frame"]["seq"] > st0["session"]["frame"]["seq"]
        st1 = server.idle()
        c1 = np.array(st1["session"]["controls"][i][:3])
        assert np.linalg.norm(c1 - c0) > 0.3
        assert held(st1) == []
        # the mirrored copy followed its original (y negated)
        eff = np.array(st1["session"]["frame"]["effective_controls"])
        np.testing.assert_allclose(eff[9 + i, :3], c1 * [1, -1, 1], atol=1e-5)
        # the mesh moved toward the new control
        d_before = nearest(st0["session"]["frame"]["positions"], c1)
        d_after = nearest(st1["session"]["frame"]["positions"], c1)
        assert d_after < 0.5 * d_before, (d_before, d_after)
        assert st1["session"]["frame"]["gaps"][i] == pytest.approx(d_after, rel=1e-4)
        shows(page, st1)
        after_img = view_image(page)
        assert not_blank(after_img) > 0.05
        changed = float((np.abs(after_img - before_img).sum(axis=2) > 30).mean())
        assert changed > 0.01, f"only {changed:.4f} of the view changed"
    finally:
        page.close()


def diagonal(positions) -> float:
    p = np.asarray(positions)
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


def test_a_one_second_drag_never_shrinks_the_clay_and_undoes_in_one_step(browser, server):
    """Interaction: the mouse drags a control for a second; every frame the server made meanwhile (sampled from its
    state route as they come) keeps the car at least 90% of its size while the clay follows. The drag is one undo
    step: Ctrl+Z on the page brings back the car exactly, the Redo button the dragged one."""
    page = open_page(browser, server)
    try:
        st0 = server.idle()
        size0 = diagonal(st0["session"]["frame"]["positions"])
        # a control within the car's length: the nose or the tail pushed in 110 px takes its end of the clay along
        # (a long move restarts as wide as it moved) and shortens the car by as much, which is following, not shrinking
        i = pick_control(page, prefer=(5, 6, 4, 7, 8, 0, 1))
        c0 = np.array(st0["session"]["controls"][i][:3])
        start = control_on_screen(page, i)
        delta = toward_centre(page, start, 110)
        frames, stop = {}, False

        def sample():
            while not stop:
                f = server.state(positions=True)["session"]["frame"]
                frames[f["seq"]] = (diagonal(f["positions"]), f["iteration"])

        with concurrent.futures.ThreadPoolExecutor(1) as pool:
            sampling = pool.submit(sample)
            mouse_drag(page, start, delta, steps=30, pause=1.0 / 30)  # one second, a move a frame
            server.wait(lambda s: not held(s), what="the release")  # its last move is in
            st1 = server.idle()
            stop = True
            sampling.result()
        during = [frames[k] for k in sorted(frames) if k > st0["session"]["frame"]["seq"]]
        assert len(during) >= 10, f"only {len(during)} frames seen during the drag"
        least = min(d for d, _ in during) / size0
        assert least >= 0.90, f"the clay shrank to {least:.2f} of its size during the drag"
        # local restarts only (as wide as the drag is long: schedule.reach_for_move), never the whole schedule
        assert min(s for _, s in during) >= int((1 - MOVE_REACH_MOST) * 1000)
        c1 = np.array(st1["session"]["controls"][i][:3])
        assert np.linalg.norm(c1 - c0) > 0.3
        assert nearest(st1["session"]["frame"]["positions"], c1) < 0.02 * size0  # followed to within 2%
        assert st1["session"]["history"][0] == st0["session"]["history"][0] + 1  # the whole drag: one step
        page.locator("#iteration-label").click()  # the page has the focus, no text field does
        page.keyboard.press("Control+z")
        back = server.wait(lambda s: s["session"]["history"] == st0["session"]["history"][:1] + [1],
                           what="Ctrl+Z")
        assert back["session"]["held"]
        np.testing.assert_array_equal(back["session"]["frame"]["positions"], st0["session"]["frame"]["positions"])
        np.testing.assert_array_equal(back["session"]["controls"], st0["session"]["controls"])
        page.locator("#redo-button").click()
        again = server.wait(lambda s: s["session"]["history"][1] == 0, what="Redo")
        np.testing.assert_array_equal(again["session"]["frame"]["positions"], st1["session"]["frame"]["positions"])
        page.keyboard.press("Control+z")  # leave the car as the module's other tests expect it
        server.wait(lambda s: s["session"]["history"][1] == 1, what="Ctrl+Z again")
    finally:
        page.close()


def test_shift_drag_moves_along_one_axis_and_a_control_out_of_sight_has_a_marker(browser, server):
    """Interaction: with Shift held the mouse moves a control along one model axis only; a control dragged out past
    the view's edge leaves the camera where it is and gets a marker at the edge, and a click on the marker brings it
    into view, so it can be grabbed again."""
    page = open_page(browser, server)
    try:
        st0 = server.idle()
        shows(page, st0)
        i = pick_control(page)
        c0 = np.array(st0["session"]["controls"][i][:3])
        start = control_on_screen(page, i)
        page.keyboard.down("Shift")
        mouse_drag(page, start, toward_centre(page, start, 100))
        page.keyboard.up("Shift")
        st1 = server.idle()
        d = np.abs(np.array(st1["session"]["controls"][i][:3]) - c0)
        assert d.max() > 0.1, "the control did not move"
        assert np.sort(d)[1] < 1e-5, f"a Shift drag moved more than one axis: {d}"
        shows(page, st1)
        j = pick_control(page, exclude=(i,))
        start = control_on_screen(page, j)
        box = canvas_box(page)
        mouse_drag(page, start, (box["x"] + box["width"] + 150 - start[0], -40), steps=20)
        st2 = server.idle()
        assert np.linalg.norm(np.array(st2["session"]["controls"][j]) - np.array(st1["session"]["controls"][j])) > 0.3
        shows(page, st2)
        camera = view_state(page)["camera"]
        page.wait_for_function(f"() => {VIEW}.describe().markers.includes('{j}')", timeout=5000)
        assert view_state(page)["camera"] == camera, "the view moved by itself"
        box = canvas_box(page)
        marker = page.locator(f".somview-marker[data-index='{j}']")
        mx, my = marker.bounding_box()["x"], marker.bounding_box()["y"]
        assert mx > box["x"] + box["width"] - 60, f"the marker is not at the right edge: {mx, my}"
        marker.click()
        page.wait_for_function(f"() => !{VIEW}.describe().markers.includes('{j}')", timeout=5000)
        x, y = control_on_screen(page, j)
        assert box["x"] <= x <= box["x"] + box["width"] and box["y"] <= y <= box["y"] + box["height"], \
            f"control {j} is still out of sight at {(x, y)}"
        for _ in range(2):  # leave the car as the module's other tests expect it
            page.locator("#undo-button").click()
            page.wait_for_timeout(200)
        server.wait(lambda s: s["session"]["history"][1] >= 2, what="two undos")
        server.idle()
    finally:
        page.close()


def test_panel_sets_schedule_and_refuses_bad_values(browser, server):
    page = open_page(browser, server)
    try:
        for field, value in (("#field-iterations", "1500"), ("#field-l_start", "0.4"), ("#field-l_end", "0.05"),
                             ("#field-smoothing", "0.1")):
            page.locator(field).fill(value)
            page.locator(field).press("Enter")
        st = server.wait(lambda s: s["session"]["parameters"]["iterations"] == 1500
                         and s["session"]["parameters"]["l_start"] == 0.4
                         and s["session"]["parameters"]["l_end"] == 0.05
                         and s["session"]["parameters"]["smoothing"] == 0.1, what="the panel's parameters")
        st = server.idle()
        assert st["session"]["frame"]["iterations"] == 1500 and st["session"]["frame"]["iteration"] == 1500
        page.wait_for_function("() => document.querySelector('#iteration-text').innerText.includes('1500 / 1500')")
        # out of range: refused with a message, the session keeps its value
        page.locator("#field-l_start").fill("1.5")
        page.locator("#field-l_start").press("Enter")
        alert = page.locator("#error-alert")
        alert.wait_for(timeout=10000)
        assert "l_start" in alert.inner_text()
        assert server.state()["session"]["parameters"]["l_start"] == 0.4
        page.locator("#field-iterations").fill("-5")
        page.locator("#field-iterations").press("Enter")
        page.wait_for_function("() => document.querySelector('#error-alert')?.innerText.includes('iterations')")
        assert server.state()["session"]["parameters"]["iterations"] == 1500
        # symmetry off from the switch: each mirrored copy becomes a control of its own, and nothing moves
        before = server.state(positions=True)["session"]["frame"]["positions"]
        page.locator("#symmetry-switch").click()
        st = server.wait(lambda s: len(s["session"]["controls"]) == 18 and not s["session"]["parameters"]["symmetry"]
                         and s["session"]["pending_intents"] == 0, what="symmetry off")
        assert len(st["session"]["frame"]["effective_controls"]) == 18
        assert st["session"]["frame"]["positions"] == before
        page.locator("#symmetry-switch").click()  # on again: the copies pair up with their controls
        server.wait(lambda s: len(s["session"]["controls"]) == 9 and s["session"]["parameters"]["symmetry"]
                    and len(s["session"]["frame"]["effective_controls"]) == 18, what="symmetry on")
        # a metric weight from the features table, and Pause / Train
        weight = page.locator("#features-table tr").nth(3).locator("input")
        weight.fill("2.5")
        weight.press("Enter")
        server.wait(lambda s: s["session"]["parameters"]["metric_weights"][3] == 2.5, what="metric weight")
        weight.fill("-1")
        weight.press("Enter")
        page.wait_for_function("() => document.querySelector('#error-alert')?.innerText.includes('metric weight')")
        assert server.state()["session"]["parameters"]["metric_weights"][3] == 2.5
        # and at the field that caused it
        page.locator("#features-table tr").nth(3).locator(".v-messages").get_by_text("metric weight").wait_for()
        weight.fill("1")
        weight.press("Enter")
        # the run button says what a press does (a settled map trains, a running one pauses, a paused one resumes)
        button = page.locator("#train-button")
        server.wait(lambda s: not s["session"]["frame"]["running"], what="the map settled")
        page.wait_for_function("() => document.querySelector('#train-button').innerText.trim() === 'TRAIN'")
        iterations = page.locator("#field-iterations")
        iterations.fill("1000000")
        iterations.press("Enter")
        server.wait(lambda s: s["session"]["frame"]["running"], what="a long run")
        page.wait_for_function("() => document.querySelector('#train-button').innerText.trim() === 'PAUSE'")
        button.click()
        server.wait(lambda s: s["session"]["paused"] and not s["session"]["frame"]["running"], what="paused")
        page.wait_for_function("() => document.querySelector('#train-button').innerText.trim() === 'RESUME'")
        button.click()
        server.wait(lambda s: not s["session"]["paused"] and s["session"]["frame"]["running"], what="training again")
        iterations.fill("1000")
        iterations.press("Enter")
        server.wait(lambda s: not s["session"]["frame"]["running"], what="the run ended at the new S")
        # controls from the panel: add one, recolour it, remove it
        page.locator("#add-control").click()
        server.wait(lambda s: len(s["session"]["controls"]) == 10, what="a tenth control")
        page.locator("#controls-table tr").nth(9).locator("input[type=color]").fill("#00ff00")
        st = server.wait(lambda s: len(s["session"]["controls"]) == 10
                         and abs(s["session"]["controls"][9][3] - 1 / 3) < 1e-3
                         and abs(s["session"]["controls"][9][4] - 1.0) < 1e-3, what="the green control")
        page.locator("#controls-table tr").nth(9).locator("button").click()
        server.wait(lambda s: len(s["session"]["controls"]) == 9, what="back to nine controls")
        # back to the preset's schedule for the tests that follow
        for field, value in (("#field-iterations", "1000"), ("#field-l_start", "0.25"), ("#field-l_end", "0.03"),
                             ("#field-smoothing", "0")):
            page.locator(field).fill(value)
            page.locator(field).press("Enter")
        server.wait(lambda s: s["session"]["parameters"]["iterations"] == 1000
                    and s["session"]["parameters"]["smoothing"] == 0.0, what="defaults back")
    finally:
        page.close()


def test_the_panel_comes_from_the_parameters_declaration_and_follows_a_change_made_elsewhere(browser, server):
    """Every parameter field carries the declared help as its tooltip; a value set by another client (the set
    intent on the views' websocket, as the XR page or a script sends it) shows in the page's field; a refused one
    comes back to that client as an error and changes nothing."""
    import aiohttp

    from somwidget.frontend.model.settings import PARAMETERS

    page = open_page(browser, server)
    try:
        for p in PARAMETERS:  # a field for each, with its help as the tooltip
            assert page.locator(f"#param-{p.name}").get_attribute("title") == p.help, p.name

        async def send(*intents, expect_error=False):
            async with aiohttp.ClientSession() as cs, cs.ws_connect(server.base.replace("http", "ws") + "/view/ws",
                                                                    headers={"Origin": server.base}) as ws:
                for intent in intents:
                    await ws.send_json(intent)
                await ws.send_json({"type": "ping", "t": 1})  # answered after the intents before it
                replies = []
                while True:
                    msg = await ws.receive(timeout=10)
                    if msg.type != aiohttp.WSMsgType.TEXT:
                        continue
                    if '"error"' in msg.data:
                        replies.append(msg.data)
                    if '"pong"' in msg.data:
                        return replies

        def run(*intents):  # on a thread of its own: Playwright's sync API holds this thread's event loop
            with concurrent.futures.ThreadPoolExecutor(1) as pool:
                return pool.submit(lambda: asyncio.run(send(*intents))).result()

        replies = run({"type": "set", "name": "smoothing", "value": 0.05}, {"type": "set", "name": "l_end", "value": 2})
        assert replies and "l_end" in replies[0]
        page.wait_for_function("() => document.querySelector('#field-smoothing').value === '0.05'",
                               timeout=10000)
        st = server.state()
        assert st["session"]["parameters"]["smoothing"] == 0.05 and st["session"]["parameters"]["l_end"] == 0.03
        run({"type": "set", "name": "smoothing", "value": 0})
        server.wait(lambda s: s["session"]["parameters"]["smoothing"] == 0.0, what="smoothing back to 0")
        server.idle()
    finally:
        page.close()


def test_bad_upload_shows_an_error_and_the_session_goes_on(browser, server, tmp_path):
    page = open_page(browser, server)
    try:
        gen = server.state()["session"]["generation"]
        bad = tmp_path / "not-a-mesh.obj"
        bad.write_bytes(b"\x00\x01 this is no mesh at all \xff" * 50)
        page.locator("#mesh-upload").set_input_files(str(bad))
        alert = page.locator("#error-alert")
        alert.wait_for(timeout=20000)
        assert "not-a-mesh.obj" in alert.inner_text()
        flat = tmp_path / "flat.obj"
        flat.write_text("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n")
        page.locator("#mesh-upload").set_input_files(str(flat))
        page.wait_for_function("() => document.querySelector('#error-alert')?.innerText.includes('degenerate')",
                               timeout=20000)
        # too many vertices for the session (a 513 x 513 sheet: 263,169 > 262,144 on the CPU)
        big = wave_mesh(tmp_path / "big.ply", 513)
        page.locator("#mesh-upload").set_input_files(str(big))
        page.wait_for_function("() => document.querySelector('#error-alert')?.innerText.includes('exceed the limit')",
                               timeout=30000)
        st = server.state()
        assert st["session"]["preset"] == "car" and st["session"]["generation"] == gen
        # the session still answers intents from the view
        st = server.idle()
        page.locator("#reset-button").click()
        server.wait(lambda s: s["session"]["frame"]["seq"] > st["session"]["frame"]["seq"], what="reset frame")
        server.idle()
    finally:
        page.close()


def test_two_pages_share_the_session(browser, server):
    a = open_page(browser, server)
    b = open_page(browser, server)
    try:
        st0 = server.idle()
        assert st0["clients"] >= 2
        a_before = view_image(a)
        # page B drags a control; page A sees it
        shows(a, st0)
        a_camera = view_state(a)["camera"]
        i = pick_control(b, prefer=(5, 6, 4, 2, 3, 0, 1, 7, 8))
        start = control_on_screen(b, i)
        mouse_drag(b, start, toward_centre(b, start))
        st1 = server.idle()
        moved = np.linalg.norm(np.array(st1["session"]["controls"][i]) - np.array(st0["session"]["controls"][i]))
        assert moved > 0.2
        shows(a, st1)
        a_after = view_image(a)
        assert float((np.abs(a_after - a_before).sum(axis=2) > 30).mean()) > 0.005, "page A did not see B's move"
        # and the other way round: page A drags another control
        shows(b, st1)
        b_before = view_image(b)
        j = pick_control(a, prefer=(3, 7, 1, 4, 0, 2, 5, 6, 8), exclude=(i,))
        start = control_on_screen(a, j)
        mouse_drag(a, start, toward_centre(a, start))
        st2 = server.idle()
        assert np.linalg.norm(np.array(st2["session"]["controls"][j]) - np.array(st1["session"]["controls"][j])) > 0.2
        shows(b, st2)
        b_after = view_image(b)
        assert float((np.abs(b_after - b_before).sum(axis=2) > 30).mean()) > 0.005, "page B did not see A's move"
        # each tab keeps its own camera: orbiting in A (a drag on empty space) leaves B's camera where it was
        b_camera = view_state(b)["camera"]
        box = canvas_box(a)
        mouse_drag(a, (box["x"] + 30, box["y"] + box["height"] - 30), (120, -40), steps=10)
        assert np.linalg.norm(np.subtract(view_state(a)["camera"], a_camera)) > 0.1, "A's camera did not orbit"
        np.testing.assert_allclose(view_state(b)["camera"], b_camera, atol=1e-9)
        assert server.state()["session"]["controls"] == st2["session"]["controls"]  # orbiting moved no control
    finally:
        a.close()
        b.close()


def test_client_leaving_mid_drag_leaves_the_session_consistent(browser, server):
    page = open_page(browser, server)
    server.idle()
    i = pick_control(page)
    start = control_on_screen(page, i)
    mouse_drag(page, start, toward_centre(page, start, 60), release=False)
    server.wait(lambda s: held(s) == [i], what="the grab")
    history = server.state()["session"]["history"]
    page.close()  # the button is still down
    st1 = server.wait(lambda s: not held(s), what="the drag to be released")
    st1 = server.idle()
    controls = np.array(st1["session"]["controls"])
    assert np.isfinite(controls).all()
    np.testing.assert_allclose(np.array(st1["session"]["frame"]["controls"]), controls, atol=1e-6)
    assert st1["session"]["history"] == history  # the drag it left is the one step it began
    # a new tab shows the controls where they are and can drag again
    page = open_page(browser, server)
    try:
        np.testing.assert_allclose(np.array([page.evaluate(f"() => {VIEW}.controlModel({j})") for j in range(9)]),
                                   controls[:, :3], atol=1e-5)
        j = pick_control(page)
        start = control_on_screen(page, j)
        mouse_drag(page, start, toward_centre(page, start, 60))
        st2 = server.idle()
        assert np.linalg.norm(np.array(st2["session"]["controls"][j]) - controls[j]) > 0.1
    finally:
        page.close()


def test_another_tab_closing_leaves_the_drag_alone(browser, server):
    """Tab A holds a control with the mouse; tab B opens and closes. A's drag goes on (only the tab that pressed
    gets its button released when it goes), and A's release ends it where A let go."""
    a = open_page(browser, server)
    try:
        st0 = server.idle()
        i = pick_control(a)
        start = control_on_screen(a, i)
        delta = toward_centre(a, start, 90)
        mouse_drag(a, start, (delta[0] / 2, delta[1] / 2), steps=12, release=False)
        st = server.wait(lambda s: held(s) == [i], what="A's grab")
        clients = st["clients"]
        b = open_page(browser, server)
        server.wait(lambda s: s["clients"] == clients + 1, what="tab B connected")
        b.close()
        server.wait(lambda s: s["clients"] == clients, what="tab B gone")
        time.sleep(0.3)
        st = server.state()
        assert held(st) == [i], "tab B's closing ended tab A's drag"
        held_at = np.array(st["session"]["controls"][i][:3])
        # A goes on dragging: the control still follows A's mouse
        x, y = start[0] + delta[0] / 2, start[1] + delta[1] / 2
        for k in range(1, 13):
            a.mouse.move(x + delta[0] / 2 * k / 12, y + delta[1] / 2 * k / 12)
            time.sleep(0.03)
        st = server.wait(lambda s: np.linalg.norm(np.array(s["session"]["controls"][i][:3]) - held_at) > 0.05,
                         what="the control to follow A's mouse after B left")
        assert held(st) == [i]
        a.mouse.up()
        st1 = server.wait(lambda s: not held(s), what="A's release")
        assert np.linalg.norm(np.array(st1["session"]["controls"][i][:3]) - np.array(st0["session"]["controls"][i][:3])
                              ) > 0.2
        server.idle()
    finally:
        a.close()


def test_a_drag_goes_on_with_its_control_when_another_tab_removes_one_before_it(browser, server):
    """Interaction in two tabs: tab A holds a control with the mouse; tab B removes control 0 from its panel. A's
    mouse keeps moving the same control (now one place earlier), never the one that slid into its place, and A's
    release lets it go. The removal and the drag are two undo steps, in the order they completed."""
    a = open_page(browser, server)
    b = open_page(browser, server)
    try:
        st0 = server.idle()
        i = pick_control(a, prefer=(3, 5, 6, 4, 2, 7, 1, 8))
        assert i > 0
        start = control_on_screen(a, i)
        delta = toward_centre(a, start, 100)
        mouse_drag(a, start, (delta[0] / 3, delta[1] / 3), steps=8, release=False)
        server.wait(lambda s: held(s) == [i], what="A's grab")
        before = np.array(server.state()["session"]["controls"])
        b.locator("#controls-table tr").nth(0).locator("button").click()  # tab B removes control 0
        server.wait(lambda s: len(s["session"]["controls"]) == 8 and held(s) == [i - 1],
                    what="control 0 removed, A's control now one place earlier")
        x, y = start[0] + delta[0] / 3, start[1] + delta[1] / 3
        for k in range(1, 13):
            a.mouse.move(x + 2 * delta[0] / 3 * k / 12, y + 2 * delta[1] / 3 * k / 12)
            time.sleep(0.03)
        a.mouse.up()
        st = server.wait(lambda s: not held(s), what="A's release")
        st = server.idle()
        after = np.array(st["session"]["controls"])
        assert np.linalg.norm(after[i - 1, :3] - before[i, :3]) > 0.1, "A's control stopped following the mouse"
        np.testing.assert_array_equal(after[i], before[i + 1])  # the control that slid into A's place: untouched
        # the removal (completed first) and the drag are a step each: the first undo takes back the drag, and
        # keeps the removal; the second brings the car back
        steps = st["session"]["history"][0]
        a.locator("#undo-button").click()
        st = server.wait(lambda s: s["session"]["history"][0] == steps - 1, what="the drag taken back")
        assert len(st["session"]["controls"]) == 8
        a.locator("#undo-button").click()
        server.wait(lambda s: len(s["session"]["controls"]) == 9, what="the removed control back")
        server.idle()
        np.testing.assert_allclose(np.array(server.state()["session"]["controls"]),
                                   np.array(st0["session"]["controls"]), atol=1e-6)
    finally:
        a.close()
        b.close()


def test_preset_chooser_lines_and_export(browser, server, tmp_path):
    page = open_page(browser, server)
    try:
        gen = server.state()["session"]["generation"]
        page.locator(".v-select:has(#preset-select) .v-field").click()
        page.get_by_text("Case study 3: lines").click()
        st = server.wait(lambda s: s["session"]["preset"] == "lines" and s["session"]["generation"] > gen,
                         what="the lines preset")
        st = server.idle()
        assert st["session"]["n_dims"] == 8 and len(st["session"]["frame"]["effective_controls"]) == 16
        shows(page, st)
        assert view_state(page)["kEff"] == 16
        assert not_blank(view_image(page)) > 0.05
        def stamps(before):  # the minute of the click: "<day>-<hhmm>", local time (two exports of a day differ)
            return {f"{t:%Y-%m-%d-%H%M}" for t in (before, datetime.datetime.now())}

        before = datetime.datetime.now()
        with page.expect_download(timeout=20000) as dl:  # OBJ: the format menu's first choice
            page.locator("#export-mesh").click()
        assert dl.value.suggested_filename in {f"lines-{t}.obj" for t in stamps(before)}  # the session and the time
        path = tmp_path / "lines.obj"
        dl.value.save_as(path)
        text = path.read_text()
        assert text.count("\nv ") + text.startswith("v ") == 1204  # roots and tips
        page.locator(".v-select:has(#export-format) .v-field").click()  # the format menu: Rhino
        page.get_by_text("Rhino .3dm (mesh, controls)").click()
        before = datetime.datetime.now()
        with page.expect_download(timeout=20000) as dl:
            page.locator("#export-mesh").click()
        assert dl.value.suggested_filename in {f"lines-{t}.3dm" for t in stamps(before)}
        dl.value.save_as(tmp_path / "lines.3dm")
        rhino = helpers.read_3dm(tmp_path / "lines.3dm")
        assert len(rhino["clay"].vertices) == 1204 and len(rhino["controls"]) == 8
        before = datetime.datetime.now()
        with page.expect_download(timeout=20000) as dl:
            page.locator("#save-session").click()
        assert dl.value.suggested_filename in {f"lines-{t}.npz" for t in stamps(before)}
        saved = tmp_path / "session.npz"
        dl.value.save_as(saved)
        assert saved.stat().st_size > 1000
        page.locator(".v-select:has(#preset-select) .v-field").click()
        page.get_by_text("Case study 2: car").click()
        server.wait(lambda s: s["session"]["preset"] == "car", what="back to the car")
        page.locator("#session-upload").set_input_files(str(saved))
        server.wait(lambda s: s["session"]["preset"] == "lines" and s["session"]["n_dims"] == 8,
                    what="the saved session")
        server.idle()
        # a good mesh file: an octahedron becomes the clay
        octa = tmp_path / "octa.obj"
        octa.write_text("v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n"
                        "f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n")
        page.locator("#mesh-upload").set_input_files(str(octa))
        st = server.wait(lambda s: s["session"]["n_vertices"] == 6, what="the uploaded mesh")
        assert st["session"]["preset"] == "mesh:octa" and st["panel"]["error_message"] == ""
        st = server.idle()
        # the person's own shape, shown as it is: nothing trained, its controls on its vertices
        assert len(st["session"]["controls"]) == 6
        assert st["session"]["frame"]["iteration"] == st["session"]["frame"]["iterations"]
        corners = np.array(st["session"]["frame"]["positions"])
        np.testing.assert_allclose(np.abs(corners).sum(axis=1), 1.0, atol=1e-6)
        shows(page, st)
        assert view_state(page)["k"] == 6
        assert not_blank(view_image(page)) > 0.02
    finally:
        page.close()


def test_server_prints_its_url(server):
    text = server.log_path.read_text()
    assert f"http://127.0.0.1:{server.port}/" in text, text[-2000:]


# -- the upload handler, called as trame calls it (the protocol: crafted browser file names) -------------------------
OCTAHEDRON = (b"v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n"
              b"f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n")
_APP_NAMES = itertools.count(1)


@pytest.fixture
def local_app(tmp_path, monkeypatch):
    """The app (app.build_app) around a paused CPU session in this process, on a trame server that never starts;
    temporary files go to tmp_path/"tmp" so the test sees what is left behind."""
    from trame.app import get_server

    from somwidget.frontend.model import Session
    from somwidget.frontend.web.app import build_app

    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    session = Session("car", device="cpu", start=False)
    app = build_app(session, server=get_server(f"upload-test-{next(_APP_NAMES)}", client_type="vue3"))
    yield app
    app.close()
    session.close()


def _upload(app, name, content, field="mesh_upload"):
    value = {"name": name, "size": len(content), "type": "", "content": content}
    setattr(app.state, field, value)  # what the browser's file field leaves in trame's state
    handler = app.upload_mesh if field == "mesh_upload" else app.upload_session
    # an event loop of its own, on a thread of its own (Playwright's sync API keeps one running in this thread)
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        pool.submit(asyncio.run, handler(value)).result(120)


@pytest.mark.parametrize("name, shown", [
    ("../../escape.obj", "escape.obj"),
    ("..\\..\\escape.obj", "escape.obj"),
    ("nul\x00in\nname.obj", "nulinname.obj"),
    ("x" * 300 + ".obj", None),
])
def test_upload_handler_names_the_temporary_file_itself(local_app, tmp_path, name, shown):
    """The browser's file name picks the suffix and labels messages; it never becomes a path: `..`, separators, NUL
    and 300-byte names load the mesh, nothing is written outside a temporary folder that is removed, and the field
    is cleared."""
    app = local_app
    _upload(app, name, OCTAHEDRON)
    assert app.state.error_message == ""
    preset = app.session.preset
    assert preset.n_vertices == 6 and preset.name.startswith("mesh:")
    if shown is not None:
        assert preset.title == shown and preset.name == "mesh:" + shown[:-4]
    else:
        assert preset.title.endswith(".obj") and len(preset.title) <= 80
    assert app.state.mesh_upload is None
    assert os.listdir(tmp_path / "tmp") == []  # the temporary folder is gone
    assert sorted(os.listdir(tmp_path)) == ["tmp"]  # nothing escaped into the parent


@pytest.mark.parametrize("name, content, message", [
    ("..", OCTAHEDRON, "is not a mesh file"),
    ("no-suffix", OCTAHEDRON, "is not a mesh file"),
    ("junk.obj", b"\x00\x01 no mesh \xff" * 20, "junk.obj: "),
    ("empty.obj", b"", "is empty"),
    ("e" * 300 + "\x00.ply", b"ply\nformat ascii 1.0\nend_header\n", "..."),
])
def test_upload_handler_errors_clear_the_field_and_the_temporary_folder(local_app, tmp_path, name, content,
                                                                         message):
    app = local_app
    before = app.session.generation
    _upload(app, name, content)
    assert message in app.state.error_message
    assert str(tmp_path) not in app.state.error_message  # no server path in what the browser sees
    assert app.state.mesh_upload is None  # the bytes do not stay in trame's state
    assert app.session.generation == before and app.session.preset.name == "car"
    assert os.listdir(tmp_path / "tmp") == []


def test_session_upload_handler_clears_the_field(local_app, tmp_path):
    app = local_app
    _upload(app, "../saved\x00.npz", b"not a zip archive" * 10, field="session_upload")
    assert app.state.error_message and str(tmp_path) not in app.state.error_message
    assert "saved.npz" in app.state.error_message
    assert app.state.session_upload is None and os.listdir(tmp_path / "tmp") == []
    _upload(app, "empty.npz", b"", field="session_upload")
    assert "is empty" in app.state.error_message and app.state.session_upload is None


def test_variants_gallery_and_picking_one_is_an_undo_step(browser, server):
    """The panel's Variants section: a sweep of six variants shows six thumbnails (each a drawn clay, not a blank),
    clicking one makes it the session's shape in the view, and Undo brings the shape before it back."""
    page = open_page(browser, server)
    try:
        st0 = server.idle()
        page.locator("#variants-n").fill("6")
        page.locator("#variants-jitter").fill("0.08")
        page.wait_for_timeout(300)
        page.locator("#sweep").click()
        page.wait_for_function("() => document.querySelectorAll('#variants-gallery img').length === 6",
                               timeout=120000)
        thumbs = page.locator("#variants-gallery img")
        from PIL import Image

        shots = [np.asarray(Image.open(io.BytesIO(thumbs.nth(i).screenshot())).convert("RGB")).astype(int)
                 for i in range(6)]
        for shot in shots:  # each thumbnail shows a clay on the background, not an empty tile
            assert (np.abs(shot - shot[3, -3]).sum(axis=2) > 60).mean() > 0.05
        before_image = view_image(page)
        thumbs.nth(4).click()
        st1 = server.idle()
        assert st1["session"]["history"][0] == st0["session"]["history"][0] + 1
        assert st1["session"]["controls"] != st0["session"]["controls"]
        assert not st1["session"]["frame"]["running"]  # a variant is shown as trained: nothing regrows
        shows(page, st1)
        assert float((np.abs(view_image(page) - before_image).sum(axis=2) > 30).mean()) > 0.002
        page.locator("#undo-button").click()
        st2 = server.idle()
        assert st2["session"]["controls"] == st0["session"]["controls"]
        assert st2["session"]["frame"]["centroid"] == pytest.approx(st0["session"]["frame"]["centroid"], abs=1e-6)
    finally:
        page.close()
