"""VS Code and Colab draw an anywidget from its `_esm` text alone, with no Jupyter server extension (anywidget's
convention): in a bare Chromium page (no Jupyter at all) the clay view's module and the panel's module load from the
widgets' `_esm`, their `render` draws into an element with a stand-in model, and the view says hello over it."""

from __future__ import annotations

import os

import helpers
import pytest
from helpers import CHROMIUM, CHROMIUM_ARGS

from somwidget.frontend.model.panel import ACTION_HELP

pytestmark = pytest.mark.browser

#: A stand-in for anywidget's model: traits in a map, messages recorded.
LOAD = """async ([esm, traits]) => {
  const url = URL.createObjectURL(new Blob([esm], { type: 'text/javascript' }));
  const mod = (await import(url)).default;
  const sent = [];
  const model = { get: (k) => traits[k], set: (k, v) => { traits[k] = v; }, save_changes: () => {},
    on: () => {}, off: () => {}, send: (m) => sent.push(m) };
  const el = document.createElement('div');
  el.style.width = '600px';
  document.body.appendChild(el);
  mod.render({ model, el });
  await new Promise((r) => setTimeout(r, 500));
  return { sent, html: el.innerHTML.length, canvas: !!el.querySelector('canvas'),
           inputs: el.querySelectorAll('input, select, button').length,
           buttons: Object.fromEntries([...el.querySelectorAll('button')].map((b) => [b.textContent, b.title])) };
}"""


def test_the_modules_load_from_their_esm_without_jupyter(tmp_path):
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} is missing")
    from somwidget.frontend.model import Session
    from somwidget.frontend.notebook import show

    session = Session("car", device="cpu", paused=True, autosave=False)
    w = show(session, panel="anywidget")
    try:
        panel = w.panel
        panel_traits = {k: getattr(panel, k) for k in ("fields", "sections", "values", "status", "presets", "groups",
                                                        "features", "controls", "exports", "actions", "off_clay",
                                                        "error")}
        with helpers.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page()
                page.set_content("<html><body></body></html>")
                view = page.evaluate(LOAD, [w.view._esm, {"height": 300, "picture": ""}])
                assert view["canvas"] and {"type": "hello"} in [{"type": m.get("type")} for m in view["sent"]], view
                shown = page.evaluate(LOAD, [panel._esm, panel_traits])
                assert shown["inputs"] > 20, shown  # every declared field, the buttons, the menus
                # the buttons say what they do in the web page's words (model/panel.py ACTIONS)
                for name in ("reset", "reload_preset", "undo", "refine"):
                    label, words = panel.actions[name]
                    assert shown["buttons"].get(label) == ACTION_HELP[name], (name, shown["buttons"])
            finally:
                browser.close()
    finally:
        w.close()
        session.close()
