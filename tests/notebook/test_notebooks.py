"""The notebooks in notebooks/ run top to bottom in a fresh kernel (nbclient), headless, and end with a picture.

The kernel is this interpreter (the venv's python with ipykernel): the test writes a kernelspec for it into a
temporary directory, so nothing has to be installed into Jupyter's own kernel list. Committed notebooks carry no
outputs. A notebook that documents a lighter run in a cell tagged "parameters" runs with PARAMETERS below. VTK
renders off-screen through EGL (VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow, set by scripts/test.sh and defaulted
here).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

from jupyter_client.kernelspec import KernelSpecManager  # noqa: E402
from jupyter_client.manager import KernelManager  # noqa: E402

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
EXPECTED = ["01_space_grid", "02_car", "03_lines", "04_your_own_mesh", "05_speed", "06_clay_rules", "07_variants",
            "08_shape_briefs", "09_modelling_app"]
KERNEL = "somwidget-test"
CELL_TIMEOUT = 240  # seconds for one cell on a slow, shared machine
#: What the tests set in a notebook's cell tagged "parameters" (papermill's convention: a cell after it sets them),
#: where the notebook documents a lighter run: the speed curve up to 4,096 neurons instead of 8,000, 8 variants of the
#: car instead of 32, the shape briefs' figures from 2,000 points instead of 10,000. The cells are the same.
PARAMETERS = {"05_speed": 'SIDES = {"cpu": (6, 8, 12, 16), "cuda:0": (6, 8, 12, 16, 20, 24, 32)}',
              "07_variants": "N = 256 if DEVICE.startswith('cuda') else 8",
              "08_shape_briefs": "SAMPLES = 2_000"}


@pytest.fixture(scope="module")
def kernel_dir(tmp_path_factory) -> Path:
    """A kernelspec for this interpreter in a temporary directory."""
    root = tmp_path_factory.mktemp("kernels")
    spec = root / KERNEL
    spec.mkdir()
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "somwidget tests", "language": "python",
        "env": {"VTK_DEFAULT_OPENGL_WINDOW": os.environ.get("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow"),
                "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p),
                "MPLBACKEND": "module://matplotlib_inline.backend_inline"},
    }))
    return root


def test_every_notebook_is_here():
    assert [p.stem for p in NOTEBOOKS] == EXPECTED


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_committed_without_outputs(path):
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    for i, cell in enumerate(nb.cells):
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, f"cell {i} of {path.name} has outputs"
    assert nb.cells[0].cell_type == "markdown" and nb.cells[0].source.startswith("# ")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_runs_top_to_bottom(path, kernel_dir):
    nb = nbformat.read(path, as_version=4)
    if path.stem in PARAMETERS:
        tagged = [i for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", [])]
        assert len(tagged) == 1, f"{path.name} should have one cell tagged 'parameters'"
        name = PARAMETERS[path.stem].split("=")[0].strip()
        assert f"\n{name} = " in "\n" + nb.cells[tagged[0]].source, f"{path.name}'s parameters set no {name}"
        nb.cells.insert(tagged[0] + 1, nbformat.v4.new_code_cell(PARAMETERS[path.stem]))
    km = KernelManager(kernel_name=KERNEL, kernel_spec_manager=KernelSpecManager(kernel_dirs=[str(kernel_dir)]))
    client = nbclient.NotebookClient(nb, km=km, timeout=CELL_TIMEOUT, kernel_name=KERNEL,
                                     resources={"metadata": {"path": str(path.parent)}})
    t0 = time.monotonic()
    client.execute()  # raises CellExecutionError with the cell and its traceback on the first failure
    took = time.monotonic() - t0
    print(f"{path.name}: {took:.1f} s")
    code = [c for c in nb.cells if c.cell_type == "code"]
    errors = [o for c in code for o in c.outputs if o.get("output_type") == "error"]
    assert not errors, errors
    last = code[-1]
    # a picture at the end: a still (somwidget.render), or the live view whose saved output keeps one (the app)
    assert "somwidget.render(" in last.source or "somwidget.show(" in last.source, \
        "the notebook should end with a picture (somwidget.render) or the live view (somwidget.show)"
    assert any("image/png" in o.get("data", {}) for o in last.outputs), f"{path.name}: the last cell shows no image"
