"""Clean failures (issue 17, item 5), each written as the attack or the mistake that went wrong before:
indices truncated or a dict as a preset name reaching a traceback, messages that show Python internals, a size
limit that disagreed with the README, upload folders left behind by a killed server, and Warp's red CUDA warning
on every CPU start."""

from __future__ import annotations

import asyncio
import os
import re
import subprocess
import sys
import tempfile

import helpers
import numpy as np
import pytest

from somwidget.backend import io, session_file

INTERNALS = re.compile(r"IndexError|KeyError|TypeError|allow_pickle|pickle|Traceback|/tmp/|somwidget-upload")


@pytest.fixture
def app(tmp_path, monkeypatch):
    from trame.app import get_server

    from somwidget.frontend.model import Session
    from somwidget.frontend.web.app import build_app

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    session = Session("car", device="cpu", start=False, autosave=False)
    a = build_app(session, server=get_server(f"clean-failures-{os.getpid()}-{id(tmp_path)}", client_type="vue3"))
    yield a
    a.close()
    session.close()


@pytest.mark.parametrize("index", ["0", 1.9, None, [1], True])
def test_a_control_index_that_is_not_an_integer_is_refused_not_truncated(app, index):
    before = app.session.controls.copy()
    app.panel_state.remove_control(index)
    assert "integer index" in app.state.error_message, app.state.error_message
    app.panel_state.set_colour(index, "#00ff00")
    assert "integer index" in app.state.error_message
    np.testing.assert_array_equal(app.session.controls, before)


@pytest.mark.parametrize("name", [{"a": 1}, ["car"], 3])
def test_a_preset_name_that_is_not_text_gets_a_message(app, name):
    asyncio.run(app.choose_preset(name))
    assert "unknown preset" in app.state.error_message
    assert app.session.preset.name == "car" and app.state.preset_name == "car"


def test_reader_messages_say_what_is_wrong_without_python_internals(tmp_path):
    cases = {"faces.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
             "faces.off": "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n",
             "cut.ply": "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n0\n"}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(ValueError) as info:
            io.load_mesh(tmp_path / name)
        message = str(info.value).replace(str(tmp_path / name), "FILE")
        assert not INTERNALS.search(message), message
    (tmp_path / "not-a-session.npz").write_text("hello, this is text")
    with pytest.raises(ValueError) as info:
        session_file.load_session(tmp_path / "not-a-session.npz")
    message = str(info.value).replace(str(tmp_path / "not-a-session.npz"), "FILE")
    assert "not an .npz archive" in message and not INTERNALS.search(message), message


def test_an_uploaded_non_session_names_the_file_not_a_temporary_path(app):
    content = b"this is not a session at all"
    asyncio.run(app.upload_session({"name": "mine.npz", "size": len(content), "type": "", "content": content}))
    message = app.state.error_message
    assert "mine.npz" in message and not INTERNALS.search(message), message


def test_the_size_limit_in_messages_is_the_docs():
    from somwidget.frontend.web import uploads

    readme = (helpers.ROOT / "docs" / "modelling.md").read_text()  # where the README sends a person for uploads
    shown = re.search(r"up to (\d+) MB", readme).group(1)
    with pytest.raises(ValueError) as info:
        uploads.file_of({"name": "big.obj", "size": 60_000_000, "content": b"x"})
    assert f"the limit is {shown} MB" in str(info.value)


def test_upload_folders_of_a_killed_server_are_removed_at_the_next_start(tmp_path, monkeypatch):
    from trame.app import get_server

    from somwidget.frontend.model import Session
    from somwidget.frontend.web.app import build_app

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a pid that is gone
    left = tmp_path / f"somwidget-upload-{dead.pid}-abcd"
    left.mkdir()
    (left / "upload.obj").write_text("v 0 0 0\n")
    alive = tmp_path / f"somwidget-upload-{os.getppid()}-efgh"  # another live server's upload in progress
    alive.mkdir()
    own = tmp_path / f"somwidget-upload-{os.getpid()}-ijkl"
    session = Session("car", device="cpu", start=False, autosave=False)
    app = build_app(session, server=get_server(f"sweep-{id(tmp_path)}", client_type="vue3"))
    try:
        assert not left.exists(), "the killed server's upload folder is still there"
        assert alive.exists()
        own.mkdir()
    finally:
        app.close()
        session.close()
    assert not own.exists(), "the app left its own upload folder behind on exit"
    assert alive.exists()


def test_a_cpu_start_says_which_device_trains_once_without_warps_red_warning():
    serve = helpers.Serve()
    try:
        out = serve.output()
    finally:
        serve.stop()
    assert "training on the CPU" in out, out[-2000:]
    assert "Warp CUDA warning" not in out and "Could not find or load" not in out, out[-2000:]
    code = ("from somwidget.frontend.notebook import show\n"
            "a = show('car', device='cpu'); b = show('space-grid', device='cpu'); a.close(); b.close()\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         cwd=helpers.ROOT, env={**os.environ, "PYTHONPATH": str(helpers.ROOT)})
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.count("somwidget: training on the CPU") == 1, run.stdout
    assert "CUDA warning" not in run.stderr and "Could not find or load" not in run.stderr, run.stderr[-2000:]


def test_warps_other_start_up_output_still_reaches_stderr():
    """The capture keeps only the CUDA driver line back: anything else Warp's start prints still shows."""
    code = ("import os, sys\n"
            "from somwidget.backend import device\n"
            "import warp as wp\n"
            "real = wp.init\n"
            "def init():\n"
            "    os.write(2, b'Warp something else\\n')\n"
            "    real()\n"
            "wp.init = init\n"
            "device.init()\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=helpers.ROOT, env={**os.environ, "PYTHONPATH": str(helpers.ROOT)})
    assert run.returncode == 0, run.stderr
    assert "Warp something else" in run.stderr and "CUDA warning" not in run.stderr

