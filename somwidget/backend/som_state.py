"""What a Som's training changes (warp.sim's State): the weights W on the device (with a spare buffer for the moved
weights of step 2 and the copy `anchor()` keeps), the cycle s, the winner keys, and the device block of the effective
controls and cycle counters that the captured runs read. The paths (cpu_path.py, cuda_path.py, rows_path.py,
local_path.py, shaping_path.py) read and write it; `Graphs` keeps their captured runs.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
import warp as wp

try:  # Warp's internals, for `copy_array` (warp-lang is pinned to 1.19.x in pyproject.toml)
    from warp._src import context as _warp_context
except ImportError:  # pragma: no cover - another Warp layout: wp.copy then
    _warp_context = None

from .block_boxes import BlockBoxes
from .cycle_kernels import MAX_CONTROLS
from .som_controls import Controls
from .som_model import SomModel
from .som_schedule import SomSchedule

KEY_NONE = np.uint64(0xFFFFFFFFFFFFFFFF)


class SomState:
    """A Som's weights, cycle s and winner keys on the model's device.

    w, w_moved: (N,) vectors, the weights and the moved weights of a cycle with smoothing; w_anchor: the weights
    `anchor()` kept (None before), with anchor_pending while a restart from them waits for its run. s, parity (CUDA:
    which of the two counters holds s), winners_valid (keys[s % 3] holds the winners of W(s)). keys (3,
    MAX_CONTROLS): winner keys (primitives.winner_key) rotating by s % 3. c: the effective controls (MAX_CONTROLS
    slots, `upload`); cycle: the counters the kernels pass on (CUDA: two; CPU: one per core).
    boxes: the CPU's block boxes of the weights (block_boxes.BlockBoxes), None on CUDA.
    """

    def __init__(self, model: SomModel, boxes: BlockBoxes | None) -> None:
        dev, vec = model.device, model.vec
        self.device = dev
        self.boxes = boxes
        self.w = wp.array(model.start, dtype=vec, device=dev)
        self.w_moved = wp.empty_like(self.w)
        self.w_anchor: wp.array | None = None
        self.anchor_pending = False  # the next run starts by copying the anchor back (set_controls(from_anchor=True))
        self.anchor_version = 0  # counts `anchor()` calls
        self.anchor_restarts = 0  # counts restarts from the anchor (`from_anchor(True)`)
        # The effective controls (a fixed-size buffer: captured graphs keep its pointer) and the cycle counters (CUDA:
        # two that the kernels pass on, ping-pong; CPU: one per core; a 64-byte line each, no false sharing between
        # cores), in one device block. The host writes them into `staging`: on the CPU that is the block itself; on
        # CUDA pinned memory, which goes up in one asynchronous copy when a run starts afresh (`set_cycle`), so that
        # a drag frame costs one copy more than a plain one, not a wait.
        counters = 64 if dev == "cpu" else 2
        control_bytes = MAX_CONTROLS * model.n_dims * 4
        self.block = wp.zeros(control_bytes + counters * 64, dtype=wp.uint8, device=dev)
        self.c = wp.array(ptr=self.block.ptr, dtype=vec, shape=(MAX_CONTROLS,), device=dev)
        counter_words = wp.array(ptr=self.block.ptr + control_bytes, dtype=wp.int32, shape=(counters * 16,),
                                 device=dev)
        self.cycle = [counter_words[i * 16: i * 16 + 1] for i in range(counters)]
        self.staging = None if dev == "cpu" else wp.zeros_like(self.block, device="cpu", pinned=True)
        self._uploaded = None if dev == "cpu" else wp.Event(dev)
        self._staging_busy = False  # an upload from `staging` may still be under way
        words = (self.block if self.staging is None else self.staging).numpy().view(np.float32)
        self._control_rows = words[: control_bytes // 4].reshape(MAX_CONTROLS, model.n_dims)
        self.counter_words = words[control_bytes // 4:].view(np.int32)
        self.n_slots = 0  # effective controls in `c`
        #: While a batch holds this state (a studio's room: its controls go into the batch's row), an upload waits
        #: here until the Som runs again or is given back (`lend`): a drag's move costs no rows written twice
        self.lent = False
        self._waiting: Controls | None = None
        self.keys = wp.full((3, MAX_CONTROLS), KEY_NONE, dtype=wp.uint64, device=dev)
        self.stalled = wp.zeros(1, dtype=wp.int32, device=dev)  # set only by a distance-rows cycle that stalls
        self.s = 0
        self.parity = 0
        self.winners_valid = False
        if dev == "cpu":  # the keys as one flat array, and a host view of them (CPU memory)
            self.flat_keys = wp.array(ptr=self.keys.ptr, dtype=wp.uint64, shape=(3 * MAX_CONTROLS,), device="cpu")
            self.keys_host = self.keys.numpy()

    # -- controls and counters ------------------------------------------------------------------------------------
    def cpu_boxes(self) -> BlockBoxes:
        """The CPU's block boxes; RuntimeError on CUDA, which keeps none."""
        if self.boxes is None:
            raise RuntimeError(f"SomState: no block boxes on {self.device} (the CPU's local cycle keeps them)")
        return self.boxes

    def upload(self, controls: Controls) -> None:
        """The effective controls into the fixed-size buffer, so that the captured graphs stay valid while only their
        values change (a drag); with a mirror in pairs, each original next to its copy (slots 2i and 2i + 1), the order
        in which step 2 applies them. On CUDA they go up with the next `set_cycle`. While `lent`, they wait for it
        (or for `lend(False)`)."""
        if self.lent:
            self._waiting = controls
            self.winners_valid = False  # (the next run's set_cycle writes them first)
            return
        self._write(controls)

    def _write(self, controls: Controls) -> None:
        """`upload`'s writing of the rows, lent or not (what waited is written)."""
        self._waiting = None
        self._staging_ready()
        rows = self._control_rows
        k = len(controls.values)
        n = controls.n_slots
        if controls.mirror:
            rows[0:n:2] = controls.values
            rows[1:n:2] = controls.values
            for d in controls.mirror:
                rows[1:n:2, d] *= -1.0
        else:
            rows[:k] = controls.values
        rows[n:] = 0.0
        self.n_slots = n
        self.winners_valid = False

    def lend(self, lent: bool) -> None:
        """A batch holds this state from now on (`lent`), or gave it back: an upload that waited is made now."""
        self.lent = lent
        if not lent and self._waiting is not None:
            self._write(self._waiting)

    def set_cycle(self) -> None:
        """Every cycle counter to s; on CUDA the staged controls go up with them, in one asynchronous copy."""
        if self._waiting is not None:  # a run of a state still lent: its controls first
            self._write(self._waiting)
        self._staging_ready()
        self.counter_words[:] = self.s
        if self.staging is not None:
            copy_array(self.block, self.staging)
            wp.record_event(self._uploaded)
            self._staging_busy = True

    def _staging_ready(self) -> None:
        """On CUDA, wait until the last upload has left the staging buffer (so that it can be written again)."""
        if self._staging_busy:
            wp.synchronize_event(self._uploaded)
            self._staging_busy = False

    # -- the schedule's position --------------------------------------------------------------------------------
    def restart(self, s: int) -> None:
        """Continue the schedule from cycle s with the winners found afresh."""
        self.s = s
        self.winners_valid = False

    def start_run(self) -> bool:
        """Whether a run of the paper's captured cycles starts afresh (the winners of cycle s unknown: it finds them
        first), the counters then set to s."""
        fresh = not self.winners_valid
        if fresh:
            self.set_cycle()
        return fresh

    def fresh_winners(self, find: Callable[[], None]) -> None:
        """keys[s % 3]: the winners of the current weights, found by `find` unless they are known."""
        if self.winners_valid:
            return
        self.settle_anchor()
        self.set_cycle()
        find()
        self.winners_valid = True

    def winners(self, count: int) -> np.ndarray:
        """(count,) the neurons of the winner keys of cycle s (slot order)."""
        keys = self.keys.numpy()[self.s % 3, :count]
        return (keys & np.uint64(0xFFFFFFFF)).astype(np.int64)

    # -- weights ------------------------------------------------------------------------------------------------
    def weights_replaced(self) -> None:
        """Any weight may have changed outside the local cycle's moves: the CPU's boxes are made again when next
        needed, and going back to the anchor copies every neuron."""
        if self.boxes is not None:
            self.boxes.invalidate()

    def assign(self, weights: np.ndarray) -> None:
        """New weights (checked, of the model's shape); a restart from the anchor no longer waits."""
        self.anchor_pending = False
        self.w.assign(weights)
        self.weights_replaced()

    def anchor(self) -> None:
        """Keep a copy of the current weights (and on the CPU their boxes) for a restart from them."""
        self.settle_anchor()
        self.anchor_version += 1
        if self.w_anchor is None:
            self.w_anchor = wp.empty_like(self.w)
        wp.copy(self.w_anchor, self.w)
        if self.boxes is not None:
            self.boxes.keep_anchor(self.w)

    def from_anchor(self, on: bool) -> None:
        """The next run starts from the anchored weights (`on`) or from the latest ones. CUDA copies them back as a
        node of the run's first graph; the CPU copies them now."""
        self.anchor_pending = on
        self.anchor_restarts += int(on)
        if on and self.device == "cpu":
            self.settle_anchor()

    def settle_anchor(self) -> None:
        """The anchored weights into the current ones now, if a restart from the anchor still waits for its run."""
        if self.anchor_pending:
            self.anchor_pending = False
            if self.boxes is not None and self.boxes.anchored:  # the CPU: only the blocks moved since (with boxes)
                self.boxes.back_to_anchor(self.w, self.w_anchor)
            else:
                copy_array(self.w, self.w_anchor)


