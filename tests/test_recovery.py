"""Nothing lost: the autosave (frontend/model/autosave.py) and `Session.recover()` after a real SIGKILL, and
`somwidget serve` recovering by itself (with `--fresh` to start anew)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from helpers import ROOT, Serve, wait_for

from somwidget.backend import io
from somwidget.frontend.model import autosave, storage
from somwidget.frontend.model import Session

#: A session that makes three steps (a drag, a new control, a setting), waits until its own autosave holds the
#: last one (written by itself when training settles: no flush), writes what it holds, says READY and waits to be
#: killed.
CHILD = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    from somwidget.backend import io
    from somwidget.frontend.model import Session

    preset, out = sys.argv[1], sys.argv[2]
    s = Session(preset, device="cpu")
    assert s.wait_idle(60)
    with s.gesture():
        for t in np.linspace(0.1, 1.0, 6):
            s.move_control(1, s.controls[1, :3] + t * np.float32([0.0, 0.05, 0.1]))
    s.add_control()
    s.set_reach(0.09)
    assert s.wait_idle(60)
    want = s.snapshot()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:  # the autosave of the settled state
        try:
            saved = io.load_session(s.autosave_path)
            if saved["iteration"] == want["iteration"] and np.array_equal(saved["weights"], want["weights"]) \\
                    and np.array_equal(saved["controls"], want["controls"]) and saved["reach"] == 0.09:
                break
        except ValueError:
            pass
        time.sleep(0.05)
    else:
        raise SystemExit("the autosave never held the last step")
    np.save(out + "/weights.npy", want["weights"])
    np.save(out + "/controls.npy", want["controls"])
    json.dump({"iteration": want["iteration"], "parameters": want["parameters"], "path": str(s.autosave_path)},
              open(out + "/state.json", "w"))
    print("READY", flush=True)
    time.sleep(600)
""")


def crash_a_session(data_dir, out, preset: str = "car") -> dict:
    """Run CHILD with its own data directory, SIGKILL it once it is READY; returns what it held."""
    env = dict(os.environ, SOMWIDGET_DATA_DIR=str(data_dir), PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-c", CHILD, preset, str(out)], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    try:
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if line.strip() == "READY":
                break
        else:
            raise AssertionError("the child session ended early:\n" + "".join(lines)[-3000:])
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    state = json.loads((out / "state.json").read_text())
    state["weights"] = np.load(out / "weights.npy")
    state["controls"] = np.load(out / "controls.npy")
    return state


def test_recover_after_sigkill_brings_back_the_last_step_exactly(tmp_path, monkeypatch):
    data = tmp_path / "data"
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(data))
    assert Session.recover(device="cpu") is None  # nothing crashed yet
    held = crash_a_session(data, tmp_path)
    assert autosave.crashed() == [storage.autosave_dir() / os.path.basename(held["path"])]
    s = Session.recover(device="cpu")
    try:
        assert s is not None and s.recovered["preset"] == "car"
        f = s.frame
        np.testing.assert_array_equal(f.weights, held["weights"])
        np.testing.assert_array_equal(s.controls, held["controls"])
        assert f.iteration == held["iteration"] and s.parameters == held["parameters"]
        assert f.held and not f.running
        time.sleep(0.3)
        np.testing.assert_array_equal(s.frame.weights, held["weights"])  # nothing trains until the next intent
        # the recovered session took the autosave over: the crashed one is gone, its own is there
        assert autosave.crashed() == []
        assert s.autosave_path.exists()
        assert Session.recover(device="cpu") is None
    finally:
        s.close()
    assert not list(storage.autosave_dir().iterdir())  # a clean close leaves nothing to recover


def test_a_clean_close_leaves_nothing_and_a_live_session_is_not_taken(tmp_path, monkeypatch):
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(tmp_path))
    a = Session("sphere", device="cpu")
    try:
        a.move_control(0, a.controls[0] + 0.1)
        assert a.wait_idle(30) and a.flush_autosave()
        saved = io.load_session(a.autosave_path)
        np.testing.assert_array_equal(saved["controls"], a.controls)
        assert Session.recover(device="cpu") is None  # its lock is held: alive, not crashed
        files = sorted(p.name for p in storage.autosave_dir().iterdir())
        assert len(files) == 2 and files[0].endswith(".lock") and files[1].endswith(".npz")  # no temporary left
    finally:
        a.close()
    assert not list(storage.autosave_dir().iterdir())


def test_crashed_autosaves_are_bounded(tmp_path, monkeypatch):
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(tmp_path))
    folder = storage.autosave_dir()
    folder.mkdir(parents=True)
    source = Session("grid", device="cpu", start=False, autosave=False)
    state = source.session_state()
    source.close()
    for i in range(autosave.KEEP_CRASHED + 3):  # states whose sessions are gone: free locks
        io.save_session(folder / f"old-{i}.npz", state)
        (folder / f"old-{i}.lock").touch()
        os.utime(folder / f"old-{i}.npz", (1000 + i, 1000 + i))
    found = autosave.crashed()
    assert [p.name for p in found] == [f"old-{i}.npz" for i in range(autosave.KEEP_CRASHED + 2, 2, -1)]
    assert len(list(folder.glob("*.npz"))) == autosave.KEEP_CRASHED


def test_serve_recovers_by_itself_and_fresh_starts_anew(tmp_path):
    data = tmp_path / "data"
    held = crash_a_session(data, tmp_path, preset="torus")
    srv = Serve(env={"SOMWIDGET_DATA_DIR": str(data)})
    try:
        assert "recovered the session" in srv.output()
        st = srv.state(positions=True)
        assert st["session"]["preset"] == "torus" and st["session"]["recovered"]
        assert "did not close cleanly" in st["panel"]["recovered_message"]
        np.testing.assert_allclose(st["session"]["controls"], held["controls"], rtol=0, atol=0)
        np.testing.assert_allclose(st["session"]["frame"]["positions"], held["weights"], rtol=0, atol=0)
    finally:
        srv.stop()  # a clean stop (SIGTERM): the recovered session's autosave goes too
    wait_for(lambda: not list(autosave.crashed(data / "autosave")), what="no crashed session left")
    crash_a_session(data, tmp_path, preset="sphere")
    srv = Serve("--fresh", env={"SOMWIDGET_DATA_DIR": str(data)})
    try:
        st = srv.state()
        assert st["session"]["preset"] == "car" and not st["session"]["recovered"]
        assert st["panel"]["recovered_message"] == ""
    finally:
        srv.stop()
    assert len(autosave.crashed(data / "autosave")) == 1  # --fresh left the crashed one for later


@pytest.mark.parametrize("bad", [b"", b"PK\x03\x04 not a zip", b"\x93NUMPY"])
def test_an_unreadable_autosave_is_set_aside(tmp_path, monkeypatch, bad):
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(tmp_path))
    folder = storage.autosave_dir()
    folder.mkdir(parents=True)
    (folder / "broken.npz").write_bytes(bad)
    (folder / "broken.lock").touch()
    assert Session.recover(device="cpu") is None
    assert not list(folder.iterdir())
