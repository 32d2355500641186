"""Distance rows past the dense table: int32 hop rows D[u, .] of recent winners kept on the Som's device
(`RowCache`), computed on demand (topology.RowSearch; on the CPU local_kernels.search_row, as deep as a cycle reads
them), and `control_parts`, the runs of controls whose winners' rows fit in the cache at once.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
import warp as wp

from .cycle_kernels import LONGEST_GRAPH, MAX_CONTROLS
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

    def __init__(self, topology: Topology, device: str, size: int | None) -> None:
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


def control_parts(winners: np.ndarray, size: int, unit: int) -> list[tuple[int, int]]:
    """Consecutive runs [lo, hi) of the controls whose distinct winners fit in `size` cache rows, each neuron still
    applying the controls in list order; a unit of `unit` controls (2: a mirrored pair) is never split."""
    parts: list[tuple[int, int]] = []
    lo, seen = 0, set[int]()
    for c in range(0, len(winners), unit):
        group = set(winners[c:c + unit].tolist())
        if len(seen | group) > size:
            parts.append((lo, c))
            lo, seen = c, set()
        seen |= group
    parts.append((lo, len(winners)))
    return parts