class Graphs:
    """Captured graphs of runs of cycles by key (with the packed arguments of their dependent launches, which must
    live as long as they do), all dropped when what they hold changes (`valid_for`), or by `clear()`."""

    def __init__(self, device: str) -> None:
        self.device = device
        self._held: dict[tuple, tuple] = {}
        self._setup: tuple | None = None

    def valid_for(self, controls: Controls, schedule: SomSchedule) -> None:
        """Keep the graphs only if they were captured for this learning table, lambda, count of control slots and
        pairing of step 2 (what a graph holds)."""
        setup = (schedule.version, schedule.values.smoothing, controls.n_slots, controls.pairs(schedule.table_max))
        if setup != self._setup:
            self._held.clear()
            self._setup = setup

    def clear(self) -> None:
        self._held.clear()
        self._setup = None

    def get(self, key: tuple, record: Callable[[], list | None]):
        """The graph of `key`, captured from `record()` the first time."""
        held = self._held.get(key)
        if held is None:
            with wp.ScopedCapture(device=self.device) as capture:
                records = record()
            held = self._held[key] = (capture.graph, records)
        return held[0]


@functools.cache
def _memcpy(name: str):
    """Warp's memcpy entry point `name` (wp_memcpy_h2d, wp_memcpy_d2d), None where there is none."""
    core = getattr(getattr(_warp_context, "runtime", None), "core", None)
    return getattr(core, name, None)


def copy_array(dest: wp.array, src: wp.array) -> None:
    """`src` into `dest`, of the same size. Into a CUDA array from a pinned host array or one on the same device:
    asynchronous, on the device's stream, through Warp's own memcpy entry points without wp.copy's checks (a sixth
    of its time; this runs every drag frame). wp.copy on the CPU, and where those entry points are missing."""
    copy = None if dest.device.is_cpu else _memcpy("wp_memcpy_h2d" if src.device.is_cpu else "wp_memcpy_d2d")
    if copy is None:
        wp.copy(dest, src)
        return
    device = dest.device
    if not copy(device.context, dest.ptr, src.ptr, dest.capacity, device.stream.cuda_stream):
        raise RuntimeError(f"Som: a copy to {device} failed")
