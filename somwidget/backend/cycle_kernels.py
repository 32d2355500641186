"""The cycle's kernels (som.py, The cycle): winner search, move and smoothing, per feature count n (a row
of weights is a Warp vector of length n), in two decompositions of the same cycle.

On CUDA a thread per neuron moves it, a thread per control scans each block of 32 neurons (their new weights shared
in the block) for the winners, and the whole cycle is one kernel (two with smoothing), launched dependent on the one
before where the GPU allows (dependent_launch.py); small meshes with up to 32 controls use spread_kernels.py. On
the CPU, where Warp runs a launch on one thread, each core replays its own graph: the neurons are split between the
cores for the move and smoothing, the controls for the winner search, with a spinning barrier between the phases.

Winner keys (primitives.winner_key) live in three rotating buffers indexed by s % 3: cycle s reads buffer s, fills
buffer s + 1 with the winners of the next cycle and clears buffer s + 2, so a whole run replays from a captured
graph with no host work. Past the dense table (distance rows mode) the same cycle reads int32 distance rows that
the host keeps for recent winners; a cycle whose winner has no row stalls (see `cycle_kernels`), and
distance_kernels.py computes rows on demand.
"""

import functools
from types import SimpleNamespace
from typing import Any

import warp as wp

from .primitives import FLOAT_MAX, INDEX_MASK, KEY_NONE, UNREACHABLE, wait_for_previous_grid, winner_key
from .smoothing_kernels import smoothed

#: Effective controls a cycle takes (originals plus mirrored copies): the winner keys' buffers hold this many.
MAX_CONTROLS = 256
#: Cycles in the longest captured graph; runs are split into powers of two.
LONGEST_GRAPH = 512
#: Threads per block on CUDA, a whole warp or more (the winner search shares the block's weights through a tile):
#: a thread per control scans the block's neurons.
CUDA_BLOCK = wp.constant(32)
#: Above this many neurons a block reads the current winner key before its atomic min (measured on an H200: the
#: 65,536-neuron cycle 14.4 -> 10.6 us; the extra read made the 602-neuron car slower, 5.8 -> 7.8 us).
CHECK_BEFORE_ATOMIC = wp.constant(2048)


@wp.func
def clear_keys(keys: wp.array2d(dtype=wp.uint64), buf: int, n_controls: int):
    for c in range(n_controls):
        keys[buf, c] = KEY_NONE


@wp.func
def pass_counter(keys: wp.array2d(dtype=wp.uint64), s: int, n_controls: int, cycle_out: wp.array(dtype=wp.int32),
                 find_next: int):
    """End of cycle s by one thread: with find_next the keys of cycle s + 2 cleared and the counter advanced to
    s + 1; without, the counter passed on unchanged (a later kernel of the cycle ends it)."""
    if find_next != 0:
        clear_keys(keys, (s + 2) % 3, n_controls)
        cycle_out[0] = s + 1
    else:
        cycle_out[0] = s


# -- D[u_c, v] and the rate L[s, D[u_c, v]], by where the distances live ---------------------------------------
# The cycle kernels are generic in their `distances` argument, with one overload per source: the dense table
# (uint16, 65535 = unreachable) or distance rows past it (int32, -1 = unreachable), the rows a host-side cache keeps
# for recent winners, found through slot_of (the row of each neuron, -1 = none). These functions are overloaded
# (Warp picks by the type of `distances`), so the dense kernels compile without the rows' lookups and stall checks.
@wp.func
def winner_row(distances: wp.array2d(dtype=wp.uint16), slot_of: wp.array(dtype=wp.int32),
               keys: wp.array2d(dtype=wp.uint64), buf: int, c: int) -> int:
    """The row of `distances` that holds D[u_c, .]: the winner's own row of the dense table."""
    return wp.int32(keys[buf, c] & INDEX_MASK)


@wp.func
def winner_row(distances: wp.array2d(dtype=wp.int32), slot_of: wp.array(dtype=wp.int32),  # noqa: F811 (overload)
               keys: wp.array2d(dtype=wp.uint64), buf: int, c: int) -> int:
    """The cache row holding the distances from control c's winner, -1 when it has none."""
    return slot_of[wp.int32(keys[buf, c] & INDEX_MASK)]


