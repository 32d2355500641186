"""The one browser client (JavaScript under src/, built with vite into dist/): the clay view that the web app's page,
the notebook widget and the headset page all draw with, the link to the server and the WebXR session.

Python only needs to find the build: `DIST` (the folder) and `view_module()` (the clay view's ES module, which the
notebook widget loads). Build it with `npm ci && npm run build` in this folder (`bash scripts/setup.sh` does it).
"""

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parent
#: The client's build: the headset pages (index.html, emulator.html, assets/) and the clay view's module somview.js.
DIST = HERE / "dist"
#: What to run when the build is missing.
BUILD_HINT = (f"build it with `npm ci && npm run build` in {HERE} (in a checkout `bash scripts/setup.sh` does it; a "
              "wheel made with Node.js on the PATH carries it)")


class ClientNotBuilt(RuntimeError):
    """The browser client's build (dist/) is missing: this checkout or wheel was made without the npm step."""


def view_module() -> str:
    """The clay view's ES module (dist/somview.js) as text; ClientNotBuilt when the client is not built."""
    path = DIST / "somview.js"
    if not path.is_file():
        raise ClientNotBuilt(f"the clay view is not built ({path} is missing): {BUILD_HINT}")
    return path.read_text(encoding="utf-8")


__all__ = ["DIST", "ClientNotBuilt", "view_module"]
