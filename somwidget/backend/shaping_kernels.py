"""The shaping cycle's kernels: controls with a radius of influence, symmetry groups of any size and strokes
(shaping_path.py runs them; its smoothing steps, Taubin's pair among them, are smoothing_kernels.py's).

One cycle, as the algorithm's three steps, generic on the CPU and on CUDA (a thread per neuron or per control):
  1. `find`: u_c = argmin_v sum_j m_j (C_cj - W_vj)^2 for every effective control, from the weights before the
     cycle (a thread per control and stretch of neurons, an atomic min of winner keys); a control with a radius
     searches only at a restart's first cycle and then keeps the node it grabbed there (`hold`): it carries that
     node's region to the control, and a control that holds the clay still pulls back clay that slides under it
     (were it to take whichever node is nearest, clay sliding along the surface would bring it a new winner at no
     distance, and the clay it held would go unheld: BENCHMARKS.md, "The engine's shaping path"); `gather` keeps
     each winner's weights W_u (the move below must not read a winner that another thread already moved);
  2. `move`: each neuron applies the control groups in order (a group: a control and its symmetric copies, their
     rates from the same W_v, scaled by 1 / max(1, sum of rates) when the group has copies). A control of radius 0
     is the paper's: W_v += L[s, D[u, v]] (C - W_v). A control of radius r carries the clay around its winner:
     W_v += alpha(s) g(v) (C - W_u), g = exp(-|x_v - x_u|^2 / (2 sigma^2)) of the distance between v's and the
     winner's positions where the restart began (`rest`: the falloff keeps its shape while the region moves), 0 in
     another connected part of the mesh; so the region moves with the winner, falling off smoothly, and no node but
     the winner is drawn onto the control. sigma is r / 2, widened (`fit`, once a restart) where the control is
     so far from its winner that a bump that narrow would crease: the top of a bump of height h turns about
     h e / sigma^2 radians an edge of length e, held to FIT_TURN. A group of such controls is scaled by the sum of
     its falloffs g (two copies whose regions overlap move the nodes between them by their mean, not their sum); a
     stroke's samples (many, close together) move a node by their offsets' mean weighted by g, times the largest g:
     along the stroke each sample's region follows it as one control's would, and away from it the clay falls off
     as one sample's falloff does (dividing by the sum alone would leave a flat top with a steep wall). A group of
     carrying controls leaves node v as it is where alpha sum_j g_j(v) |C_j - W_u_j| (the most it could move v, in
     the largest dim) is below `floor` (CARRY_CUT of the start shape's size: under the rounding of its
     coordinates), so a drag touches only the nodes within reach of a control that moves (local_path.py skips the
     rest on the CPU; `balls` gives each control's reach);
  3. smoothing: smoothing_kernels.smooth_kernel, once a cycle, twice for Taubin's pair (lambda, then the negative
     mu that undoes the shrinking).
"""

import functools
from types import SimpleNamespace
from typing import Any

import warp as wp

from .local_kernels import BLOCK, SUPER, local_kernels
from .primitives import FLOAT_MAX, INDEX_MASK, UNREACHABLE, winner_key

#: Neurons one thread of `find` scans for one control.
FIND_STRETCH = 256
#: The most a carried bump's top may turn from one edge to the next (radians): 18 degrees, chosen by measurement
#: (BENCHMARKS.md, "Shaping rules": the sphere's own 11 degrees an edge plus this stay under 30).
FIT_TURN = wp.constant(0.3141592653589793)
#: A carrying group leaves a node as it is where the most it could move it in a cycle is below CARRY_CUT times the
#: start shape's size (its bounding diagonal): 2^-24, half of float32's epsilon.
CARRY_CUT = 2.0**-24
#: The balls of `balls` are drawn for a floor this much lower, and their squared radii widened by BALL_SLACK, so a
#: block outside every ball of a group holds no node the group moves, whatever float32 rounding does.
BALL_FLOOR_SHARE = 0.99
BALL_SLACK = wp.constant(wp.float32(1.001))


@wp.func
def row_of(distances: wp.array2d(dtype=wp.uint16), slot_of: wp.array(dtype=wp.int32), u: int) -> int:
    """The dense table's row of neuron u: its own."""
    return u


@wp.func
def row_of(distances: wp.array2d(dtype=wp.int32), slot_of: wp.array(dtype=wp.int32), u: int) -> int:  # noqa: F811
    """The cached distance row of neuron u (the path fetched every winner's row before the move)."""
    return slot_of[u]


