"""The CPU's cores for one Som: how many share a cycle (one for small cycles), each core's range of neurons, the
thread pool that runs the other cores' work, and the spinning barrier (primitives.barrier) the dense cycle's phases
meet at. cpu_path.py, local_path.py and shaping_path.py share one `CpuCores`.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

from .device import usable_cores
from .primitives import barrier, sched_yield_address

_YIELD = sched_yield_address()
#: Neuron-control pairs a cycle must have per core before the CPU cycle is split (about 1 ms of work each).
PAIRS_PER_EXTRA_CORE = 1 << 18


def cores_for(n_neurons: int, n_controls: int) -> int:
    """Cores for a CPU Som: one for small cycles (a barrier costs more than it saves on a busy machine), else those
    this process may use, at most 8."""
    if n_neurons * n_controls < PAIRS_PER_EXTRA_CORE:
        return 1
    return max(1, min(usable_cores(), 8, n_neurons * n_controls // PAIRS_PER_EXTRA_CORE))


class CpuCores:
    """The cores a CPU Som's cycles run on. requested: `Som(cpu_cores=...)` (None: the engine chooses); count and
    ranges: the plan for the current controls (`plan`); busy: the cores a local run shares its blocks between
    (`share`)."""

    def __init__(self, requested: int | None) -> None:
        self.requested = requested
        self.count = 1
        self.busy = 1
        self.ranges: list[tuple[int, int]] = []
        self._planned_for: tuple[int, int] | None = None
        self._pool: ThreadPoolExecutor | None = None
        self.meet = wp.zeros(1, dtype=wp.int64, device="cpu")  # the barrier's counter
        self.meet_failed = wp.zeros(1, dtype=wp.int32, device="cpu")

    def plan(self, n_neurons: int, n_controls: int) -> None:
        """Split the cycle for n_controls effective controls: neuron ranges for the move and smoothing, a thread per
        extra core (again only when the count of controls changed)."""
        if self._planned_for == (n_neurons, n_controls):
            return
        self._planned_for = (n_neurons, n_controls)
        cores = min(self.requested or cores_for(n_neurons, n_controls), n_neurons)
        bounds = np.linspace(0, n_neurons, cores + 1).astype(int)
        self.ranges = list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))
        if cores > 1 and self._pool is None:
            self._pool = ThreadPoolExecutor(63, thread_name_prefix="som-core")
        if cores != self.count:
            self.meet.zero_()  # barrier generations count in multiples of the core count
        self.count = cores

    def share(self, neurons: int, n_controls: int) -> None:
        """Before a local run: `busy`, the cores it splits its work between. One unless the last run moved `neurons`
        enough for more (as for the full cycle, `cores_for`: a core's share of neuron-control pairs a cycle), so a
        drag that touches a small region waits for no other core; all of `requested` when given."""
        enough = neurons * max(1, n_controls) >= 2 * PAIRS_PER_EXTRA_CORE
        self.busy = self.count if enough or self.requested is not None else 1

    def meet_between_phases(self) -> None:
        """Launch the barrier: every core of the plan meets here (nothing with one core). Recorded into each core's
        graph between the phases of a cycle."""
        if self.count > 1:
            wp.launch(barrier, dim=1, device="cpu", inputs=[self.meet, self.count, _YIELD, self.meet_failed])

    def replay(self, graphs: list) -> None:
        """Each core's graph on its own thread (the first on this one)."""
        others = [self._pool.submit(wp.capture_launch, g) for g in graphs[1:]] if self._pool else []
        wp.capture_launch(graphs[0])
        for job in others:
            job.result()
        if self.count > 1 and self.meet_failed.numpy()[0]:
            self.meet_failed.zero_()
            self.meet.zero_()
            raise RuntimeError("Som: a CPU core did not reach the cycle barrier (was a worker thread stopped?)")

    def _threads(self) -> ThreadPoolExecutor:
        """The extra cores' threads (`plan` starts them when it plans more than one core)."""
        if self._pool is None:
            raise RuntimeError("CpuCores: work split between cores before `plan` planned more than one")
        return self._pool

    def super_ranges(self, n_super: int) -> list[tuple[int, int]]:
        """Each busy core's range of superblocks."""
        bounds = np.linspace(0, n_super, self.busy + 1).astype(int)
        return list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))

    def on_cores(self, kernel: wp.Kernel, inputs: Callable[..., list], split: list[tuple]) -> None:
        """`kernel` on every core at once, core i given inputs(*split[i])."""
        others = [self._threads().submit(wp.launch, kernel, dim=1, device="cpu", inputs=inputs(*part))
                  for part in split[1:]] if len(split) > 1 else []
        wp.launch(kernel, dim=1, device="cpu", inputs=inputs(*split[0]))
        for job in others:
            job.result()
