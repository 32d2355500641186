"""The CPU's local cycle: a drag costs what it touches. A cycle moves only the blocks of neurons within reach of a
winner and searches only the blocks that may hold one (local_kernels.py, block_boxes.py), and gives the full
computation's weights bit for bit.

It runs the paper's rule past the dense table (distance rows, searched only as deep as the cut table's reach,
schedule.NEIGHBOURHOOD_CUT) and lends the shaping path its search (`find_in_blocks`). The host drives each cycle: it
reads the winners, fetches their rows, and launches each phase on every core (the blocks, or the controls, split
between them).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .cpu_cores import CpuCores
from .cpu_path import CpuPath
from .cycle_kernels import MAX_CONTROLS
from .local_kernels import local_kernels
from .row_cache import control_parts
from .som_controls import Controls
from .som_model import SomModel
from .som_schedule import SomSchedule
from .som_state import SomState


def find_in_blocks(model: SomModel, state: SomState, cores: CpuCores, controls: wp.array, count: int,
                   keys: wp.array, hint_at: int, out_at: int) -> None:
    """Step 1 for `count` controls: each one's winner key into keys[out_at + c] (keys: a flat uint64 array),
    searched from the block of the neuron in keys[hint_at + c] (any value will do: it only speeds the search) through
    the blocks whose boxes may hold a nearer neuron; the controls split between the busy cores. The full scan's
    winners, bit for bit."""
    boxes = state.cpu_boxes()
    boxes.ensure(state.w)
    kern = local_kernels(model.n_dims)
    busy = min(cores.busy, count)
    cores.on_cores(kern.find, lambda first: [state.w, controls, first, busy, count, model.m, keys, hint_at, out_at,
                                             *boxes.arrays], [(core,) for core in range(busy)])


class LocalPath:
    """Distance rows on the CPU, a cycle at a time: per cycle the winners' rows (searched as deep as the cycle's
    reach), the move of the blocks within reach (all of them with smoothing, which moves every neuron), smoothing,
    and the next winners. Controls whose winners outnumber the cache move in parts."""

    def __init__(self, cores: CpuCores) -> None:
        self.cores = cores

    def forget(self) -> None:
        """Nothing captured: each cycle is launched from the host."""

    def winners(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule) -> np.ndarray:
        state.fresh_winners(lambda: CpuPath.find_winners(model, state))
        return controls.from_slots(state.winners(state.n_slots))

    def run(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, cycles: int) -> None:
        state.settle_anchor()
        cores, boxes, cache = self.cores, state.cpu_boxes(), model.row_cache()
        reach_hops = schedule.reach_hops
        if reach_hops is None:
            raise RuntimeError("LocalPath: the schedule has no reach per cycle (the CPU's schedule keeps one)")
        cores.plan(model.n_neurons, controls.n_slots)
        cores.share(boxes.work(), state.n_slots)
        boxes.tighten()
        kern = local_kernels(model.n_dims, controls.pairs(schedule.table_max))
        smoothing = schedule.values.smoothing > 0.0
        keys = state.flat_keys
        if not state.winners_valid:
            at = (state.s % 3) * MAX_CONTROLS
            find_in_blocks(model, state, cores, state.c, state.n_slots, keys, at, at)
            state.winners_valid = True
        for _ in range(cycles):
            s = state.s
            at = (s % 3) * MAX_CONTROLS
            winners = (state.keys_host[s % 3, : state.n_slots] & np.uint64(0xFFFFFFFF)).astype(np.int64)
            for lo, hi in control_parts(winners, cache.size, 2 if controls.mirror else 1):
                cache.fetch(list(dict.fromkeys(winners[lo:hi].tolist())), int(reach_hops[s]))
                cores.on_cores(kern.move, lambda sb_lo, sb_hi, lo=lo, hi=hi, s=s, at=at: [
                    state.w, state.c, lo, hi, schedule.table, s, schedule.reach_dev, model.distances, model.slot_of,
                    cache.near, cache.super_near, keys, at, *boxes.arrays, boxes.moved, boxes.super_moved, sb_lo,
                    sb_hi, int(smoothing)], cores.super_ranges(boxes.n_super))
            if smoothing:
                wp.copy(state.w_moved, state.w)
                cores.on_cores(model.kernels.smooth_part, lambda lo, hi: [
                    state.w_moved, state.w, model.offsets, model.neighbors, model.mask, schedule.values.smoothing,
                    lo, hi, state.stalled], cores.ranges if cores.busy > 1 else [(0, model.n_neurons)])
                state.weights_replaced()
            find_in_blocks(model, state, cores, state.c, state.n_slots, keys, at, ((s + 1) % 3) * MAX_CONTROLS)
            state.s += 1
        boxes.count_region()
