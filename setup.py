"""The wheel carries the browser client (somwidget/frontend/client/dist): building the package builds the client
first when it is not built yet (`npm ci` when its node_modules are missing, then `npm run build`), and stops with a
message that says how when it cannot (no npm on the PATH, or npm failed). The project's metadata is pyproject.toml's.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

CLIENT = Path(__file__).resolve().parent / "somwidget" / "frontend" / "client"
HOW = ("install Node.js (18 or newer, with npm) and build again, or build the client first: `npm ci && npm run build` "
       "in somwidget/frontend/client (in a checkout, `bash scripts/setup.sh` does it)")


def build_client() -> None:
    """Build the client into CLIENT/dist unless it is there; SystemExit with what to do when it cannot be built."""
    if (CLIENT / "dist" / "somview.js").is_file():
        return
    npm = shutil.which("npm")
    if npm is None:
        raise SystemExit(f"somwidget: the browser client is not built (its dist/ is missing) and npm is not on the "
                         f"PATH: {HOW}")
    steps = ([] if (CLIENT / "node_modules").is_dir() else [[npm, "ci", "--no-audit", "--no-fund"]])
    for step in [*steps, [npm, "run", "build"]]:
        print(f"somwidget: building the browser client: {' '.join(step[1:])} in {CLIENT}", flush=True)
        if subprocess.run(step, cwd=CLIENT).returncode != 0:
            raise SystemExit(f"somwidget: building the browser client failed (`npm {' '.join(step[1:])}`; its output "
                             f"is above): {HOW}")
    if not (CLIENT / "dist" / "somview.js").is_file():
        raise SystemExit(f"somwidget: `npm run build` made no dist/somview.js: {HOW}")


class BuildWithClient(build_py):
    """build_py, after the client is built (its dist/ is package data); an editable install (`pip install -e`)
    leaves it to the checkout (scripts/setup.sh builds it)."""

    def run(self) -> None:
        if not getattr(self, "editable_mode", False):
            build_client()
        super().run()


setup(cmdclass={"build_py": BuildWithClient})
