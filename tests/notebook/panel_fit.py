"""Whether the panel fits its page (issue 36, items 2 and 4): the checks test_panel_fits.py runs in Voila and marimo,
and test_notebook_panel.py in JupyterLab 4 and Notebook 7 (on the page its drag test has opened).

At each width every field of the panel (inputs, menus, buttons, sliders' handles) is in the page's width, on screen
once scrolled to, and not covered: the element at its centre (elementFromPoint) is the field itself; and no label,
button or heading is cut (its scrollWidth fits its clientWidth). SOMWIDGET_SHOTS=<folder> keeps a screenshot of each
host at 360 pixels there.
"""

from __future__ import annotations

import os

#: The page widths checked: a laptop, a phone.
WIDTHS = (1280, 360)
#: Every element of the page and of its shadow roots (marimo draws each widget in one) matching a selector.
FIND = """(selector) => { const out = []; const walk = (root) => { for (const e of root.querySelectorAll('*')) {
  if (e.matches(selector)) out.push(e); if (e.shadowRoot) walk(e.shadowRoot); } }; walk(document); return out; }"""

#: What is wrong with the first panel of the page at this width: fields out of the page's width, not on screen once
#: scrolled to, or under another element; labels cut. [] when it fits.
CHECK = """async () => {
  const find = """ + FIND + """;
  const panel = find('.somwidget-panel')[0];
  if (!panel) return ['no panel'];
  const shown = (e) => { const r = e.getBoundingClientRect(); return r.width > 0 && r.height > 0
    && getComputedStyle(e).visibility !== 'hidden'; };
  const inPanel = (selector) => [...panel.querySelectorAll(selector),
    ...[...panel.querySelectorAll('*')].filter((e) => e.shadowRoot)
      .flatMap((e) => [...e.shadowRoot.querySelectorAll(selector)])];
  const fields = inPanel('input, select, button, textarea, a, .noUi-handle, .widget-readout').filter(shown);
  const problems = [];
  const name = (e) => (e.getAttribute('title') || e.getAttribute('aria-label') || e.textContent || e.value
    || e.placeholder || e.className || e.tagName).toString().trim().slice(0, 40);
  // a field's verdict after it was scrolled to and the host settled: a windowed notebook (Notebook 7) places its
  // cells again over a few frames after a scroll, so a field is judged on the last of up to 12 looks
  const frame = () => new Promise((r) => requestAnimationFrame(r));
  const verdict = (f) => {
    const r = f.getBoundingClientRect();
    const x = r.left + r.width / 2, y = r.top + r.height / 2;
    if (r.left < -1 || r.right > innerWidth + 1) {
      return `off the width: ${name(f)} [${Math.round(r.left)}, ${Math.round(r.right)}] of ${innerWidth}`;
    }
    if (y < 0 || y > innerHeight) return `not on screen: ${name(f)}`;
    const hit = f.getRootNode().elementFromPoint(x, y);
    if (!hit || !(hit === f || f.contains(hit) || (hit.tagName === 'LABEL' && hit.contains(f)))) {
      return `covered: ${name(f)} by ${hit ? hit.tagName + '.' + hit.className : 'nothing'}`;
    }
    return null;
  };
  for (const f of fields) {
    let problem = null;
    for (let look = 0; look < 12; look++) {
      f.scrollIntoView({ block: 'center', inline: 'nearest' });
      await frame();
      await frame();
      problem = verdict(f);
      if (!problem) break;
    }
    if (problem) problems.push(problem);
  }
  const labels = 'label, .widget-label, .widget-label-basic, button, .widget-html-content, .widget-readout, th';
  for (const l of inPanel(labels)) {
    if (!shown(l)) continue;
    if (l.scrollWidth > l.clientWidth + 1) problems.push(`cut: ${name(l)} (${l.scrollWidth} > ${l.clientWidth})`);
  }
  return problems.length ? problems : (fields.length > 20 ? [] : [`only ${fields.length} fields`]);
}"""


def make_room(page) -> None:
    """What a person does in a narrow JupyterLab: close the file browser (it keeps its width) and the news toast."""
    tab = page.locator(".jp-SideBar.jp-mod-left .lm-TabBar-tab.lm-mod-current")
    if tab.count():
        tab.first.click()
    no = page.locator(".jp-toast-button", has_text="No")
    if no.count() and no.first.is_visible():
        no.first.click()


def check_widths(page, host: str) -> None:
    """At each width the panel fits (CHECK); a screenshot at 360 pixels where SOMWIDGET_SHOTS says."""
    for width in WIDTHS:
        page.set_viewport_size({"width": width, "height": 900})
        page.wait_for_timeout(1500)  # the page lays itself out again
        if width < 600 and host == "jupyterlab":
            make_room(page)
            page.wait_for_timeout(800)
        problems = page.evaluate(CHECK)
        assert problems == [], f"{host} at {width} px: {problems}"
        if width == 360 and os.environ.get("SOMWIDGET_SHOTS"):
            page.evaluate(f"() => ({FIND})('.somwidget-panel')[0].scrollIntoView({{block: 'start'}})")
            page.wait_for_timeout(300)
            page.screenshot(path=os.path.join(os.environ["SOMWIDGET_SHOTS"], f"panel-{host}-360.png"))


def wait_for_view(page, timeout: float = 180000) -> None:
    page.wait_for_function(f"() => ({FIND})('.somview').some((e) => e.somview && e.somview.describe().painted > 0) "
                           f"&& ({FIND})('.somwidget-panel').length > 0", timeout=timeout)
