"""The API reference is generated from the docstrings (scripts/api_docs.py runs pdoc, as docs/development.md says):
it builds, and the public API and the documented internal parts are in it with their docstrings."""

from __future__ import annotations

import subprocess
import sys

import helpers


def test_the_api_reference_builds_from_the_docstrings(tmp_path):
    out = tmp_path / "api"
    run = subprocess.run([sys.executable, "scripts/api_docs.py", str(out)], cwd=helpers.ROOT,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "Traceback" not in run.stderr, run.stderr[-3000:]
    top = (out / "somwidget.html").read_text(encoding="utf-8")
    for name in ("Som", "Topology", "Symmetry", "show", "render", "sweep"):
        assert f'id="{name}"' in top, f"somwidget.{name} is missing from the reference"
    pages = {p.relative_to(out).as_posix() for p in out.rglob("*.html")}
    for page in ("somwidget/backend/som.html", "somwidget/backend/schedule.html",
                 "somwidget/frontend/model/session.html", "somwidget/frontend/transport/messages.html",
                 "somwidget/frontend/transport/connection.html"):
        assert page in pages, f"{page} is missing from the reference ({len(pages)} pages)"
    session = (out / "somwidget/frontend/model/session.html").read_text(encoding="utf-8")
    assert "modelling session" in session.lower()  # the class's docstring made it into the page
