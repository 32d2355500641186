"""The sphere app the view tests act on: `somwidget serve --preset sphere` once per test file, a tab on it per test,
and where the view draws things (read through its read-only `describe()` and `controlScreen`)."""

from __future__ import annotations

from helpers import Serve

VIEW = "document.getElementById('clay-view')?.somview"


def serve_sphere():
    """The module's server (a fixture's body: `yield from serve_sphere()`)."""
    srv = Serve("--preset", "sphere")
    yield srv
    srv.stop()


def open_tab(browser, server):
    """A tab on the app once its view has drawn the session as it is; the session is left as it was found (every
    step a test made undone). A fixture's body: `yield from open_tab(browser, server)`."""
    steps = server.idle()["session"]["history"][0]
    page = browser.new_page(viewport={"width": 1200, "height": 800})
    page.goto(server.url)
    page.wait_for_function(f"() => {{ const v = {VIEW}; return v && v.describe().painted > 0; }}", timeout=30000)
    page.wait_for_timeout(400)
    yield page
    page.close()
    undo_to(browser, server, steps)


def undo_to(browser, server, steps: int) -> None:
    """Press the toolbar's Undo until the session has `steps` undo steps again."""
    st = server.idle()
    if st["session"]["history"][0] <= steps:
        return
    page = browser.new_page(viewport={"width": 1200, "height": 800})
    page.goto(server.url)
    page.wait_for_selector("#undo-button", timeout=30000)
    for _ in range(st["session"]["history"][0] - steps):
        page.wait_for_function("() => !document.querySelector('#undo-button').disabled", timeout=10000)
        page.locator("#undo-button").click()
        page.wait_for_timeout(250)
    server.wait(lambda s: s["session"]["history"][0] <= steps, what="the steps undone")
    page.close()


def view(page) -> dict:
    return page.evaluate(f"() => {VIEW}.describe()")


def canvas(page) -> dict:
    return page.locator("#clay-view canvas").bounding_box()


def centre(page, dx: float = 0.0, dy: float = 0.0) -> tuple[float, float]:
    box = canvas(page)
    return box["x"] + box["width"] / 2 + dx, box["y"] + box["height"] / 2 + dy