@wp.func
def row_missing(distances: wp.array2d(dtype=wp.uint16), row: int) -> int:
    """The dense table has every row: never missing."""
    return 0


@wp.func
def row_missing(distances: wp.array2d(dtype=wp.int32), row: int) -> int:  # noqa: F811 (overload)
    """1 for a winner without a cached row (row -1: the cycle must stall), else 0."""
    return wp.where(row < 0, 1, 0)


@wp.func
def rate_at(table: wp.array2d(dtype=wp.float32), s: int, distances: wp.array2d(dtype=wp.uint16), row: int,
            v: int) -> wp.float32:
    """L[s, D[u_c, v]] with D[u_c, .] = distances[row], and 0 for unreachable neurons (65535)."""
    d = distances[row, v]
    return wp.where(d != UNREACHABLE, table[s, wp.min(wp.int32(d), table.shape[1] - 1)], wp.float32(0.0))


@wp.func
def rate_at(table: wp.array2d(dtype=wp.float32), s: int, distances: wp.array2d(dtype=wp.int32),  # noqa: F811
            row: int, v: int) -> wp.float32:
    """L[s, D[u_c, v]] with D[u_c, .] = distances[row], and 0 for unreachable neurons (-1); a missing row
    (-1) reads row 0, whose rate the stalled cycle never applies."""
    d = distances[wp.max(row, 0), v]
    return wp.where(d >= 0, table[s, wp.clamp(d, 0, table.shape[1] - 1)], wp.float32(0.0))


@wp.func
def rows_missing(distances: wp.array2d(dtype=wp.uint16), slot_of: wp.array(dtype=wp.int32),
                 keys: wp.array2d(dtype=wp.uint64), buf: int, c_lo: int, c_hi: int) -> int:
    """The dense table has every row: never missing."""
    return 0


@wp.func
def rows_missing(distances: wp.array2d(dtype=wp.int32), slot_of: wp.array(dtype=wp.int32),  # noqa: F811 (overload)
                 keys: wp.array2d(dtype=wp.uint64), buf: int, c_lo: int, c_hi: int) -> int:
    """1 when a winner of the controls c_lo .. c_hi - 1 has no cached row (the cycle must stall), else 0."""
    missing = int(0)
    for c in range(c_lo, c_hi):
        missing = wp.max(missing, row_missing(distances, winner_row(distances, slot_of, keys, buf, c)))
    return missing


#: The two sources of distances a cycle kernel is compiled for (see `winner_row`).
DISTANCE_SOURCES = (wp.array2d(dtype=wp.uint16), wp.array2d(dtype=wp.int32))


#: How step 2 applies the controls (a compile-time choice of the kernels): one by one; in mirrored pairs whose two
#: rates never sum past 1 (every rate of the table is at most 0.5, as with l_start <= 0.5), where the scale
#: 1 / max(1, l1 + l2) is exactly 1 and is left out; in mirrored pairs that may need it.
SINGLES, PAIRS, SCALED_PAIRS = 0, 1, 2


