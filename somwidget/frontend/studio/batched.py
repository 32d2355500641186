"""The rooms of one worker stepped together: rooms whose Soms share a topology, a schedule and point controls step in
one batched launch a round (backend/batch.py: BatchSom, the variants' kernels), the others by themselves.

Each room's training thread asks for its step as it would step alone (`BatchedSteps.step`, the trainer's
`stepper`); the first to ask leads a round: it waits up to `window` seconds for the other rooms that stepped lately,
then for each group of alike Soms loads their weights, cycles and controls into one BatchSom, steps each to its own
cycle (a room's pace sets its cycles) in one launch, and puts each room's weights back (`Som.restore`: the same
state a step of its own leaves, but for the winners, which its next step finds afresh from the same weights). A Som
alone in its group, or one the kernels do not take (radii, strokes, a radial group, the Taubin rule, a mesh past the
batch's size), steps by itself. Every room's thread waits for the round it joined; a failure reaches each of them.

In one process every Warp call is serialised (backend.device.warp_lock), so stepping rooms apart costs a launch and
two copies a room a frame; batched, a round costs one launch and the copies, whatever the number of rooms
(bench_studio.py --mode engine measures both).
"""

from __future__ import annotations

import threading
import time
import weakref

import numpy as np

from ...backend.batch import MAX_BATCH_NEURONS, BatchSom
from ...backend.som import Som
from ..model.trainer import step_alone

#: How long a round's leader waits for the rooms that stepped lately (s).
WINDOW = 0.002
#: A room that stepped within this many seconds is waited for by the next round.
RECENT = 0.25


def _topology_key(topology, cache: dict) -> tuple:
    """A key equal for topologies of equal meshes (rooms of one preset each build their own), cached per object."""
    entry = cache.get(id(topology))
    if entry is not None and entry[0]() is topology:
        return entry[1]
    key = (topology.n_vertices, hash(np.asarray(topology.offsets).tobytes()),
           hash(np.asarray(topology.neighbors).tobytes()))
    cache[id(topology)] = (weakref.ref(topology), key)
    return key


def batch_key(som, cache: dict) -> tuple | None:
    """What Soms stepped in one launch share (None: this one steps by itself): the mesh, the device, the controls'
    count and mirror, the schedule, smooth_dims and metric weights; point controls, no strokes, no radial group."""
    if not isinstance(som, Som) or som.n_neurons > MAX_BATCH_NEURONS or som.radii.any():
        return None
    if any(s != 1 for s in som.strokes) or (som.smoothing_rule == "taubin" and som.smoothing > 0):
        return None
    k = len(som.controls)
    if len(som.effective_controls) != k * (2 if som.mirror else 1):  # a radial (or other) group
        return None
    return (_topology_key(som.topology, cache), som.device, som.n_dims, k, som.mirror, som.smooth_dims,
            som.metric_weights.tobytes(), som.iterations, som.l_start, som.l_end, som.smoothing, som.reach)


class _Ask:
    __slots__ = ("som", "cycles", "key", "ran", "error", "done")

    def __init__(self, som, cycles: int, key):
        self.som, self.cycles, self.key = som, cycles, key
        self.ran, self.error, self.done = 0, None, threading.Event()


