"""Clients cannot write the page or each other's state (issue 17, item 2), as the attack: a crafted websocket client
of the trame page sends state updates for the page template, `busy` and a preset name of the wrong type, while a
tab is open in Chromium; none reaches the server's state or any tab, new tabs included, and a key the page's own
widgets write still goes through."""

from __future__ import annotations

import asyncio
import concurrent.futures
import os

import helpers
import msgpack
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS

pytestmark = pytest.mark.browser

playwright_sync = pytest.importorskip("playwright.sync_api", reason="Python Playwright is not installed")
if not os.path.exists(CHROMIUM):  # pragma: no cover - depends on the machine
    pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)", allow_module_level=True)

VIEW = "document.getElementById('clay-view')?.somview"


async def crafted_client(base: str, changes: list) -> None:
    import aiohttp

    async with aiohttp.ClientSession() as cs, cs.ws_connect(base.replace("http", "ws") + "/ws",
                                                            headers={"Origin": base}) as ws:
        messages = [{"wslink": "1.0", "id": "system:c0:0", "method": "wslink.hello",
                     "args": [{"secret": "wslink-secret"}], "kwargs": {}},
                    {"wslink": "1.0", "id": "rpc:c0:1", "method": "trame.state.update", "args": [changes],
                     "kwargs": {}}]
        for mid, msg in enumerate(messages, start=1):
            await ws.send_bytes(helpers.wslink_chunk(mid, msgpack.packb(msg)))
            await ws.receive(timeout=10)


def test_a_crafted_client_cannot_write_the_template_or_other_tabs_state():
    serve = helpers.Serve()
    try:
        with playwright_sync.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                tab = browser.new_page()
                tab.goto(serve.url)
                tab.wait_for_function(f"() => {{ const v = {VIEW}; return v && v.describe().frames > 0; }}",
                                      timeout=30000)
                serve.idle()
                attack = [{"key": "trame__template_main", "value": "<div id='pwned'>owned</div>"},
                          {"key": "busy", "value": True},
                          {"key": "error_message", "value": "a message another client wrote"},
                          {"key": "preset_name", "value": {"not": "a name"}},
                          {"key": "param_symmetry", "value": False}]  # the page's own widget: goes through
                with concurrent.futures.ThreadPoolExecutor(1) as pool:  # Playwright holds this thread's loop
                    pool.submit(lambda: asyncio.run(crafted_client(serve.base, attack))).result()
                st = serve.wait(lambda s: not s["session"]["parameters"]["symmetry"]
                                and len(s["session"]["controls"]) == 18, what="the allowed key (symmetry off) applied")
                assert st["session"]["preset"] == "car"
                assert st["panel"]["error_message"] == ""
                tab.wait_for_timeout(1000)
                assert tab.locator("#pwned").count() == 0
                assert tab.locator("#mesh-upload").is_enabled()  # `busy` did not reach the tab
                assert tab.locator("#clay-view canvas").count() == 1  # the page is the app's still
                fresh = browser.new_page()  # a tab opened after the attack gets the app's page too
                fresh.goto(serve.url)
                fresh.wait_for_function(f"() => {{ const v = {VIEW}; return v && v.describe().frames > 0; }}",
                                        timeout=30000)
                assert fresh.locator("#pwned").count() == 0 and fresh.locator("#mesh-upload").is_enabled()
                assert "refused a client's state update for trame__template_main, busy, error_message, " \
                       "preset_name" in serve.output()
            finally:
                browser.close()
    finally:
        serve.stop()
