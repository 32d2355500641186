"""The shaping cycle (a path of `Som`, som.py): controls with a radius of influence, symmetry groups beyond a
mirrored pair, strokes (runs of controls that act as one), and Taubin's smoothing, in the generic kernels of
shaping_kernels.py. A Som takes this path whenever
one of them is in use; with point controls, no symmetry or a mirror, and the paper's Laplacian step, it takes the
case studies' paths (cpu_path.py, cuda_path.py, rows_path.py) and gives their results bit for bit.

Each cycle launches its kernels from here (no captured graphs): find, gather (and, at a restart, fit), move, then one or
two smoothing steps. A carrying control's winner is searched only at a restart's first cycle (it keeps the node it
grabbed: shaping_kernels.hold), so with no point control the later cycles search nothing. In distance rows mode the
point controls' winners come back to the host each cycle and their rows are fetched before the move; controls with a
radius read only which part of the mesh a node is in. On the CPU the search and the move are local_path.py's: only the
blocks of neurons a group can move are moved (each carrying control's reach from `balls`, the blocks' boxes of rest
positions), and only those that may hold a winner searched.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .metrics import bounding_diagonal, median_edge
from .shaping_kernels import CARRY_CUT, FIND_STRETCH, shaping_kernels
from .topology import _components

#: A control's radius r is the distance at which its pull has fallen to exp(-2) = 0.14 of the winner's: the
#: Gaussian's sigma is r / 2 (widened for a far pull: shaping_kernels.fit).
SIGMA_OF_RADIUS = 0.5
#: Taubin's pass band: with lambda > 0 the second step's mu = 1 / (PASS_BAND - 1 / lambda) < -lambda undoes the
#: first step's shrinking of the shape's broad curves and keeps damping the fine ripples. Chosen by measurement on
#: the sphere preset (BENCHMARKS.md, "Smoothing that keeps the volume"): the usual 0.1 grew it by up to 20% over a
#: whole run at lambda 0.3, 0 shrank it by 2.7%; 0.015 keeps it within 0.1% for lambda 0.05 to 0.3.
PASS_BAND = 0.015


def taubin_mu(strength: float) -> float:
    """The negative second step of Taubin's lambda / mu pair for lambda = strength."""
    return 1.0 / (PASS_BAND - 1.0 / strength)


