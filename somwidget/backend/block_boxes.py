"""The CPU's blocks of neurons and their boxes: the neurons in blocks of local_kernels.BLOCK and the blocks in
superblocks of local_kernels.SUPER, each with the bounding box of its weights, which tell the local cycle
(local_path.py) which blocks may hold a winner; and which blocks moved since `anchor()`, so that a drag's next frame
copies back only those.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .cpu_cores import CpuCores
from .local_kernels import BLOCK, block_count, local_kernels, super_count


class BlockBoxes:
    """The boxes of the weights' blocks and superblocks (lo, hi, super lo, super hi: `arrays`), made again when the
    weights were replaced (`invalidate`, then `ensure`); moved and super_moved mark the blocks moved since the anchor,
    `region` counts those the last run moved."""

    def __init__(self, n_neurons: int, n_dims: int, cores: CpuCores) -> None:
        self._kernels = local_kernels(n_dims)
        vec = self._kernels.vec
        n_blocks, n_super = block_count(n_neurons), super_count(n_neurons)
        self._cores = cores
        self.arrays = [wp.empty(n, dtype=vec, device="cpu") for n in (n_blocks, n_blocks, n_super, n_super)]
        self.valid = False
        self.moved = wp.zeros(n_blocks, dtype=wp.int32, device="cpu")  # blocks moved since the anchor was kept
        self.super_moved = wp.zeros(n_super, dtype=wp.int32, device="cpu")
        self.all_moved = True  # or any neuron since (the weights replaced, smoothed)
        self.region = n_blocks  # blocks the last run moved: the next one's work, which sets how many cores share it
        self._anchor: list[wp.array] | None = None  # the anchored weights' boxes

    @property
    def n_super(self) -> int:
        return len(self.arrays[2])

    @property
    def anchored(self) -> bool:
        return self._anchor is not None

    def invalidate(self) -> None:
        """Any weight may have changed: the boxes are made again when next needed, and going back to the anchor
        copies every neuron."""
        self.valid = False
        self.all_moved = True

    def ensure(self, weights: wp.array) -> None:
        """The boxes of `weights`, made again if they were replaced (the busy cores sharing the superblocks)."""
        if not self.valid:
            self._cores.on_cores(self._kernels.boxes, lambda lo, hi: [weights, *self.arrays, lo, hi],
                                 self._cores.super_ranges(self.n_super))
            self.valid = True

    def tighten(self) -> None:
        """Before a run: the superblocks' boxes as tight as their blocks' (they only grew while blocks moved)."""
        if self.valid:
            wp.launch(self._kernels.tighten, dim=1, device="cpu", inputs=self.arrays)

    def keep_anchor(self, weights: wp.array) -> None:
        """`anchor()`: the boxes kept with the weights; nothing moved since."""
        self.ensure(weights)
        self._anchor = [wp.clone(a) for a in self.arrays]
        self.moved.zero_()
        self.super_moved.zero_()
        self.all_moved = False

    def back_to_anchor(self, weights: wp.array, anchor: wp.array) -> None:
        """The anchored weights and boxes back: the blocks moved since (all, after anything else changed them)."""
        kept_boxes = self._anchor
        if kept_boxes is None:
            raise RuntimeError("BlockBoxes: no anchor kept to go back to (keep_anchor first)")
        if self.all_moved:
            wp.copy(weights, anchor)
            for box, kept in zip(self.arrays, kept_boxes):
                wp.copy(box, kept)
            self.moved.zero_()
            self.super_moved.zero_()
        else:
            wp.launch(self._kernels.back_to_anchor, dim=1, device="cpu",
                      inputs=[weights, anchor, *self.arrays, *kept_boxes, self.moved, self.super_moved])
        self.valid = True
        self.all_moved = False

    def work(self) -> int:
        """Neurons of the blocks the last run moved (all, when anything else changed them): the next run's work."""
        return (len(self.moved) if self.all_moved else self.region) * int(BLOCK)

    def count_region(self) -> None:
        """After a run: the blocks it moved (since the anchor), for the next run's `CpuCores.share`."""
        self.region = len(self.moved) if self.all_moved else int(np.count_nonzero(self.moved.numpy()))
