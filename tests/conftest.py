"""Shared fixtures for every test.

Tests live in folders by room (engine, model, transport, web, notebook, xr, package) and carry markers: `browser`
(drives a real Chromium), `gpu` (runs on a CUDA device, skipped without one), `slow` (a minute or more). The fast
loop is `pytest -m "not browser and not slow"`.

`device` is parametrised over DEVICES: "cpu" always, "cuda:0" only when Warp reports a CUDA device
(otherwise that case is skipped with a reason). Every engine test runs the real Warp kernels.
"""

from __future__ import annotations

import os
import sys
import tempfile

import numpy as np
import pytest

# The reference module lives beside the tests; make it importable whatever pytest's import mode.
_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

# Autosaves, certificates and history spills of every session the tests make (and of the servers they start, which
# inherit the environment) go to a folder of this run, never to the user's data directory.
os.environ["SOMWIDGET_DATA_DIR"] = tempfile.mkdtemp(prefix="somwidget-test-data-")


def _cuda_device_count() -> int:
    try:
        import warp as wp

        wp.config.log_level = wp.LOG_WARNING
        wp.init()
        return int(wp.get_cuda_device_count())
    except (ImportError, RuntimeError, OSError):  # no warp, or no usable CUDA driver: CPU only
        return 0


HAS_CUDA = _cuda_device_count() > 0

DEVICES = [
    "cpu",
    pytest.param(
        "cuda:0",
        marks=[pytest.mark.gpu, pytest.mark.skipif(not HAS_CUDA, reason="warp reports no CUDA device on this machine")],
    ),
]


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    """A Warp device string the engine is run on: "cpu", or "cuda:0" where one exists."""
    return request.param


@pytest.fixture(params=DEVICES)
def devices(request) -> str:
    """The same parametrisation under the plural name."""
    return request.param


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20181210)


@pytest.fixture(scope="module")
def browser():
    """A real Chromium (Debian's, driven by Playwright), one a test file; a file may define its own."""
    from helpers import CHROMIUM, CHROMIUM_ARGS
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


#: The test files that took longest in a full run (`pytest -n 2 --dist loadfile --durations=0`, summed per file, most
#: first; 2026-11-28 on the 2-core CI box). xdist hands out whole files in the order of the collection, so these go
#: first: a long file started last would keep one worker busy while the others have run out of work. Order only: a
#: file that is missing here (or gone) runs after them, in the order pytest collects it.
LONGEST_FILES = (
    "web/test_app_browser.py", "notebook/test_notebooks.py", "notebook/test_notebook_panel.py",
    "web/test_view_modelling.py", "model/test_recovery.py", "web/test_modelling_by_hand.py", "xr/test_xr_browser.py",
    "web/test_web_panel_browser.py", "web/test_view_handling.py", "web/test_fifth_trial.py",
    "notebook/test_saved_notebook.py", "studio/test_batched_rooms.py", "package/test_wheel.py",
    "web/test_shaping_panels.py", "notebook/test_panel_fits.py", "web/test_fourth_trial.py",
    "engine/test_handles_reference.py", "web/test_third_trial.py", "xr/test_many_hands_browser.py",
    "model/test_memory_bounds.py", "package/test_api_docs.py", "model/test_session.py",
    "notebook/test_marimo_browser.py", "model/test_save_failures.py", "transport/test_clean_failures.py",
    "studio/test_wall_browser.py", "web/test_panel_hints.py", "transport/test_slow_clients.py",
    "notebook/test_notebook_and_browser.py", "engine/test_handles.py", "xr/test_xr_serve.py",
    "model/test_recovery_damaged.py", "engine/test_clay.py", "web/test_client_state.py",
)


def pytest_collection_modifyitems(config, items) -> None:
    """The longest files first (LONGEST_FILES), each file's tests kept together and in their order; scripts/test.sh
    passes --no-loadscope-reorder so that xdist keeps this order instead of putting the files with most tests first."""
    rank = {name: i for i, name in enumerate(LONGEST_FILES)}

    def file_rank(item) -> int:
        path = os.path.relpath(str(item.path), _HERE).replace(os.sep, "/")
        return rank.get(path, len(rank))

    items[:] = sorted(items, key=file_rank)  # a stable sort: the rest keep pytest's order
