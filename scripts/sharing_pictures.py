"""The pictures of docs/sharing/: what a person sees around a mouse up, and who else is on the session.

    python scripts/sharing_pictures.py release OUT.png    # the frames around a mouse up on a settled clay
    python scripts/sharing_pictures.py presence OUT.png   # two views of one session, each showing the other

`release`: a real Session (the car, S = 10,000) served by XRServer, the XR page's desktop preview in Chromium
(Playwright); the mouse drags control 2, holds still until the clay has settled, and lets go. Screenshots are taken
just before the mouse up and as fast as the page allows for a second and a half after it; the strip shows the one
before, the one after it with the lowest iteration shown (a run the release started, if any; else the middle one),
and the last, each captioned with the iteration the page shows and how far its vertices are from the settled clay's.
Run it in a tree of an older commit to see what a mouse up did there.
"""

from __future__ import annotations

import io
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from helpers import CHROMIUM, CHROMIUM_ARGS  # noqa: E402
from playwright.sync_api import sync_playwright  # noqa: E402

from somwidget.frontend.model import Session  # noqa: E402
from somwidget.frontend.web.standalone import XRServer  # noqa: E402

VIEWPORT = {"width": 420, "height": 420}
CROP = (30, 142, 420, 362)  # the clay, below the page's HUD, above its bar


def shot(page, settled=None) -> tuple[Image.Image, int, float]:
    """(picture, iteration shown, largest vertex distance from `settled`, model units)."""
    picture = Image.open(io.BytesIO(page.screenshot())).convert("RGB").crop(CROP)
    shown = np.array(page.evaluate("somxr.positions(602)")).reshape(-1, 3)
    far = 0.0 if settled is None else float(np.linalg.norm(shown - settled, axis=1).max())
    return picture, page.evaluate("somxr.state().iteration"), far


def press_on(page, index: int) -> tuple[float, float]:
    for j in (index, index + 9):
        x, y = page.evaluate(f"somxr.controlScreen({j})")
        page.mouse.move(x, y)
        try:
            page.wait_for_function(f"somxr.state().hover.some((j) => j % 9 === {index})", timeout=3000)
        except Exception:
            continue
        page.mouse.down()
        return x, y
    raise RuntimeError(f"control {index} cannot be taken with the mouse")


def captioned(picture: Image.Image, text: str) -> Image.Image:
    out = Image.new("RGB", (picture.width, picture.height + 18), "white")
    out.paste(picture, (0, 18))
    ImageDraw.Draw(out).text((4, 3), text, fill="black")
    return out


def release(out: Path) -> None:
    session = Session("car", device="cpu", autosave=False)
    try:
        assert session.wait_idle(120)
        session.set_iterations(10_000)
        assert session.wait_idle(120)
        with XRServer(session) as srv, sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_page(viewport=VIEWPORT)
            page.goto(srv.base + "/xr/")
            page.wait_for_function("window.somxr && somxr.state().frames > 0", timeout=30000)
            x, y = press_on(page, 2)
            for s in range(1, 17):
                page.mouse.move(x - 3 * s, y - 5 * s)
                page.wait_for_timeout(30)
            deadline = time.monotonic() + 60
            while not (session.frame.iteration == session.frame.iterations and not session.frame.running):
                assert time.monotonic() < deadline, "the clay did not settle"
                time.sleep(0.05)
            page.wait_for_function(f"somxr.state().seq >= {session.frame.seq}", timeout=10000)
            page.wait_for_timeout(300)
            settled = session.frame.positions.copy()
            before = shot(page, settled)
            page.mouse.up()
            after = []
            t0 = time.monotonic()
            while time.monotonic() - t0 < 1.5:
                after.append((time.monotonic() - t0, *shot(page, settled)))
            browser.close()
    finally:
        session.close()
    lowest = min(range(len(after)), key=lambda n: after[n][2])
    pick = lowest if after[lowest][2] < before[1] else len(after) // 2
    panels = [captioned(before[0], f"mouse up: iteration {before[1]:,}")]
    for t, pic, it, far in (after[pick], after[-1]):
        panels.append(captioned(pic, f"+{t * 1000:.0f} ms: iteration {it:,}, moved {far:.2f}"))
    strip = Image.new("RGB", (sum(p.width for p in panels) + 8 * (len(panels) - 1), panels[0].height), "white")
    left = 0
    for panel in panels:
        strip.paste(panel, (left, 0))
        left += panel.width + 8
    strip.save(out, optimize=True)
    print(f"{out}: {len(after)} screenshots after the mouse up: iterations {[a[2] for a in after]}, vertices moved "
          f"up to {[round(a[3], 3) for a in after]}")


def presence(out: Path) -> None:
    session = Session("car", device="cpu", autosave=False)
    try:
        assert session.wait_idle(120)
        with XRServer(session) as srv, sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            a, b = (browser.new_page(viewport={"width": 640, "height": 420}) for _ in range(2))
            for page in (a, b):
                page.goto(srv.base + "/xr/")
                page.wait_for_function("window.somxr && somxr.state().frames > 0", timeout=30000)
            b.wait_for_function("somxr.state().presence.length === 2", timeout=10000)
            x, y = press_on(a, 2)  # A holds control 2 and drags it a little
            for s in range(1, 6):
                a.mouse.move(x - 4 * s, y - 3 * s)
                a.wait_for_timeout(40)
            b.wait_for_function("document.querySelector('.somview-presence').innerText.includes('holds 2')",
                                timeout=10000)
            press_on(b, 2)  # B tries it too: refused, and told who holds it
            b.mouse.up()
            b.wait_for_function("(somxr.state().lastError || '').includes('held by')", timeout=10000)
            panels = [captioned(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), caption)
                      for page, caption in ((a, "view A: dragging control 2"),
                                            (b, "view B: control 2 in A's colour; B's grab refused"))]
            a.mouse.up()
            browser.close()
    finally:
        session.close()
    strip = Image.new("RGB", (panels[0].width * 2 + 8, panels[0].height), "white")
    strip.paste(panels[0], (0, 0))
    strip.paste(panels[1], (panels[0].width + 8, 0))
    strip = strip.resize((strip.width * 3 // 4, strip.height * 3 // 4), Image.LANCZOS)
    strip.save(out, optimize=True)
    print(out)


if __name__ == "__main__":
    {"release": release, "presence": presence}[sys.argv[1]](Path(sys.argv[2]))
