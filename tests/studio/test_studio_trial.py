"""A teacher's first-time trial of the studio in Chromium, with the mouse and keyboard only (issue 37): what they met,
each acted as they did and checked as they see it.

- a parked room's thumbnail on the wall after the studio restarts (kept in the room's folder, not only in memory);
- the watch page shown read-only: its editing controls disabled, with a tooltip that says why, the view still orbits;
- an error said once on a room's page, where it can be read;
- "Copy link" on the wall says it copied (or shows the link to copy by hand);
- a tooltip near the window's right edge stays on screen;
- a click on a thumbnail says the room is opening until its tab has it.

Needs /usr/bin/chromium, Python Playwright and the built client (npm run build).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from helpers import skip_unless_browser_and_client
from room_page import press_on

from somwidget.frontend.studio.limits import StudioLimits
from somwidget.frontend.studio.serve import StudioServer

pytestmark = pytest.mark.browser

skip_unless_browser_and_client()

SHOTS = os.environ.get("SOMWIDGET_SHOTS")  # a folder to keep the pages' screenshots in (looked at by a person)
#: What the wall's person sees of a room: how many of its thumbnail's pixels are drawn on.
INK = """(name) => {
  const canvas = document.querySelector(`section.room[data-name="${name}"] canvas`);
  const data = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
  let ink = 0;
  for (let i = 3; i < data.length; i += 4) { if (data[i] > 0) ink += 1; }
  return ink;
}"""


def shot(page, name: str) -> None:
    if SHOTS:
        page.screenshot(path=os.path.join(SHOTS, name))


def test_a_parked_rooms_thumbnail_is_on_the_wall_after_the_studio_restarts(tmp_path, browser):
    folder = tmp_path / "rooms"
    with StudioServer(folder, device="cpu", limits=StudioLimits(park_after=0)) as studio:
        studio.call(studio.front.create("ada", "sphere"))
        session = studio.front.places[0].rooms.get("ada").session
        assert session.wait_idle(180)
    # the studio stopped (the room parked, saved); started again, the room is known but nobody opens it
    with StudioServer(folder, device="cpu", limits=StudioLimits(park_after=0)) as studio:
        assert not studio.front.places[0].rooms.live()
        page = browser.new_page(viewport={"width": 900, "height": 600})
        page.goto(studio.wall_url)
        page.wait_for_function("somwall.state().rooms.some((r) => r.name === 'ada')", timeout=30000)
        page.wait_for_function("somwall.state().rooms.some((r) => r.name === 'ada' && r.drawn > 0)", timeout=10000)
        page.wait_for_timeout(100)
        assert page.evaluate(INK, "ada") > 2000  # the sphere's clay drawn, not an empty frame
        assert "parked" in page.inner_text('section.room[data-name="ada"] .state')
        assert not studio.front.places[0].rooms.live()  # shown without bringing the room back
        shot(page, "wall_after_restart.png")
        page.close()


@pytest.fixture(scope="module")
def studio(tmp_path_factory):
    with StudioServer(tmp_path_factory.mktemp("rooms"), device="cpu", limits=StudioLimits(park_after=0)) as s:
        s.call(s.front.create("bea", "sphere"))
        assert s.front.places[0].rooms.get("bea").session.wait_idle(180)
        yield s


def session_of(studio, name):
    return studio.front.places[0].rooms.get(name).session


#: The watch page's controls that change the clay: the HUD's buttons and the view's drawing tools.
EDITING = ("#train", "#undo", "#redo", "#reset", ".somview-stroke", ".somview-revolve")


def test_the_watch_page_shows_itself_read_only_and_its_view_still_orbits(studio, browser):
    session = session_of(studio, "bea")
    before, steps = session.controls.copy(), session.history[0]
    page = browser.new_page(viewport={"width": 1000, "height": 640})
    page.goto(studio.room_url("bea", watch=True))
    page.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=30000)
    page.wait_for_timeout(300)
    shot(page, "watch_page.png")
    for selector in EDITING:  # what the person sees: greyed out, and the tooltip says why and what to do instead
        control = page.locator(selector)
        assert control.is_disabled(), f"{selector} looks enabled on a page that only watches"
        title = control.get_attribute("title") or ""
        assert "watching only" in title and "Take part" in title, (selector, title)
    assert page.locator(".somview-fit").is_enabled() and page.locator(".somview-display").is_enabled()
    # the headset's menu (drawn in the room around the clay) greys the same buttons, and a press on one does nothing
    for name in ("train", "undo", "redo", "reset", "stroke"):
        button = page.evaluate(f"somxr.button('{name}')")
        assert not button["enabled"] and max(button["face"]) > 60, (name, button)  # the dim grey face, not the dark one
    assert page.evaluate("somxr.button('here')")["enabled"]
    assert page.evaluate("somxr.state().menuStatus").startswith("WATCHING ONLY")

    # a drag that starts on a control turns the view (the camera moves round the clay)
    camera = "document.getElementById('view').somview.rig.camera.position.toArray()"
    eye = np.array(page.evaluate(camera))
    x, y = page.evaluate("somxr.controlScreen(0)")
    page.mouse.move(x, y)
    page.wait_for_timeout(150)
    assert page.evaluate("somxr.state().hover") == []  # no control lights up to be taken
    page.mouse.down()
    for s in range(1, 10):
        page.mouse.move(x + 15 * s, y - 4 * s)
        page.wait_for_timeout(30)
    page.mouse.up()
    page.wait_for_timeout(200)
    moved = np.linalg.norm(np.array(page.evaluate(camera)) - eye)
    assert moved > 0.1 * np.linalg.norm(eye), f"the view did not orbit (its camera moved {moved:.3g})"
    page.keyboard.press("Control+z")  # and the keys that change the clay do nothing
    page.keyboard.press("Delete")
    page.wait_for_timeout(500)
    assert page.evaluate("somxr.state().errors") == []  # nothing was sent to be refused
    assert session.wait_idle(60)
    np.testing.assert_array_equal(session.controls, before)
    assert session.history[0] == steps
    page.close()


#: The elements the person sees that say `text` themselves (their own text nodes), as [selector-ish, rect].
SAYING = """(text) => {
  const out = [];
  for (const el of document.querySelectorAll('body *')) {
    const own = [...el.childNodes].filter((n) => n.nodeType === 3).map((n) => n.textContent).join('');
    if (!own.includes(text)) continue;
    const r = el.getBoundingClientRect();
    const style = getComputedStyle(el);
    if (r.width && r.height && style.visibility !== 'hidden' && el.checkVisibility({ opacityProperty: true })) {
      out.push({ id: el.id, cls: el.className, x: r.x + r.width / 2, y: r.y + r.height / 2 });
    }
  }
  return out;
}"""


def test_an_error_on_a_rooms_page_is_said_once_where_it_can_be_read(studio, browser):
    k = session_of(studio, "bea").n_controls
    context = browser.new_context(viewport={"width": 1000, "height": 640})
    first, second = context.new_page(), context.new_page()
    for page in (first, second):
        page.goto(studio.room_url("bea"))
        page.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=30000)
    press_on(first, 2, k)  # the first person holds control 2
    first.wait_for_timeout(300)
    x, y = press_on(second, 2, k)  # the second tries to drag it too: refused, told who holds it
    for s in range(1, 5):
        second.mouse.move(x - 6 * s, y + 4 * s)
        second.wait_for_timeout(40)
    second.mouse.up()
    second.wait_for_function("(somxr.state().lastError || '').includes('held by')", timeout=10000)
    shot(second, "room_page_error.png")
    shown = second.evaluate(SAYING, "held by")
    assert len(shown) == 1, f"the error is shown {len(shown)} times: {shown}"
    (where,) = shown
    assert where["id"] == "error", where  # in the panel
    on_top = second.evaluate(f"document.elementFromPoint({where['x']}, {where['y']}).id")
    assert on_top == "error", f"the error is covered by #{on_top}"
    first.mouse.up()
    context.close()


def open_wall(context, studio):
    wall = context.new_page()
    wall.goto(studio.wall_url)
    wall.wait_for_function("somwall.state().rooms.some((r) => r.name === 'bea' && r.drawn > 0)", timeout=30000)
    return wall


def test_copy_link_says_copied_or_shows_the_link_to_copy_by_hand(studio, browser):
    link = studio.room_url("bea")
    context = browser.new_context(viewport={"width": 900, "height": 600})
    context.grant_permissions(["clipboard-read", "clipboard-write"], origin=studio.base)
    wall = open_wall(context, studio)
    copy = wall.locator('section.room[data-name="bea"] a.copy')
    copy.click()
    wall.wait_for_function("""document.querySelector('section.room[data-name="bea"] a.copy').textContent
                              === 'Copied'""", timeout=3000)
    shot(wall, "wall_copied.png")
    assert wall.evaluate("navigator.clipboard.readText()") == link
    wall.wait_for_function("""document.querySelector('section.room[data-name="bea"] a.copy').textContent
                              === 'Copy link'""", timeout=6000)  # for a moment
    context.close()

    # a browser that refuses the clipboard (a page over plain http beyond this machine): the link to copy by hand
    context = browser.new_context(viewport={"width": 900, "height": 600})
    context.add_init_script("""navigator.clipboard.writeText = () =>
        Promise.reject(new DOMException('Write permission denied.', 'NotAllowedError'));""")
    wall = open_wall(context, studio)
    wall.locator('section.room[data-name="bea"] a.copy').click()
    field = wall.locator('section.room[data-name="bea"] .by-hand input')
    field.wait_for(state="visible", timeout=3000)
    assert field.input_value() == link
    assert wall.evaluate("[document.activeElement.selectionStart, document.activeElement.selectionEnd]") == \
        [0, len(link)]  # selected: Ctrl+C copies it
    assert "Copy this link" in wall.inner_text('section.room[data-name="bea"] .by-hand')
    shot(wall, "wall_copy_by_hand.png")
    context.close()


def test_the_radius_label_and_the_status_line_stay_on_screen_and_clear_of_the_bar_in_a_narrow_window(studio, browser):
    width, height = 640, 600
    page = browser.new_page(viewport={"width": width, "height": height})
    page.goto(studio.room_url("bea"))
    page.wait_for_function("window.somxr && somxr.state().connected && somxr.state().frames > 0", timeout=30000)
    label = page.locator(".somview-radius")
    for x in range(width - 40, width // 2, -20):  # the pointer on the clay as near the window's right edge as it goes
        page.mouse.move(x, height // 2)
        page.wait_for_timeout(120)
        if label.is_visible():
            break
    shot(page, "radius_label_at_the_edge.png")
    assert label.is_visible(), "no radius label beside the cursor"
    box = label.bounding_box()
    assert box["x"] >= 0 and box["x"] + box["width"] <= width, f"the label is cut off at the side: {box}"
    assert box["y"] >= 0 and box["y"] + box["height"] <= height, f"the label is cut off: {box}"
    page.mouse.move(x - 10, height - 20)  # and near the bottom edge: it goes above the cursor
    page.wait_for_timeout(120)
    if label.is_visible():
        box = label.bounding_box()
        assert box["y"] + box["height"] <= height, f"the label is cut off at the bottom: {box}"
    # in a window this narrow the status line at the foot stays clear of the view's bar of buttons
    status = page.locator(".somview-status").bounding_box()
    for button in page.locator(".somview-bar button").all():
        b = button.bounding_box()
        apart = (status["x"] + status["width"] <= b["x"] or b["x"] + b["width"] <= status["x"]
                 or status["y"] + status["height"] <= b["y"] or b["y"] + b["height"] <= status["y"])
        assert apart, f"the status line {status} runs under the button {button.inner_text()!r} {b}"
    page.close()


def test_a_click_on_a_thumbnail_says_the_room_is_opening_until_its_tab_shows_it(studio, browser):
    context = browser.new_context(viewport={"width": 900, "height": 600})
    wall = open_wall(context, studio)
    note = wall.locator('section.room[data-name="bea"] .opening')
    with context.expect_page() as opened:
        wall.click('section.room[data-name="bea"] canvas')
    assert note.is_visible() and "Opening bea" in note.inner_text()  # at once, on the card clicked
    shot(wall, "wall_opening.png")
    tab = opened.value
    tab.wait_for_function("window.somxr && somxr.state().frames > 0", timeout=30000)
    note.wait_for(state="hidden", timeout=5000)  # gone once the room shows in its tab
    context.close()
