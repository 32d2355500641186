"""The paper's cycle past the dense table's 65,536 neurons: the cycle kernels read int32 distance rows of the winners
from a cache on the device (row_cache.RowCache); a cycle whose winners lack a row stalls, the host computes the rows
and the run goes on from that cycle. It drives the CUDA path's captured graphs (on the CPU, the dense path's: the
full computation that the local cycle, local_path.py, gives bit for bit).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .cpu_path import CpuPath
from .cuda_path import CudaPath
from .cycle_kernels import CUDA_BLOCK, LONGEST_GRAPH
from .row_cache import control_parts
from .som_controls import Controls
from .som_model import SomModel
from .som_schedule import SomSchedule
from .som_state import SomState


class RowsPath:
    """Distance rows mode, driving `inner` (CudaPath on a GPU, CpuPath on the CPU), whose graphs it replays."""

    def __init__(self, inner: CpuPath | CudaPath) -> None:
        self.inner = inner

    def forget(self) -> None:
        self.inner.forget()

    def winners(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule) -> np.ndarray:
        return self.inner.winners(model, state, controls, schedule)

    def run(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, cycles: int) -> None:
        """`cycles` cycles reading distance rows: the winners' rows are fetched, then a graph runs until done or a
        cycle stalls on a winner without a row (it then leaves everything as it was); the host fetches that cycle's
        rows and goes on from it. A cycle whose distinct winners outnumber the cache rows runs in parts."""
        state.settle_anchor()
        cache = model.row_cache()
        target = state.s + cycles
        smoothing = schedule.values.smoothing > 0.0
        self.inner.prepare(model, controls, schedule)
        while state.s < target:
            state.fresh_winners(lambda: self.inner.find_winners(model, state))
            winners = state.winners(state.n_slots)
            distinct = list(dict.fromkeys(winners.tolist()))
            if len(distinct) > cache.size:
                self._cycle_in_parts(model, state, controls, schedule, winners, smoothing)
                continue
            cache.fetch(distinct, schedule.d_max)
            left = target - state.s
            chunk = min(cache.span, 1 << (left.bit_length() - 1))
            reached = self.inner.run_known(model, state, controls, schedule, chunk)
            if reached < state.s + chunk:  # stalled: the graph's later cycles did nothing, try shorter ones
                state.stalled.zero_()
                cache.stalls += 1
                cache.span = max(1, cache.span // 4)
            else:
                cache.span = min(LONGEST_GRAPH, cache.span * 2)
            state.s = reached
            state.winners_valid = True
        state.weights_replaced()

    def _cycle_in_parts(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule,
                        winners: np.ndarray, smoothing: bool) -> None:
        """One cycle in consecutive runs of controls whose winners fit in the cache (each neuron still applies the
        controls in list order)."""
        dev, cache, kern, k = model.device, model.row_cache(), model.kernels, state.n_slots
        movers = model.kernels_for(controls.pairs(schedule.table_max))
        parts = control_parts(winners, cache.size, 2 if controls.mirror else 1)
        moved = state.w_moved if smoothing else state.w
        source = state.w
        c_in, c_out = state.cycle[0], state.cycle[1]
        lam = schedule.values.smoothing
        for i, (lo, hi) in enumerate(parts):
            cache.fetch(list(dict.fromkeys(winners[lo:hi].tolist())), schedule.d_max)
            if dev == "cpu":
                wp.launch(movers.move_part, dim=1, device=dev,
                          inputs=[source, moved, state.c, lo, hi, schedule.table, model.distances, model.slot_of,
                                  state.keys, c_in, 0, model.n_neurons, state.stalled])
            else:
                find_next = int(not smoothing and i == len(parts) - 1)
                wp.launch_tiled(movers.move, dim=[model.blocks], block_dim=int(CUDA_BLOCK), device=dev,
                                inputs=[source, moved, state.c, lo, hi, k, model.m, schedule.table, model.distances,
                                        model.slot_of, state.keys, c_in, c_out, find_next, state.stalled])
            source = moved
        if dev == "cpu":
            if smoothing:
                wp.launch(kern.smooth_part, dim=1, device=dev,
                          inputs=[moved, state.w, model.offsets, model.neighbors, model.mask, lam, 0,
                                  model.n_neurons, state.stalled])
            wp.launch(kern.find_part, dim=1, device=dev,
                      inputs=[state.w, state.c, k, model.m, state.keys, c_in, 0, 1, 1, state.stalled])
        elif smoothing:
            wp.launch_tiled(kern.smooth, dim=[model.blocks], block_dim=int(CUDA_BLOCK), device=dev,
                            inputs=[moved, state.w, model.offsets, model.neighbors, model.mask, lam, state.c, k,
                                    model.m, state.keys, c_out, c_in, state.stalled])
        state.s += 1
        state.set_cycle()
        state.winners_valid = True
