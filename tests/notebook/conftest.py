"""One Jupyter server for every notebook test of a pytest worker.

A Jupyter server started as JupyterLab 4 also serves Notebook 7 (its pages at /notebooks/..., the `notebook`
package's server extension), so one server stands for both: `jupyter.url(path, app)` opens a notebook in either.
Starting a server takes 10-40 s on CI's two shared cores; each test file used to start its own, some several.

Each test gets a fresh folder in the server's root (`notebook_dir`), so no two tests share a notebook file or its
kernel, and every kernel the test started is shut down after it, as a server of its own would have on exit.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile
import urllib.error
import urllib.request
from pathlib import Path

import helpers
import pytest

TOKEN = "t0k"


@contextlib.contextmanager
def jupyter_server(app: str, root: Path, *options: str):
    """A real JupyterLab 4 (`app` "jupyterlab") or Notebook 7 ("notebook") server on `root`; yields its port."""
    pytest.importorskip(app)
    if not os.path.exists(helpers.CHROMIUM):
        pytest.skip(f"{helpers.CHROMIUM} is missing")
    port = helpers.free_port()
    env = {**os.environ, "PYTHONPATH": str(helpers.ROOT), "SOMWIDGET_DATA_DIR": str(root / "data")}
    with helpers.server_process([sys.executable, "-m", app, "--allow-root", "--no-browser", f"--port={port}",
                                 "--ServerApp.ip=127.0.0.1", f"--IdentityProvider.token={TOKEN}",
                                 f"--ServerApp.root_dir={root}", *options], root / "lab.log",
                                f"http://127.0.0.1:{port}/api?token={TOKEN}", app, env=env, timeout=120):
        yield port


class Jupyter:
    """A running Jupyter server (JupyterLab 4 and Notebook 7) on `root`, at http://127.0.0.1:`port`/."""

    def __init__(self, port: int, root: Path, settings: Path):
        self.port, self.root, self.settings = port, root, settings
        self.base = f"http://127.0.0.1:{port}"

    def url(self, path: Path, app: str = "jupyterlab") -> str:
        """The page of the notebook at `path` (under `root`) in JupyterLab ("jupyterlab") or Notebook 7 ("notebook")."""
        pytest.importorskip(app)
        page = "lab/tree" if app == "jupyterlab" else "notebooks"
        return f"{self.base}/{page}/{Path(path).relative_to(self.root).as_posix()}?token={TOKEN}"

    def api(self, path: str, method: str = "GET", body: dict | None = None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(f"{self.base}{path}", data=data, method=method,
                                     headers={"Authorization": f"token {TOKEN}", "Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=30) as r:
            text = r.read()
        return json.loads(text) if text else None

    def shut_down_kernels(self, folder: Path) -> None:
        """Shut down the kernel of every notebook under `folder` (its session's memory goes with it)."""
        prefix = Path(folder).relative_to(self.root).as_posix() + "/"
        for session in self.api("/api/sessions"):
            if session["path"].startswith(prefix):
                with contextlib.suppress(urllib.error.HTTPError):  # gone already
                    self.api(f"/api/sessions/{session['id']}", "DELETE")

    @contextlib.contextmanager
    def lab_setting(self, plugin: str, values: dict):
        """JupyterLab's user setting of `plugin` ("@jupyter-widgets/jupyterlab-manager:plugin") set to `values`
        while the block runs (as a person sets it in the Settings Editor), then back to the defaults."""
        self.api(f"/lab/api/settings/{plugin}", "PUT", {"raw": json.dumps(values)})
        try:
            yield
        finally:
            self.api(f"/lab/api/settings/{plugin}", "PUT", {"raw": "{}"})


@pytest.fixture(scope="session")
def jupyter(tmp_path_factory):
    """The worker's Jupyter server (started by the first test that needs it, stopped at the end of the run)."""
    root = tmp_path_factory.mktemp("jupyter")
    settings = tmp_path_factory.mktemp("jupyter-settings")
    with jupyter_server("jupyterlab", root, f"--LabApp.user_settings_dir={settings}") as port:
        yield Jupyter(port, root, settings)


@pytest.fixture
def notebook_dir(jupyter) -> Path:
    """A fresh folder in the Jupyter server's root for one test's notebooks; their kernels are shut down after it."""
    folder = Path(tempfile.mkdtemp(prefix="t", dir=jupyter.root))
    yield folder
    jupyter.shut_down_kernels(folder)
