"""The web app's panel tells the truth, and the page survives a server restart: Chromium (Playwright) against
`somwidget serve`, acting as a person does (the keyboard in the panel's fields, the mouse on its buttons).

- a refused value (smoothing -0.3, l_end -1, a metric weight -1) shows its message, and its field then shows the
  value in effect, also after a reload;
- Ctrl+Z in a field undoes the typing there, not a step of the clay; outside a field it undoes the step;
- the run button says what a press does (Pause / Resume / Train), and a new preset is not left paused;
- the server killed and started again on the same port: the page says it is reconnecting, comes back by itself with
  the session as the restarted server has it (recovered from its autosave), and the recovered banner can be
  dismissed; the XR page's clay view reconnects too.
"""

from __future__ import annotations

import glob
import json
import time

import pytest
from helpers import Serve, free_port, wait_for
from playwright import sync_api as playwright_sync
from test_app_browser import VIEW, VIEWPORT, open_page

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def server():
    srv = Serve()
    yield srv
    srv.stop()


def field(page, name: str) -> str:
    return page.locator(f"#field-{name}").input_value()


def type_into(page, name: str, text: str) -> None:
    """Click the field, replace its text by typing, press Enter (as a person does)."""
    box = page.locator(f"#field-{name}")
    box.click()
    page.keyboard.press("Control+a")
    page.keyboard.type(text)
    page.keyboard.press("Enter")


def field_shows(page, name: str, value: str, server, timeout: float = 5000) -> None:
    """Wait until the field `name` shows `value`; else fail saying what it shows, what has the focus and the
    session's undo history."""
    try:
        page.wait_for_function("([n, v]) => document.querySelector('#field-' + n).value === v", arg=[name, value],
                               timeout=timeout)
    except playwright_sync.TimeoutError:
        shown, focus = page.evaluate("(n) => [document.querySelector('#field-' + n).value, "
                                     "document.activeElement?.id || document.activeElement?.tagName]", name)
        raise AssertionError(f"#field-{name} shows {shown!r}, not {value!r} (focus on {focus}, history "
                             f"{server.state()['session']['history']})") from None


def run_label(page) -> str:
    return page.locator("#train-button").inner_text().strip()


def wait_label(page, label: str) -> None:
    page.wait_for_function("(l) => document.querySelector('#train-button').innerText.trim() === l", arg=label,
                           timeout=15000)


def test_a_refused_value_shows_its_message_then_the_value_in_effect_also_after_a_reload(browser, server):
    page = open_page(browser, server)
    try:
        for name, typed, in_effect in (("smoothing", "-0.3", "0"), ("l_end", "-1", "0.03")):
            type_into(page, name, typed)
            page.wait_for_function("(n) => document.querySelector('#error-alert')?.innerText.includes(n + ':')",
                                   arg=name, timeout=10000)
            page.wait_for_function("([n, v]) => document.querySelector('#field-' + n).value === v",
                                   arg=[name, in_effect], timeout=10000)
            assert typed in page.locator(f"#param-{name} .v-messages").inner_text()  # the message at the field
        params = server.state()["session"]["parameters"]
        assert params["smoothing"] == 0.0 and params["l_end"] == 0.03
        weight = page.locator("#features-table tr").nth(3).locator("input")
        weight.click()
        page.keyboard.press("Control+a")
        page.keyboard.type("-1")
        page.keyboard.press("Enter")
        page.wait_for_function("() => document.querySelector('#error-alert')?.innerText.includes('metric weight')",
                               timeout=10000)
        page.wait_for_function("() => document.querySelectorAll('#features-table tr')[3].querySelector('input')"
                               ".value === '1'", timeout=10000)
        page.reload()
        page.wait_for_function(f"() => {VIEW}?.describe().painted > 0", timeout=30000)
        assert (field(page, "smoothing"), field(page, "l_end")) == ("0", "0.03")
        assert page.locator("#features-table tr").nth(3).locator("input").input_value() == "1"
    finally:
        page.close()


def test_ctrl_z_in_a_field_undoes_the_typing_there_and_elsewhere_a_step(browser, server):
    page = open_page(browser, server)
    try:
        type_into(page, "smoothing", "0.1")  # a step of the clay to undo
        server.wait(lambda s: s["session"]["parameters"]["smoothing"] == 0.1, what="smoothing 0.1")
        steps = server.idle()["session"]["history"]  # the step recorded and shown in a frame
        page.locator("#field-smoothing").click()
        page.keyboard.press("Control+a")
        page.keyboard.type("0.4")
        page.keyboard.press("Control+z")  # the field's own undo: the typing goes
        field_shows(page, "smoothing", "0.1", server)
        page.wait_for_timeout(500)
        st = server.state()
        assert st["session"]["history"] == steps and st["session"]["parameters"]["smoothing"] == 0.1
        page.locator("#iteration-text").click()  # out of the field: Ctrl+Z is the clay's undo
        page.keyboard.press("Control+z")
        server.wait(lambda s: s["session"]["parameters"]["smoothing"] == 0.0, what="the step undone")
        field_shows(page, "smoothing", "0", server, timeout=10000)
        server.idle()
    finally:
        page.close()


