"""Recovery brings back what can be read, never writes before the session is whole, and says what happened in a
person's words (issue 38, items 2 to 4), each written as the fault on a saved folder with every kind of step
(autosave_damage.make_saved: two meshes' starts, undo and redo steps): a damaged undo or redo step is left out with
those beyond it, a damaged current step gives way to the newest readable undo step; a start that fails half way, or
a process that ends before its session is whole, leaves the folder byte for byte; the notices name the file, what was
wrong and where the folder is kept, in the notebook panel and as one log line, and never in numpy's words."""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from autosave_damage import ORIGIN, Saved, digest, make_saved, same_folder, snapshot
from helpers import ROOT

from somwidget.frontend.model import Session, autosave
from somwidget.frontend.model.readback import read_folder
from somwidget.frontend.model.timeline import Timeline


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> Saved:
    root = tmp_path_factory.mktemp("partial-saved")
    old = os.environ.get("SOMWIDGET_DATA_DIR")
    os.environ["SOMWIDGET_DATA_DIR"] = str(root)
    try:
        return Saved.of(make_saved(root))
    finally:
        os.environ["SOMWIDGET_DATA_DIR"] = old


@pytest.fixture
def folder(saved, tmp_path, monkeypatch):
    """A copy of the saved folder where a restart looks."""
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(tmp_path))
    target = tmp_path / "autosave" / saved.folder.name
    shutil.copytree(saved.folder, target)
    return target


def weights_of(folder, record) -> str:
    with np.load(folder / record["file"]) as z:
        return digest(z["weights"])


def aside_of(folder):
    aside, = [p for p in folder.parent.iterdir() if p.name.startswith(folder.name + ".unreadable-")]
    return aside


def test_a_damaged_undo_step_is_left_out_with_those_before_it_and_the_current_step_comes_back(saved, folder, caplog):
    m = saved.manifest
    n = len(m["undo"])
    damaged = folder / m["undo"][n - 3]["file"]  # the third step Undo would reach
    damaged.write_bytes(os.urandom(5000))
    before = snapshot(folder)
    with caplog.at_level(logging.WARNING):
        s = Session.recover(origin=ORIGIN, device="cpu", start=False)
    try:
        assert digest(s.files.snapshot()["weights"]) == saved.current  # the current step, exactly
        assert tuple(s.history) == (2, len(m["redo"]))  # the two undo steps after the damaged one, the redo step
        notice, = s.notices
        assert f"{damaged} (undo step 3 of {n}): not a saved session file" in notice, notice
        assert "pickle" not in notice and "allow_pickle" not in notice  # numpy's words are not the person's
        assert f"left out: {n - 2} steps" in notice and f"kept at {aside_of(folder)}, unchanged" in notice
        assert "Brought back: the last step, with 2 undo steps and 1 redo step" in notice, notice
        assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == [notice]  # one log line
        assert same_folder(before, snapshot(aside_of(folder)))
        assert s.undo() and s.undo() and not s.undo()  # the two steps, read back
        assert digest(s.files.snapshot()["weights"]) == weights_of(aside_of(folder), m["undo"][n - 2])
    finally:
        s.close()


def test_a_damaged_redo_step_is_left_out_and_the_rest_comes_back(saved, folder):
    m = saved.manifest
    damaged = folder / m["redo"][-1]["file"]
    damaged.write_bytes(damaged.read_bytes()[:200])  # cut short
    s = Session.recover(origin=ORIGIN, device="cpu", start=False)
    try:
        assert tuple(s.history) == (len(m["undo"]), 0)
        assert digest(s.files.snapshot()["weights"]) == saved.current
        notice, = s.notices
        assert f"{damaged} (redo step 1 of 1): not a saved session file" in notice and "left out: 1 step." in notice
    finally:
        s.close()


def test_a_damaged_current_step_gives_way_to_the_newest_readable_undo_step(saved, folder):
    m = saved.manifest
    n = len(m["undo"])
    current, newest = folder / m["current"]["file"], folder / m["undo"][-1]["file"]
    with np.load(current) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["weights"][5, 1] = np.nan
    np.savez(current, **arrays)
    newest.unlink()  # and the newest undo step is gone
    os.symlink(saved.folder / m["undo"][-1]["file"], newest)  # replaced by a link out of the folder: not read
    s = Session.recover(origin=ORIGIN, device="cpu", start=False)
    try:
        assert digest(s.files.snapshot()["weights"]) == weights_of(folder.parent / aside_of(folder).name,
                                                                   m["undo"][-2])
        assert tuple(s.history) == (n - 2, 0)
        message = s.recovered["message"]
        assert "as it was 2 steps before its end, because its last 2 steps could not be read" in message, message
        notice, = s.notices
        assert f"{current} (the current step): its weights (the clay's shape) hold a value that is not a number" \
            in notice, notice
        assert f"{newest} (undo step 1 of {n}): a link to somewhere else, not a file of this folder" in notice
        assert "Brought back instead: the step 2 steps before the last (the newest that could be read)" in notice
        assert "left out: 3 steps" in notice  # the current step, the newest undo step and the redo step
    finally:
        s.close()


