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
