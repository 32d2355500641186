"""The picture of docs/studio/: the wall of a studio with three rooms, each modelled by a designer.

    python scripts/studio_pictures.py docs/studio/wall.png

A real studio (StudioServer, rooms in this process on the CPU) with rooms of the car, the sphere and the torus; a
designer joins each (`somwidget.join`, a notebook's hand) and drags a control or two; the teacher watches one room on a
desktop page. Chromium (Playwright) opens the wall with the teacher's link once every thumbnail shows the settled clay,
and the picture is the wall's page.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from helpers import CHROMIUM, CHROMIUM_ARGS  # noqa: E402
from playwright.sync_api import sync_playwright  # noqa: E402

import somwidget  # noqa: E402
from somwidget.frontend.studio.limits import StudioLimits  # noqa: E402
from somwidget.frontend.studio.serve import StudioServer  # noqa: E402

ROOMS = {"ada": ("car", [(4, [0.0, 0.0, 0.25])]),
         "group-2": ("sphere", [(0, [0.0, 0.0, 0.35]), (2, [0.3, 0.0, 0.0])]),
         "lin": ("torus", [(1, [0.0, 0.0, 0.3])])}


def main(out: str) -> None:
    with StudioServer(tempfile.mkdtemp(prefix="somwidget-studio-"), device="cpu",
                      limits=StudioLimits(park_after=0)) as studio:
        designers = {}
        for name, (preset, moves) in ROOMS.items():
            studio.call(studio.front.create(name, preset))
            room = designers[name] = somwidget.join(studio.room_url(name))
            assert room.wait_idle(300)  # the car grows first
            for index, by in moves:
                room.move_control(index, room.control_positions[index] + np.float32(by))
        for name in ROOMS:
            assert studio.front.places[0].rooms.get(name).session.wait_idle(300)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            context = browser.new_context(viewport={"width": 1040, "height": 430}, device_scale_factor=1)
            watcher = context.new_page()  # the teacher, watching ada's room on a desktop page
            watcher.goto(studio.room_url("ada", watch=True).replace(studio.front.rooms["ada"].token,
                                                                     studio.access.teacher))
            watcher.wait_for_function("window.somxr && somxr.state().frames > 0", timeout=60000)
            wall = context.new_page()
            wall.goto(studio.wall_url)
            wall.wait_for_function("somwall.state().rooms.length === 3 && "
                                   "somwall.state().rooms.every((r) => r.drawn > 0)", timeout=60000)
            time.sleep(2.5)  # the latest frame of each, and the "changed ... ago" line
            Path(out).parent.mkdir(parents=True, exist_ok=True)
            wall.screenshot(path=out)
            browser.close()
        for room in designers.values():
            room.close()
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/studio/wall.png")
