"""Handles: what a Som's controls with a radius hold of the clay (DESIGN.md "Handles"; tests/reference_handles.py is
the normative float64 reference, whose docstring this follows).

A grab binds each member of the control (the control and its symmetric copies): its winner u (fixed while the binding
lives), its place p = W_u, and its patch, the nodes joined to u through nodes whose straight distance from W_u is below
the radius r, weighted (1 - t^2)^2. While it lives, each cycle steps p after the member by at most r / 4 and binds the
patch again around the same u, within its reach R = max(r, WIDEN |p - p(grab)|) (a lift taller than the radius rolls,
the patch widening as the hand goes), and the patch is carried to p (shaping_kernels.py). A release ends nothing at
once: a released binding still carries its patch to where the hand left it until the run reaches S or the next restart
(a set_controls, a parameter change), then ends. A control of radius > 0 moved while no hand holds it (a typed position)
is grabbed at its old place and released at once. Controls with a radius that nothing binds do nothing. A bound node's
target is a convex blend of its anchor and points within R of a place its member has been, and a node several bindings
hold takes their weighted mean displacement; the target is clamped into the box of the start and every place of the
members grown by the largest radius (only a widened patch's rim could reach past it), and every node after Taubin's
steps (whose mu and volume steps could stand out by a hair) into that box grown by BOX_MARGIN of the start's size: no
node leaves the box.

The engine keeps one binding per slot (member g of control c: slot c G + g). A grab of a control whose released
bindings still live ends them first (the reference would keep both until its next restart; they carry to the same
place once the released one has arrived). A change of the controls' count, symmetry group or of which controls have a
radius, a reset, restored or assigned weights end every binding and let go of every hold.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import warp as wp

from .metrics import bounding_diagonal
from .shaping_kernels import FIND_STRETCH, clear_flag, shaping_kernels
from .som_controls import Controls
from .som_model import SomModel
from .som_state import KEY_NONE, SomState

#: Taubin's lambda is capped here: past about 0.72 the pair amplifies the checkerboard mode of a quad mesh
#: ((1 - 2 lambda)(1 - 2 mu) < -1) and the clay blows up (BENCHMARKS.md, "Handles").
TAUBIN_MOST = 0.7
#: The clamp's box is grown by this share of the start's size beyond the largest radius.
BOX_MARGIN = 0.01
#: Meshes of up to this many nodes bind a patch in one launch, a block of up to FLOOD_THREADS threads a handle row
#: (its rounds behind a barrier); larger ones launch a round at a time over every node (BENCHMARKS.md, "Handles in
#: the engine").
FLOOD_IN_BLOCKS_MOST = 16384
FLOOD_THREADS = 512


def members_of(controls: Controls) -> np.ndarray:
    """(k G, n) float32: member g of control c (its image under the group's map g) at slot c G + g."""
    if controls.order == 1:
        return np.ascontiguousarray(controls.values, np.float32)
    maps = controls.group_maps()
    grouped = np.einsum("gij,kj->kgi", maps, controls.values.astype(np.float64))
    return np.ascontiguousarray(grouped.reshape(-1, controls.values.shape[1]), np.float32)


class Handles:
    """The bindings of one Som: which controls a hand holds (`held`), which slots have a live binding (`live`), the
    box, and their device arrays (slot arrays made again when the controls' structure changes, `version` counts
    them). The events are its methods; shaping_path.ShapingPath runs the cycles on its arrays."""

    def __init__(self, model: SomModel):
        self.model = model
        dev, n, vec = model.device, model.n_neurons, model.vec
        self.kernels = shaping_kernels(model.n_dims)
        #: the threads of a block a handle row where a patch is bound in one launch (the CPU, meshes of up to
        #: FLOOD_IN_BLOCKS_MOST nodes), else 0 (a launch a round)
        self.block_threads = 1 if dev == "cpu" else min(FLOOD_THREADS, 32 * -(-n // 32)) if (
            n <= FLOOD_IN_BLOCKS_MOST) else 0
        self.held: set[int] = set()
        self.live = np.zeros(0, bool)
        self.bound: set[int] = set()  # the controls whose members' bindings live
        self.controls: Controls | None = None
        self.version = 0
        self._structure: tuple | None = None
        self._uploaded: Controls | None = None  # the controls whose members and radii the device holds
        start = model.start.astype(np.float64)
        self._lo, self._hi = start.min(axis=0), start.max(axis=0)
        self.size = bounding_diagonal(start[:, model.position_dims]) or 1.0
        self._box_version = 0  # counts the box's changes (a grow that moved it, other radii) ...
        self._box_sent: int | None = None  # ... and the one the device holds (None: none yet)
        self._pad_for: np.ndarray | None = None  # the radii whose padding `_pad` holds
        self._radii_for: np.ndarray | None = None  # the radii whose members' radii the device holds
        self._grown: Controls | None = None  # the controls the box last took
        position = np.zeros(model.n_dims, np.float32)
        position[model.position_dims] = 1.0
        self.position = vec(*position.tolist())
        self.anchors = wp.empty(n, dtype=vec, device=dev)
        self.held_nodes = wp.zeros(n, dtype=wp.int32, device=dev)  # 1 where a live binding holds the node
        self.stepped = wp.zeros(1, dtype=wp.int32, device=dev)
        self.changed = wp.zeros(1, dtype=wp.int32, device=dev)
        self.unarrived = wp.zeros(1, dtype=wp.int32, device=dev)  # 1 when a place stepped short of its member
        self.claim = wp.zeros(1, dtype=wp.int32, device=dev)  # step_block: the blocks that stepped, counted

    # -- the slots ----------------------------------------------------------------------------------------------
    def _layout(self, controls: Controls) -> None:
        """The slot arrays for the controls' structure (count, group order, which have a radius); made again, and
        every binding ended, when it changes."""
        last = self.controls
        if last is not None and controls.radii is last.radii and controls.order == last.order and (
                controls.strokes is last.strokes):
            return  # (a move keeps the radii array: the same structure, found without a look)
        structure = (len(controls.values), controls.order, tuple((controls.radii > 0).tolist()), controls.strokes)
        if structure == self._structure:
            return
        self._structure = structure
        self.version += 1
        dev, vec, n = self.model.device, self.model.vec, self.model.n_neurons
        k, order = len(controls.values), controls.order
        slots = k * order
        copies = np.arange(order)
        point = np.flatnonzero(controls.radii == 0)
        self.order = order
        rows, starts, first = [], [0], 0  # the handle rows by group: a stroke's samples (or one control), one copy
        for length in controls.strokes:
            run = [c for c in range(first, first + length) if controls.radii[c] > 0]
            first += length
            for g in range(order if run else 0):
                rows += [c * order + g for c in run]
                starts.append(len(rows))
        self.n_rows = len(rows)
        self.rows = np.array(rows, np.int32)  # the slot of each handle row
        self.row_of = np.full(slots, -1, np.int64)
        self.row_of[self.rows] = np.arange(self.n_rows)
        self.point_slots = (point[:, None] * order + copies).ravel().astype(np.int32)
        self.live = np.zeros(slots, bool)
        self.bound = set()
        self.held.clear()
        self.held_nodes.zero_()
        self._uploaded = None

        def ints(values):
            values = np.asarray(values, np.int32)
            return wp.array(values if len(values) else np.zeros(1, np.int32), dtype=wp.int32, device=dev)

        self.slot_of_row = ints(self.rows)
        self.group_start = ints(starts)
        self.point_controls = wp.array(point.astype(np.int32), dtype=wp.int32, device=dev)
        self.point_slot_list = ints(self.point_slots)
        # the members, after them the boxes (lo, hi grown by BOX_MARGIN; lo, hi by the radius alone) and a carry-only
        # run's cycles (`cycles[0][0]`): one copy
        sent = wp.zeros(slots + 5, dtype=vec, device=dev)
        self.members, self.box, self.cycles = sent[:slots], sent[slots:slots + 4], sent[slots + 4:]
        self._sent = sent
        host = sent if dev == "cpu" else wp.zeros(slots + 5, dtype=vec, device="cpu", pinned=True)
        self._members_host = host  # (on the CPU the device array itself: written in place, no copy)
        self._members_sent = None if dev == "cpu" else wp.Event(dev)
        self._members_busy = False
        self._staged = host.numpy()
        self._box_sent = None
        self._cycles_staged: int | None = None
        self._unsent = False  # staged rows the device does not have yet
        self.probe = wp.zeros(slots, dtype=vec, device=dev)  # members where a grab searches
        self.radius = wp.zeros(slots, dtype=wp.float32, device=dev)
        self._radii_for = None
        self.reach = wp.zeros(slots, dtype=wp.float32, device=dev)  # the radius widened for how far it was carried
        self.live_dev = wp.zeros(slots, dtype=wp.int32, device=dev)
        self.winners = wp.zeros(slots, dtype=wp.int32, device=dev)
        self.places = wp.zeros(slots, dtype=vec, device=dev)
        self.starts = wp.zeros(slots, dtype=vec, device=dev)  # each binding's place at its grab
        self.winner_anchors = wp.zeros(slots, dtype=vec, device=dev)
        self.keys = wp.full(slots, KEY_NONE, dtype=wp.uint64, device=dev)
        self.rebind = wp.zeros(max(1, self.n_rows), dtype=wp.int32, device=dev)
        self.binding = wp.zeros(max(1, self.n_rows), dtype=wp.int32, device=dev)
        self.patch = wp.full((self.n_rows, n), -1.0, dtype=wp.float32, device=dev) if self.n_rows else None

    def adopt(self, controls: Controls) -> None:
        """The Som's controls are now `controls` (their members and radii go up with the next run)."""
        if controls is self.controls:
            return
        if self.controls is None or controls.radii is not self.controls.radii:
            self._box_version += 1  # (grown by the largest radius; a move keeps the radii array)
        self._layout(controls)
        self.controls = controls
        if controls.any_radius or controls.symmetry is not None:
            self.grow(controls.effective())
            self._grown = controls

    def upload(self, controls: Controls, send: bool = True) -> None:
        """The members, radii and boxes on the device for these controls (those not there yet: a move uploads the
        members, and the boxes when it grew them); `send` False: staged, to go up with the next `send`."""
        if controls is not self.controls:
            self.adopt(controls)
        members = self._uploaded is not controls
        if members and self._grown is not controls:
            self.grow(controls.effective())
        if members or self._box_sent != self._box_version:
            self._writable()
            if members:
                self._staged[:-5] = members_of(controls)
            if self._box_sent != self._box_version:
                self._stage_box()
            self._unsent = True
        if members:
            self._upload_radii(controls)
            self._uploaded = controls
        if send:
            self.send()

    def stage_cycles(self, cycles: int) -> None:
        """A carry-only run's cycles into `cycles` (with the next `send`; exact in float32 to 2^24, and a longer run
        stops sooner than that only where its places have not arrived in 2^24 steps of a quarter radius)."""
        cycles = min(cycles, 1 << 24)
        if cycles != self._cycles_staged:
            self._writable()
            self._staged[-1, 0] = cycles
            self._cycles_staged = cycles
            self._unsent = True

    def _writable(self) -> None:
        """On CUDA, wait until the last copy has left the pinned rows (so that they can be written again)."""
        if self._members_busy:
            wp.synchronize_event(self._members_sent)
            self._members_busy = False

    def send(self) -> None:
        """The staged members, boxes and cycles to the device in one copy (if any changed): on CUDA through pinned
        memory in an asynchronous copy, as the paper's controls go up (SomState.set_cycle); on the CPU they were
        written in place."""
        if self._unsent and self._members_sent is not None:
            wp.copy(self._sent, self._members_host)
            wp.record_event(self._members_sent)
            self._members_busy = True
        self._unsent = False

    def _upload_radii(self, controls: Controls) -> None:
        """The radii, member by member (only when they changed: a move keeps the radii array)."""
        if controls.radii is self._radii_for:
            return
        if self._radii_for is None or not np.array_equal(controls.radii, self._radii_for):
            self.radius.assign(np.repeat(controls.radii.astype(np.float32), controls.order))
        self._radii_for = controls.radii

    def _stage_box(self) -> None:
        """The boxes into the staged rows after the members: the start's, every weight set's and every member's places
        grown on the position dims by the largest radius and BOX_MARGIN of the start's size (Taubin's clamp), and by
        the radius alone (the carry's)."""
        radii = self.controls.radii if self.controls is not None else None
        if self._pad_for is not radii or radii is None:
            radius = float(radii.max(initial=0.0)) if radii is not None else 0.0
            self._pad = np.zeros((2, len(self._lo)))
            self._pad[:, self.model.position_dims] = [[radius + BOX_MARGIN * self.size], [radius]]
            self._pad_for = radii
        staged = self._staged[-5:-1]
        np.subtract(self._lo, self._pad, out=staged[0::2])
        np.add(self._hi, self._pad, out=staged[1::2])
        self._box_sent = self._box_version

    # -- the box ------------------------------------------------------------------------------------------------
    def grow(self, points: np.ndarray) -> None:
        """The box takes these places (or weights) too (goes up with the next run when that moved it)."""
        p = np.asarray(points).reshape(-1, len(self._lo))
        if len(p):
            lo, hi = p.min(axis=0), p.max(axis=0)
            if (lo < self._lo).any() or (hi > self._hi).any():
                self._lo = np.minimum(self._lo, lo)
                self._hi = np.maximum(self._hi, hi)
                self._box_version += 1

    # -- events -------------------------------------------------------------------------------------------------
    def grab(self, state: SomState, controls: Iterable[int]) -> None:
        """Bind every member of these controls (those with a radius that no hand holds yet) and hold them."""
        c = self.controls
        assert c is not None, "Handles.adopt comes first (the Som adopts its controls when made)"
        chosen = [i for i in controls if c.radii[i] > 0 and i not in self.held]
        if not chosen:
            return
        self._end([i for i in chosen if self.live[self._slots([i])].any()], state)
        self._bind(state, c, c, chosen)
        self.held.update(chosen)

    def release(self, controls: Iterable[int]) -> None:
        """The hand lets go: the bindings carry on until the run ends or the next restart."""
        self.held.difference_update(controls)

    def moved(self, state: SomState, new: Controls) -> None:
        """set_controls: the released bindings end; a control with a radius that moved while no hand holds it is
        grabbed at its old place and released at once; then `new` are the controls."""
        old = self.controls
        self.end_released(state)
        if new.any_radius and old is not None and len(new.values) == len(old.values) and new.order == old.order and (
                new.radii is old.radii or np.array_equal(new.radii > 0, old.radii > 0)):
            moved = np.flatnonzero((new.values != old.values).any(axis=1)).tolist()
            typed = [i for i in moved if i not in self.held and new.radii[i] > 0]
            if typed:
                self._bind(state, old, new, typed)
        self.adopt(new)

    def end_released(self, state: SomState) -> None:
        """A restart, or the run at S: every binding no hand holds ends."""
        if self.bound:  # (point controls bind nothing: a drag's every move)
            let_go = sorted(self.bound - self.held)
            if let_go:
                self._end(let_go, state)

    def end_all(self, state: SomState) -> None:
        """Every binding ends and every hold is let go (new weights, another group, a reset)."""
        self.held.clear()
        self.bound.clear()
        if self.live.any():
            self.live[:] = False
            self.live_dev.zero_()
            self.held_nodes.zero_()

    # -- device work --------------------------------------------------------------------------------------------
    def _slots(self, controls: Iterable[int]) -> np.ndarray:
        return np.array([c * self.order + g for c in controls for g in range(self.order)], np.int64)

    def _end(self, controls: list[int], state: SomState) -> None:
        slots = self._slots(controls)
        if not len(slots) or not self.live[slots].any():
            return
        self.live[slots] = False
        self.bound.difference_update(controls)
        self.live_dev.assign(self.live.astype(np.int32))
        if self.live.any():
            state.settle_anchor()
            self.reanchor(state)
        else:
            self.held_nodes.zero_()

    def _bind(self, state: SomState, at: Controls, radii: Controls, controls: list[int]) -> None:
        """Bind the members of `controls` where `at` has them, with the radii of `radii`: each one's winner, place and
        patch; then every anchor again."""
        model, kern, dev = self.model, self.kernels, self.model.device
        state.settle_anchor()
        slots = self._slots(controls)
        self._upload_radii(radii)
        self._uploaded = None  # (the members of the new controls still go up)
        self.probe.assign(members_of(at))
        self.keys.fill_(KEY_NONE)
        stretches = max(1, math.ceil(model.n_neurons / FIND_STRETCH))
        wp.launch(kern.find, dim=len(slots) * stretches, device=dev,
                  inputs=[state.w, self.probe, wp.array(slots.astype(np.int32), dtype=wp.int32, device=dev), model.m,
                          self.keys, stretches])
        binding = np.zeros(max(1, self.n_rows), np.int32)
        binding[self.row_of[slots]] = 1
        self.binding.assign(binding)
        wp.launch(kern.bind, dim=self.n_rows, device=dev, inputs=[self.slot_of_row, self.binding, self.keys, state.w,
                                                                  self.winners, self.places, self.starts, self.radius,
                                                                  self.reach, self.rebind])
        self.changed.fill_(1)
        self.bind_patches(state)
        self.live[slots] = True
        self.bound.update(controls)
        self.live_dev.assign(self.live.astype(np.int32))
        self.reanchor(state)

    def bind_patches(self, state: SomState) -> None:
        """The patches of the rows marked in `rebind`, from the weights now: seeded with their winners, then flooded
        while a round joins a node; one launch of a block a row (`flood_block`) on the CPU and on meshes of up to
        FLOOD_IN_BLOCKS_MOST nodes, else a launch a round in a conditional loop (changed[0] must be 1). Launched, or
        recorded into a captured graph."""
        model, kern, dev = self.model, self.kernels, self.model.device
        n = model.n_neurons
        if self.block_threads:
            threads = self.block_threads
            wp.launch(kern.flood_block, dim=self.n_rows * threads, block_dim=threads, device=dev,
                      inputs=[state.w, self.rebind, self.slot_of_row, self.winners, self.reach, self.position,
                              model.offsets, model.neighbors, self.patch])
            return
        rows = (self.n_rows, n)
        wp.launch(kern.seed, dim=rows, device=dev, inputs=[self.rebind, self.slot_of_row, self.winners, self.patch])

        def round_():
            wp.launch(clear_flag, dim=1, device=dev, inputs=[self.changed])
            wp.launch(kern.flood, dim=rows, device=dev,
                      inputs=[state.w, self.rebind, self.slot_of_row, self.winners, self.reach, self.position,
                              model.offsets, model.neighbors, self.patch, self.changed])

        wp.capture_while(self.changed, round_)

    def reanchor(self, state: SomState) -> None:
        """Every anchor from the weights now (launched, or recorded into a captured graph)."""
        wp.launch(self.kernels.reanchor, dim=max(self.model.n_neurons, len(self.live)), device=self.model.device,
                  inputs=[state.w, self.live_dev, self.winners, self.anchors, self.winner_anchors])

    def winners_now(self) -> np.ndarray:
        """(k G,) the winner of each live binding, -1 for the other slots."""
        out = np.full(len(self.live), -1, np.int64)
        if self.live.any():
            out[self.live] = self.winners.numpy()[self.live]
        return out
