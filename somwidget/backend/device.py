"""Choosing the Warp device: None picks CUDA when present, else the CPU."""

from __future__ import annotations

import functools
import threading

import warp as wp


wp.config.log_level = wp.LOG_WARNING  # no start-up banner; warnings still show


def resolve(device: str | None) -> str:
    """'cpu', 'cuda:N' (or 'cuda' = 'cuda:0') when that GPU exists; None = best available."""
    wp.init()
    n_cuda = wp.get_cuda_device_count()
    if device is None or device == "auto":
        return "cuda:0" if n_cuda > 0 else "cpu"
    if not isinstance(device, str):
        raise ValueError(f"device: expected None, 'auto', 'cpu' or 'cuda:N', got {device!r}")
    if device == "cpu":
        return "cpu"
    if device == "cuda":
        device = "cuda:0"
    if device.startswith("cuda:") and device[5:].isdigit():
        index = int(device[5:])
        if index >= n_cuda:
            have = "no CUDA device" if n_cuda == 0 else f"CUDA devices 0..{n_cuda - 1}"
            raise ValueError(f"device: {device!r} is not available (this machine has {have}); use 'cpu' or None")
        return device
    raise ValueError(f"device: expected None, 'auto', 'cpu', 'cuda' or 'cuda:N', got {device!r}")



#: Warp records every launch made on a device while a graph of that device is being captured, whichever thread
#: makes it. All of the engine's Warp work takes this lock, so a capture holds only its own launches and several
#: threads (a session training while another loads a mesh, two sessions in one process) stay apart.
warp_lock = threading.RLock()


def warp_exclusive(method):
    """Run `method` holding `warp_lock`."""

    @functools.wraps(method)
    def locked(*args, **kwargs):
        with warp_lock:
            return method(*args, **kwargs)

    return locked