class BatchedSteps:
    """The stepper of one worker's rooms (see the module's docstring). `launches`, `batched`: batched launches made
    and the room steps they took; `alone`: room steps run by themselves."""

    def __init__(self, window: float = WINDOW, recent: float = RECENT):
        self.window, self.recent = window, recent
        self._cond = threading.Condition()
        self._asks: list[_Ask] = []
        self._leading = False
        self._round = threading.Lock()  # one round at a time uses the batches
        self._recent: dict[int, float] = {}  # id(som) -> when it last asked
        self._topologies: dict = {}
        self._batches: dict[tuple, BatchSom] = {}
        self.launches = self.batched = self.alone = 0

    def step(self, som, cycles: int) -> int:
        """Step `som` `cycles` cycles, in a launch with other rooms' alike Soms where any ask meanwhile; the cycles
        it ran. Called by a room's training thread holding that room's Som lock."""
        key = batch_key(som, self._topologies)
        if key is None:
            self.alone += 1
            return step_alone(som, cycles)
        ask = _Ask(som, cycles, key)
        now = time.monotonic()
        with self._cond:
            self._recent[id(som)] = now
            self._asks.append(ask)
            self._cond.notify_all()
            lead = not self._leading
            self._leading = self._leading or lead
            if lead:  # wait for the rooms that stepped lately (or the window's end)
                expected = sum(1 for t in self._recent.values() if now - t <= self.recent)
                deadline = now + self.window
                while len(self._asks) < expected and (left := deadline - time.monotonic()) > 0:
                    self._cond.wait(left)
                asks, self._asks, self._leading = self._asks, [], False
                self._recent = {i: t for i, t in self._recent.items() if now - t <= self.recent}
        if lead:
            with self._round:
                self._run(asks)
        else:
            ask.done.wait()
        if ask.error is not None:
            raise ask.error
        return ask.ran

    def step_together(self, soms, cycles) -> list[int]:
        """One round from this thread: step each Som its cycles, alike ones in one launch (none of them may be
        stepping elsewhere meanwhile); the cycles each ran. What a round of the rooms' threads does, for benchmarks."""
        asks = [_Ask(som, int(k), batch_key(som, self._topologies)) for som, k in zip(soms, cycles)]
        with self._round:
            self._run(asks)
        for ask in asks:
            if ask.error is not None:
                raise ask.error
        return [ask.ran for ask in asks]

    def forget(self) -> None:
        """Drop the batches kept (rooms parked: their memory goes too)."""
        with self._round:
            self._batches.clear()

    def _run(self, asks: list[_Ask]) -> None:
        groups: dict[tuple, list[_Ask]] = {}
        for ask in asks:
            groups.setdefault(ask.key, []).append(ask)
        for key, group in groups.items():
            try:
                if key is None or len(group) == 1:
                    for ask in group:
                        self.alone += 1
                        ask.ran = step_alone(ask.som, ask.cycles)
                else:
                    self._launch(key, group)
            except Exception as exc:  # each room's thread reports it as its step's failure
                for ask in group:
                    ask.error = exc
            finally:
                for ask in group:
                    ask.done.set()

    def _launch(self, key: tuple, group: list[_Ask]) -> None:
        """One launch for the group: their states in, each stepped to its own cycle, their weights back."""
        soms = [ask.som for ask in group]
        batch = self._batch(key, soms[0], len(soms))
        size = batch.n_variants
        weights = np.empty((size, soms[0].n_neurons, soms[0].n_dims), np.float32)
        controls = np.empty((size,) + soms[0].controls.shape, np.float32)
        s = np.zeros(size, np.int64)
        for b, som in enumerate(soms):
            weights[b], controls[b], s[b] = som.weights, som.controls, som.iteration
        weights[len(soms):], controls[len(soms):] = weights[0], controls[0]  # slots not used this round: no cycles
        to = s.copy()
        to[:len(soms)] = np.minimum(s[:len(soms)] + [ask.cycles for ask in group], soms[0].iterations)
        batch.load(weights, s, controls)
        batch.step_to(to)
        out = batch.weights
        for b, ask in enumerate(group):
            ask.som.restore(out[b], int(to[b]))
            ask.ran = int(to[b] - s[b])
        self.launches += 1
        self.batched += len(group)

    def _batch(self, key: tuple, som: Som, count: int) -> BatchSom:
        """The group's BatchSom, made for at least `count` rooms (its slots doubling as rooms join)."""
        batch = self._batches.get(key)
        if batch is None or batch.n_variants < count:
            size = 1 << max(1, (count - 1).bit_length())
            batch = BatchSom(som.topology, som.weights, np.repeat(som.controls[None], size, axis=0),
                             iterations=som.iterations, l_start=som.l_start, l_end=som.l_end,
                             smoothing=som.smoothing, reach=som.reach, smooth_dims=som.smooth_dims,
                             metric_weights=som.metric_weights, mirror=som.mirror, device=som.device)
            self._batches[key] = batch
        return batch


__all__ = ["BatchedSteps", "batch_key"]
