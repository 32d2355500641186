"""The CUDA cycle (a path of `Som`, som.py): a run of cycles captured as a graph of one kernel a cycle (two with
smoothing where the halos do not fit), launched dependent on the one before where the GPU allows
(dependent_launch.py); small meshes with up to 32 controls spread the controls over the warps of a block
(spread_kernels.py), and with smoothing move each block's halo too (halos.py).
"""

from __future__ import annotations

import warp as wp

from . import dependent_launch
from .cycle_kernels import CUDA_BLOCK, SINGLES, cycle_kernels
from .halos import block_halos
from .spread_kernels import (SHARED_TABLE_WORDS, spread_cycle_inputs, spread_cycle_kernel,
                             spread_smoothing_cycle_inputs, spread_smoothing_cycle_kernel)

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

    def __init__(self, halos, device: str):
        self.chunks, self.width = halos.chunks, halos.width
        self.neurons = wp.array(halos.neurons, dtype=wp.int32, device=device)
        self.local = wp.array(halos.local, dtype=wp.int32, device=device)


class CudaPath:
    """The CUDA cycle of a Som (mixed into `Som`; its state lives there)."""

    def _record_cuda(self, cycles: int, fresh: bool, parity: int, smoothing: bool, anchored: bool = False) -> list:
        """A kernel a cycle (move + next winners), or two with smoothing (move; smooth + next winners). Without
        `fresh` the winners of the first cycle are known (always so in distance rows mode); `anchored` starts with
        the anchored weights copied back (`set_controls(..., from_anchor=True)`). Returns the packed arguments of
        the dependent launches, which the graph needs as long as it lives."""
        dev, threads, k = self.device, int(CUDA_BLOCK), self._k_eff
        dependent = dependent_launch.available(dev)
        after_kernel = False
        records = []

        def launch(kernel, inputs, threads=threads):
            nonlocal after_kernel
            if dependent and after_kernel:
                records.append(dependent_launch.launch_tiled_after_kernel(kernel, self._blocks, threads, inputs, dev))
            else:
                wp.launch_tiled(kernel, dim=[self._blocks], block_dim=threads, device=dev, inputs=inputs)
            after_kernel = True

        pairs = self._pairs
        move, move_threads, spread = self._movers().move, threads, False
        shared_table = self._table.shape[1] <= SHARED_TABLE_WORDS
        halos = self._smoothing_in_one_kernel() if smoothing else None
        if self.n_neurons <= SMALL_MESH:
            if k <= _SPREAD_MOST_CONTROLS and not smoothing:
                warps, per_warp = _spread_shape(k, 1, pairs != SINGLES)
                move = spread_cycle_kernel(self.n_dims, warps, per_warp, shared_table, self._rows_mode, pairs)
                move_threads, spread = 32 * warps, True
            else:
                move = cycle_kernels(self.n_dims, min(32, 8 * ((k + 7) // 8)), pairs).move

        if anchored:
            wp.copy(self._w, self._w_anchor)
        if fresh:
            self._launch_find()
            after_kernel = True
        if halos is not None:  # a kernel a cycle from one weights array to the other, then back in self._w
            warps, per_warp = _spread_shape(k, halos.chunks, pairs != SINGLES)
            kernel = spread_smoothing_cycle_kernel(self.n_dims, warps, per_warp, shared_table, halos.chunks,
                                                   halos.width, pairs)
            pair = (self._w, self._w_moved)
            for i in range(cycles):
                p = (parity + i) % 2
                launch(kernel, spread_smoothing_cycle_inputs(
                    pair[i % 2], pair[1 - i % 2], self._c, k, self._m, self._table, self._distances, self._keys,
                    self._cycle[p], self._cycle[1 - p], halos.neurons, halos.local, self._offsets, self._mask,
                    self._smoothing), 32 * warps)
            if cycles % 2:
                wp.copy(self._w, self._w_moved)
            return records
        p = parity
        for _ in range(cycles):
            c_in, c_out = self._cycle[p], self._cycle[1 - p]
            moved = self._w_moved if smoothing else self._w
            if spread:
                launch(move, spread_cycle_inputs(self._w, moved, self._c, k, self._m, self._table, self._distances,
                                                 self._slot_of, self._keys, c_in, c_out, self._stalled),
                       move_threads)
            else:
                launch(move, [self._w, moved, self._c, 0, k, k, self._m, self._table, self._distances,
                              self._slot_of, self._keys, c_in, c_out, int(not smoothing), self._stalled], move_threads)
            if smoothing:
                launch(self._kernels.smooth, [self._w_moved, self._w, self._offsets, self._neighbors, self._mask,
                                              self._smoothing, self._c, k, self._m, self._keys, c_out, c_in,
                                              self._stalled])
            else:
                p = 1 - p
        return records

    def _movers(self):
        """The kernels of step 2 for the current controls: pair by pair when mirrored."""
        return cycle_kernels(self.n_dims, 8, self._pairs)

    def _block_halos(self) -> _DeviceHalos | None:
        """The block halos of the one-kernel smoothing cycle on CUDA (dense table, small mesh), uploaded once here,
        never inside a graph capture; None where it does not apply or they do not fit."""
        if self.device == "cpu" or self._rows_mode or self.n_neurons > SMALL_MESH:
            return None
        found = block_halos(self.topology.offsets, self.topology.neighbors, self.n_neurons)
        if found.chunks > _SPREAD_MOST_WARPS or found.width > _SMOOTHING_MOST_NEIGHBOURS:
            return None
        return _DeviceHalos(found, self.device)

    def _smoothing_in_one_kernel(self) -> _DeviceHalos | None:
        """The block halos where a smoothing cycle runs as one kernel (at most 32 controls), else None."""
        return self._halos if self._k_eff <= _SPREAD_MOST_CONTROLS else None
