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