class ShapingPath:
    """The shaping cycle of a Som (mixed into `Som`; its state lives there)."""

    def _median_edge(self) -> float:
        """The median length of the start mesh's edges in the position dims (the hop cutoff's unit)."""
        return median_edge(self._start[:, self._position_dims], self.topology.edges) or 1.0

    def _upload_shaping(self) -> None:
        """The effective controls grouped on the device (each stroke's samples, or a single control, followed by
        their copies: the members of one group), each one's sigma (0: a point control), and where each group
        starts; `_sh_public` maps a device slot to its place in `effective_controls`."""
        maps = self._group_maps()
        order = len(maps)
        k = len(self._controls)
        slots, starts = [], [0]  # (control, copy) of each device slot; where each group starts
        first = 0
        for length in self._strokes:
            slots += [(c, g) for g in range(order) for c in range(first, first + length)]
            first += length
            starts.append(len(slots))
        stroke = np.array([length > 1 for length in self._strokes], np.int32)
        group_of = np.repeat(np.arange(len(starts) - 1), np.diff(starts)).astype(np.int32)
        c_of = np.array([c for c, _ in slots], np.int64)
        g_of = np.array([g for _, g in slots], np.int64)
        c64 = self._controls.astype(np.float64)
        grouped = np.einsum("sij,sj->si", maps[g_of], c64[c_of])
        self._sh_public = g_of * k + c_of
        sigma = self._radii.astype(np.float64)[c_of] * SIGMA_OF_RADIUS
        if self._edge is None:
            self._edge = self._median_edge()
            self._floor = CARRY_CUT * (bounding_diagonal(self._start[:, self._position_dims]) or 1.0)
            self._component = wp.array(_components(self.topology)[0].astype(np.int32), dtype=wp.int32,
                                       device=self.device)
        dev = self.device
        self._sh_controls = wp.array(grouped.astype(np.float32), dtype=self._kernels.vec, device=dev)
        self._sh_sigma = wp.array(sigma.astype(np.float32), dtype=wp.float32, device=dev)
        self._sh_inv = wp.zeros(len(sigma), dtype=wp.float32, device=dev)
        self._sh_point = (self._radii == 0)[c_of]  # the effective controls that read distances
        self._sh_fit_pending = True
        self._sh_groups = wp.array(np.array(starts, np.int32), dtype=wp.int32, device=dev)
        self._sh_n_groups = len(starts) - 1
        self._sh_stroke = wp.array(stroke, dtype=wp.int32, device=dev)
        if getattr(self, "_sh_keys", None) is None or len(self._sh_keys) != k * order:  # else: the last winners,
            self._sh_keys = wp.full(k * order, np.uint64(0xFFFFFFFFFFFFFFFF), dtype=wp.uint64, device=dev)  # hints
            self._sh_grabbed = wp.empty_like(self._sh_keys)  # the carrying controls' winners since the restart
        self._sh_winners = wp.empty(k * order, dtype=self._kernels.vec, device=dev)
        self._sh_offsets = wp.zeros(k * order, dtype=wp.float32, device=dev)
        self._sh_radius2 = wp.zeros(k * order, dtype=wp.float32, device=dev)
        self._sh_group_of = wp.array(group_of, dtype=wp.int32, device=dev)
        if getattr(self, "_sh_rest", None) is None:
            self._sh_rest = wp.empty_like(self._w)
            if dev == "cpu":  # the boxes of the rest positions' blocks and superblocks
                self._rest_boxes = [wp.empty_like(a) for a in self._boxes]

    def _shaping_find(self) -> None:
        """Step 1: the winners. A carrying control grabs its winner at a restart's first cycle and carries that
        node for the rest of the run (shaping_kernels.hold); only point controls search again every cycle."""
        if self._sh_controls is None:
            self._upload_shaping()
        fresh = self._sh_fit_pending or self._sh_rest_pending
        if not fresh and not self._sh_point.any():  # every control carries the node it grabbed
            return
        kern = shaping_kernels(self.n_dims)
        if self.device == "cpu":  # from each control's last winner, in the blocks that may hold a nearer one
            self._local_find(self._sh_controls, len(self._sh_keys), self._sh_keys, 0, 0)
        else:
            stretches = max(1, math.ceil(self.n_neurons / FIND_STRETCH))
            self._sh_keys.fill_(np.uint64(0xFFFFFFFFFFFFFFFF))
            wp.launch(kern.find, dim=len(self._sh_keys) * stretches, device=self.device,
                      inputs=[self._w, self._sh_controls, self._m, self._sh_keys, stretches])
        if fresh:
            wp.copy(self._sh_grabbed, self._sh_keys)
        else:
            wp.launch(kern.hold, dim=len(self._sh_keys), device=self.device,
                      inputs=[self._sh_keys, self._sh_grabbed, self._sh_sigma])

    def _run_shaping(self, cycles: int) -> None:
        """`cycles` cycles from s of the shaping rules."""
        self._settle_anchor()
        if self._sh_controls is None:
            self._upload_shaping()
        if self._sh_rest_pending:  # a restart: the falloffs measure distances on the shape it began from
            if self._rest_source is None or self._rest_source != self._rest_taken:  # (a drag's frames: the anchor's)
                wp.copy(self._sh_rest, self._w)
                if self.device == "cpu":
                    self._ensure_boxes()
                    for kept, box in zip(self._rest_boxes, self._boxes):
                        wp.copy(kept, box)
            self._rest_taken = self._rest_source
            self._sh_rest_pending = False
            self._sh_fit_pending = True
        kern = shaping_kernels(self.n_dims)
        dev, n = self.device, self.n_neurons
        steps = self._smoothing_steps()
        position = np.zeros(self.n_dims, np.float32)
        position[self._position_dims] = 1.0
        position = self._kernels.vec(*position.tolist())
        masks = [self._kernels.vec(*(strength * self._mask_of(self._smooth_dims)).tolist()) for strength in steps]
        rows = int(self._rows_mode)
        near = [self._cache.near, self._cache.super_near] if rows and dev == "cpu" else [self._no_near] * 2
        if dev == "cpu":
            self._share_cores()
            self._tighten()
        for _ in range(cycles):
            self._shaping_find()
            wp.launch(kern.gather, dim=len(self._sh_keys), device=dev,
                      inputs=[self._w, self._sh_keys, self._sh_controls, self._sh_winners, self._sh_offsets])
            if self._sh_fit_pending:  # the first cycle of a restart: each carrying control's width for its pull
                wp.launch(kern.fit, dim=len(self._sh_keys), device=dev,
                          inputs=[self._sh_controls, self._sh_winners, self._sh_sigma, float(self._edge), position,
                                  self._sh_inv])
                self._sh_fit_pending = False
            reach = int(self._reach_hops[self._s]) if dev == "cpu" else self._d_max  # CPU rows: only this deep
            if self._rows_mode and self._sh_point.any():
                winners = (self._sh_keys.numpy() & np.uint64(0xFFFFFFFF)).astype(np.int64)[self._sh_point]
                self._cache.fetch(list(dict.fromkeys(winners.tolist())), reach)
            moving = [self._w, self._sh_rest, self._sh_controls, self._sh_winners, self._sh_keys, self._sh_inv,
                      self._sh_offsets, self._component, self._sh_groups, self._sh_stroke, self._sh_n_groups,
                      self._table, self._s, self._distances, self._slot_of, position, self._floor]
            if dev == "cpu":
                wp.launch(kern.balls, dim=len(self._sh_keys), device=dev,
                          inputs=[self._sh_inv, self._sh_offsets, self._sh_group_of, self._sh_groups, self._table,
                                  self._s, self._floor, self._sh_radius2])
                self._on_cores(kern.move_blocks, lambda sb_lo, sb_hi: [
                    *moving, self._sh_radius2, *self._rest_boxes, *near, reach, rows, *self._boxes, self._moved,
                    self._super_moved, sb_lo, sb_hi])
            else:
                wp.launch(kern.move, dim=n, device=dev, inputs=moving)
            for pull in masks:  # into the spare buffer and back (the other paths' graphs hold both buffers' places)
                wp.launch(kern.smooth, dim=n, device=dev,
                          inputs=[self._w, self._w_moved, self._offsets, self._neighbors, pull])
                wp.copy(self._w, self._w_moved)
                self._weights_replaced()
            self._s += 1
        if dev == "cpu":
            self._count_region()

    def _shaping_winners(self) -> np.ndarray:
        """(k_eff,) the winners now, in the order of `effective_controls` (copies by group element)."""
        self._settle_anchor()
        self._shaping_find()
        grouped = (self._sh_keys.numpy() & np.uint64(0xFFFFFFFF)).astype(np.int64)
        out = np.empty_like(grouped)
        out[self._sh_public] = grouped
        return out
