"""Programmatic dependent launch (CUDA, compute capability 9.0+): a kernel launched so that its blocks start while
the kernel before it in the stream is still running. Each such kernel calls `primitives.wait_for_previous_grid`
before it reads anything the previous kernel writes, so only the launch itself overlaps; the results are those of
an ordinary launch. The next kernel is launched once every block of the one before has ended or called
`primitives.let_next_grid_launch`. Warp has no launch option for this, so the launch goes through the driver's
cuLaunchKernelEx with Warp's own compiled kernel and packed arguments.
"""

from __future__ import annotations

import ctypes
import functools
import sys
from typing import Any

import warp as wp

#: CUlaunchAttributeID CU_LAUNCH_ATTRIBUTE_PROGRAMMATIC_STREAM_SERIALIZATION (cuda.h).
_PROGRAMMATIC_STREAM_SERIALIZATION = 6


class _LaunchAttribute(ctypes.Structure):
    """CUlaunchAttribute: an id, padding to 8 bytes, a 64-byte value union."""

    _fields_ = [("id", ctypes.c_int), ("pad", ctypes.c_char * 4), ("value", ctypes.c_int * 16)]


class _LaunchConfig(ctypes.Structure):
    """CUlaunchConfig."""

    _fields_ = [("grid", ctypes.c_uint * 3), ("block", ctypes.c_uint * 3), ("shared_bytes", ctypes.c_uint),
                ("stream", ctypes.c_void_p), ("attributes", ctypes.POINTER(_LaunchAttribute)),
                ("n_attributes", ctypes.c_uint)]


#: The first driver (CUDA 12.3) whose stream capture records dependent launches into graphs.
_OLDEST_DRIVER = 12030


@functools.cache
def _launch_kernel_ex():
    """The driver's cuLaunchKernelEx, or None where the driver lacks it or is older than _OLDEST_DRIVER."""
    try:
        driver = ctypes.CDLL("nvcuda.dll" if sys.platform == "win32" else "libcuda.so.1")
        launch = driver.cuLaunchKernelEx
        version = ctypes.c_int(0)
        if driver.cuDriverGetVersion(ctypes.byref(version)) != 0 or version.value < _OLDEST_DRIVER:
            return None
    except (OSError, AttributeError):
        return None
    launch.argtypes = [ctypes.POINTER(_LaunchConfig), ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    launch.restype = ctypes.c_int
    return launch


def available(device: str) -> bool:
    """Whether kernels for `device` are compiled for 9.0+ (where `wait_for_previous_grid` is compiled in) and the
    driver has cuLaunchKernelEx."""
    if device == "cpu":
        return False
    arch = wp.get_device(device).get_cuda_compile_arch()
    return arch is not None and arch >= 90 and _launch_kernel_ex() is not None


def launch_tiled_after_kernel(kernel: wp.Kernel, blocks: int, block_dim: int, inputs: list, device: str) -> Any:
    """`wp.launch_tiled(kernel, dim=[blocks], block_dim=block_dim, ...)` on the device's current stream, its blocks
    allowed to start before the kernel launched just before it in the stream ends. Returns Warp's launch
    record, which holds the packed arguments: keep it as long as a graph that captured the launch lives."""
    record = wp.launch(kernel, dim=[blocks, block_dim], block_dim=block_dim, inputs=inputs, device=device,
                       record_cmd=True)
    attribute = _LaunchAttribute(id=_PROGRAMMATIC_STREAM_SERIALIZATION)
    attribute.value[0] = 1
    config = _LaunchConfig(grid=(ctypes.c_uint * 3)(blocks, 1, 1), block=(ctypes.c_uint * 3)(block_dim, 1, 1),
                           shared_bytes=record.hooks.forward_smem_bytes,
                           stream=wp.get_stream(device).cuda_stream, attributes=ctypes.pointer(attribute),
                           n_attributes=1)
    error = _launch_kernel_ex()(ctypes.byref(config), record.hooks.forward, record.params_addr, None)
    if error != 0:
        raise RuntimeError(f"cuLaunchKernelEx of {kernel.key} on {device} failed with CUDA error {error}")
    return record