@wp.func
def hops_at(distances: wp.array2d(dtype=wp.uint16), row: int, v: int) -> int:
    """D[u, v] from the dense table, -1 for unreachable."""
    d = distances[row, v]
    return wp.where(d != UNREACHABLE, wp.int32(d), -1)


@wp.func
def hops_at(distances: wp.array2d(dtype=wp.int32), row: int, v: int) -> int:  # noqa: F811 (overload)
    """D[u, v] from a cached distance row, -1 for unreachable (the path fetched every winner's row before)."""
    return distances[wp.max(row, 0), v]


@functools.cache
def shaping_kernels(n_dims: int) -> SimpleNamespace:
    """The shaping cycle's kernels for weights of n_dims features (compiled once per device on first use)."""
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)
    options = {"max_unroll": 32}
    moved_block = local_kernels(n_dims).moved_block

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def find(weights: wp.array(dtype=vec), controls: wp.array(dtype=vec), metric: wp.array(dtype=vec),
             keys: wp.array(dtype=wp.uint64), stretches: int):
        """Step 1, a thread per (control, stretch of FIND_STRETCH neurons): the stretch's nearest neuron (the lowest
        index on a tie) into keys[c] by atomic min."""
        tid = wp.tid()
        c = tid // stretches
        lo = (tid % stretches) * FIND_STRETCH
        hi = wp.min(lo + FIND_STRETCH, weights.shape[0])
        target = controls[c]
        m = metric[0]
        best = FLOAT_MAX
        best_v = lo
        for v in range(lo, hi):
            diff = target - weights[v]
            dist = wp.dot(wp.cw_mul(diff, m), diff)
            nearer = dist < best
            best = wp.where(nearer, dist, best)
            best_v = wp.where(nearer, v, best_v)
        wp.atomic_min(keys, c, winner_key(best, best_v))

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def hold(keys: wp.array(dtype=wp.uint64), grabbed: wp.array(dtype=wp.uint64), sigma: wp.array(dtype=wp.float32)):
        """After step 1 past a restart's first cycle: each carrying control (sigma > 0) keeps the winner it grabbed
        there; a point control keeps the winner just found."""
        j = wp.tid()
        if sigma[j] > wp.float32(0.0):
            keys[j] = grabbed[j]

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def gather(weights: wp.array(dtype=vec), keys: wp.array(dtype=wp.uint64), controls: wp.array(dtype=vec),
               winners: wp.array(dtype=vec), offsets: wp.array(dtype=wp.float32)):
        """Each control's winner's weights before the move, and how far the control lies from it (largest dim)."""
        c = wp.tid()
        w = weights[wp.int32(keys[c] & INDEX_MASK)]
        winners[c] = w
        apart = controls[c] - w
        largest = wp.float32(0.0)
        for i in range(wp.static(n_dims)):
            largest = wp.max(largest, wp.abs(apart[i]))
        offsets[c] = largest

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def fit(controls: wp.array(dtype=vec), winners: wp.array(dtype=vec), sigma: wp.array(dtype=wp.float32),
            edge: wp.float32, position: vec, inv_two_sigma2: wp.array(dtype=wp.float32)):
        """At a restart, each carrying control's falloff: sigma widened so that its bump's top turns at most
        FIT_TURN an edge for the control's distance h from its winner; 0 stays 0 (a point control)."""
        j = wp.tid()
        s0 = sigma[j]
        if s0 > wp.float32(0.0):
            apart = wp.cw_mul(controls[j] - winners[j], position)
            width = wp.max(s0, wp.sqrt(wp.length(apart) * edge / wp.float32(FIT_TURN)))
            inv_two_sigma2[j] = wp.float32(1.0) / (wp.float32(2.0) * width * width)
        else:
            inv_two_sigma2[j] = wp.float32(0.0)

    @wp.func
    def moved_by_group(w: vec, v: int, lo: int, hi: int, stroke: int, rest: wp.array(dtype=vec),
                       controls: wp.array(dtype=vec), winners: wp.array(dtype=vec), keys: wp.array(dtype=wp.uint64),
                       inv_two_sigma2: wp.array(dtype=wp.float32), offsets: wp.array(dtype=wp.float32),
                       component: wp.array(dtype=wp.int32), table: wp.array2d(dtype=wp.float32), s: int,
                       distances: Any, slot_of: wp.array(dtype=wp.int32), position: vec, floor: wp.float32) -> vec:
        """Step 2 of one group (members lo .. hi - 1) for neuron v of weights w (see the module's docstring)."""
        alpha = table[s, 0]
        last = table.shape[1] - 1
        step = vec()
        total = wp.float32(0.0)
        nearest = wp.float32(0.0)
        carried = wp.float32(0.0)  # sum of falloff x offset: alpha times it bounds the carrying members' step
        pulled = int(0)  # a point member with a rate
        for j in range(lo, hi):
            u = wp.int32(keys[j] & INDEX_MASK)
            k = inv_two_sigma2[j]
            if k == wp.float32(0.0):  # the paper's point control: towards the control
                d = hops_at(distances, row_of(distances, slot_of, u), v)
                if d >= 0:
                    rate = table[s, wp.min(d, last)]
                    step += rate * (controls[j] - w)
                    total += rate
                    pulled = wp.where(rate > wp.float32(0.0), 1, pulled)
            elif component[u] == component[v]:  # a control with a radius: along with its winner
                apart = wp.cw_mul(rest[v] - rest[u], position)
                falloff = wp.exp(-k * wp.dot(apart, apart))
                step += (alpha * falloff) * (controls[j] - winners[j])
                total += falloff
                nearest = wp.max(nearest, falloff)
                carried += falloff * offsets[j]
        if pulled == 0 and alpha * carried < floor:
            return w
        if stroke != 0:
            if total > wp.float32(0.0):
                step = step * (nearest / total)
        elif hi - lo > 1:
            step = step / wp.max(wp.float32(1.0), total)
        return w + step

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def move(
        weights: wp.array(dtype=vec),
        rest: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        winners: wp.array(dtype=vec),
        keys: wp.array(dtype=wp.uint64),
        inv_two_sigma2: wp.array(dtype=wp.float32),
        offsets: wp.array(dtype=wp.float32),
        component: wp.array(dtype=wp.int32),
        group_start: wp.array(dtype=wp.int32),
        stroke: wp.array(dtype=wp.int32),
        n_groups: int,
        table: wp.array2d(dtype=wp.float32),
        s: int,
        distances: Any,
        slot_of: wp.array(dtype=wp.int32),
        position: vec,
        floor: wp.float32,
    ):
        """Step 2 for neuron v, group after group, in place: v reads only its own weights and the gathered
        winners."""
        v = wp.tid()
        w = weights[v]
        for g in range(n_groups):
            w = moved_by_group(w, v, group_start[g], group_start[g + 1], stroke[g], rest, controls, winners, keys,
                               inv_two_sigma2, offsets, component, table, s, distances, slot_of, position, floor)
        weights[v] = w

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def balls(inv_two_sigma2: wp.array(dtype=wp.float32), offsets: wp.array(dtype=wp.float32),
              group_of: wp.array(dtype=wp.int32), group_start: wp.array(dtype=wp.int32),
              table: wp.array2d(dtype=wp.float32), s: int, floor: wp.float32, radius2: wp.array(dtype=wp.float32)):
        """Each carrying control's reach this cycle: the squared distance (in rest positions) beyond which alpha g
        |C - W_u| falls below floor / (its group's size), so that no node outside every ball of a group is moved by
        it; -1 for none (a control at its winner moves nothing), 0 for a point control (rows tell its reach)."""
        j = wp.tid()
        k = inv_two_sigma2[j]
        radius2[j] = wp.float32(0.0)
        if k > wp.float32(0.0):
            g = group_of[j]
            size = wp.float32(group_start[g + 1] - group_start[g])
            ratio = table[s, 0] * offsets[j] * size / (floor * wp.float32(BALL_FLOOR_SHARE))
            radius2[j] = wp.where(ratio > wp.float32(1.0), BALL_SLACK * wp.log(ratio) / k, wp.float32(-1.0))

    @wp.func
    def touches(b: int, lo: int, hi: int, rest: wp.array(dtype=vec), rest_lo: wp.array(dtype=vec),
                rest_hi: wp.array(dtype=vec), keys: wp.array(dtype=wp.uint64), radius2: wp.array(dtype=wp.float32),
                near: wp.array2d(dtype=wp.int32), slot_of: wp.array(dtype=wp.int32), reach: int, rows: int,
                position: vec) -> int:
        """1 when the group lo .. hi - 1 may move a neuron of block b (or superblock b, given the superblocks' boxes
        and least hop counts): a carrying member's ball meets the block's box of rest positions, or a point member's
        winner lies within reach of the block (always, for the dense table)."""
        for j in range(lo, hi):
            u = wp.int32(keys[j] & INDEX_MASK)
            r2 = radius2[j]
            if r2 == wp.float32(0.0):
                if rows == 0 or near[slot_of[u], b] <= reach:
                    return 1
            elif r2 > wp.float32(0.0):
                centre = rest[u]
                gap = wp.cw_mul(wp.max(wp.max(rest_lo[b] - centre, centre - rest_hi[b]), vec()), position)
                if wp.dot(gap, gap) <= r2:
                    return 1
        return 0

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def move_blocks(
        weights: wp.array(dtype=vec),
        rest: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        winners: wp.array(dtype=vec),
        keys: wp.array(dtype=wp.uint64),
        inv_two_sigma2: wp.array(dtype=wp.float32),
        offsets: wp.array(dtype=wp.float32),
        component: wp.array(dtype=wp.int32),
        group_start: wp.array(dtype=wp.int32),
        stroke: wp.array(dtype=wp.int32),
        n_groups: int,
        table: wp.array2d(dtype=wp.float32),
        s: int,
        distances: Any,
        slot_of: wp.array(dtype=wp.int32),
        position: vec,
        floor: wp.float32,
        radius2: wp.array(dtype=wp.float32),
        rest_lo: wp.array(dtype=vec),
        rest_hi: wp.array(dtype=vec),
        rest_super_lo: wp.array(dtype=vec),
        rest_super_hi: wp.array(dtype=vec),
        near: wp.array2d(dtype=wp.int32),
        super_near: wp.array2d(dtype=wp.int32),
        reach: int,
        rows: int,
        lo_box: wp.array(dtype=vec),
        hi_box: wp.array(dtype=vec),
        super_lo: wp.array(dtype=vec),
        super_hi: wp.array(dtype=vec),
        moved_blocks: wp.array(dtype=wp.int32),
        moved_supers: wp.array(dtype=wp.int32),
        sb_lo: int,
        sb_hi: int,
    ):
        """`move` on the CPU for the blocks of superblocks sb_lo .. sb_hi - 1, a group at a time over each block's
        neurons, skipping the superblocks and blocks a group cannot move (`touches`, with the boxes of their rest
        positions); then the moved blocks' boxes (local_kernels' moved_block)."""
        n = weights.shape[0]
        n_blocks = lo_box.shape[0]
        for sb in range(sb_lo, sb_hi):
            reached = int(0)
            for g in range(n_groups):
                if reached == 0:
                    reached = touches(sb, group_start[g], group_start[g + 1], rest, rest_super_lo, rest_super_hi, keys,
                                      radius2, super_near, slot_of, reach, rows, position)
            if reached == 0:
                continue
            for b in range(sb * SUPER, wp.min(sb * SUPER + SUPER, n_blocks)):
                moved = int(0)
                for g in range(n_groups):
                    lo = group_start[g]
                    hi = group_start[g + 1]
                    if touches(b, lo, hi, rest, rest_lo, rest_hi, keys, radius2, near, slot_of, reach, rows,
                               position):
                        moved = 1
                        k = inv_two_sigma2[lo]
                        if hi - lo == 1 and k > wp.float32(0.0):  # one carrying control: moved_by_group's terms
                            u = wp.int32(keys[lo] & INDEX_MASK)
                            alpha = table[s, 0]
                            centre = rest[u]
                            part = component[u]
                            offset = controls[lo] - winners[lo]
                            largest = offsets[lo]
                            for v in range(b * BLOCK, wp.min(b * BLOCK + BLOCK, n)):
                                if component[v] == part:
                                    apart = wp.cw_mul(rest[v] - centre, position)
                                    falloff = wp.exp(-k * wp.dot(apart, apart))
                                    if alpha * (falloff * largest) >= floor:
                                        weights[v] = weights[v] + (alpha * falloff) * offset
                        else:
                            for v in range(b * BLOCK, wp.min(b * BLOCK + BLOCK, n)):
                                weights[v] = moved_by_group(weights[v], v, lo, hi, stroke[g], rest, controls, winners,
                                                            keys, inv_two_sigma2, offsets, component, table, s,
                                                            distances, slot_of, position, floor)
                if moved != 0:
                    moved_block(weights, lo_box, hi_box, super_lo, super_hi, moved_blocks, moved_supers, b)

    for source in (wp.array2d(dtype=wp.uint16), wp.array2d(dtype=wp.int32)):
        wp.overload(move, {"distances": source})
        wp.overload(move_blocks, {"distances": source})
    return SimpleNamespace(vec=vec, find=find, hold=hold, gather=gather, fit=fit, move=move, balls=balls,
                           move_blocks=move_blocks)