def test_an_older_step_of_a_newer_somwidget_is_left_out_but_a_current_one_sets_the_folder_aside(saved, folder):
    m = json.loads((folder / "manifest.json").read_text())
    m["undo"][-1]["parameters"]["from_the_future"] = 1.0
    (folder / "manifest.json").write_text(json.dumps(m))
    s = Session.recover(origin=ORIGIN, device="cpu", start=False)
    try:
        assert tuple(s.history) == (0, 1) and "a newer somwidget wrote it" in s.notices[0]
    finally:
        s.close()
    new = s.autosave.path
    m = json.loads((new / "manifest.json").read_text())
    m["current"]["parameters"]["from_the_future"] = 1.0
    (new / "manifest.json").write_text(json.dumps(m))
    before = snapshot(new)
    assert Session.recover(origin=ORIGIN, device="cpu", start=False) is None
    assert same_folder(before, snapshot(aside_of(new)))


def test_a_start_that_fails_half_way_writes_nothing_and_goes_on(saved, folder, monkeypatch):
    before = snapshot(folder)

    def broken(self, *args):
        raise RuntimeError("warp: a kernel launch failed (cudaErrorIllegalAddress)")

    monkeypatch.setattr(Timeline, "bring_back", broken)
    assert Session.recover(origin=ORIGIN, device="cpu", start=False) is None  # and no exception: the start goes on
    aside = aside_of(folder)
    assert same_folder(before, snapshot(aside))
    assert [p.name for p in folder.parent.iterdir()] == [aside.name]  # the half-built session wrote nowhere


def test_at_exit_a_session_that_never_finished_starting_is_not_saved(saved, folder):
    """The issue's worst case: the process that took the folder over ends (here normally, its atexit closing every
    live session) before the session rebuilt from it is whole: not a byte is written."""
    before = snapshot(folder)
    child = textwrap.dedent(f"""
        from pathlib import Path
        from somwidget.frontend.model import Session, autosave
        from somwidget.frontend.model.store import SessionStore
        store = SessionStore.adopt(Path({str(folder)!r}))
        s = Session("sphere", device="cpu", start=False, origin={ORIGIN!r}, _store=store)
        s.move_control(1, s.controls[1, :3] + 0.3)  # a step: due for a save, were the session whole
        s.start()
        assert s.wait_idle(60)
        raise SystemExit(3)  # the start fails: the process ends
    """)
    done = subprocess.run([sys.executable, "-c", child], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 3, done.stderr[-2000:]
    assert same_folder(before, snapshot(folder))


def test_a_session_brought_back_whole_writes_nothing_until_its_next_step(saved, folder):
    before = snapshot(folder)
    s = Session.recover(origin=ORIGIN, device="cpu")  # its training thread runs
    try:
        assert s.notices == [] and s.autosave.path == folder
        assert s.wait_idle(30)
        time.sleep(autosave.AUTOSAVE_SECONDS + 0.5)  # the training thread's turns ask whether a save is due
        assert s.autosave.writer.saves == 0 and same_folder(before, snapshot(folder))  # nothing due: nothing written
        s.move_control(0, s.controls[0, :3] + 0.05)  # the next step
        assert s.wait_idle(60) and s.autosave.flush(30)
    finally:
        s.close()
    m = json.loads((folder / "manifest.json").read_text())
    assert len(m["undo"]) == len(saved.manifest["undo"]) + 1
    assert not (folder / saved.manifest["current"]["file"]).exists()  # deleted by that later step, and only then
    assert read_folder(folder, 1 << 20).whole


def test_the_notebook_panel_shows_what_was_kept_where(saved, folder):
    from somwidget.frontend.notebook.panel import Panel

    (folder / saved.manifest["redo"][0]["file"]).write_bytes(b"")
    s = Session.recover(origin=ORIGIN, device="cpu", start=False)
    panel = Panel(s, auto_refresh=False)
    try:
        text = panel.notices.children[0].value
        assert panel.notices.layout.display != "none"
        assert "Part of your saved session could not be read" in text and "kept at" in text
        assert str(aside_of(folder)) in text
        panel.notices.children[1].click()
        assert panel.notices.layout.display == "none"
    finally:
        panel.close()
        s.close()
