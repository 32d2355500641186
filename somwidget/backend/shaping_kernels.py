"""The shaping cycle's kernels: handles (controls with a radius, bound at a grab), point controls with symmetry groups
of any size, smoothing of the free nodes with the volume of every closed part put back (shaping_path.py runs them;
DESIGN.md "Handles"; tests/reference_handles.py states the rule in float64).

Slot j = c G + g is member g of control c (M_g C_c, G the group's order); a control of radius r > 0 has a row of its
own in `patch` (R, N) for each member: the member's binding, -1 where a node is not bound. One cycle s:
  1. `find` (point members only): u_j = argmin_v sum_i m_i (C_ji - W_vi)^2 from the weights before the cycle (a thread
     per member and stretch of FIND_STRETCH neurons, an atomic min of winner keys: the lowest index on a tie);
  2. `move_points`: each point control and its copies in control order, W_v += L[s, D[u, v]] (C - W_v), a group's
     rates from the same W_v and scaled by 1 / max(1, their sum) when it has copies;
  3. the handles: `advance` steps each live binding's place p towards its member by at most STEP r (the straight
     length on the position dims), takes its reach R = max(r, WIDEN |p - p(grab)|) and marks it for binding again;
     then, if any moved, `seed` and `flood` (repeated while it joins a node; `flood_block` does both in one launch)
     bind the patch again: the nodes joined to the winner u through nodes whose straight distance from W_u is below
     R, each weighted w = (1 - t^2)^2, t = |W_v - W_u| / R; and `reanchor` takes every anchor again (A_v = W_v,
     a_u = W_u). `step_block` does all of step 3 (a) in one launch, a block a handle row, where `flood_block`
     binds (the CPU, meshes of up to handles.FLOOD_IN_BLOCKS_MOST nodes). `carry` puts every bound node on its
     target T_v = A_v + (1 - prod_b (1 - w_bv)) sum_b w_bv (p_b - a_u,b) / sum_b w_bv, clamped into the box grown by
     the radius alone (box[2], box[3]: a patch wider than r could carry its rim out of it);
  4. `smooth_free`: lambda's (and with Taubin's rule mu's) Jacobi step of the uniform Laplacian on the nodes no binding
     holds; with Taubin's rule `part_volumes` before and after, `volume_gradient` and `put_back` move the free nodes
     of each closed part along the volume's gradient by what the steps took, then clamp every node into the box.
"""

import functools
from types import SimpleNamespace
from typing import Any

import warp as wp

from .primitives import FLOAT_MAX, INDEX_MASK, UNREACHABLE, sync_block_any, winner_key
from .smoothing_kernels import smoothed

#: Neurons one thread of `find` scans for one member.
FIND_STRETCH = 256
#: A binding steps towards its member by at most this share of its radius a cycle, and binds again at each step.
STEP = wp.constant(wp.float32(0.25))
#: A binding carried farther than half its radius binds a patch this many times as wide as it has been carried (its
#: reach, never less than the radius; tests/reference_handles.py WIDEN): a lift taller than the radius rolls instead
#: of standing up in a step with a crease at its foot (BENCHMARKS.md, "A lift taller than its radius").
WIDEN = wp.constant(wp.float32(2.0))
#: `flood_block` marks a node inside the ball that is not bound (yet) with this (a node not bound is -1 after it).
INSIDE = wp.constant(wp.float32(-2.0))


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


@wp.func
def falloff(d: wp.float32, r: wp.float32) -> wp.float32:
    """(1 - t^2)^2 of t = d / r: 1 at the winner, flat there and at the rim."""
    t = d / r
    q = wp.float32(1.0) - t * t
    return q * q


@wp.func
def corner(w: Any) -> wp.vec3d:
    """A node's position (dims 0, 1, 2) in float64, for the volumes."""
    return wp.vec3d(wp.float64(w[0]), wp.float64(w[1]), wp.float64(w[2]))


@wp.kernel(enable_backward=False)
def clear_flag(flag: wp.array(dtype=wp.int32)):
    """flag[0] = 0, as a kernel: a conditional node's body holds kernels (a memset there needs a newer CUDA)."""
    flag[0] = 0


