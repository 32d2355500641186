"""The paper's cycle on the CPU with the dense table: each core replays a captured graph of its own share, the neurons
split between the cores for steps 2 and 3, the controls for step 1, a spinning barrier between the phases
(cycle_kernels.py, cpu_cores.py). Small meshes run on one core.
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from .cpu_cores import CpuCores
from .som_controls import Controls
from .som_model import SomModel
from .som_schedule import SomSchedule
from .som_state import Graphs, SomState


class CpuPath:
    """The CPU's dense cycle: `run` replays each core's graph (`record` captures it), `winners` finds the winners of
    the current weights. It also runs distance rows on the CPU when rows_path.RowsPath drives it (the full
    computation the local cycle must equal)."""

    def __init__(self, cores: CpuCores) -> None:
        self.cores = cores
        self.graphs = Graphs("cpu")

    def winners(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule) -> np.ndarray:
        state.fresh_winners(lambda: self.find_winners(model, state))
        return controls.from_slots(state.winners(state.n_slots))

    @staticmethod
    def find_winners(model: SomModel, state: SomState) -> None:
        """Step 1 on the CPU from the current weights, every control on this core: keys[s % 3] (s = cycle[0])."""
        wp.launch(model.kernels.find_part, dim=1, device="cpu", inputs=[state.w, state.c, state.n_slots, model.m,
                                                                        state.keys, state.cycle[0], 0, 1, 0,
                                                                        state.stalled])

    def forget(self) -> None:
        """Drop the captured graphs (before the learning table they hold is made again)."""
        self.graphs.clear()

    def prepare(self, model: SomModel, controls: Controls, schedule: SomSchedule) -> None:
        """Before a run: the cores' plan and the graphs for these controls and this schedule."""
        self.cores.plan(model.n_neurons, controls.n_slots)
        self.graphs.valid_for(controls, schedule)

    def run(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, cycles: int) -> None:
        """`cycles` cycles from s (at most cycle_kernels.LONGEST_GRAPH)."""
        fresh = state.start_run()
        smoothing = schedule.values.smoothing > 0.0
        self.prepare(model, controls, schedule)
        self.replay(model, state, controls, schedule, (cycles, fresh, smoothing), cycles, fresh, smoothing)
        state.weights_replaced()
        state.s += cycles
        state.winners_valid = True

    def run_known(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule,
                  cycles: int) -> int:
        """`cycles` cycles from s whose first winners are known (distance rows mode). Returns the cycle reached, short
        of s + cycles where a cycle stalled on a missing row."""
        smoothing = schedule.values.smoothing > 0.0
        self.replay(model, state, controls, schedule, ("rows", cycles, smoothing), cycles, False, smoothing)
        return int(state.cycle[0].numpy()[0])

    def replay(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, key: tuple,
               cycles: int, fresh: bool, smoothing: bool) -> None:
        """Each core's graph of `key` (captured the first time) on its own thread."""
        self.cores.replay([self.graphs.get((*key, core), functools.partial(
            self.record, model, state, controls, schedule, core, cycles, fresh, smoothing))
            for core in range(self.cores.count)])

    def record(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, core: int,
               cycles: int, fresh: bool, smoothing: bool) -> None:
        """One core's share: move and smooth its neurons, find the winners of its controls, meet between phases.
        Without `fresh` the winners of the first cycle are known (always so in distance rows mode)."""
        kern, cores, counter = model.kernels, self.cores, state.cycle[core]
        lo, hi = cores.ranges[core]
        move_part = model.kernels_for(controls.pairs(schedule.table_max)).move_part
        k, stalled = state.n_slots, state.stalled
        find = [state.w, state.c, k, model.m, state.keys, counter, core, cores.count]
        if fresh:
            wp.launch(kern.find_part, dim=1, device="cpu", inputs=[*find, 0, stalled])
            cores.meet_between_phases()
        moved = state.w_moved if smoothing else state.w
        for _ in range(cycles):
            wp.launch(move_part, dim=1, device="cpu",
                      inputs=[state.w, moved, state.c, 0, k, schedule.table, model.distances, model.slot_of,
                              state.keys, counter, lo, hi, stalled])
            cores.meet_between_phases()
            if smoothing:
                wp.launch(kern.smooth_part, dim=1, device="cpu",
                          inputs=[moved, state.w, model.offsets, model.neighbors, model.mask,
                                  schedule.values.smoothing, lo, hi, stalled])
                cores.meet_between_phases()
            wp.launch(kern.find_part, dim=1, device="cpu", inputs=[*find, 1, stalled])
            cores.meet_between_phases()
