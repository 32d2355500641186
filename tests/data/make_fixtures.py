"""Writes the files tests/model/test_old_files.py reads: a session file and an autosave folder. Those in tests/data
were made by this script at commit 7a5338a (2026-11-27), before the settings were declared once (with the Session
calls of then: set_reach, set_symmetry, set_metric_weights, snapshot, flush_autosave, autosave_path, which are the
calls of session.settings, session.files and session.autosave below). Run it again only to make files of the format
of the day, never over these: they stand for the files people already have.

    SOMWIDGET_DATA_DIR=$(mktemp -d) PYTHONPATH=. python tests/data/make_fixtures.py tests/data

Writes:
    session-v1-sphere.npz          `session.save` of a sphere: a moved control, a radius, S 300, smoothing 0.05,
                                   reach 0.2, the mirror on, metric weights (1, 1, 0.5)
    autosave-v1-sphere/            the autosave folder of a sphere session that set smoothing, then made a drag
                                   (grab, moves, release), then set S; closed normally
    expected-v1.json               what each held when it was written (controls, radii, parameters, s, history,
                                   a SHA-256 of the current weights' float32 bytes)
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
from pathlib import Path

import numpy as np

from somwidget.frontend.model import Session


def digest(weights) -> str:
    return hashlib.sha256(np.ascontiguousarray(weights, np.float32).tobytes()).hexdigest()


def described(session: Session) -> dict:
    snap = session.files.snapshot()
    return {"controls": snap["controls"].tolist(), "radii": snap["radii"].tolist(),
            "parameters": snap["parameters"], "iteration": snap["iteration"], "history": list(session.history),
            "weights_sha256": digest(snap["weights"]), "preset": snap["preset"].name}


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    expected = {}

    s = Session("sphere", device="cpu", autosave=False)
    s.set_parameter("iterations", 300)
    s.set_smoothing(0.05)
    s.settings.set("reach", 0.2)
    s.settings.set_symmetry(True)
    s.settings.set_metric_weights([1.0, 1.0, 0.5])
    s.set_control_radius(1, 0.15)
    s.move_control(0, s.controls[0, :3] + np.float32([0.0, 0.0, 0.2]))
    assert s.wait_idle(120), s.error
    s.save(out / "session-v1-sphere.npz")
    expected["session-v1-sphere.npz"] = described(s)
    s.close()

    s = Session("sphere", device="cpu", origin="fixture")
    s.set_smoothing(0.05)
    assert s.wait_idle(120), s.error
    with s.gesture():
        start = s.controls[2, :3]
        for t in np.linspace(0.05, 0.25, 4):
            s.move_control(2, start + np.float32([0.0, 0.0, t]))
    assert s.wait_idle(120), s.error
    s.set_parameter("iterations", 400)
    assert s.wait_idle(120), s.error
    assert s.autosave.flush(30)
    expected["autosave-v1-sphere"] = described(s)
    folder = s.autosave.path
    s.close()
    target = out / "autosave-v1-sphere"
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(folder, target, ignore=shutil.ignore_patterns("lock"))
    (out / "expected-v1.json").write_text(json.dumps(expected, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    assert os.environ.get("SOMWIDGET_DATA_DIR"), "set SOMWIDGET_DATA_DIR to a folder of its own"
    main(Path(sys.argv[1]))