@functools.cache
def shaping_kernels(n_dims: int) -> SimpleNamespace:
    """The shaping cycle's kernels for weights of n_dims features (compiled once per device on first use)."""
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)
    options = {"max_unroll": 32}

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def find(weights: wp.array(dtype=vec), members: wp.array(dtype=vec), slots: wp.array(dtype=wp.int32),
             metric: wp.array(dtype=vec), keys: wp.array(dtype=wp.uint64), stretches: int):
        """Step 1, a thread per (listed slot, stretch of FIND_STRETCH neurons): the stretch's nearest neuron to the
        slot's member (the lowest index on a tie) into keys[slot] by atomic min (keys cleared before)."""
        tid = wp.tid()
        j = slots[tid // stretches]
        lo = (tid % stretches) * FIND_STRETCH
        hi = wp.min(lo + FIND_STRETCH, weights.shape[0])
        target = members[j]
        m = metric[0]
        best = FLOAT_MAX
        best_v = lo
        for v in range(lo, hi):
            diff = target - weights[v]
            dist = wp.dot(wp.cw_mul(diff, m), diff)
            nearer = dist < best
            best = wp.where(nearer, dist, best)
            best_v = wp.where(nearer, v, best_v)
        wp.atomic_min(keys, j, winner_key(best, best_v))

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def move_points(weights: wp.array(dtype=vec), members: wp.array(dtype=vec), keys: wp.array(dtype=wp.uint64),
                    point_controls: wp.array(dtype=wp.int32), order: int, table: wp.array2d(dtype=wp.float32),
                    counter: wp.array(dtype=wp.int32), parity: int, distances: Any, slot_of: wp.array(dtype=wp.int32)):
        """Step 2 for neuron v: each point control's group in control order (s = counter[parity]; thread 0 passes
        s + 1 on in counter[1 - parity])."""
        v = wp.tid()
        s = counter[parity]
        last = table.shape[1] - 1
        w = weights[v]
        for i in range(point_controls.shape[0]):
            first = point_controls[i] * order
            step = vec()
            total = wp.float32(0.0)
            for j in range(first, first + order):
                u = wp.int32(keys[j] & INDEX_MASK)
                d = hops_at(distances, row_of(distances, slot_of, u), v)
                if d >= 0:
                    rate = table[s, wp.min(d, last)]
                    step += rate * (members[j] - w)
                    total += rate
            if order > 1:
                step = step / wp.max(wp.float32(1.0), total)
            w = w + step
        weights[v] = w
        if v == 0:
            counter[1 - parity] = s + 1

    @wp.func
    def differs(a: vec, b: vec) -> int:
        """1 where a and b differ in any feature, else 0."""
        out = int(0)
        for i in range(wp.static(n_dims)):
            if a[i] != b[i]:
                out = 1
        return out

    @wp.func
    def place_step(m: vec, p: vec, r: wp.float32, position: vec) -> vec:
        """A binding's place p one step towards its member m: onto it when within STEP r (over the position
        features), else STEP r along the way."""
        gap = wp.length(wp.cw_mul(m - p, position))
        most = STEP * r
        if gap <= most:
            return m
        return p + (m - p) * (most / gap)

    @wp.func
    def reach_of(p: vec, start: vec, r: wp.float32, position: vec) -> wp.float32:
        """The reach of a binding whose place went from `start` to p: its radius r, widened to WIDEN times the way."""
        return wp.max(r, WIDEN * wp.length(wp.cw_mul(p - start, position)))

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def advance(slot_of_row: wp.array(dtype=wp.int32), live: wp.array(dtype=wp.int32),
                members: wp.array(dtype=vec), radius: wp.array(dtype=wp.float32), position: vec,
                places: wp.array(dtype=vec), starts: wp.array(dtype=vec), reach: wp.array(dtype=wp.float32),
                rebind: wp.array(dtype=wp.int32), stepped: wp.array(dtype=wp.int32),
                changed: wp.array(dtype=wp.int32), unarrived: wp.array(dtype=wp.int32)):
        """Step 3 (a) for handle row r: a live binding whose place differs from its member steps towards it by at
        most STEP r, takes the reach max(r, WIDEN |p - p(grab)|) and is marked for binding again (rebind[r];
        stepped and changed set, both 0 before; unarrived set when the step stops short of the member)."""
        r = wp.tid()
        j = slot_of_row[r]
        rebind[r] = 0
        if live[j] != 0:
            m = members[j]
            if differs(m, places[j]) != 0:
                p = place_step(m, places[j], radius[j], position)
                if differs(m, p) != 0:
                    unarrived[0] = 1
                places[j] = p
                reach[j] = reach_of(p, starts[j], radius[j], position)
                rebind[r] = 1
                stepped[0] = 1
                changed[0] = 1

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def bind(slot_of_row: wp.array(dtype=wp.int32), binding: wp.array(dtype=wp.int32), keys: wp.array(dtype=wp.uint64),
             weights: wp.array(dtype=vec), winners: wp.array(dtype=wp.int32), places: wp.array(dtype=vec),
             starts: wp.array(dtype=vec), radius: wp.array(dtype=wp.float32), reach: wp.array(dtype=wp.float32),
             rebind: wp.array(dtype=wp.int32)):
        """A grab, for handle row r marked in `binding`: the winner found for it (keys), its place and start that
        node's weights, its reach its radius, and a patch to bind (rebind[r]); the other rows are left as they
        are."""
        r = wp.tid()
        rebind[r] = 0
        if binding[r] != 0:
            j = slot_of_row[r]
            u = wp.int32(keys[j] & INDEX_MASK)
            winners[j] = u
            places[j] = weights[u]
            starts[j] = weights[u]
            reach[j] = radius[j]
            rebind[r] = 1

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def seed(rebind: wp.array(dtype=wp.int32), slot_of_row: wp.array(dtype=wp.int32),
             winners: wp.array(dtype=wp.int32), patch: wp.array2d(dtype=wp.float32)):
        """A patch to bind again: only its winner (weight 1), every other node unbound (-1)."""
        r, v = wp.tid()
        if rebind[r] != 0:
            patch[r, v] = wp.where(v == winners[slot_of_row[r]], wp.float32(1.0), wp.float32(-1.0))

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def flood(weights: wp.array(dtype=vec), rebind: wp.array(dtype=wp.int32), slot_of_row: wp.array(dtype=wp.int32),
              winners: wp.array(dtype=wp.int32), reach: wp.array(dtype=wp.float32), position: vec,
              offsets: wp.array(dtype=wp.int32), neighbors: wp.array(dtype=wp.int32),
              patch: wp.array2d(dtype=wp.float32), changed: wp.array(dtype=wp.int32)):
        """One round of the patch's flood: a node inside the ball (straight distance from W_u below the binding's
        reach R, its radius widened by advance) next to a bound node is bound, weight falloff(d, R); changed[0] set
        when any is (cleared before). Bound is for good, so rounds that see a neighbour bound in the same round only
        reach the end sooner."""
        r, v = wp.tid()
        if rebind[r] != 0 and patch[r, v] < wp.float32(0.0):
            j = slot_of_row[r]
            d = wp.length(wp.cw_mul(weights[v] - weights[winners[j]], position))
            ball = reach[j]
            if d < ball:
                joined = int(0)
                for e in range(offsets[v], offsets[v + 1]):
                    if patch[r, neighbors[e]] >= wp.float32(0.0):
                        joined = 1
                if joined != 0:
                    patch[r, v] = falloff(d, ball)
                    changed[0] = 1

    @wp.func
    def flood_patch(weights: wp.array(dtype=vec), r: int, u: int, ball: wp.float32, t: int, threads: int,
                    position: vec, offsets: wp.array(dtype=wp.int32), neighbors: wp.array(dtype=wp.int32),
                    patch: wp.array2d(dtype=wp.float32)):
        """Row r's patch bound around winner u within `ball` by the `threads` threads of one block (thread t): the
        seed, then rounds behind a barrier until one joins no node (`flood_block`)."""
        n = patch.shape[1]
        centre = weights[u]
        for v in range(t, n, threads):
            inside = wp.length(wp.cw_mul(weights[v] - centre, position)) < ball
            patch[r, v] = wp.where(v == u, wp.float32(1.0), wp.where(inside, INSIDE, wp.float32(-1.0)))
        joining = int(1)
        while sync_block_any(joining) != 0:
            joining = int(0)
            for v in range(t, n, threads):
                if patch[r, v] == INSIDE:
                    joined = int(0)
                    for e in range(offsets[v], offsets[v + 1]):
                        if patch[r, neighbors[e]] >= wp.float32(0.0):
                            joined = 1
                    if joined != 0:
                        patch[r, v] = falloff(wp.length(wp.cw_mul(weights[v] - centre, position)), ball)
                        joining = int(1)
        for v in range(t, n, threads):
            if patch[r, v] == INSIDE:
                patch[r, v] = wp.float32(-1.0)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def flood_block(weights: wp.array(dtype=vec), rebind: wp.array(dtype=wp.int32),
                    slot_of_row: wp.array(dtype=wp.int32), winners: wp.array(dtype=wp.int32),
                    reach: wp.array(dtype=wp.float32), position: vec, offsets: wp.array(dtype=wp.int32),
                    neighbors: wp.array(dtype=wp.int32), patch: wp.array2d(dtype=wp.float32)):
        """`seed` and every round of `flood` in one launch, a block per handle row (its threads share the nodes out,
        a barrier between rounds, until a round joins no node): the same patch, since the flood's end (the nodes
        joined to u inside the ball) does not depend on the order nodes join in. On the CPU a block is one thread,
        whose rounds are sweeps in index order (a node joins in the sweep that reaches its neighbour). The seed marks
        the nodes inside the ball OUTSIDE (-2: a round looks at no other node and measures none again; a widened
        reach makes the patch deep, many rounds), and the last round's barrier is followed by those left marked set
        to -1."""
        i = wp.tid()
        threads = wp.block_dim()
        r = i // threads
        t = i - r * threads
        if r < patch.shape[0]:
            if rebind[r] != 0:
                j = slot_of_row[r]
                flood_patch(weights, r, winners[j], reach[j], t, threads, position, offsets, neighbors, patch)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def step_block(slot_of_row: wp.array(dtype=wp.int32), live: wp.array(dtype=wp.int32),
                   members: wp.array(dtype=vec), radius: wp.array(dtype=wp.float32), position: vec,
                   places: wp.array(dtype=vec), starts: wp.array(dtype=vec), reach: wp.array(dtype=wp.float32),
                   winners: wp.array(dtype=wp.int32), weights: wp.array(dtype=vec), offsets: wp.array(dtype=wp.int32),
                   neighbors: wp.array(dtype=wp.int32), patch: wp.array2d(dtype=wp.float32),
                   anchors: wp.array(dtype=vec), winner_anchors: wp.array(dtype=vec),
                   unarrived: wp.array(dtype=wp.int32), claim: wp.array(dtype=wp.int32)):
        """Step 3 (a) in one launch, a block per handle row (where `flood_block` binds): `advance`, then, when the
        row's place stepped, its patch bound again (`flood_patch`) and every anchor taken again (`reanchor`, by the
        first block whose row stepped: claim[0], 0 before, cleared by `carry`; the weights it reads no thread
        writes). Every thread of the block takes the step (the same values); thread 0 writes it after a barrier
        (once every thread has read the place)."""
        i = wp.tid()
        threads = wp.block_dim()
        r = i // threads
        t = i - r * threads
        if r < patch.shape[0]:
            j = slot_of_row[r]
            p = places[j]
            ball = wp.float32(0.0)
            moving = int(0)
            stops_short = int(0)
            if live[j] != 0:
                m = members[j]
                moving = differs(m, p)
                if moving != 0:
                    p = place_step(m, p, radius[j], position)
                    stops_short = differs(m, p)
                    ball = reach_of(p, starts[j], radius[j], position)
            if sync_block_any(moving) != 0:
                first = int(0)
                if t == 0:
                    places[j] = p
                    reach[j] = ball
                    if stops_short != 0:
                        unarrived[0] = 1
                    if wp.atomic_add(claim, 0, 1) == 0:
                        first = 1
                flood_patch(weights, r, winners[j], ball, t, threads, position, offsets, neighbors, patch)
                if sync_block_any(first) != 0:
                    for v in range(t, weights.shape[0], threads):
                        anchors[v] = weights[v]
                    for k in range(t, live.shape[0], threads):
                        if live[k] != 0:
                            winner_anchors[k] = weights[winners[k]]

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def reanchor(weights: wp.array(dtype=vec), live: wp.array(dtype=wp.int32), winners: wp.array(dtype=wp.int32),
                 anchors: wp.array(dtype=vec), winner_anchors: wp.array(dtype=vec)):
        """Every anchor taken again from the weights: A_v = W_v, and each live binding's a_u = W_u (a thread per
        node and per slot, whichever are more)."""
        i = wp.tid()
        if i < weights.shape[0]:
            anchors[i] = weights[i]
        if i < live.shape[0]:
            if live[i] != 0:
                winner_anchors[i] = weights[winners[i]]

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def count_from(cycles: wp.array(dtype=vec), left: wp.array(dtype=wp.int32), going: wp.array(dtype=wp.int32)):
        """A carry-only run's loop begins: its cycles (sent with the members, cycles[0][0]) left, and going."""
        left[0] = wp.int32(cycles[0][0])
        going[0] = 1

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def carry(slot_of_row: wp.array(dtype=wp.int32), group_start: wp.array(dtype=wp.int32),
              live: wp.array(dtype=wp.int32), patch: wp.array2d(dtype=wp.float32), places: wp.array(dtype=vec),
              winner_anchors: wp.array(dtype=vec), anchors: wp.array(dtype=vec), weights: wp.array(dtype=vec),
              held: wp.array(dtype=wp.int32), stepped: wp.array(dtype=wp.int32), unarrived: wp.array(dtype=wp.int32),
              claim: wp.array(dtype=wp.int32), box: wp.array(dtype=vec), counting: int, left: wp.array(dtype=wp.int32),
              going: wp.array(dtype=wp.int32)):
        """Step 3 (b) for node v: onto its target when a live binding holds it (held[v] = 1), else left (0); a group
        of rows (a stroke's samples, one copy) counts as one binding, its weight their largest, its displacement their
        weighted mean. Thread 0 clears `stepped`, `unarrived` and `claim` for the next cycle's step (read by then); with
        `counting`, a carry-only run's loop (shaping_path), it first counts the cycle: one fewer left (left[0]), and
        going[0] = 1 while a place stopped short of its member in it and cycles are left (once every place is on its
        member, the next cycle steps none, binds nothing again and carries every patch to where this one did: it and
        every later one change nothing, so the run stops here)."""
        v = wp.tid()
        if v == 0:
            if counting != 0:
                n = left[0] - 1
                left[0] = n
                going[0] = wp.where(unarrived[0] != 0 and n > 0, 1, 0)
            stepped[0] = 0
            unarrived[0] = 0
            claim[0] = 0
        num = vec()
        den = wp.float32(0.0)
        miss = wp.float32(1.0)
        for group in range(group_start.shape[0] - 1):
            lo = group_start[group]
            hi = group_start[group + 1]
            most = wp.float32(0.0)
            gnum = vec()
            gden = wp.float32(0.0)
            for r in range(lo, hi):
                j = slot_of_row[r]
                if live[j] != 0:
                    w = patch[r, v]
                    if w > wp.float32(0.0):
                        most = wp.max(most, w)
                        gnum += w * (places[j] - winner_anchors[j])
                        gden += w
            if gden > wp.float32(0.0):
                if hi - lo > 1:
                    gnum = gnum * (most / gden)
                num += gnum
                den += most
                miss *= wp.float32(1.0) - most
        if den > wp.float32(0.0):
            target = anchors[v] + num * ((wp.float32(1.0) - miss) / den)
            weights[v] = wp.max(box[2], wp.min(target, box[3]))
            held[v] = 1
        else:
            held[v] = 0

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def smooth_free(weights_in: wp.array(dtype=vec), weights_out: wp.array(dtype=vec),
                    offsets: wp.array(dtype=wp.int32), neighbors: wp.array(dtype=wp.int32), pull: vec,
                    held: wp.array(dtype=wp.int32)):
        """Step 4: one Jacobi step (pull = strength x the smooth dims' mask) of the nodes no binding holds."""
        v = wp.tid()
        if held[v] != 0:
            weights_out[v] = weights_in[v]
        else:
            weights_out[v] = smoothed(weights_in, v, offsets, neighbors, pull)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def part_volumes(weights: wp.array(dtype=vec), triangles: wp.array2d(dtype=wp.int32),
                     triangle_part: wp.array(dtype=wp.int32), sums: wp.array(dtype=wp.float64), at: int):
        """Each closed part's signed volume, sum of p0 . (p1 x p2) / 6 over its triangles, into sums[at + part]
        (cleared before; float64)."""
        t = wp.tid()
        a = corner(weights[triangles[t, 0]])
        b = corner(weights[triangles[t, 1]])
        c = corner(weights[triangles[t, 2]])
        wp.atomic_add(sums, at + triangle_part[t], wp.dot(a, wp.cross(b, c)) / wp.float64(6.0))

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def volume_gradient(weights: wp.array(dtype=vec), node_part: wp.array(dtype=wp.int32),
                        held: wp.array(dtype=wp.int32), triangle_offsets: wp.array(dtype=wp.int32),
                        triangles_of: wp.array(dtype=wp.int32), triangles: wp.array2d(dtype=wp.int32),
                        gradient: wp.array(dtype=wp.vec3d), sums: wp.array(dtype=wp.float64), at: int):
        """dV/dp_v of a free node of a closed part (sum over its triangles of p_next x p_prev / 6; 0 for the other
        nodes), and |dV/dp_v|^2 summed over each part's free nodes into sums[at + part]."""
        v = wp.tid()
        part = node_part[v]
        g = wp.vec3d()
        if part >= 0 and held[v] == 0:
            for e in range(triangle_offsets[v], triangle_offsets[v + 1]):
                t = triangles_of[e]
                i0 = triangles[t, 0]
                i1 = triangles[t, 1]
                i2 = triangles[t, 2]
                a = corner(weights[i0])
                b = corner(weights[i1])
                c = corner(weights[i2])
                if v == i0:
                    g += wp.cross(b, c)
                if v == i1:
                    g += wp.cross(c, a)
                if v == i2:
                    g += wp.cross(a, b)
            g = g / wp.float64(6.0)
            wp.atomic_add(sums, at + part, wp.dot(g, g))
        gradient[v] = g

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def put_back(weights: wp.array(dtype=vec), node_part: wp.array(dtype=wp.int32), held: wp.array(dtype=wp.int32),
                 gradient: wp.array(dtype=wp.vec3d), sums: wp.array(dtype=wp.float64), parts: int,
                 box: wp.array(dtype=vec)):
        """A free node of a closed part moved along dV/dp_v by (V - V') / sum |dV/dp|^2 (sums: the parts' volumes
        before, after, and the gradients' squares), then every node clamped into the box (box[0] .. box[1])."""
        v = wp.tid()
        w = weights[v]
        part = node_part[v]
        if part >= 0 and held[v] == 0:
            norm = sums[2 * parts + part]
            if norm > wp.float64(0.0):
                k = (sums[part] - sums[parts + part]) / norm
                g = gradient[v]
                w[0] = w[0] + wp.float32(k * g[0])
                w[1] = w[1] + wp.float32(k * g[1])
                w[2] = w[2] + wp.float32(k * g[2])
        weights[v] = wp.max(box[0], wp.min(w, box[1]))

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def copy_weights(source: wp.array(dtype=vec), dest: wp.array(dtype=vec)):
        v = wp.tid()
        dest[v] = source[v]

    for source in (wp.array2d(dtype=wp.uint16), wp.array2d(dtype=wp.int32)):
        wp.overload(move_points, {"distances": source})
    return SimpleNamespace(vec=vec, find=find, move_points=move_points, advance=advance, bind=bind, seed=seed,
                           flood=flood, flood_block=flood_block, step_block=step_block, reanchor=reanchor,
                           count_from=count_from, carry=carry,
                           smooth_free=smooth_free, part_volumes=part_volumes, volume_gradient=volume_gradient,
                           put_back=put_back, copy_weights=copy_weights)
