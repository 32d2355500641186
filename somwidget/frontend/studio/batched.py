"""Rooms' Soms held in batches between rounds: alike rooms (a topology, a schedule, point controls) are variants of one
BatchSom (backend/batch.py, the variants' kernels) stepped in one launch a round by the worker's loop (rounds.py).

While a room is held, its weights and cycle live in the batch's device arrays, not its Som: a round puts in only what
changed (its controls and cycle after a move, its weights back to the anchor's when a drag's move restarts from
there: `BatchSom.move`), steps every held room of a batch to its own cycle in one launch, and reads every weight
back in one transfer; each room's frame is its row of that copy (`host`). The Som keeps everything else (its
controls, settings, anchor) and follows the cycle (its state's s, through `Som.parts`, the engine's internal API);
its own weights are stale until the room is given back (`give_back`: its row of the last copy `restore`d into it),
which happens before anything else reads or changes the Som: whoever takes the room's Som lock (an undo, a save, a
preset switch, a setting: `RoomLock`) and any queued operation a batch cannot apply (`applies_in_batch`) gets the
Som back first. An autosave only reads: it takes the lock as a round's turn does (`RoomLock.for_save`) and reads the
weights a give-back would restore, the room's row of the last round (`state_to_save`), with no copy to the device
and back. A room given back is held again at its next round that steps it with alike rooms. The weights a
batch reaches equal those of the Soms stepped apart (the same kernels' arithmetic; tests/studio/test_batched_rooms.py).
"""

from __future__ import annotations

import contextlib
import threading
import time
import weakref
from dataclasses import dataclass

import numpy as np

from ...backend.batch import MAX_BATCH_NEURONS, BatchSom
from ...backend.presets import colours_of
from ...backend.som import Som
from ...backend.som_state import SomState
from ..model.operations import Grab, Publish, Release, SetControls


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


def applies_in_batch(op) -> bool:
    """Whether a batch holding a room's state applies `op` as its Som would: a move of point controls (from the
    latest weights or the drag's anchor), a grab or release (point controls bind nothing), a frame to publish."""
    if isinstance(op, SetControls):
        return not op.keep and op.rest is None and not np.any(op.radii)
    return isinstance(op, (Grab, Release, Publish))


def keeps_key(op, key: tuple | None) -> bool:
    """Whether `op` leaves a Som's batch key (`batch_key`) as it was: a grab, a release, a frame, or a move of point
    controls that keeps their count and strokes (so a round need not find the key again)."""
    if isinstance(op, (Grab, Release, Publish)):
        return True
    return (key is not None and isinstance(op, SetControls) and applies_in_batch(op)
            and np.shape(op.controls) == (key[3], key[2]) and all(s == 1 for s in op.strokes))


@dataclass
class _Loan:
    """A room held by a batch: its Som, its variant, its weights as the last round left them, and the Som's count of
    restarts from its anchor that the batch has made too."""

    key: tuple
    som: Som
    state: SomState  # the Som's state (its s, its anchor's restarts): read every round, found once
    slot: int
    host: np.ndarray
    restarts: int
    stepped: int = -1  # the group's round whose copy `host` is a row of (-1: none yet), and its row there
    row: int = -1


class _Group:
    """One BatchSom of alike rooms, a variant a room; its size doubles as rooms join."""

    def __init__(self) -> None:
        self._batch: BatchSom | None = None  # made by the first `slot`
        self.free: list[int] = []
        self.moves: list[tuple] = []  # (slot, controls, s, from anchor): the held rooms' moves, put in at once
        self.rounds = 0  # launches made
        # the last round's copy of every weight and the slots it stepped
        self.stepped: tuple[np.ndarray, np.ndarray] | None = None
        self.colours: dict = {}  # layout -> (m, N, 3) their nodes' colours, made when first asked for

    @property
    def batch(self) -> BatchSom:
        """The group's BatchSom; a group holds a room (and has moves to put in) only once `slot` made it."""
        if self._batch is None:
            raise RuntimeError("a batch group was used before its first room took a slot (_Group.slot)")
        return self._batch

    def put_moves(self) -> None:
        """The moves `hold` noted since the last round into the batch, in one call (BatchSom.move_rows)."""
        if self.moves:
            moves, self.moves = self.moves, []
            slots, controls, s, anchor = zip(*moves)
            self.batch.move_rows(np.array(slots), np.stack(controls), np.array(s), np.array(anchor, bool))

    def slot(self, som: Som) -> int:
        if not self.free:
            self._grow(som)
        return self.free.pop()

    def _grow(self, som: Som) -> None:
        old = self._batch
        size = 2 if old is None else 2 * old.n_variants
        batch = BatchSom(som.topology, som.start_weights, np.repeat(som.controls[None], size, axis=0),
                         iterations=som.iterations, l_start=som.l_start, l_end=som.l_end, smoothing=som.smoothing,
                         reach=som.reach, smooth_dims=som.smooth_dims, metric_weights=som.metric_weights,
                         mirror=som.mirror, device=som.device)
        if old is not None:
            batch.take_over(old)
        first = 0 if old is None else old.n_variants
        self.free = list(range(size - 1, first - 1, -1)) + self.free
        self._batch = batch


