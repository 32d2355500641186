"""The shaping cycle: handles (controls with a radius, handles.py), symmetry groups beyond a mirrored pair and
Taubin's smoothing, in the kernels of shaping_kernels.py. A Som takes this path whenever one of them is in use
(Controls.shaping); with point controls, no symmetry or a mirror, and the paper's Laplacian step, it takes the
paper's paths and gives their results bit for bit.

A run of cycles is captured as a graph (on the CPU too, where Warp replays it without Python) and replayed: a cycle
is the point members' search and move (when there are point controls), the handles' step, binding again and carry
(when a binding lives; on the CPU and meshes of up to handles.FLOOD_IN_BLOCKS_MOST nodes the step, the flood and the
anchors are one launch of a block a handle row, `step_block`, so a cycle is two launches; on bigger meshes binding
again is a conditional node holding a conditional loop of a launch a round),
and the smoothing of the free nodes with the volume put back and the clamp (with smoothing). With nothing but
handles, the run is one conditional loop, whatever its length (the carry counts the cycles on the device), that stops
after the first cycle at whose end every place is on its member, as every later cycle would carry to the same places
(a drag frame's move within a quarter radius: one cycle). The cycle s
reaches the point members' move through a device counter (two, passed on in turn), so one graph serves every s. Past
the dense table, point members need their winners' distance rows fetched by the host each cycle: those cycles are
launched one by one.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .closed_parts import closed_parts, no_closed_parts
from .cycle_kernels import LONGEST_GRAPH
from .handles import TAUBIN_MOST, Handles
from .shaping_kernels import FIND_STRETCH
from .smoothing_kernels import smoothing_steps
from .som_controls import Controls
from .som_model import SomModel, mask_of
from .som_schedule import SomSchedule
from .som_state import KEY_NONE, Graphs, SomState


def capped_steps(schedule: SomSchedule) -> list[float]:
    """The strengths of a cycle's smoothing steps, Taubin's lambda capped at handles.TAUBIN_MOST."""
    strength = schedule.values.smoothing
    if schedule.rule == "taubin":
        strength = min(strength, TAUBIN_MOST)
    return smoothing_steps(strength, schedule.rule)


class ShapingPath:
    """The shaping cycle of one Som: its handles (`handles`), the closed parts whose volume the smoothing keeps, the
    counters, and the captured runs."""

    def __init__(self, model: SomModel):
        self.model = model
        self.handles = Handles(model)
        self.graphs = Graphs(model.device)
        self.captured = model.device == "cpu" or wp.is_conditional_graph_supported()
        self.counter = wp.zeros(2, dtype=wp.int32, device=model.device)
        self.left = wp.zeros(1, dtype=wp.int32, device=model.device)  # a carry-only run's cycles left ...
        self.going = wp.zeros(1, dtype=wp.int32, device=model.device)  # ... and whether it goes on
        self._counter_s: int | None = None  # the s counter[parity] holds (None: unknown)
        self._parity = 0
        self._setup: tuple | None = None
        self._parts = None
        self._planned: tuple | None = None  # (controls, schedule, plan): most_cycles's, for the run that follows

    def forget(self) -> None:
        """Drop the captured graphs (the learning table they hold is made again)."""
        self.graphs.clear()
        self._setup = None

    def _closed(self):
        """The closed parts on the device (measured on first use; none below three feature dims)."""
        if self._parts is None:
            model = self.model
            parts = closed_parts(model.topology) if model.n_dims >= 3 else no_closed_parts(model.n_neurons)
            self._parts = parts.on(model.device)
            self.sums = wp.zeros(max(1, 3 * parts.count), dtype=wp.float64, device=model.device)
            self.gradient = wp.zeros(model.n_neurons, dtype=wp.vec3d, device=model.device)
        return self._parts

    # -- a run ------------------------------------------------------------------------------------------------------
    def _plan(self, controls: Controls, schedule: SomSchedule) -> tuple:
        """(point members, a live binding, the smoothing steps, Taubin's rule) of a run of these controls (whose
        members and radii are staged first, to go up with the run's `send`); the plan `most_cycles` made just
        before, when it was for these controls and this schedule."""
        planned, self._planned = self._planned, None
        if planned is not None and planned[0] is controls and planned[1] is schedule:
            return planned[2]
        h = self.handles
        h.upload(controls, send=False)
        steps = capped_steps(schedule)
        return len(h.point_slots) > 0, bool(h.live.any()), tuple(steps), schedule.rule == "taubin" and bool(steps)

    def most_cycles(self, controls: Controls, schedule: SomSchedule) -> int | None:
        """The most cycles one `run` takes: any number (None) for a run of nothing but handles (one graph for every
        length: a conditional loop that counts its cycles on the device), else cycle_kernels.LONGEST_GRAPH. (Som.step
        asks it right before the run, which takes its plan.)"""
        plan = self._plan(controls, schedule)
        self._planned = (controls, schedule, plan)
        points, live, steps, _ = plan
        return None if live and not points and not steps and self.captured else LONGEST_GRAPH

    def run(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule, cycles: int) -> None:
        """`cycles` cycles from s of the shaping rules."""
        state.settle_anchor()
        h = self.handles
        plan = self._plan(controls, schedule)
        points, live, steps, taubin = plan
        if taubin:
            self._closed()  # (made before a capture: a graph must not allocate)
        if points and self._counter_s != state.s:
            self.counter.assign(np.array([state.s, state.s], np.int32))
            self._counter_s, self._parity = state.s, 0
        if live and not points and not steps:
            h.stage_cycles(cycles)  # (the carry-only loop's count, sent with the members: one graph for every length)
            cycles_key = 0
        else:
            cycles_key = cycles
        h.send()
        if points or live or steps:
            if self.captured and not (model.rows and points):
                setup = (h.version, schedule.version, model.smooth_dims)
                if setup != self._setup:
                    self.graphs.clear()
                    self._setup = setup
                graph = self.graphs.get((cycles_key, self._parity, *plan), lambda: self._record(
                    model, state, schedule, cycles, self._parity, plan, fetch=False))
                wp.capture_launch(graph)
            else:
                self._record(model, state, schedule, cycles, self._parity, plan, fetch=model.rows and points)
        if points:
            self._parity = (self._parity + cycles) % 2
            self._counter_s = state.s + cycles
        state.s += cycles
        state.weights_replaced()
        state.winners_valid = False

    def _record(self, model: SomModel, state: SomState, schedule: SomSchedule, cycles: int, parity: int, plan: tuple,
                fetch: bool) -> None:
        """The launches of `cycles` cycles (captured, or run at once); `fetch`: the point winners' distance rows
        fetched by the host before each move (distance rows mode, never captured)."""
        points, live, steps, taubin = plan
        h, kern, dev, n = self.handles, self.handles.kernels, model.device, model.n_neurons
        pulls = [model.vec(*(strength * mask_of(model.smooth_dims, model.n_dims)).tolist()) for strength in steps]
        parts = self._closed() if taubin else None
        volume = parts is not None and parts.count > 0
        stretches = max(1, math.ceil(n / FIND_STRETCH))
        if live and not points and not steps:  # carry only: the cycles after the places arrived change nothing
            wp.launch(kern.count_from, dim=1, device=dev, inputs=[h.cycles, self.left, self.going])

            def cycle() -> None:
                self._step_places(model, state)
                self._carry(model, state, counting=True)

            wp.capture_while(self.going, cycle)
            return
        for i in range(cycles):
            if points:
                h.keys.fill_(KEY_NONE)
                wp.launch(kern.find, dim=len(h.point_slots) * stretches, device=dev,
                          inputs=[state.w, h.members, h.point_slot_list, model.m, h.keys, stretches])
                if fetch:
                    self._fetch(model, schedule, state.s + i)
                wp.launch(kern.move_points, dim=n, device=dev,
                          inputs=[state.w, h.members, h.keys, h.point_controls, h.order, schedule.table, self.counter,
                                  (parity + i) % 2, model.distances, model.slot_of])
            if live:
                self._step_places(model, state)
                self._carry(model, state)
            if steps:
                self._smooth(model, state, pulls, parts if volume else None, taubin)

    def _step_places(self, model: SomModel, state: SomState) -> None:
        """Step 3 (a): each live binding's place steps after its member, and the patches that stepped are bound again
        (a conditional node); where a patch is bound in one launch, all of it in one (`step_block`)."""
        h = self.handles
        if h.block_threads:
            wp.launch(h.kernels.step_block, dim=h.n_rows * h.block_threads, block_dim=h.block_threads,
                      device=model.device,
                      inputs=[h.slot_of_row, h.live_dev, h.members, h.radius, h.position, h.places, h.starts, h.reach,
                              h.winners, state.w, model.offsets, model.neighbors, h.patch, h.anchors,
                              h.winner_anchors, h.unarrived, h.claim])
            return
        wp.launch(h.kernels.advance, dim=h.n_rows, device=model.device,
                  inputs=[h.slot_of_row, h.live_dev, h.members, h.radius, h.position, h.places, h.starts, h.reach,
                          h.rebind, h.stepped, h.changed, h.unarrived])

        def bind_again() -> None:
            h.bind_patches(state)
            h.reanchor(state)

        wp.capture_if(h.stepped, bind_again)

    def _carry(self, model: SomModel, state: SomState, counting: bool = False) -> None:
        """Step 3 (b): every held node onto its target (clears `stepped` for the next cycle); `counting`: in a
        carry-only run's loop, the cycle counted and whether the loop goes on."""
        h = self.handles
        wp.launch(h.kernels.carry, dim=model.n_neurons, device=model.device,
                  inputs=[h.slot_of_row, h.group_start, h.live_dev, h.patch, h.places, h.winner_anchors, h.anchors,
                          state.w, h.held_nodes, h.stepped, h.unarrived, h.claim, h.box, int(counting), self.left,
                          self.going])

    def _smooth(self, model: SomModel, state: SomState, pulls: list, parts, taubin: bool) -> None:
        """Step 4: the smoothing steps on the free nodes; with Taubin's rule the volume of each closed part put back
        (`parts`) and the clamp into the box."""
        h, kern, dev, n = self.handles, self.handles.kernels, model.device, model.n_neurons
        if parts is not None:
            self.sums.zero_()
            wp.launch(kern.part_volumes, dim=parts.n_triangles, device=dev,
                      inputs=[state.w, parts.triangles, parts.triangle_part, self.sums, 0])
        pair = (state.w, state.w_moved)
        for i, pull in enumerate(pulls):
            wp.launch(kern.smooth_free, dim=n, device=dev,
                      inputs=[pair[i % 2], pair[1 - i % 2], model.offsets, model.neighbors, pull, h.held_nodes])
        if len(pulls) % 2:
            wp.launch(kern.copy_weights, dim=n, device=dev, inputs=[state.w_moved, state.w])
        if not taubin:
            return
        closed = self._closed()
        if parts is not None:
            wp.launch(kern.part_volumes, dim=parts.n_triangles, device=dev,
                      inputs=[state.w, parts.triangles, parts.triangle_part, self.sums, parts.count])
            wp.launch(kern.volume_gradient, dim=n, device=dev,
                      inputs=[state.w, parts.node_part, h.held_nodes, parts.triangle_offsets, parts.triangles_of,
                              parts.triangles, self.gradient, self.sums, 2 * parts.count])
        wp.launch(kern.put_back, dim=n, device=dev,
                  inputs=[state.w, closed.node_part, h.held_nodes, self.gradient, self.sums, closed.count, h.box])

    def _fetch(self, model: SomModel, schedule: SomSchedule, s: int) -> None:
        """Distance rows mode: the rows of the point members' winners, fetched as deep as cycle s reaches."""
        h = self.handles
        keys = h.keys.numpy()[h.point_slots]
        winners = (keys & np.uint64(0xFFFFFFFF)).astype(np.int64)
        reach = int(schedule.reach_hops[s]) if schedule.reach_hops is not None else schedule.d_max
        model.row_cache().fetch(list(dict.fromkeys(winners.tolist())), reach)

    # -- winners ----------------------------------------------------------------------------------------------------
    def winners(self, model: SomModel, state: SomState, controls: Controls, schedule: SomSchedule) -> np.ndarray:
        """(k_eff,) in the order of `Controls.effective`: a live binding's winner, else the nearest node now."""
        state.settle_anchor()
        h = self.handles
        h.upload(controls)
        slots = len(h.live)
        stretches = max(1, math.ceil(model.n_neurons / FIND_STRETCH))
        h.keys.fill_(KEY_NONE)
        every = wp.array(np.arange(slots, dtype=np.int32), dtype=wp.int32, device=model.device)
        wp.launch(h.kernels.find, dim=slots * stretches, device=model.device,
                  inputs=[state.w, h.members, every, model.m, h.keys, stretches])
        found = (h.keys.numpy() & np.uint64(0xFFFFFFFF)).astype(np.int64)
        bound = h.winners_now()
        found = np.where(bound >= 0, bound, found)
        k = len(controls.values)
        out = np.empty_like(found)
        slot = np.arange(slots)
        out[(slot % h.order) * k + slot // h.order] = found
        return out
