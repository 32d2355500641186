"""The wheel: `python -m build` makes one that holds the built browser client, and installed in a fresh venv (no npm,
no checkout on the path) it serves the app with its clay view and makes the notebook widget. From a fresh clone (no
client built) the build builds the client, or stops with a message that says how where npm is missing (issue 27,
item 6); a widget whose client is missing raises one clear error."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import sysconfig
import time
import zipfile

import helpers
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("build", reason="the build package is not installed")
DIST = helpers.ROOT / "somwidget" / "frontend" / "client" / "dist"
ANNOUNCED = re.compile(r"somwidget serving .* at (http://127\.0\.0\.1:\d+)/")


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """One wheel built from a fresh clone (the build builds the client), installed in a fresh venv."""
    if not (DIST / "somview.js").is_file():
        pytest.fail("the browser client is not built: run scripts/setup.sh")
    tmp = tmp_path_factory.mktemp("wheel")
    clone = fresh_clone(tmp)
    client = clone / "somwidget" / "frontend" / "client"
    (client / "node_modules").symlink_to(DIST.parent / "node_modules")  # as `npm ci` leaves them (no network here)
    out = subprocess.run([sys.executable, "-m", "build", "--wheel", "--outdir", str(tmp / "dist"), str(clone)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, (out.stdout + out.stderr)[-3000:]
    assert "somwidget: building the browser client: run build" in out.stdout
    wheel, = (tmp / "dist").glob("somwidget-*.whl")
    # a fresh venv without a pip of its own (ensurepip takes 5-30 s here): this pip installs into it (--python)
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(tmp / "venv")], check=True, timeout=300)
    py = tmp / "venv" / "bin" / "python"
    own = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # a checkout on the path reads as installed
    subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", "--no-index",
                    str(wheel)], check=True, timeout=300, env=own)
    # the dependencies come from the test venv's site-packages; the checkout is not on the path
    env = {**os.environ, "PYTHONPATH": sysconfig.get_paths()["purelib"],
           "SOMWIDGET_DATA_DIR": str(tmp / "data")}
    return wheel, tmp / "venv", env, tmp


def test_a_build_from_a_clone_builds_the_client_into_the_wheel(installed):
    wheel, *_ = installed
    names = zipfile.ZipFile(wheel).namelist()
    assert "somwidget/frontend/client/dist/somview.js" in names
    assert "somwidget/frontend/client/dist/index.html" in names
    assert not [n for n in names if "node_modules" in n]


def test_the_installed_wheel_serves_the_app_and_makes_the_widget(installed):
    _, venv, env, tmp = installed
    py = str(venv / "bin" / "python")
    code = ("import somwidget, sys; from somwidget.frontend.notebook import show; "
            "w = show('car', device='cpu'); assert 'mountWebView' in w.view._esm; w.close(); print(somwidget.__file__)")
    out = subprocess.run([py, "-c", code], cwd=tmp, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert str(venv) in out.stdout, out.stdout  # the wheel's copy, not the checkout
    log = open(tmp / "serve.log", "w")
    proc = subprocess.Popen([str(venv / "bin" / "somwidget"), "serve", "--port", "0", "--device", "cpu", "--fresh"],
                            cwd=tmp, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while not (m := ANNOUNCED.search((tmp / "serve.log").read_text())):
            assert proc.poll() is None and time.monotonic() < deadline, (tmp / "serve.log").read_text()[-3000:]
            time.sleep(0.2)
        base = m.group(1)
        status, body = helpers.request(base + "/")
        assert status == 200 and b"<html" in body.lower()
        status, body = helpers.request(base + "/xr/somview.js")
        assert status == 200 and b"mountWebView" in body
    finally:
        proc.terminate()
        proc.wait(20)
        log.close()


def fresh_clone(tmp_path):
    """A clone of this repository as a new user gets it: the committed files, no client build, no node_modules."""
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(helpers.ROOT), str(clone)], check=True, timeout=120)
    assert not (clone / "somwidget" / "frontend" / "client" / "dist").exists()
    return clone


def test_a_build_from_a_fresh_clone_without_npm_stops_and_says_how(tmp_path):
    clone = fresh_clone(tmp_path)
    out = subprocess.run([sys.executable, "-m", "build", "--outdir", str(tmp_path / "dist"), str(clone)],
                         capture_output=True, text=True, timeout=600, env={**os.environ, "PATH": "/nonexistent"})
    text = out.stdout + out.stderr
    assert out.returncode != 0, text[-2000:]
    assert "the browser client is not built (its dist/ is missing) and npm is not on the PATH" in text, text[-3000:]
    assert "`npm ci && npm run build` in somwidget/frontend/client" in text
    assert not list((tmp_path / "dist").glob("*.whl"))


def test_a_widget_without_its_client_raises_one_clear_error(tmp_path):
    """A checkout without the npm step: show() says what to run, once, and makes no session."""
    archive = subprocess.run(["git", "archive", "HEAD", "somwidget"], cwd=helpers.ROOT, capture_output=True,
                             check=True, timeout=120).stdout
    subprocess.run(["tar", "-x", "-C", str(tmp_path)], input=archive, check=True, timeout=120)
    assert not (tmp_path / "somwidget" / "frontend" / "client" / "dist").exists()
    code = "from somwidget.frontend.notebook import show\nshow('car', device='cpu')\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": str(tmp_path), "SOMWIDGET_DATA_DIR": str(tmp_path / "data")})
    assert out.returncode == 1
    assert out.stderr.count("Traceback") == 1 and "Exception ignored" not in out.stderr, out.stderr[-2000:]
    error = out.stderr.strip().splitlines()[-1]
    assert error.startswith("somwidget.frontend.client.ClientNotBuilt: the clay view is not built"), error
    assert "npm ci && npm run build" in error
    assert "training on" not in out.stdout and not (tmp_path / "data").exists()  # no session was made