class BatchedRooms:
    """The batches of one worker's rooms and which room each holds (see the module's docstring); rooms are named by
    an owner (their trainer). `launches`, `batched`: launches made and the room steps they took; `widest`: the most
    rooms one launch stepped."""

    def __init__(self) -> None:
        self._lock = threading.RLock()  # the batches; never held while waiting for a room's Som lock
        self._groups: dict[tuple, _Group] = {}
        self._loans: dict[object, _Loan] = {}
        self._topologies: dict = {}
        self.launches = self.batched = self.widest = 0
        self.given_back = 0  # rooms' Soms given their state back (each an upload, and the next hold another)

    def key(self, som) -> tuple | None:
        return batch_key(som, self._topologies)

    def holds(self, owner) -> bool:
        return owner in self._loans

    def host(self, owner) -> np.ndarray:
        """The weights of a held room as its batch's last round (or its lending) left them."""
        return self._loans[owner].host

    def state_to_save(self, owner) -> tuple[np.ndarray, int] | None:
        """(weights, cycle s) of a held room that a save writes, without giving it back (caller holds its Som lock, as
        a round's turn takes it): those `give_back` would leave in its Som, a copy of its row of the last round and
        the cycle that round reached, read together; None when the room is not held. A room whose Som restarted from
        its anchor since that round (its state is its own anchor's then) is given back and None returned: its Som's
        own state is the one to save."""
        with self._lock:
            loan = self._loans.get(owner)
            if loan is None:
                return None
            group = self._groups.get(loan.key)
            pending = group is not None and (group.batch.restarts_from_anchor(loan.slot) or any(
                slot == loan.slot and anchor for slot, _, _, anchor in group.moves))
            if pending or loan.state.anchor_restarts != loan.restarts:
                self._give_back(owner)
                return None
            return loan.host.copy(), int(loan.state.s)

    def hold(self, owner, som: Som, key: tuple) -> None:
        """Before a round steps the room (caller holds its Som lock): held already, its moved controls and cycle go
        in (from the anchor where its Som restarted from there); else its state goes into a free variant of its
        group's batch (the room's Som changed: the old one is given back first)."""
        with self._lock:
            loan = self._loans.get(owner)
            if loan is not None and (loan.som is not som or loan.key != key):
                self._give_back(owner)
                loan = None
            if loan is None:
                group = self._groups.setdefault(key, _Group())
                group.put_moves()  # before a growth copies the batch
                slot = group.slot(som)
                host = som.weights  # the anchor settled first
                state = som.parts.state
                group.batch.put(slot, host, som.iteration, som.controls, state.w_anchor)
                state.lend(True)  # its moves' controls go into the batch's row, not its own rows, until given back
                self._loans[owner] = _Loan(key, som, state, slot, host, state.anchor_restarts)
                return
            restarts = loan.state.anchor_restarts  # a drag's move restarts from its anchor: the batch's row too
            self._groups[key].moves.append((loan.slot, som.controls, loan.state.s, restarts != loan.restarts))
            loan.restarts = restarts

    def colours(self, owner, layout) -> np.ndarray | None:
        """The nodes' colours (read-only) of a held room's weights as its batch's last round left them, made for every
        room that round stepped in one call (presets.colours_of is row by row: the values a room's own call gives);
        None when the room is not held, not stepped by that round, or its layout has no colour dims."""
        with self._lock:
            loan = self._loans.get(owner)
            group = None if loan is None else self._groups.get(loan.key)
            if loan is None or group is None or loan.stepped != group.rounds or layout.colour_space == "none":
                return None
            made = group.colours.get(layout)
            if made is None:
                assert group.stepped is not None  # the round the loan was stepped by (loan.stepped) set it
                host, slots = group.stepped
                rows = host[slots]  # (m, N, n): the rooms that round stepped
                m, n_nodes, n = rows.shape
                made = colours_of(rows.reshape(m * n_nodes, n), layout).reshape(m, n_nodes, 3)
                made.setflags(write=False)
                group.colours[layout] = made
            return made[loan.row]

    def give_back(self, owner) -> None:
        """The room's Som gets its state back (caller holds its Som lock, or it has no round any more)."""
        if owner in self._loans:
            with self._lock:
                self._give_back(owner)

    def _give_back(self, owner) -> None:
        loan = self._loans.pop(owner, None)
        if loan is None:
            return
        self.given_back += 1
        loan.state.lend(False)  # the controls its moves left waiting go into its own rows
        group = self._groups.get(loan.key)
        if group is not None:
            group.put_moves()
        pending = group is not None and group.batch.forget(loan.slot)
        if group is not None:
            group.free.append(loan.slot)
        if not pending and loan.som.parts.state.anchor_restarts == loan.restarts:  # else its own anchor is its state
            loan.som.restore(loan.host, loan.som.iteration)

    def step(self, asks: list[tuple[object, int]]) -> dict:
        """One launch a batch: each held room (owner, cycles) stepped its cycles (none past S); for each owner
        (cycles run, seconds its launch took) or the exception its launch raised (its room given back as it was)."""
        out: dict = {}
        with self._lock:
            groups: dict[tuple, list] = {}
            for owner, cycles in asks:
                loan = self._loans.get(owner)
                if loan is not None:  # else given back since it was held: it steps next round
                    groups.setdefault(loan.key, []).append((owner, loan, cycles))
            for key, items in groups.items():
                group = self._groups[key]
                try:
                    batch = group.batch
                    group.put_moves()
                    slots = np.fromiter((loan.slot for _, loan, _ in items), np.int64, len(items))
                    wanted = np.fromiter((c for _, _, c in items), np.int64, len(items))  # each room's cycles
                    s = batch.iteration
                    to = s.copy()
                    to[slots] = np.minimum(s[slots] + wanted, batch.iterations[slots])
                    t = time.perf_counter()
                    batch.step_to(to)
                    host = batch.weights
                except Exception as exc:  # each room's turn reports it; the rooms go back as they were
                    for owner, _, _ in items:
                        self._give_back(owner)
                        out[owner] = exc
                    self._groups.pop(key, None)
                    continue
                seconds = time.perf_counter() - t
                reached, ran = to[slots].tolist(), (to[slots] - s[slots]).tolist()
                group.rounds += 1
                group.stepped, group.colours = (host, slots), {}
                for row, ((owner, loan, _), at, n) in enumerate(zip(items, reached, ran)):
                    loan.host = host[loan.slot]
                    loan.stepped, loan.row = group.rounds, row
                    loan.state.restart(at)  # s moved on, the winners found afresh
                    out[owner] = (n, seconds)
                self.launches += 1
                self.batched += len(items)
                self.widest = max(self.widest, len(items))
        return out

    def forget(self) -> None:
        """Drop the batches (every room parked: their memory goes too)."""
        with self._lock:
            for owner in list(self._loans):
                self._give_back(owner)
            self._groups.clear()


class RoomLock:
    """A room's Som lock (its state's `som_lock`) while a batch may hold its Som's state: whoever takes it gets the
    Som with its state given back first; the rounds' own turns (`turn`) and a save (`for_save`) take it as it is, a
    save reading the held room's weights and cycle through `state_to_save` (ModellingState.lent)."""

    def __init__(self, lock, give_back, state_to_save=lambda: None) -> None:
        self._lock = lock
        self._give_back = give_back
        self.state_to_save = state_to_save

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        if not self._lock.acquire(blocking, timeout):
            return False
        try:
            self._give_back()
        except BaseException:
            self._lock.release()
            raise
        return True

    def release(self) -> None:
        self._lock.release()

    def turn(self, blocking: bool = True) -> bool:
        """Taken for a round's turn: the Som stays lent."""
        return self._lock.acquire(blocking)

    @contextlib.contextmanager
    def for_save(self):
        """Taken for a save (`turn`): the Som stays lent; `state_to_save()` gives the weights and cycle it writes."""
        self._lock.acquire()
        try:
            yield self
        finally:
            self._lock.release()

    def __enter__(self) -> bool:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self._lock.release()


__all__ = ["BatchedRooms", "RoomLock", "applies_in_batch", "batch_key", "keeps_key"]
