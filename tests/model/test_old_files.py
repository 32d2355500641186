"""Files people already have load with the code of today: a session file and an autosave folder written before the
settings were declared once (tests/data, made by tests/data/make_fixtures.py at commit 7a5338a) come back exactly as
they were saved; and with a setting declared since (added to the declaration here), they load with its default."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from somwidget.backend import schedule, session_file
from somwidget.frontend.model import Session

DATA = Path(__file__).resolve().parents[1] / "data"
EXPECTED = json.loads((DATA / "expected-v1.json").read_text(encoding="utf-8"))
#: A setting declared after the files were written: the session's own, so the engine needs nothing new.
NEW = schedule.Setting("tension", "tension", "float", 0.0, 1.0, 0.35, slider=(0.0, 1.0, 0.01), scope="session",
                       help="A setting the files of tests/data were written before.")


def digest(weights) -> str:
    return hashlib.sha256(np.ascontiguousarray(weights, np.float32).tobytes()).hexdigest()


def as_saved(session: Session, expected: dict) -> None:
    """The session holds what the file held: preset, controls, radii, settings, s and weights, exactly."""
    snap = session.files.snapshot()
    assert snap["preset"].name == expected["preset"]
    np.testing.assert_array_equal(snap["controls"], np.float32(expected["controls"]))
    np.testing.assert_array_equal(snap["radii"], np.float32(expected["radii"]))
    assert snap["iteration"] == expected["iteration"]
    assert digest(snap["weights"]) == expected["weights_sha256"]
    for name, value in expected["parameters"].items():
        assert snap["parameters"][name] == value, name


@pytest.fixture
def autosave_folder(tmp_path, monkeypatch):
    """The old autosave folder copied where a session looks for stopped sessions (a data folder of this test)."""
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(tmp_path))
    target = tmp_path / "autosave" / "20261127-000000-1-fixture"
    shutil.copytree(DATA / "autosave-v1-sphere", target)
    return target


@pytest.fixture
def new_setting(monkeypatch):
    """The declaration with one more setting, as a later version would have it."""
    settings = (*schedule.SETTINGS, NEW)
    monkeypatch.setattr(schedule, "SETTINGS", settings)
    monkeypatch.setattr(schedule, "BY_NAME", {s.name: s for s in settings})
    return NEW


def test_a_session_file_of_before_loads_as_it_was_saved():
    expected = EXPECTED["session-v1-sphere.npz"]
    with Session("sphere", device="cpu", autosave=False) as s:
        s.load(DATA / "session-v1-sphere.npz")
        assert s.wait_applied(60)
        as_saved(s, expected)
        assert s.frame.held and s.error is None


def test_an_autosave_of_before_is_recovered_with_its_history(autosave_folder):
    expected = EXPECTED["autosave-v1-sphere"]
    s = Session.recover(origin="fixture", device="cpu")
    assert s is not None, "the old autosave was not recovered"
    try:
        assert s.recovered["path"] == str(autosave_folder) and not s.notices
        assert tuple(s.history) == tuple(expected["history"])
        as_saved(s, expected)
        assert s.undo() and s.wait_applied(60)  # the step before S was set: its own settings, read back too
        assert s.parameters["iterations"] == 1000 and s.parameters["smoothing"] == 0.05
    finally:
        s.close()


def test_a_setting_declared_since_reads_as_its_default_from_a_session_file(new_setting):
    state = session_file.load_session(DATA / "session-v1-sphere.npz")
    assert state["tension"] == new_setting.default
    with Session("sphere", device="cpu", autosave=False) as s:
        assert s.settings["tension"] == new_setting.default
        s.settings.set("tension", 0.8)
        s.load(DATA / "session-v1-sphere.npz")
        assert s.wait_applied(60)
        assert s.settings["tension"] == new_setting.default  # the file's (none): the default
        as_saved(s, EXPECTED["session-v1-sphere.npz"])


def test_a_setting_declared_since_is_kept_by_new_files(new_setting, tmp_path):
    with Session("sphere", device="cpu", autosave=False) as s:
        s.settings.set("tension", 0.8)
        s.save(tmp_path / "new.npz")
        assert session_file.load_session(tmp_path / "new.npz")["tension"] == 0.8
        s.settings.set("tension", 0.1)
        s.load(tmp_path / "new.npz")
        assert s.settings["tension"] == 0.8


def test_a_setting_declared_since_reads_as_its_default_from_an_autosave(new_setting, autosave_folder):
    manifest = json.loads((autosave_folder / "manifest.json").read_text(encoding="utf-8"))
    assert "tension" not in manifest["current"]["parameters"]  # written before it
    s = Session.recover(origin="fixture", device="cpu")
    assert s is not None and not s.notices, "the old autosave was set aside instead of read"
    try:
        assert s.settings["tension"] == new_setting.default
        as_saved(s, EXPECTED["autosave-v1-sphere"])
        assert s.undo() and s.wait_applied(60)
        assert s.settings["tension"] == new_setting.default  # an undo step of before: its default too
        s.settings.set("tension", 0.6)  # and it goes on saving with the new setting
        assert s.autosave.flush(30)
        manifest = json.loads((autosave_folder / "manifest.json").read_text(encoding="utf-8"))
        assert manifest["current"]["parameters"]["tension"] == 0.6
    finally:
        s.close()


def test_an_engine_setting_declared_since_reads_as_its_default_from_a_session_file(monkeypatch):
    """A setting of the engine (a Som keyword): the file's state has it at its default, for the Som to take."""
    added = dataclasses.replace(NEW, name="stiffness", scope="engine", default=0.5)
    settings = (*schedule.SETTINGS, added)
    monkeypatch.setattr(schedule, "SETTINGS", settings)
    monkeypatch.setattr(schedule, "BY_NAME", {s.name: s for s in settings})
    state = session_file.load_session(DATA / "session-v1-sphere.npz")
    assert state["stiffness"] == 0.5 and state["iterations"] == 300


def test_an_autosave_with_a_setting_this_version_does_not_know_is_set_aside(autosave_folder):
    manifest = json.loads((autosave_folder / "manifest.json").read_text(encoding="utf-8"))
    manifest["current"]["parameters"]["from_the_future"] = 1.0
    (autosave_folder / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    assert Session.recover(origin="fixture", device="cpu", start=False) is None
    aside = [p for p in autosave_folder.parent.iterdir() if ".unreadable" in p.name]
    assert len(aside) == 1 and (aside[0] / "manifest.json").exists()  # kept, never deleted
