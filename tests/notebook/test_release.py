"""A closed view gives its memory back (issue 36, item 4): `show()`'s widget closed (`.close()`, what a host's close
of the output runs; Voila's kernel culled is tests/notebook/test_panel_fits.py) closes the session it made, and the
process's resident memory (RSS) falls back to what it was before: the session's Warp arrays, its distance table and
its history are freed. Measured in a fresh interpreter, after a smaller first session warmed the caches (Warp's
kernels, the client's module, the imports)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import helpers
import pytest

CODE = r"""
import gc, json, sys
sys.path.insert(0, sys.argv[1])
from helpers import proc_status_mb
import os
from somwidget.frontend.notebook import show

def rss():
    gc.collect()
    return proc_status_mb(os.getpid(), "VmRSS")

VIEW = sys.argv[2] == "view"

def big(refined=2):
    w = show("car", device="cpu", paused=True, view=VIEW)
    for _ in range(refined):  # 602 nodes -> 9,602: a distance table of 184 MB
        w.session.refine()
    assert w.session.wait_applied(300)
    return w

warm = big(1); warm.close(); del warm  # the imports, Warp's kernels, the client's module
base = rss()
import weakref
w = big()
n = int(w.session.frame.positions.shape[0])
session = weakref.ref(w.session)
opened = rss()
w.close(); del w
closed = rss()
print(json.dumps({"n": n, "base": base, "opened": opened, "closed": closed, "alive": session() is not None}))
"""


@pytest.mark.slow
@pytest.mark.parametrize("view", ["panel", "view"])
def test_closing_the_widget_frees_the_sessions_memory(tmp_path, view):
    env = {**os.environ, "PYTHONPATH": str(helpers.ROOT), "SOMWIDGET_DATA_DIR": str(tmp_path / "data")}
    out = subprocess.run([sys.executable, "-c", CODE, str(helpers.ROOT / "tests"), view], env=env,
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    grown = got["opened"] - got["base"]
    assert got["n"] > 9000 and grown > 150, got  # the session held its table and arrays
    assert not got["alive"], got  # nothing holds the closed session
    assert got["closed"] - got["base"] < 0.2 * grown, got  # and its memory went back to the system
