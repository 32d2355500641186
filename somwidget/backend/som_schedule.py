"""The schedule a Som runs: schedule.Schedule's values, the smoothing rule, and the learning table they make on the
device, L[s, d] = alpha(s) theta(d, s) (the paper's section III; schedule.learning_table), with where a local
restart begins in it, s0 = floor((1 - reach) S).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import warp as wp

from .schedule import NEIGHBOURHOOD_CUT, Schedule, reach_hops
from .smoothing_kernels import smoothing_steps

#: Learning table entries (S x (d_max + 1) float32) a Som may hold: 2 GiB.
MAX_TABLE_ENTRIES = 1 << 29


def restart_iteration(reach: float, iterations: int) -> int:
    """s0 = floor((1 - reach) S), at most S - 1: where a local restart begins in the unchanged schedule."""
    return min(math.floor((1.0 - reach) * iterations), iterations - 1)  # (math: every move finds it)


class SomSchedule:
    """values: the Schedule (a value of each of schedule.KEYS); rule: "laplacian" or "taubin"; table: L on the
    device, (S, d_max + 1) float32, made by `rebuild` (version counts the tables made); table_max: its largest rate;
    reach_hops (CPU): the farthest hop count with a non-zero rate at each cycle, as a list and as `reach_dev`."""

    def __init__(self, values: Schedule, rule: str, device: str) -> None:
        self.values = values
        self.rule = rule
        self.device = device
        self.table: wp.array | None = None
        self._host: np.ndarray | None = None  # the table on the host (the CPU's is the device array itself)
        self.table_max = 0.0
        self.d_max = 0
        self.version = 0
        self.reach_hops: np.ndarray | None = None
        self.reach_dev: wp.array | None = None

    def rebuild(self, values: Schedule, d_max: int, cut: bool, drop: Callable[[], None]) -> None:
        """Make `values` the schedule, with its table for hop distances up to d_max (`cut`: theta < 2^-24 is 0,
        schedule.NEIGHBOURHOOD_CUT). ValueError, and nothing changed, when the table would exceed MAX_TABLE_ENTRIES.
        One table at a time: `drop` lets go of what holds the old one (the captured graphs) before the new one is
        made, and on the CPU the device array is the host array itself, so a change costs at most one table."""
        if values.iterations * (d_max + 1) > MAX_TABLE_ENTRIES:
            raise ValueError(f"iterations: the learning table S x (d_max + 1) = {values.iterations:,} x {d_max + 1:,} "
                             f"exceeds {MAX_TABLE_ENTRIES:,} entries (2 GiB); use fewer iterations")
        drop()
        self.table = self._host = None
        self.values = values
        host = values.learning_table(d_max, NEIGHBOURHOOD_CUT if cut else 0.0)
        self.table_max = float(host.max())
        self.d_max = d_max
        self._host = host
        self.table = wp.array(host, dtype=wp.float32, device=self.device, copy=self.device != "cpu")
        self.version += 1
        if self.device == "cpu":  # the local cycle's reach per cycle (the CPU's only)
            self.reach_hops = reach_hops(host)
            self.reach_dev = wp.array(self.reach_hops, dtype=wp.int32, device="cpu")
        else:  # the device holds it; `host_table()` reads it back
            self._host = None

    def device_table(self) -> wp.array:
        """L on the device; RuntimeError before `rebuild` made it."""
        if self.table is None:
            raise RuntimeError("SomSchedule: no learning table yet (rebuild makes it)")
        return self.table

    def host_table(self) -> np.ndarray:
        """L[s, d] (S, d_max + 1) float32 (a copy)."""
        if self._host is not None:
            return self._host.copy()
        assert self.table is not None  # made with the schedule
        return self.table.numpy()

    def restart_iteration(self, reach: float | None = None) -> int:
        """s0 of a local restart with `reach` (None: the schedule's)."""
        return restart_iteration(self.values.reach if reach is None else reach, self.values.iterations)

    def steps(self) -> list[float]:
        """The strengths of the smoothing steps a cycle runs (smoothing_kernels.smoothing_steps)."""
        return smoothing_steps(self.values.smoothing, self.rule)
