"""The paper's cycle on CUDA: a run of cycles captured as a graph of one kernel a cycle (two with smoothing where the
halos do not fit), launched dependent on the one before where the GPU allows (dependent_launch.py); small meshes with
up to 32 controls spread the controls over the warps of a block (spread_kernels.py), and with smoothing move each
block's halo too (halos.py).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import dependent_launch
from .cycle_kernels import CUDA_BLOCK, SINGLES, cycle_kernels
from .halos import block_halos
from .som_controls import Controls
from .som_model import SomModel
from .som_schedule import SomSchedule
from .som_state import KEY_NONE, Graphs, SomState
from .spread_kernels import (
    SHARED_TABLE_WORDS,
    spread_cycle_inputs,
    spread_cycle_kernel,
    spread_smoothing_cycle_inputs,
    spread_smoothing_cycle_kernel,
)

#: Meshes up to this many neurons have latency-bound cycles on CUDA (a block per 32 neurons leaves most of the GPU
#: idle). With at most 32 controls a block spreads the controls over up to eight warps (`spread_cycle_kernel`; with
#: smoothing, and the dense table, `spread_smoothing_cycle_kernel`, where each block also moves the neighbours of
#: its neurons that other blocks own: at most _SPREAD_MOST_WARPS chunks of 32, neurons of at most
#: _SMOOTHING_MOST_NEIGHBOURS neighbours); otherwise the move kernel looks up the rates of all controls at once, up
#: to 32 (measured on an H200, BENCHMARKS.md).
SMALL_MESH = 16384
_SPREAD_MOST_WARPS = 8
_SPREAD_MOST_CONTROLS = 32
_SMOOTHING_MOST_NEIGHBOURS = 16


def _spread_shape(controls: int, least_warps: int, paired: bool = False) -> tuple[int, int]:
    """(warps, controls a warp) of a spread cycle kernel: at most _SPREAD_MOST_WARPS warps, at least least_warps;
    with `paired` an even number of slots (warps x per_warp), so that no pair lacks its second slot."""
    per_warp = -(-controls // _SPREAD_MOST_WARPS)
    warps = max(-(-controls // per_warp), least_warps)
    per_warp = -(-controls // warps)
    if paired and (warps * per_warp) % 2:
        warps += 1  # odd x odd: warps < _SPREAD_MOST_WARPS (8 is even), so one more warp still fits
    return warps, per_warp


class _DeviceHalos:
    """BlockHalos (halos.py) on a device."""

    def __init__(self, halos, device: str) -> None:
        self.chunks, self.width = halos.chunks, halos.width
        self.neurons = wp.array(halos.neurons, dtype=wp.int32, device=device)
        self.local = wp.array(halos.local, dtype=wp.int32, device=device)


class CudaPath:
    """The CUDA cycle: `run` launches a captured graph of the run (`record` captures it), `winners` finds the winners
    of the current weights. rows_path.RowsPath drives it in distance rows mode."""

    def __init__(self, model: SomModel) -> None:
        self.graphs = Graphs(model.device)
        self.halos = self._block_halos(model)

    @staticmethod
    def _block_halos(model: SomModel) -> _DeviceHalos | None:
        """The block halos of the one-kernel smoothing cycle (dense table, small mesh), uploaded once here, never
        inside a graph capture; None where it does not apply or they do not fit."""
        if model.rows or model.n_neurons > SMALL_MESH:
            return None
        found = block_halos(model.topology.offsets, model.topology.neighbors, model.n_neurons)
        if found.chunks > _SPREAD_MOST_WARPS or found.width > _SMOOTHING_MOST_NEIGHBOURS:
            return None
        return _DeviceHalos(found, model.device)

    def smoothing_in_one_kernel(self, n_slots: int) -> _DeviceHalos | None:
        """The block halos where a smoothing cycle runs as one kernel (at most 32 controls), else None."""
        return self.halos if n_slots <= _SPREAD_MOST_CONTROLS else None

    def winners(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule) -> np.ndarray:
        state.fresh_winners(lambda: self.find_winners(model, state))
        return controls.from_slots(state.winners(state.n_slots))

    @staticmethod
    def find_winners(model: SomModel, state: SomState) -> None:
        """Step 1 on CUDA from the current weights into keys[s % 3] (s = cycle[0]), cleared first."""
        state.keys.fill_(KEY_NONE)
        wp.launch_tiled(model.kernels.find_winners, dim=[model.blocks], block_dim=int(CUDA_BLOCK),
                        device=model.device, inputs=[state.w, state.c, state.n_slots, model.m, state.keys,
                                                     state.cycle[0]])

    def forget(self) -> None:
        """Drop the captured graphs (before the learning table they hold is made again)."""
        self.graphs.clear()

    def prepare(self, model: SomModel, controls: Controls, schedule: SomSchedule) -> None:
        """Before a run: the graphs for these controls and this schedule."""
        self.graphs.valid_for(controls, schedule)

    def run(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, cycles: int) -> None:
        """`cycles` cycles from s (at most cycle_kernels.LONGEST_GRAPH), replayed from a captured graph."""
        fresh = state.start_run()
        smoothing = schedule.values.smoothing > 0.0
        parity = 0 if fresh else state.parity
        two_kernels = smoothing and self.smoothing_in_one_kernel(state.n_slots) is None
        anchored, state.anchor_pending = state.anchor_pending, False  # the graph copies the anchor back first
        self.prepare(model, controls, schedule)
        graph = self.graphs.get((cycles, fresh, parity, smoothing, anchored), lambda: self.record(
            model, state, controls, schedule, cycles, fresh, parity, smoothing, anchored))
        wp.capture_launch(graph)
        state.parity = parity if two_kernels else (parity + cycles) % 2  # a kernel a cycle passes the counter on
        state.s += cycles
        state.winners_valid = True

    def run_known(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule,
                  cycles: int) -> int:
        """`cycles` cycles from s whose first winners are known (distance rows mode): every such graph starts from
        counter 0 (one graph per length), which then gets the last one's count. Returns the cycle reached, short of
        s + cycles where a cycle stalled on a missing row."""
        smoothing = schedule.values.smoothing > 0.0
        wp.capture_launch(self.graphs.get(("rows", cycles, smoothing), lambda: self.record(
            model, state, controls, schedule, cycles, False, 0, smoothing)))
        last = 0 if smoothing else cycles % 2
        reached = int(state.cycle[last].numpy()[0])
        if last:
            state.cycle[0].fill_(reached)
        return reached

    def record(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, cycles: int,
               fresh: bool, parity: int, smoothing: bool, anchored: bool = False) -> list:
        """A kernel a cycle (move + next winners), or two with smoothing (move; smooth + next winners). Without
        `fresh` the winners of the first cycle are known (always so in distance rows mode); `anchored` starts with
        the anchored weights copied back (`set_controls(..., from_anchor=True)`). Returns the packed arguments of
        the dependent launches, which the graph needs as long as it lives."""
        dev, threads, k, blocks = model.device, int(CUDA_BLOCK), state.n_slots, model.blocks
        dependent = dependent_launch.available(dev)
        after_kernel = False
        records = []

        def launch(kernel, inputs, threads=threads) -> None:
            nonlocal after_kernel
            if dependent and after_kernel:
                records.append(dependent_launch.launch_tiled_after_kernel(kernel, blocks, threads, inputs, dev))
            else:
                wp.launch_tiled(kernel, dim=[blocks], block_dim=threads, device=dev, inputs=inputs)
            after_kernel = True

        pairs = controls.pairs(schedule.table_max)
        table, lam, w, w_moved, c = schedule.device_table(), schedule.values.smoothing, state.w, state.w_moved, state.c
        move, move_threads, spread = model.kernels_for(pairs).move, threads, False
        shared_table = table.shape[1] <= SHARED_TABLE_WORDS
        halos = self.smoothing_in_one_kernel(k) if smoothing else None
        if model.n_neurons <= SMALL_MESH:
            if k <= _SPREAD_MOST_CONTROLS and not smoothing:
                warps, per_warp = _spread_shape(k, 1, pairs != SINGLES)
                move = spread_cycle_kernel(model.n_dims, warps, per_warp, shared_table, model.rows, pairs)
                move_threads, spread = 32 * warps, True
            else:
                move = cycle_kernels(model.n_dims, min(32, 8 * ((k + 7) // 8)), pairs).move

        if anchored:
            wp.copy(w, state.w_anchor)
        if fresh:
            self.find_winners(model, state)
            after_kernel = True
        if halos is not None:  # a kernel a cycle from one weights array to the other, then back in state.w
            warps, per_warp = _spread_shape(k, halos.chunks, pairs != SINGLES)
            kernel = spread_smoothing_cycle_kernel(model.n_dims, warps, per_warp, shared_table, halos.chunks,
                                                   halos.width, pairs)
            pair = (w, w_moved)
            for i in range(cycles):
                p = (parity + i) % 2
                launch(kernel, spread_smoothing_cycle_inputs(
                    pair[i % 2], pair[1 - i % 2], c, k, model.m, table, model.distances, state.keys,
                    state.cycle[p], state.cycle[1 - p], halos.neurons, halos.local, model.offsets, model.mask, lam),
                    32 * warps)
            if cycles % 2:
                wp.copy(w, w_moved)
            return records
        p = parity
        for _ in range(cycles):
            c_in, c_out = state.cycle[p], state.cycle[1 - p]
            moved = w_moved if smoothing else w
            if spread:
                launch(move, spread_cycle_inputs(w, moved, c, k, model.m, table, model.distances, model.slot_of,
                                                 state.keys, c_in, c_out, state.stalled), move_threads)
            else:
                launch(move, [w, moved, c, 0, k, k, model.m, table, model.distances, model.slot_of, state.keys, c_in,
                              c_out, int(not smoothing), state.stalled], move_threads)
            if smoothing:
                launch(model.kernels.smooth, [w_moved, w, model.offsets, model.neighbors, model.mask, lam, c, k,
                                              model.m, state.keys, c_out, c_in, state.stalled])
            else:
                p = 1 - p
        return records

