"""The CPU's cycle (a path of `Som`, som.py): each core replays a graph of its own share, the neurons split between
the cores for the move and smoothing, the controls for the winner search, a spinning barrier between the phases
(cycle_kernels.py). Small meshes run on one core.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

from .device import usable_cores
from .primitives import barrier, sched_yield_address

_YIELD = sched_yield_address()
#: Neuron-control pairs a cycle must have per core before the CPU cycle is split (about 1 ms of work each).
PAIRS_PER_EXTRA_CORE = 1 << 18


def _cpu_cores(n_neurons: int, n_controls: int) -> int:
    """Cores for a CPU Som: one for small cycles (a barrier costs more than it saves on a busy machine), else
    those this process may use, at most 8."""
    if n_neurons * n_controls < PAIRS_PER_EXTRA_CORE:
        return 1
    return max(1, min(usable_cores(), 8, n_neurons * n_controls // PAIRS_PER_EXTRA_CORE))


class CpuPath:
    """The CPU cycle of a Som (mixed into `Som`; its state lives there)."""

    def _plan_cores(self) -> None:
        """Split the CPU cycle: neuron ranges for the move and smoothing, a thread per extra core."""
        cores = min(self._cpu_cores or _cpu_cores(self.n_neurons, self._k_eff), self.n_neurons)
        bounds = np.linspace(0, self.n_neurons, cores + 1).astype(int)
        self._ranges = list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))
        if cores > 1 and self._pool is None:
            self._pool = ThreadPoolExecutor(63, thread_name_prefix="som-core")
        if cores != self._cores:
            self._meet.zero_()  # barrier generations count in multiples of the core count
        self._cores = cores

    def _run_cpu(self, cycles: int, fresh: bool, smoothing: bool) -> None:
        graphs = [self._graph((cycles, fresh, smoothing, core), lambda core=core: self._record_cpu(core, cycles, fresh,
                                                                                                smoothing))
                  for core in range(self._cores)]
        self._replay_cpu(graphs)

    def _replay_cpu(self, graphs: list) -> None:
        """Each core's graph on its own thread (the first on this one)."""
        others = [self._pool.submit(wp.capture_launch, g) for g in graphs[1:]] if self._pool else []
        wp.capture_launch(graphs[0])
        for job in others:
            job.result()
        if self._cores > 1 and self._meet_failed.numpy()[0]:
            self._meet_failed.zero_()
            self._meet.zero_()
            raise RuntimeError("Som: a CPU core did not reach the cycle barrier (was a worker thread stopped?)")

    def _record_cpu(self, core: int, cycles: int, fresh: bool, smoothing: bool) -> None:
        """One core's share: move and smooth its neurons, find the winners of its controls, meet between phases.
        Without `fresh` the winners of the first cycle are known (always so in distance rows mode)."""
        kern, cores, (lo, hi), counter = self._kernels, self._cores, self._ranges[core], self._cycle[core]
        move_part = self._movers().move_part
        stalled = self._stalled

        def meet():
            if cores > 1:
                wp.launch(barrier, dim=1, device="cpu", inputs=[self._meet, cores, _YIELD, self._meet_failed])

        find = [self._w, self._c, self._k_eff, self._m, self._keys, counter, core, cores]
        if fresh:
            wp.launch(kern.find_part, dim=1, device="cpu", inputs=[*find, 0, stalled])
            meet()
        moved = self._w_moved if smoothing else self._w
        for _ in range(cycles):
            wp.launch(move_part, dim=1, device="cpu",
                      inputs=[self._w, moved, self._c, 0, self._k_eff, self._table, self._distances, self._slot_of,
                              self._keys, counter, lo, hi, stalled])
            meet()
            if smoothing:
                wp.launch(kern.smooth_part, dim=1, device="cpu", inputs=[moved, self._w, self._offsets, self._neighbors,
                                                                      self._mask, self._smoothing, lo, hi, stalled])
                meet()
            wp.launch(kern.find_part, dim=1, device="cpu", inputs=[*find, 1, stalled])
            meet()
