"""Distance rows mode (a path of `Som`, som.py): past the dense table's 65,536 neurons the cycle reads int32 distance
rows of recent winners from a cache on the device (`RowCache`); a cycle whose winners lack a row stalls, the rows
are computed (topology.RowSearch) and the run goes on from that cycle.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
import warp as wp

from .cycle_kernels import CUDA_BLOCK, LONGEST_GRAPH, MAX_CONTROLS
from .distance_kernels import assign_slots
from .local_kernels import block_count, search_row, super_count
from .topology import RowSearch, Topology

#: Distance rows mode: the cache's default size in bytes (int32 rows of N): on the CPU 256 MiB, on a GPU a sixteenth
#: of its memory up to 8 GiB; at least _CACHE_LEAST_ROWS rows (a GPU's graphs want every winner's row of a run at
#: hand; the CPU fetches each cycle's, and its searches cost what they visit) and at most _CACHE_MOST_ROWS.
_CACHE_BYTES = {"cpu": 256 << 20, "cuda": 8 << 30}
_CACHE_LEAST_ROWS = {"cpu": 64, "cuda": 2 * MAX_CONTROLS}
_CACHE_MOST_ROWS = 4096
#: Distance rows mode on CUDA: rings of neurons around the winners whose rows a search brings along (see _around).
_PREFETCH_RINGS = 8


class RowCache:
    """Distance rows (int32 hops, -1 = unreachable) from recent winners, kept on the Som's device; the least
    recently used row makes way for a new one. slot_of[v] is the row of neuron v, -1 when it has none."""

    def __init__(self, topology: Topology, device: str, size: int | None):
        n = topology.n_vertices
        if size is None:
            budget = _CACHE_BYTES["cpu"] if device == "cpu" else min(_CACHE_BYTES["cuda"],
                                                                     wp.get_device(device).total_memory // 16)
            least = _CACHE_LEAST_ROWS["cpu" if device == "cpu" else "cuda"]
            size = max(least, min(_CACHE_MOST_ROWS, budget // (4 * n)))
        self.size = min(max(size, 2), n)  # two at least: a mirrored pair's winners move in the same part
        self.device = device
        self.rows = wp.empty((self.size, n), dtype=wp.int32, device=device)
        self.slot_of = wp.full(n, -1, dtype=wp.int32, device=device)
        self._search = RowSearch(topology, device)
        self._offsets, self._neighbors = topology.offsets, topology.neighbors
        self._lru: OrderedDict[int, int] = OrderedDict()  # neuron -> row, least recently used first
        self._free = list(range(self.size - 1, -1, -1))
        # on the CPU rows are searched only as deep as a cycle reads them (local_path.py): each one's depth, and the
        # least hop count of each block of neurons, which tells the local cycle where a winner's rates are non-zero
        self._depth: dict[int, int] = {}
        self.near = self.super_near = None
        if device == "cpu":
            self.near = wp.empty((self.size, block_count(n)), dtype=wp.int32, device=device)
            self.super_near = wp.empty((self.size, super_count(n)), dtype=wp.int32, device=device)
            self._used = np.zeros(self.size, bool)  # slots searched into before (their `near` tells what to clear)
            self._queue = wp.empty(n, dtype=wp.int32, device=device)
        self.computed = 0  # rows searched so far for winners
        self.prefetched = 0  # rows searched ahead for their neighbours
        self.stalls = 0  # graphs that stopped on a missing row
        self.span = LONGEST_GRAPH  # cycles in the next graph: fewer while winners keep lacking rows

    def fetch(self, neurons: list[int], levels: int) -> None:
        """Rows for `neurons` (distinct, at most `size`), searching those not kept or kept less deep than `levels` (a
        row holds the hops up to its depth, -1 past it)."""
        missing, deeper = [], []
        for u in neurons:
            if u in self._lru:
                self._lru.move_to_end(u)
                if self._depth.get(u, levels) < levels:
                    deeper.append(u)
            else:
                missing.append(u)
        if not missing and not deeper:
            return
        fresh = self._around(missing, neurons) + missing  # least recent first: asked-for rows stay longest
        slots, evicted = [], []
        for u in fresh:  # the neurons asked for are the most recent: the oldest row is never one of them
            if self._free:
                slot = self._free.pop()
            else:
                old, slot = self._lru.popitem(last=False)
                self._depth.pop(old, None)
                evicted.append(old)
            self._lru[u] = slot
            slots.append(slot)
        searched, at = deeper + fresh, [self._lru[u] for u in deeper] + slots
        if self.near is None:
            self._search.run([[u] for u in searched], at, self.rows, levels)
        else:  # the CPU: searches that cost what they visit (local_kernels.search_row)
            for u, slot in zip(searched, at):
                wp.launch(search_row, dim=1, device="cpu",
                          inputs=[self._search.offsets, self._search.neighbors, u, slot, self.rows, self.near,
                                  self.super_near, self._queue, levels, int(not self._used[slot])])
                self._used[slot] = True
            self._depth.update(dict.fromkeys(searched, levels))
        if fresh:
            neurons_changed = wp.array(np.array(evicted + fresh, dtype=np.int32), device=self.device)
            values = wp.array(np.array([-1] * len(evicted) + slots, dtype=np.int32), device=self.device)
            wp.launch(assign_slots, dim=len(neurons_changed), device=self.device,
                      inputs=[self.slot_of, neurons_changed, values])
        self.computed += len(missing) + len(deeper)
        self.prefetched += len(fresh) - len(missing)

    def _around(self, missing: list[int], neurons: list[int]) -> list[int]:
        """On CUDA, uncached neurons around the winners, ring by ring (one hop from each winner, those lacking rows
        first, then two hops...), as many as the search runs alongside the missing rows at little extra time and
        at most a sixteenth of the cache (so that rows still in use stay). A winner moves one hop or less in most
        cycles and keeps drifting the same way, so rows searched ahead spare later searches."""
        room = min(self._search.alongside - len(missing), self.size // 16, self.size - len(neurons))
        if self.device == "cpu" or room <= 0:
            return []
        centres = missing + [u for u in neurons if u not in missing]
        taken = dict.fromkeys(centres)
        rings = [[u] for u in centres]
        extra: list[int] = []
        for _ in range(_PREFETCH_RINGS):
            if len(extra) >= room or not any(rings):
                break
            for i, ring in enumerate(rings):
                following = []
                for u in ring:
                    for w in self._neighbors[self._offsets[u]: self._offsets[u + 1]].tolist():
                        if w not in taken:
                            taken[w] = None
                            following.append(w)
                rings[i] = following
                extra += [w for w in following if w not in self._lru]
        return extra[:room][::-1]  # the farthest least recent


class RowsPath:
    """The distance rows cycle of a Som (mixed into `Som`; its state lives there)."""

    # -- distance rows mode -------------------------------------------------------------------------------
    def _run_rows(self, cycles: int) -> None:
        """`cycles` cycles reading distance rows: the winners' rows are fetched, then a graph runs until done or a
        cycle stalls on a winner without a row (it then leaves everything as it was); the host fetches that cycle's
        rows and goes on from it. A cycle whose distinct winners outnumber the cache rows runs in parts."""
        target = self._s + cycles
        smoothing = self._smoothing > 0.0
        while self._s < target:
            self._find_winners_now()
            winners = self._current_winners()
            distinct = list(dict.fromkeys(winners.tolist()))
            if len(distinct) > self._cache.size:
                self._cycle_in_parts(winners, smoothing)
                continue
            self._cache.fetch(distinct, self._d_max)
            left = target - self._s
            chunk = min(self._cache.span, 1 << (left.bit_length() - 1))
            if self.device == "cpu":
                self._replay_cpu([self._graph(("rows", chunk, smoothing, core),
                                              lambda core=core: self._record_cpu(core, chunk, False, smoothing))
                                  for core in range(self._cores)])
                reached = int(self._cycle[0].numpy()[0])
            else:  # every graph starts from counter 0 (one graph per length), which then gets the last one's count
                wp.capture_launch(self._graph(("rows", chunk, smoothing),
                                              lambda: self._record_cuda(chunk, False, 0, smoothing)))
                last = 0 if smoothing else chunk % 2
                reached = int(self._cycle[last].numpy()[0])
                if last:
                    self._cycle[0].fill_(reached)
            if reached < self._s + chunk:  # stalled: the graph's later cycles did nothing, try shorter ones
                self._stalled.zero_()
                self._cache.stalls += 1
                self._cache.span = max(1, self._cache.span // 4)
            else:
                self._cache.span = min(LONGEST_GRAPH, self._cache.span * 2)
            self._s = reached
            self._winners_valid = True

    def _cycle_in_parts(self, winners: np.ndarray, smoothing: bool) -> None:
        """One cycle in consecutive runs of controls whose winners fit in the cache (each neuron still applies the
        controls in list order)."""
        parts, lo, seen = [], 0, set()
        unit = 2 if self._mirror else 1  # a mirrored pair moves together: never split between parts
        for c in range(0, len(winners), unit):
            group = set(winners[c:c + unit].tolist())
            if len(seen | group) > self._cache.size:
                parts.append((lo, c))
                lo, seen = c, set()
            seen |= group
        parts.append((lo, len(winners)))
        kern, dev, cache = self._kernels, self.device, self._cache
        movers = self._movers()
        moved = self._w_moved if smoothing else self._w
        source = self._w
        c_in, c_out = self._cycle[0], self._cycle[1]
        for i, (lo, hi) in enumerate(parts):
            cache.fetch(list(dict.fromkeys(winners[lo:hi].tolist())), self._d_max)
            if dev == "cpu":
                wp.launch(movers.move_part, dim=1, device=dev,
                          inputs=[source, moved, self._c, lo, hi, self._table, self._distances, self._slot_of,
                                  self._keys, c_in, 0, self.n_neurons, self._stalled])
            else:
                find_next = int(not smoothing and i == len(parts) - 1)
                wp.launch_tiled(movers.move, dim=[self._blocks], block_dim=int(CUDA_BLOCK), device=dev,
                                inputs=[source, moved, self._c, lo, hi, self._k_eff, self._m, self._table,
                                        self._distances, self._slot_of, self._keys, c_in, c_out, find_next,
                                        self._stalled])
            source = moved
        if dev == "cpu":
            if smoothing:
                wp.launch(kern.smooth_part, dim=1, device=dev,
                          inputs=[moved, self._w, self._offsets, self._neighbors, self._mask, self._smoothing, 0,
                                  self.n_neurons, self._stalled])
            wp.launch(kern.find_part, dim=1, device=dev,
                      inputs=[self._w, self._c, self._k_eff, self._m, self._keys, c_in, 0, 1, 1, self._stalled])
        elif smoothing:
            wp.launch_tiled(kern.smooth, dim=[self._blocks], block_dim=int(CUDA_BLOCK), device=dev,
                            inputs=[moved, self._w, self._offsets, self._neighbors, self._mask, self._smoothing,
                                    self._c, self._k_eff, self._m, self._keys, c_out, c_in, self._stalled])
        self._s += 1
        self._set_cycle()
        self._winners_valid = True