def test_the_run_button_says_what_a_press_does_and_a_new_preset_is_not_left_paused(browser, server):
    page = open_page(browser, server)
    try:
        server.idle()
        wait_label(page, "TRAIN")  # settled: a press trains again
        type_into(page, "iterations", "1000000")
        server.wait(lambda s: s["session"]["frame"]["running"], what="a long run")
        wait_label(page, "PAUSE")
        page.locator("#train-button").click()
        st = server.wait(lambda s: s["session"]["paused"] and not s["session"]["frame"]["running"], what="paused")
        assert st["session"]["frame"]["iteration"] < st["session"]["frame"]["iterations"]
        wait_label(page, "RESUME")  # stopped part way: a press goes on
        page.locator("#train-button").click()
        server.wait(lambda s: not s["session"]["paused"] and s["session"]["frame"]["running"], what="resumed")
        wait_label(page, "PAUSE")
        page.locator("#train-button").click()
        server.wait(lambda s: s["session"]["paused"], what="paused again")
        wait_label(page, "RESUME")
        # a new preset while paused starts by its own rule: a case study grows
        page.locator(".v-select:has(#preset-select) .v-field").click()
        page.get_by_text("Case study 3: lines").click()
        st = server.wait(lambda s: s["session"]["preset"] == "lines", what="the lines preset")
        assert not st["session"]["paused"]
        server.idle(60)
        wait_label(page, "TRAIN")
        page.locator(".v-select:has(#preset-select) .v-field").click()
        page.get_by_text("Case study 2: car").click()
        server.wait(lambda s: s["session"]["preset"] == "car", what="the car again")
        server.idle(60)
    finally:
        page.close()


def saved_smoothing(data_dir) -> list[float]:
    """The smoothing of each autosaved session's current step in a server's data directory."""
    out = []
    for path in glob.glob(str(data_dir / "autosave" / "*" / "manifest.json")):
        try:
            out.append(float(json.loads(open(path).read())["current"]["parameters"]["smoothing"]))
        except (OSError, ValueError, KeyError):  # being renamed into place
            pass
    return out


def test_the_page_and_the_xr_page_reconnect_by_themselves_after_the_server_restarts(browser, tmp_path):
    port = free_port()
    env = {"SOMWIDGET_DATA_DIR": str(tmp_path / "data")}
    first = Serve("--port", str(port), env=env)
    second = None
    xr = None
    page = open_page(browser, first)
    try:
        xr = browser.new_page(viewport=VIEWPORT)
        xr.goto(first.base + "/xr/")
        xr.wait_for_function("() => window.somxr && somxr.state().frames > 0", timeout=30000)
        type_into(page, "smoothing", "0.05")  # a completed step: the autosave keeps it
        wait_for(lambda: 0.05 in saved_smoothing(tmp_path / "data"), what="the step autosaved")
        first.proc.kill()  # the server goes away (SIGKILL: no clean close)
        first.proc.wait(10)
        note = page.locator("#reconnecting")
        note.wait_for(timeout=10000)
        assert "reconnecting" in note.inner_text()
        xr.wait_for_function("() => document.getElementById('status').textContent.includes('reconnecting')",
                             timeout=10000)
        second = Serve("--port", str(port), env=env)  # back on the same port
        back = time.monotonic()
        page.wait_for_function(f"() => !document.getElementById('reconnecting') && {VIEW}?.describe().painted > 0",
                               timeout=15000)
        xr.wait_for_function("() => somxr.state().connected && somxr.state().link.reconnects > 0 "
                             "&& !document.getElementById('status').textContent.includes('reconnecting')",
                             timeout=15000)
        assert time.monotonic() - back < 8.0
        assert field(page, "smoothing") == "0.05"  # the session as the restarted server has it
        assert second.state()["session"]["parameters"]["smoothing"] == 0.05
        banner = page.locator("#recovered-alert")
        assert "Brought back your session" in banner.inner_text()
        banner.locator("button[aria-label='Close']").click()
        banner.wait_for(state="detached", timeout=5000)
        wait_for(lambda: second.state()["panel"]["recovered_message"] == "", what="the banner dismissed")
    finally:
        page.close()
        if xr is not None:
            xr.close()
        first.stop()
        if second is not None:
            second.stop()
