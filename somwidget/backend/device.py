"""Choosing the Warp device: None picks CUDA when present, else the CPU."""

from __future__ import annotations

import functools
import logging
import os
import sys
import tempfile
import threading

import warp as wp

log = logging.getLogger(__name__)

wp.config.log_level = wp.LOG_WARNING  # no start-up banner; warnings still show

#: Set by the first `init()`: what Warp's native start-up said about CUDA on a machine without the driver (logged,
#: not printed: `describe` says which device runs, in words).
cuda_note: str | None = None
_init_lock = threading.Lock()
_started = False


def init() -> None:
    """Start Warp once. On a machine without an NVIDIA driver Warp's native code prints "Warp CUDA warning: Could not
    find or load the NVIDIA CUDA driver..." to stderr, in red in a notebook, at every start: that line is kept in
    `cuda_note` and logged instead; anything else Warp prints there goes on to stderr."""
    global cuda_note, _started
    with _init_lock:
        if _started:
            return
        _started = True
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError):  # no real stderr (an embedded interpreter): let Warp print as it will
            wp.init()
            return
        with tempfile.TemporaryFile(mode="w+b") as captured:
            os.dup2(captured.fileno(), 2)
            try:
                wp.init()
            finally:
                os.dup2(saved, 2)
                os.close(saved)
            captured.seek(0)
            text = captured.read().decode("utf-8", "replace")
        kept = []
        for line in text.splitlines():
            if "CUDA driver" in line and "warning" in line.lower():
                cuda_note = line.strip()
                log.info("%s", cuda_note)
            elif line.strip():
                kept.append(line)
        if kept:
            print("\n".join(kept), file=sys.stderr)


def describe(device: str) -> str:
    """Which device trains, in words for a person: "the CPU (no NVIDIA GPU found)" or "the GPU cuda:0 (NAME)"."""
    if device.startswith("cuda"):
        return f"the GPU {device} ({wp.get_device(device).name})"
    why = " (no NVIDIA GPU or driver found)" if wp.get_cuda_device_count() == 0 else ""
    return f"the CPU{why}"


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity mask where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def resolve(device: str | None) -> str:
    """'cpu', 'cuda:N' (or 'cuda' = 'cuda:0') when that GPU exists; None = best available."""
    init()
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
