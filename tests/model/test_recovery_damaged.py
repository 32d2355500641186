"""The five corruptions issue 38 found, each on a real `somwidget serve` as the issue made them: one drag of a control
made and saved, kill -9, one value the restart reads corrupted, restart. Each now gives a started server, the state
its notice and message say (the step before the drag when the drag's step cannot be read, the drag itself when only
the time is damaged), a notice naming the file and what was wrong in the panel and as one line of the server's
output, and the folder set aside whole; the session goes on saving in a new folder that the next start brings back.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest
from autosave_damage import same_folder, snapshot
from helpers import Serve
from test_recovery import drag, same, send, settled, stop

from somwidget.frontend.model.readback import read_folder


@pytest.fixture(scope="module")
def killed(tmp_path_factory):
    """(the folder a killed server left, the state before its drag, the state after it)."""
    data = tmp_path_factory.mktemp("killed")
    srv = Serve(env={"SOMWIDGET_DATA_DIR": str(data)})
    try:
        before = settled(srv)
        send(srv, drag(2, [3.0, 0.6, 0.2]))
        after = settled(srv)
        os.kill(srv.proc.pid, signal.SIGKILL)
        srv.proc.wait(10)
    finally:
        srv.stop()
    folder, = (data / "autosave").iterdir()
    assert after["session"]["history"] == [1, 0]
    return folder, before, after


def _times(path: Path, key: str, factor: float) -> None:
    """One array of a step file multiplied: still finite float32 numbers, far past the engine's bounds."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays[key] = (arrays[key].astype(np.float64) * factor).astype(np.float32)
    np.savez(path, **arrays)


def _manifest(folder: Path, change) -> None:
    manifest = json.loads((folder / "manifest.json").read_text())
    change(manifest)
    (folder / "manifest.json").write_text(json.dumps(manifest))  # NaN and Infinity as JSON's extensions spell them


def _every_step(manifest):
    return [manifest["current"], *manifest["undo"], *manifest["redo"]]


CORRUPTIONS = {
    "weights x1e30": lambda f, m: _times(f / m["current"]["file"], "weights", 1e30),
    "controls x1e30": lambda f, m: _times(f / m["current"]["file"], "controls", 1e30),
    "Infinity in the metric weights": lambda f, m: _manifest(
        f, lambda m: m["current"]["parameters"]["metric_weights"].__setitem__(0, float("inf"))),
    "saved 1e300": lambda f, m: _manifest(f, lambda m: m.__setitem__("saved", 1e300)),
    "saved NaN": lambda f, m: _manifest(f, lambda m: m.__setitem__("saved", float("nan"))),
    "Infinity in every step's metric weights": lambda f, m: _manifest(
        f, lambda m: [s["parameters"]["metric_weights"].__setitem__(0, float("inf")) for s in _every_step(m)]),
}
#: What each gives: the state that comes back ("before": the step before the drag; "after": the drag; None: a new
#: session), the file the notice names, and words the notice says.
EXPECTED = {
    "weights x1e30": ("before", "current", "its weights (the clay's shape) hold a value of "),
    "controls x1e30": ("before", "current", "its controls hold a value of "),
    "Infinity in the metric weights": ("before", "manifest.json", "metric weight 0: expected a finite number, got inf"),
    "saved 1e300": ("after", "manifest.json", "1e+300 is not a time"),
    "saved NaN": ("after", "manifest.json", "nan is not a time"),
    "Infinity in every step's metric weights": (None, "manifest.json", "metric weight 0: expected a finite number"),
}


@pytest.mark.parametrize("corruption", list(CORRUPTIONS))
def test_a_corrupted_autosave_starts_the_server_with_the_right_notice(killed, corruption, tmp_path):
    source, before, after = killed
    data = tmp_path / "data"
    folder = data / "autosave" / source.name
    shutil.copytree(source, folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    CORRUPTIONS[corruption](folder, manifest)
    corrupted = snapshot(folder)
    came, file, words = EXPECTED[corruption]
    where = str(folder / (manifest["current"]["file"] if file == "current" else file))
    env = {"SOMWIDGET_DATA_DIR": str(data)}
    srv = Serve(env=env)  # it starts: the server did not
    try:
        st = srv.state(positions=True)
        session, notices = st["session"], st["session"]["notices"]
        assert len(notices) == 1 and where in notices[0] and words in notices[0], notices
        assert "x1e30" not in corruption or "e+30, beyond the 1e+18 the engine takes" in notices[0], notices
        assert st["panel"]["notice_message"] == notices[0]  # the web panel's notice
        printed = [line for line in srv.output().splitlines() if where in line]
        assert printed == [f"somwidget: {notices[0]}"], printed  # one line of the server's output
        aside, = [p for p in folder.parent.iterdir() if p.name.startswith(folder.name + ".unreadable-")]
        assert str(aside) in notices[0] and same_folder(corrupted, snapshot(aside))  # kept whole, not a byte changed
        message = session["recovered_message"]
        if came is None:
            assert not session["recovered"] and session["preset"] == "car" and "could not be brought back" in notices[0]
            return
        same(st, before if came == "before" else after)
        if came == "before":
            assert session["history"] == [0, 0]
            assert "as it was 1 step before its end, because its last step could not be read" in message, message
            assert "Brought back instead: the step before the last one" in notices[0], notices[0]
        else:
            assert session["history"] == [1, 0]
            assert message == "Brought back your session (Car) as its last completed step; Undo reaches the 1 step " \
                              "before it.", message  # no time it does not know
        assert st["panel"]["recovered_message"] == message
        new_folder = Path(session["autosave"]["path"])
        assert new_folder != folder and str(new_folder) in notices[0]
        reading = read_folder(new_folder, 1 << 20)
        assert reading.whole and len(reading.undo) == session["history"][0]  # written whole at the start
    finally:
        stop(srv, signal.SIGTERM)
    assert same_folder(corrupted, snapshot(aside))  # and after the server stopped
    if corruption == "weights x1e30":  # the next start brings back what this one did, with nothing to say
        srv = Serve(env=env)
        try:
            again = srv.state(positions=True)
            same(again, before)
            assert again["session"]["notices"] == [] and "last completed step" in \
                again["session"]["recovered_message"]
        finally:
            srv.stop()
