"""The wheel: `python -m build` makes one that holds the built browser client, and installed in a fresh venv (no npm,
no checkout on the path) it serves the app with its clay view and makes the notebook widget."""

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

pytest.importorskip("build", reason="the build package is not installed")
DIST = helpers.ROOT / "somwidget" / "frontend" / "client" / "dist"
ANNOUNCED = re.compile(r"somwidget serving .* at (http://127\.0\.0\.1:\d+)/")


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    if not (DIST / "somview.js").is_file():
        pytest.fail("the browser client is not built: run scripts/setup.sh")
    tmp = tmp_path_factory.mktemp("wheel")
    out = subprocess.run([sys.executable, "-m", "build", "--wheel", "--outdir", str(tmp / "dist"), str(helpers.ROOT)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    wheel, = (tmp / "dist").glob("somwidget-*.whl")
    subprocess.run([sys.executable, "-m", "venv", str(tmp / "venv")], check=True, timeout=300)
    py = tmp / "venv" / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], check=True,
                   timeout=300)
    # the dependencies come from the test venv's site-packages; the checkout is not on the path
    env = {**os.environ, "PYTHONPATH": sysconfig.get_paths()["purelib"],
           "SOMWIDGET_DATA_DIR": str(tmp / "data")}
    return wheel, tmp / "venv", env, tmp


def test_the_wheel_holds_the_built_client(installed):
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
