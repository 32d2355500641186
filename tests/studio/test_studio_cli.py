"""`somwidget serve --studio` as a person runs it (a subprocess, its printed links), a studio stopped and started again
(its rooms and their links kept), the studio's options refused without --studio, and the studio's imports free of UI
packages (what a GPU machine with only numpy, warp and aiohttp runs)."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest
from helpers import ROOT, Serve

from somwidget.cli import main


def links(output: str) -> dict:
    found = {"wall": re.search(r"the wall and every room \(teacher\): (\S+)", output),
             "class": re.search(r"the class \(each person makes a room of their own\): (\S+)", output),
             "alice": re.search(r"room alice: (\S+)", output)}
    assert all(found.values()), output
    return {k: m.group(1) for k, m in found.items()}


def test_serve_studio_prints_its_links_and_keeps_rooms_across_restarts():
    server = Serve("--studio", "--rooms", "alice,bob", "--park-after", "5")
    try:
        shown = links(server.output())
        wall_token = shown["wall"].split("token=")[1]
        alice_path = shown["alice"].split(str(server.port), 1)[1]
        assert server.get(alice_path)[0] == 200
        assert server.get("/r/bob/", shown["alice"].split("token=")[1])[0] == 403
        status, body = server.get("/api/rooms", wall_token)
        assert status == 200 and {r["name"] for r in json.loads(body)["rooms"]} == {"alice", "bob"}
        data = server.data_dir
    finally:
        server.stop()
    assert server.proc.returncode == 0, server.output()[-2000:]
    assert (data / "studio" / "alice" / "session" / "manifest.json").is_file()  # saved as it stopped
    again = Serve("--studio", env={"SOMWIDGET_DATA_DIR": str(data)})
    try:
        assert again.get(alice_path)[0] == 200  # the same link opens the same room
        status, body = again.get("/api/rooms", links_teacher(again.output()))
        assert {r["name"] for r in json.loads(body)["rooms"]} == {"alice", "bob"}
    finally:
        again.stop()


def links_teacher(output: str) -> str:
    return re.search(r"the wall and every room \(teacher\): \S+token=(\S+)", output).group(1)


@pytest.mark.parametrize("option", [["--workers", "2"], ["--rooms", "a"], ["--scheduler", "tcp://x:8786"]])
def test_studio_options_need_studio(option, capsys):
    assert main(["serve", *option]) == 2
    assert "add --studio" in capsys.readouterr().err


def test_studio_refuses_a_mesh(capsys):
    assert main(["serve", "--studio", "--mesh", "x.obj"]) == 2
    assert "rooms start from a preset" in capsys.readouterr().err


def test_the_studio_imports_no_ui_package():
    code = ("import sys; import somwidget.frontend.studio.serve, somwidget.frontend.studio.worker, "
            "somwidget.frontend.studio.remote, somwidget.frontend.studio.dask_rooms; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'trame', 'pyvista', 'trimesh', 'vtk', 'vtkmodules', 'wslink', 'ipywidgets', 'anywidget', 'PIL'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout
