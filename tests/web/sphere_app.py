"""The app the view tests act on: `somwidget serve --preset <name>` once per test file (the sphere's by default), a
tab on it per test, and where the view draws things (read through its read-only `describe()` and `controlScreen`)."""

from __future__ import annotations

import json
import os

import numpy as np
from helpers import Serve

VIEW = "document.getElementById('clay-view')?.somview"
SHOTS = os.environ.get("SOMWIDGET_SHOTS")  # a folder: the tests leave pictures there


def serve_sphere(preset: str = "sphere"):
    """The module's server (a fixture's body: `yield from serve_sphere()`, or `serve_sphere("grid")`)."""
    srv = Serve("--preset", preset)
    yield srv
    srv.stop()


def open_page(browser, server, width: int = 1400, height: int = 900):
    """A fresh tab of the given size once the view has drawn; closed after (the session left as the test leaves it:
    for files whose tests start from where the one before ended). A fixture's body: `yield from open_page(...)`."""
    page = browser.new_page(viewport={"width": width, "height": height})
    page.goto(server.url)
    page.wait_for_function(f"() => {{ const v = {VIEW}; return v && v.describe().painted > 0; }}", timeout=60000)
    page.wait_for_timeout(400)
    yield page
    page.close()


def model_screen(page, p) -> np.ndarray:
    """Where the model point p lies on the page (pixels), as the view draws it."""
    return np.asarray(page.evaluate(f"() => {VIEW}.modelScreen({json.dumps([float(x) for x in p])})"), float)


def shot(page, name: str, selector: str | None = "#clay-view") -> None:
    """A picture of the view (or the whole page: selector None) into SOMWIDGET_SHOTS, when that is set."""
    if SHOTS:
        os.makedirs(SHOTS, exist_ok=True)
        page.wait_for_timeout(400)
        path = os.path.join(SHOTS, f"{name}.png")
        page.locator(selector).screenshot(path=path) if selector else page.screenshot(path=path)


def drag(page, start, delta, steps: int = 12, shift: bool = False) -> None:
    """The mouse pressed at `start` (page pixels), moved by `delta` in `steps` steps 25 ms apart, released; with Shift
    held throughout when `shift`."""
    page.mouse.move(*start)
    if shift:
        page.keyboard.down("Shift")
    page.mouse.down()
    for s in range(1, steps + 1):
        page.mouse.move(start[0] + delta[0] * s / steps, start[1] + delta[1] * s / steps)
        page.wait_for_timeout(25)
    page.mouse.up()
    if shift:
        page.keyboard.up("Shift")


def press_key_in_view(page, key: str) -> None:
    """A key pressed with the pointer over the view (the view has the keys then), as a person would."""
    box = page.locator("#clay-view canvas").bounding_box()
    page.mouse.move(box["x"] + 40, box["y"] + box["height"] - 60)
    page.keyboard.press(key)
    page.wait_for_timeout(300)


def screen(page, j: int) -> np.ndarray:
    """Control j's place on the screen (page pixels)."""
    return np.asarray(page.evaluate(f"() => {VIEW}.controlScreen({j})"), float)


def open_tab(browser, server):
    """A tab on the app once its view has drawn the session as it is; the session is left as it was found (every
    step a test made undone, from the test's own tab where it can still be used). A fixture's body:
    `yield from open_tab(browser, server)`."""
    steps = server.idle()["session"]["history"][0]
    page = browser.new_page(viewport={"width": 1200, "height": 800})
    page.goto(server.url)
    page.wait_for_function(f"() => {{ const v = {VIEW}; return v && v.describe().painted > 0; }}", timeout=30000)
    page.wait_for_timeout(400)
    yield page
    try:
        undo_to(page, server, steps)
    except Exception:  # the test left its tab unusable (closed, a menu over the toolbar): a fresh tab does it
        fresh = browser.new_page(viewport={"width": 1200, "height": 800})
        fresh.goto(server.url)
        undo_to(fresh, server, steps)
        fresh.close()
    finally:
        if not page.is_closed():
            page.close()


def undo_to(page, server, steps: int) -> None:
    """Press the toolbar's Undo on `page` until the session has `steps` undo steps again (each press waited for)."""
    st = server.idle()
    page.wait_for_selector("#undo-button", timeout=30000)
    for _ in range(st["session"]["history"][0] - steps):
        before = server.state()["session"]["history"][0]
        page.wait_for_function("() => !document.querySelector('#undo-button').disabled", timeout=10000)
        page.locator("#undo-button").click(timeout=5000)
        server.wait(lambda s, n=before: s["session"]["history"][0] < n, timeout=10, what="an undo step taken")
    server.wait(lambda s: s["session"]["history"][0] <= steps, what="the steps undone")


def view(page) -> dict:
    return page.evaluate(f"() => {VIEW}.describe()")


def canvas(page) -> dict:
    return page.locator("#clay-view canvas").bounding_box()


def centre(page, dx: float = 0.0, dy: float = 0.0) -> tuple[float, float]:
    box = canvas(page)
    return box["x"] + box["width"] / 2 + dx, box["y"] + box["height"] / 2 + dy
