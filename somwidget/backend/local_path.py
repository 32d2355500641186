"""The CPU's local cycle (a path of `Som`, som.py): a drag costs what it touches. The neurons are kept in blocks of
local_kernels.BLOCK and the blocks in superblocks of local_kernels.SUPER, each with the bounding box of its weights;
a cycle moves only the blocks within reach of a winner and searches only the blocks that may hold one
(local_kernels.py), and gives the full computation's weights bit for bit.

It runs the paper's rule past the dense table (distance rows, rows_path.RowCache, searched only as deep as the cut
table's reach, schedule.NEIGHBOURHOOD_CUT) and, on the CPU, the shaping path's search and move (shaping_path.py).
The host drives each cycle: it reads the winners, fetches their rows, and launches each phase on every core (the
blocks, or the controls, split between them).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .cpu_path import PAIRS_PER_EXTRA_CORE
from .cycle_kernels import MAX_CONTROLS
from .local_kernels import BLOCK, block_count, local_kernels, super_count
from .schedule import reach_hops


class LocalPath:
    """The CPU's local cycle of a Som (mixed into `Som`; its state lives there)."""

    # -- the blocks' boxes ------------------------------------------------------------------------------------
    def _local_setup(self) -> None:
        """The boxes of the weights' blocks and the flat view of the winner keys (once, on the CPU)."""
        vec = self._kernels.vec
        n_blocks, n_super = block_count(self.n_neurons), super_count(self.n_neurons)
        self._box_lo = wp.empty(n_blocks, dtype=vec, device="cpu")
        self._box_hi = wp.empty(n_blocks, dtype=vec, device="cpu")
        self._super_lo = wp.empty(n_super, dtype=vec, device="cpu")
        self._super_hi = wp.empty(n_super, dtype=vec, device="cpu")
        self._boxes_valid = False
        self._moved = wp.zeros(n_blocks, dtype=wp.int32, device="cpu")  # blocks moved since the anchor was kept
        self._super_moved = wp.zeros(n_super, dtype=wp.int32, device="cpu")
        self._all_moved = True  # or any neuron since (the weights replaced, smoothed)
        self._region = n_blocks  # blocks the last run moved: the next one's work, which sets how many cores share it
        self._busy_cores = 1
        self._flat_keys = wp.array(ptr=self._keys.ptr, dtype=wp.uint64, shape=(3 * MAX_CONTROLS,), device="cpu")
        self._keys_host = self._keys.numpy()  # a view of the keys (CPU memory)

    def _weights_replaced(self) -> None:
        """Any weight may have changed (outside the local cycle's moves): the boxes are made again when next needed,
        and going back to the anchor copies every neuron."""
        self._boxes_valid = False
        self._all_moved = True

    @property
    def _boxes(self) -> list[wp.array]:
        """The blocks' and superblocks' boxes: lo, hi, super lo, super hi."""
        return [self._box_lo, self._box_hi, self._super_lo, self._super_hi]

    def _anchor_boxes(self) -> None:
        """`anchor()` on the CPU: the boxes kept with the weights; nothing moved since."""
        self._ensure_boxes()
        self._box_anchor = [wp.clone(a) for a in self._boxes]
        self._moved.zero_()
        self._super_moved.zero_()
        self._all_moved = False

    def _back_to_anchor(self) -> None:
        """The anchored weights and boxes back: the blocks moved since (all, after anything else changed them)."""
        if self._all_moved:
            wp.copy(self._w, self._w_anchor)
            for box, kept in zip(self._boxes, self._box_anchor):
                wp.copy(box, kept)
            self._moved.zero_()
            self._super_moved.zero_()
        else:
            wp.launch(local_kernels(self.n_dims).back_to_anchor, dim=1, device="cpu",
                      inputs=[self._w, self._w_anchor, *self._boxes, *self._box_anchor, self._moved,
                              self._super_moved])
        self._boxes_valid = True
        self._all_moved = False

    def _share_cores(self) -> None:
        """Before a run: the cores it splits its work between. One unless the last run moved blocks enough for more
        (as for the full cycle, cpu_path._cpu_cores: a core's share of neuron-control pairs a cycle), so a drag that
        touches a small region waits for no other core; all of `cpu_cores` when given."""
        region = len(self._box_lo) if self._all_moved else self._region
        enough = region * int(BLOCK) * max(1, self._k_eff) >= 2 * PAIRS_PER_EXTRA_CORE
        self._busy_cores = self._cores if enough or self._cpu_cores is not None else 1

    def _count_region(self) -> None:
        """After a run: the blocks it moved (since the anchor), for the next run's `_share_cores`."""
        self._region = len(self._box_lo) if self._all_moved else int(np.count_nonzero(self._moved.numpy()))

    def _super_ranges(self) -> list[tuple[int, int]]:
        """Each busy core's range of superblocks."""
        bounds = np.linspace(0, len(self._super_lo), self._busy_cores + 1).astype(int)
        return list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))

    def _ensure_boxes(self) -> None:
        """The boxes of the current weights, made again if they were replaced."""
        if not self._boxes_valid:
            kern = local_kernels(self.n_dims)
            self._on_cores(kern.boxes, lambda lo, hi: [self._w, *self._boxes, lo, hi])
            self._boxes_valid = True

    def _tighten(self) -> None:
        """Before a run: the superblocks' boxes as tight as their blocks' (they only grew while blocks moved)."""
        if self._boxes_valid:
            wp.launch(local_kernels(self.n_dims).tighten, dim=1, device="cpu", inputs=self._boxes)

    def _on_cores(self, kernel, inputs, split=None) -> None:
        """`kernel` on every core at once, core i given inputs(*split[i]) (default: its range of superblocks)."""
        parts = split if split is not None else self._super_ranges()
        others = [self._pool.submit(wp.launch, kernel, dim=1, device="cpu", inputs=inputs(*part))
                  for part in parts[1:]] if len(parts) > 1 else []
        wp.launch(kernel, dim=1, device="cpu", inputs=inputs(*parts[0]))
        for job in others:
            job.result()

    def _local_find(self, controls: wp.array, count: int, keys: wp.array, hint_at: int, out_at: int) -> None:
        """Step 1 for `count` controls into keys[out_at + c], the controls split between the cores."""
        self._ensure_boxes()
        kern = local_kernels(self.n_dims)
        cores = min(self._busy_cores, count)
        self._on_cores(kern.find, lambda first: [self._w, controls, first, cores, count, self._m, keys, hint_at,
                                                 out_at, *self._boxes],
                       split=[(core,) for core in range(cores)])

    # -- the paper's rule past the dense table -------------------------------------------------------------------
    def _run_local(self, cycles: int) -> None:
        """`cycles` cycles of the paper's rule reading distance rows: per cycle, the winners' rows (searched as deep
        as the cycle's reach), the move of the blocks within reach (all of them with smoothing, which moves every
        neuron), smoothing, and the next winners. Controls whose winners outnumber the cache move in parts."""
        self._settle_anchor()
        self._share_cores()
        self._tighten()
        kern = local_kernels(self.n_dims, self._pairs)
        smoothing = self._smoothing > 0.0
        keys = self._flat_keys
        if not self._winners_valid:
            self._local_find(self._c, self._k_eff, keys, (self._s % 3) * MAX_CONTROLS, (self._s % 3) * MAX_CONTROLS)
            self._winners_valid = True
        for _ in range(cycles):
            s = self._s
            at = (s % 3) * MAX_CONTROLS
            winners = (self._keys_host[s % 3, : self._k_eff] & np.uint64(0xFFFFFFFF)).astype(np.int64)
            for lo, hi in self._parts(winners):
                self._cache.fetch(list(dict.fromkeys(winners[lo:hi].tolist())), int(self._reach_hops[s]))
                self._on_cores(kern.move, lambda sb_lo, sb_hi, lo=lo, hi=hi: [
                    self._w, self._c, lo, hi, self._table, s, self._reach_dev, self._distances, self._slot_of,
                    self._cache.near, self._cache.super_near, keys, at, *self._boxes, self._moved,
                    self._super_moved, sb_lo, sb_hi, int(smoothing)])
            if smoothing:
                wp.copy(self._w_moved, self._w)
                self._on_cores(self._kernels.smooth_part, lambda lo, hi: [
                    self._w_moved, self._w, self._offsets, self._neighbors, self._mask, self._smoothing, lo, hi,
                    self._stalled], split=self._ranges if self._busy_cores > 1 else [(0, self.n_neurons)])
                self._weights_replaced()
            self._local_find(self._c, self._k_eff, keys, at, ((s + 1) % 3) * MAX_CONTROLS)
            self._s += 1
        self._count_region()

    def _parts(self, winners: np.ndarray) -> list[tuple[int, int]]:
        """Consecutive runs of controls whose distinct winners fit in the cache (a mirrored pair is never split)."""
        parts, lo, seen = [], 0, set()
        unit = 2 if self._mirror else 1
        for c in range(0, len(winners), unit):
            group = set(winners[c:c + unit].tolist())
            if len(seen | group) > self._cache.size:
                parts.append((lo, c))
                lo, seen = c, set()
            seen |= group
        parts.append((lo, len(winners)))
        return parts

    def _local_table(self) -> None:
        """The cut table's reach per cycle, as a list and as an array for the kernels (on the CPU, after the table is
        built)."""
        self._reach_hops = reach_hops(self._table_host)
        self._reach_dev = wp.array(self._reach_hops, dtype=wp.int32, device="cpu")
