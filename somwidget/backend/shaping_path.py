"""The shaping cycle: controls with a radius of influence, symmetry groups beyond a mirrored pair, strokes (runs of
controls that act as one), and Taubin's smoothing, in the generic kernels of shaping_kernels.py. A Som takes this
path whenever one of them is in use (Controls.shaping); with point controls, no symmetry or a mirror, and the
paper's Laplacian step, it takes the paper's paths and gives their results bit for bit.

Each cycle launches its kernels from here (no captured graphs): find, gather (and, at a restart, fit), move, then one
or two smoothing steps. A carrying control's winner is searched only at a restart's first cycle (it keeps the node it
grabbed: shaping_kernels.hold), so with no point control the later cycles search nothing. In distance rows mode the
point controls' winners come back to the host each cycle and their rows are fetched before the move; controls with a
radius read only which part of the mesh a node is in. On the CPU the search and the move are the local cycle's: only
the blocks of neurons a group can move are moved (each carrying control's reach from `balls`, the blocks' boxes of
rest positions), and only those that may hold a winner searched.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .cpu_cores import CpuCores
from .local_path import find_in_blocks
from .shaping_kernels import FIND_STRETCH, shaping_kernels
from .smoothing_kernels import smooth_kernel
from .som_controls import Controls
from .som_model import SomModel, mask_of
from .som_schedule import SomSchedule
from .som_state import KEY_NONE, SomState

#: A control's radius r is the distance at which its pull has fallen to exp(-2) = 0.14 of the winner's: the
#: Gaussian's sigma is r / 2 (widened for a far pull: shaping_kernels.fit).
SIGMA_OF_RADIUS = 0.5


class ShapingPath:
    """The shaping cycle. cores: the CPU's cores, where the search and the move take only the blocks within reach
    (local_path.py); None: every neuron, a thread each (CUDA, and on the CPU the full computation that the local one
    gives bit for bit). It keeps the controls grouped on the device (made again when the Controls change), their
    winners, and the rest positions the falloffs measure from (the weights where the latest restart began)."""

    def __init__(self, cores: CpuCores | None) -> None:
        self.cores = cores
        self._for: Controls | None = None  # the controls the device groups were made for
        self.keys: wp.array | None = None  # each effective control's winner key (and a search's hint)
        self.rest: wp.array | None = None
        self._rest_boxes: list[wp.array] | None = None
        self._rest_taken: int | None = None  # the anchor version the rest positions hold (None: not an anchor's)
        self._fit_pending = True

    def _upload(self, model: SomModel, state: SomState, controls: Controls) -> None:
        """The effective controls grouped on the device (each stroke's samples, or a single control, followed by
        their copies: the members of one group), each one's sigma (0: a point control), and where each group
        starts; `_public` maps a device slot to its place in `Controls.effective`."""
        maps = controls.group_maps()
        order = len(maps)
        k = len(controls.values)
        slots, starts = [], [0]  # (control, copy) of each device slot; where each group starts
        first = 0
        for length in controls.strokes:
            slots += [(c, g) for g in range(order) for c in range(first, first + length)]
            first += length
            starts.append(len(slots))
        stroke = np.array([length > 1 for length in controls.strokes], np.int32)
        group_of = np.repeat(np.arange(len(starts) - 1), np.diff(starts)).astype(np.int32)
        c_of = np.array([c for c, _ in slots], np.int64)
        g_of = np.array([g for _, g in slots], np.int64)
        grouped = np.einsum("sij,sj->si", maps[g_of], controls.values.astype(np.float64)[c_of])
        self._public = g_of * k + c_of
        sigma = controls.radii.astype(np.float64)[c_of] * SIGMA_OF_RADIUS
        dev, vec = model.device, model.vec
        self.grouped = wp.array(grouped.astype(np.float32), dtype=vec, device=dev)
        self.sigma = wp.array(sigma.astype(np.float32), dtype=wp.float32, device=dev)
        self.inv_two_sigma2 = wp.zeros(len(sigma), dtype=wp.float32, device=dev)
        self.point = (controls.radii == 0)[c_of]  # the effective controls that read distances
        self._fit_pending = True
        self.group_start = wp.array(np.array(starts, np.int32), dtype=wp.int32, device=dev)
        self.n_groups = len(starts) - 1
        self.stroke = wp.array(stroke, dtype=wp.int32, device=dev)
        if self.keys is None or len(self.keys) != k * order:  # else: the last winners, as hints
            self.keys = wp.full(k * order, KEY_NONE, dtype=wp.uint64, device=dev)
            self.grabbed = wp.empty_like(self.keys)  # the carrying controls' winners since the restart
        self.winner_weights = wp.empty(k * order, dtype=vec, device=dev)
        self.offsets = wp.zeros(k * order, dtype=wp.float32, device=dev)
        self.radius2 = wp.zeros(k * order, dtype=wp.float32, device=dev)
        self.group_of = wp.array(group_of, dtype=wp.int32, device=dev)
        if self.rest is None:
            self.rest = wp.empty_like(state.w)
            if self.cores is not None:  # the boxes of the rest positions' blocks and superblocks
                self._rest_boxes = [wp.empty_like(a) for a in state.boxes.arrays]
        self._for = controls

    def _find(self, model: SomModel, state: SomState, controls: Controls) -> None:
        """Step 1: the winners. A carrying control grabs its winner at a restart's first cycle and carries that node
        for the rest of the run (shaping_kernels.hold); only point controls search again every cycle."""
        if self._for is not controls:
            self._upload(model, state, controls)
        fresh = self._fit_pending or state.rest_pending
        if not fresh and not self.point.any():  # every control carries the node it grabbed
            return
        kern = shaping_kernels(model.n_dims)
        if self.cores is not None:  # from each control's last winner, in the blocks that may hold a nearer one
            find_in_blocks(model, state, self.cores, self.grouped, len(self.keys), self.keys, 0, 0)
        else:
            stretches = max(1, math.ceil(model.n_neurons / FIND_STRETCH))
            self.keys.fill_(KEY_NONE)
            wp.launch(kern.find, dim=len(self.keys) * stretches, device=model.device,
                      inputs=[state.w, self.grouped, model.m, self.keys, stretches])
        if fresh:
            wp.copy(self.grabbed, self.keys)
        else:
            wp.launch(kern.hold, dim=len(self.keys), device=model.device, inputs=[self.keys, self.grabbed, self.sigma])

    def run(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, cycles: int) -> None:
        """`cycles` cycles from s of the shaping rules."""
        state.settle_anchor()
        if self._for is not controls:
            self._upload(model, state, controls)
        local = self.cores is not None
        if state.rest_pending:  # a restart: the falloffs measure distances on the shape it began from
            if state.rest_source is None or state.rest_source != self._rest_taken:  # (a drag's frames: the anchor's)
                wp.copy(self.rest, state.w)
                if local:
                    state.boxes.ensure(state.w)
                    for kept, box in zip(self._rest_boxes, state.boxes.arrays):
                        wp.copy(kept, box)
            self._rest_taken = state.rest_source
            state.rest_pending = False
            self._fit_pending = True
        kern = shaping_kernels(model.n_dims)
        dev, n, vec = model.device, model.n_neurons, model.vec
        position = np.zeros(model.n_dims, np.float32)
        position[model.position_dims] = 1.0
        position = vec(*position.tolist())
        mask = mask_of(model.smooth_dims, model.n_dims)
        pulls = [vec(*(strength * mask).tolist()) for strength in schedule.steps()]
        rows = int(model.rows)
        cache = model.cache
        near = [cache.near, cache.super_near] if rows and local else [model.no_near] * 2
        if local:
            self.cores.plan(model.n_neurons, controls.n_slots)
            self.cores.share(state.boxes.work(), state.n_slots)
            state.boxes.tighten()
        for _ in range(cycles):
            s = state.s
            self._find(model, state, controls)
            wp.launch(kern.gather, dim=len(self.keys), device=dev,
                      inputs=[state.w, self.keys, self.grouped, self.winner_weights, self.offsets])
            if self._fit_pending:  # the first cycle of a restart: each carrying control's width for its pull
                wp.launch(kern.fit, dim=len(self.keys), device=dev,
                          inputs=[self.grouped, self.winner_weights, self.sigma, float(model.median_edge), position,
                                  self.inv_two_sigma2])
                self._fit_pending = False
            reach = int(schedule.reach_hops[s]) if local else schedule.d_max  # CPU rows: only this deep
            if rows and self.point.any():
                winners = (self.keys.numpy() & np.uint64(0xFFFFFFFF)).astype(np.int64)[self.point]
                cache.fetch(list(dict.fromkeys(winners.tolist())), reach)
            moving = [state.w, self.rest, self.grouped, self.winner_weights, self.keys, self.inv_two_sigma2,
                      self.offsets, model.component, self.group_start, self.stroke, self.n_groups, schedule.table, s,
                      model.distances, model.slot_of, position, model.carry_floor]
            if local:
                boxes = state.boxes
                wp.launch(kern.balls, dim=len(self.keys), device=dev,
                          inputs=[self.inv_two_sigma2, self.offsets, self.group_of, self.group_start, schedule.table,
                                  s, model.carry_floor, self.radius2])
                self.cores.on_cores(kern.move_blocks, lambda sb_lo, sb_hi, moving=moving, reach=reach, boxes=boxes: [
                    *moving, self.radius2, *self._rest_boxes, *near, reach, rows, *boxes.arrays, boxes.moved,
                    boxes.super_moved, sb_lo, sb_hi], self.cores.super_ranges(boxes.n_super))
            else:
                wp.launch(kern.move, dim=n, device=dev, inputs=moving)
                state.weights_replaced()  # (the CPU's boxes, where this runs the full computation there)
            for pull in pulls:  # into the spare buffer and back (the other paths' graphs hold both buffers' places)
                wp.launch(smooth_kernel(model.n_dims), dim=n, device=dev,
                          inputs=[state.w, state.w_moved, model.offsets, model.neighbors, pull])
                wp.copy(state.w, state.w_moved)
                state.weights_replaced()
            state.s += 1
        if local:
            state.boxes.count_region()
        state.winners_valid = False

    def winners(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule) -> np.ndarray:
        """(k_eff,) the winners now, in the order of `Controls.effective` (copies by group element)."""
        state.settle_anchor()
        self._find(model, state, controls)
        grouped = (self.keys.numpy() & np.uint64(0xFFFFFFFF)).astype(np.int64)
        out = np.empty_like(grouped)
        out[self._public] = grouped
        return out
