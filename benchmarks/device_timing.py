"""Wall-clock timing of device work for the benchmark scripts: the device is synchronised before the clock starts
and before it stops."""

import time

import warp as wp


def device_timer(device: str):
    """(sync, timed) for `device`: sync() waits for its queued work; timed(fn) returns (seconds, fn())."""

    def sync():
        wp.synchronize_device(device)

    def timed(fn):
        sync()
        t = time.perf_counter()
        out = fn()
        sync()
        return time.perf_counter() - t, out

    return sync, timed