@functools.cache
def cycle_kernels(n_dims: int, gather: int = 8, pairs: int = SINGLES) -> SimpleNamespace:
    """The cycle's kernels for weights with n_dims features (each compiled once, on first use per device); `move`
    looks up the rates of `gather` controls at once (a multiple of 8 up to 32).

    With `pairs` (PAIRS or SCALED_PAIRS) the controls come as mirrored pairs, each original next to its copy (slots 2i,
    2i + 1; the Som keeps them so on the device): `move` and `move_part` apply each pair at once (`move_pair`).

    `move` and `move_part` are generic in `distances` (the dense table or distance rows, see `winner_row`); each
    source has its own overload. In distance rows mode a cycle whose winners lack a row stalls: the move sets
    stalled[0] and leaves everything as it was, the later kernels of the graph see the flag and do nothing, and
    the host computes the missing rows and replays from that cycle. A cycle moves by controls c_lo .. c_hi - 1,
    so a cache smaller than the winner count can still run it in parts (each neuron applies the controls in
    order). The dense path passes slot_of and stalled too (a zero flag that nothing sets; slot_of unread).
    """
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)
    gathered = wp.types.vector(length=gather, dtype=wp.float32)
    options = {"max_unroll": 32}

    @wp.func
    def distance(target: vec, w: vec, metric: vec) -> wp.float32:
        """sum_j m_j (C_cj - W_vj)^2: the winner criterion with metric weights."""
        diff = target - w
        return wp.dot(wp.cw_mul(diff, metric), diff)

    @wp.func
    def move_pair(w: vec, l1: wp.float32, l2: wp.float32, a: vec, b: vec) -> vec:
        """Step 2 for a mirrored pair: W + (l1 (A - W) + l2 (B - W)) / max(1, l1 + l2), written as
        W + (m ((A + B) - 2 W) + h (A - B)) / max(1, l1 + l2) with m, h = (l1 +- l2) / 2, which swapping the pair
        (l1 <-> l2, A <-> B) or mirroring W, A and B maps onto itself bit for bit, fused multiply-adds or not: a
        symmetric mesh stays exactly symmetric. With PAIRS the division by 1 is left out (the same bits)."""
        m = wp.float32(0.5) * (l1 + l2)
        h = wp.float32(0.5) * (l1 - l2)
        step = m * ((a + b) - wp.float32(2.0) * w) + h * (a - b)
        if wp.static(pairs == SCALED_PAIRS):
            step = step / wp.max(wp.float32(1.0), l1 + l2)
        return w + step

    # -- CUDA: a thread per neuron, a block of 32 ----------------------------------------------------------
    @wp.func
    def find_winners_of_block(
        w: vec,
        n_neurons: int,
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: vec,
        keys: wp.array2d(dtype=wp.uint64),
        buf: int,
        block: int,
        lane: int,
    ):
        """Step 1: u_c = argmin_v sum_j m_j (C_cj - W_vj)^2. Each thread brings its neuron's weights w (a thread
        past the mesh, those of the last neuron); a thread per control scans the block's neurons from shared
        memory, then one atomic min per control and block."""
        block_w = wp.tile(w, preserve_type=True)  # read here, in shared memory: a global round trip costs far more
        lo = block * CUDA_BLOCK
        for c in range(lane, n_controls, CUDA_BLOCK):
            target = controls[c]
            best = FLOAT_MAX
            best_v = lo
            for i in range(CUDA_BLOCK):  # unrolled: the reads overlap
                dist = distance(target, block_w[i], metric)
                nearer = dist < best  # strict: the lowest index wins a tie
                best = wp.where(nearer, dist, best)
                best_v = wp.where(nearer, wp.min(lo + i, n_neurons - 1), best_v)
            key = winner_key(best, best_v)
            # keys only fall: on a big mesh most blocks see a better key already and skip the contended atomic
            if n_neurons <= CHECK_BEFORE_ATOMIC or key < keys[buf, c]:
                wp.atomic_min(keys, buf, c, key)

    @wp.func
    def end_cycle(
        w: vec,
        n_neurons: int,
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        keys: wp.array2d(dtype=wp.uint64),
        s: int,
        cycle_out: wp.array(dtype=wp.int32),
        find_next: int,
        block: int,
        lane: int,
    ):
        """With find_next: step 1 of cycle s + 1 from the new weights w, the keys of cycle s + 2 cleared and the
        counter advanced; without, the counter passed on unchanged (a later kernel of the cycle ends it)."""
        if find_next != 0:
            find_winners_of_block(w, n_neurons, controls, n_controls, metric[0], keys, (s + 1) % 3, block, lane)
        if block == 0 and lane == 0:
            pass_counter(keys, s, n_controls, cycle_out, find_next)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def find_winners(
        weights: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        keys: wp.array2d(dtype=wp.uint64),
        cycle: wp.array(dtype=wp.int32),
    ):
        """Winners of cycle s = cycle[0] from the current weights into keys[s % 3] (cleared beforehand)."""
        wait_for_previous_grid()
        block, lane = wp.tid()
        w = weights[wp.min(block * CUDA_BLOCK + lane, weights.shape[0] - 1)]
        find_winners_of_block(w, weights.shape[0], controls, n_controls, metric[0], keys, cycle[0] % 3, block, lane)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def move(
        weights_in: wp.array(dtype=vec),
        weights_out: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        c_lo: int,
        c_hi: int,
        n_controls: int,
        metric: wp.array(dtype=vec),
        table: wp.array2d(dtype=wp.float32),
        distances: Any,
        slot_of: wp.array(dtype=wp.int32),
        keys: wp.array2d(dtype=wp.uint64),
        cycle_in: wp.array(dtype=wp.int32),
        cycle_out: wp.array(dtype=wp.int32),
        find_next: int,
        stalled: wp.array(dtype=wp.int32),
    ):
        """Step 2 of cycle s: W_v <- W_v + L[s, D[u_c, v]] (C_c - W_v) for the controls c_lo .. c_hi - 1 in list
        order (all n_controls but for a cycle run in parts); stalls on a missing distance row.

        The row stays in registers; rates are gathered `gather` controls at a time so their loads overlap (past
        c_hi they are 0 and change nothing). With find_next (no smoothing) the kernel then finds the winners of
        cycle s + 1 and advances the counter. Launched dependent (see dependent_launch.py), it waits for the
        kernel before it first.
        """
        wait_for_previous_grid()
        block, lane = wp.tid()
        s = cycle_in[0]
        buf = s % 3
        v = block * CUDA_BLOCK + lane
        u = wp.min(v, weights_in.shape[0] - 1)  # every thread looks up every row: all find the same miss
        w = weights_in[u]
        missing = int(0)  # stays 0 with the dense table (row_missing), a constant the compiler folds
        for c0 in range(c_lo, c_hi, gather):
            rates = gathered()
            for g in range(gather):  # unrolled: independent key -> (slot ->) distance -> rate chains
                c = wp.min(c0 + g, c_hi - 1)
                row = winner_row(distances, slot_of, keys, buf, c)
                missing = wp.max(missing, row_missing(distances, row))
                r = rate_at(table, s, distances, row, u)
                rates[g] = wp.where(c0 + g < c_hi, r, wp.float32(0.0))
            if wp.static(pairs != SINGLES):
                for g in range(0, gather, 2):
                    w = move_pair(w, rates[g], rates[g + 1], controls[wp.min(c0 + g, c_hi - 1)],
                                  controls[wp.min(c0 + g + 1, c_hi - 1)])
            else:
                for g in range(gather):
                    w = w + rates[g] * (controls[wp.min(c0 + g, c_hi - 1)] - w)
        if missing == 0:
            if v < weights_in.shape[0]:
                weights_out[v] = w
            end_cycle(w, weights_in.shape[0], controls, n_controls, metric, keys, s, cycle_out, find_next, block, lane)
        elif block == 0 and lane == 0:
            stalled[0] = 1
            cycle_out[0] = s

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def smooth(
        weights_in: wp.array(dtype=vec),
        weights_out: wp.array(dtype=vec),
        offsets: wp.array(dtype=wp.int32),
        neighbors: wp.array(dtype=wp.int32),
        mask: wp.array(dtype=vec),
        strength: wp.float32,
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        keys: wp.array2d(dtype=wp.uint64),
        cycle_in: wp.array(dtype=wp.int32),
        cycle_out: wp.array(dtype=wp.int32),
        stalled: wp.array(dtype=wp.int32),
    ):
        """Step 3 of cycle s (smoothing_kernels.smoothed), then the winners of cycle s + 1 and the counter advance;
        skipped (the counter passed on) when the cycle stalled."""
        wait_for_previous_grid()
        block, lane = wp.tid()
        s = cycle_in[0]
        if stalled[0] == 0:
            v = block * CUDA_BLOCK + lane
            w = smoothed(weights_in, wp.min(v, weights_in.shape[0] - 1), offsets, neighbors, strength * mask[0])
            if v < weights_in.shape[0]:
                weights_out[v] = w
            end_cycle(w, weights_in.shape[0], controls, n_controls, metric, keys, s, cycle_out, 1, block, lane)
        elif block == 0 and lane == 0:
            cycle_out[0] = s

    # -- CPU: each core runs one launch over its share ------------------------------------------------------
    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def move_part(
        weights_in: wp.array(dtype=vec),
        weights_out: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        c_lo: int,
        c_hi: int,
        table: wp.array2d(dtype=wp.float32),
        distances: Any,
        slot_of: wp.array(dtype=wp.int32),
        keys: wp.array2d(dtype=wp.uint64),
        cycle: wp.array(dtype=wp.int32),
        lo: int,
        hi: int,
        stalled: wp.array(dtype=wp.int32),
    ):
        """Step 2 of cycle s for neurons lo..hi-1 and controls c_lo .. c_hi - 1 (with `pairs`, pair by pair),
        control-major so each distance row is read in order; stalls on a missing distance row."""
        s = cycle[0]
        buf = s % 3
        if rows_missing(distances, slot_of, keys, buf, c_lo, c_hi) != 0:  # every core finds the same
            stalled[0] = 1
        else:
            for v in range(lo, hi):
                weights_out[v] = weights_in[v]
            if wp.static(pairs != SINGLES):
                for c in range(c_lo, c_hi, 2):
                    a = controls[c]
                    b = controls[c + 1]
                    row_a = winner_row(distances, slot_of, keys, buf, c)
                    row_b = winner_row(distances, slot_of, keys, buf, c + 1)
                    for v in range(lo, hi):
                        weights_out[v] = move_pair(weights_out[v], rate_at(table, s, distances, row_a, v),
                                                   rate_at(table, s, distances, row_b, v), a, b)
            else:
                for c in range(c_lo, c_hi):
                    target = controls[c]
                    row = winner_row(distances, slot_of, keys, buf, c)
                    for v in range(lo, hi):
                        w = weights_out[v]
                        weights_out[v] = w + rate_at(table, s, distances, row, v) * (target - w)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def smooth_part(
        weights_in: wp.array(dtype=vec),
        weights_out: wp.array(dtype=vec),
        offsets: wp.array(dtype=wp.int32),
        neighbors: wp.array(dtype=wp.int32),
        mask: wp.array(dtype=vec),
        strength: wp.float32,
        lo: int,
        hi: int,
        stalled: wp.array(dtype=wp.int32),
    ):
        """Step 3 for neurons lo..hi-1, skipped when the cycle stalled."""
        if stalled[0] == 0:
            pull = strength * mask[0]
            for v in range(lo, hi):
                weights_out[v] = smoothed(weights_in, v, offsets, neighbors, pull)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def find_part(
        weights: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        keys: wp.array2d(dtype=wp.uint64),
        cycle: wp.array(dtype=wp.int32),
        first: int,
        step: int,
        ahead: int,
        stalled: wp.array(dtype=wp.int32),
    ):
        """Step 1 for controls first, first + step, ...: winners over all neurons into keys[(s + ahead) % 3];
        with ahead = 1 this is the next cycle's search and the core's counter advances. Skipped (the counter
        stays) when the cycle stalled."""
        if stalled[0] == 0:
            s = cycle[0]
            buf = (s + ahead) % 3
            m = metric[0]
            for c in range(first, n_controls, step):
                target = controls[c]
                best = FLOAT_MAX
                best_v = int(0)
                for v in range(weights.shape[0]):
                    dist = distance(target, weights[v], m)
                    nearer = dist < best  # strict: the lowest index wins a tie
                    best = wp.where(nearer, dist, best)
                    best_v = wp.where(nearer, v, best_v)
                keys[buf, c] = winner_key(best, best_v)
            cycle[0] = s + ahead

    for source in DISTANCE_SOURCES:
        wp.overload(move, {"distances": source})
        wp.overload(move_part, {"distances": source})

    return SimpleNamespace(vec=vec, distance=distance, move_pair=move_pair, find_winners=find_winners, move=move,
                           smooth=smooth, move_part=move_part, smooth_part=smooth_part, find_part=find_part)
