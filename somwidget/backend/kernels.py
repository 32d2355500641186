"""Warp kernels of the SOM engine: BFS grid distances, winner search, move and smoothing.

The same kernels run on CUDA and on the CPU. The cycle kernels are specialised per feature count n (a row of
weights is a Warp vector of length n) and written as grid-stride loops: on CUDA each thread handles one neuron;
on the CPU Warp runs a block as a single thread, which then walks all neurons.

Winner keys pack (distance bits << 32 | neuron index) into one uint64: distances are non-negative floats, whose
bit patterns order like the values, so the smallest key is the nearest neuron with the lowest index on a tie.
Keys live in three rotating buffers indexed by s % 3: cycle s reads buffer s, fills buffer s + 1 with the winners
of the next cycle and clears buffer s + 2, so a whole run replays from a captured graph with no host work.
"""


import functools
from types import SimpleNamespace

import warp as wp

UNREACHABLE = wp.constant(wp.uint16(65535))
KEY_NONE = wp.constant(wp.uint64(0xFFFFFFFFFFFFFFFF))
INDEX_MASK = wp.constant(wp.uint64(0xFFFFFFFF))
#: Threads per block on CUDA: a thread per control scans the block's neurons for the winner search.
CUDA_BLOCK = wp.constant(32)


@wp.func_native("union { float f; uint32_t u; } c; c.f = x; return c.u;")
def float_bits(x: wp.float32) -> wp.uint32: ...


@wp.func
def winner_key(distance: wp.float32, v: int) -> wp.uint64:
    return (wp.uint64(float_bits(distance)) << wp.uint64(32)) | wp.uint64(v)


@wp.func
def clear_keys(keys: wp.array2d(dtype=wp.uint64), buf: int, n_controls: int):
    for c in range(n_controls):
        keys[buf, c] = KEY_NONE


@wp.kernel(enable_backward=False)
def bfs_rows(
    offsets: wp.array(dtype=wp.int32),
    neighbors: wp.array(dtype=wp.int32),
    sources: wp.array(dtype=wp.int32),
    rows: wp.array2d(dtype=wp.uint16),
    queue: wp.array2d(dtype=wp.int32),
    eccentricity: wp.array(dtype=wp.int32),
):
    """One breadth-first search per source (paper III-D): hop counts to every vertex, rows pre-filled with 65535.

    eccentricity[b] is the largest finite distance from source b; a value >= 65535 means the row overflowed.
    """
    b = wp.tid()
    n = rows.shape[1]
    src = sources[b]
    rows[b, src] = wp.uint16(0)
    queue[b, 0] = src
    head = int(0)
    tail = int(1)
    far = int(0)
    while head < tail:
        u = queue[b, head]
        head += 1
        du = int(rows[b, u])
        far = du
        for e in range(offsets[u], offsets[u + 1]):
            w = neighbors[e]
            if rows[b, w] == UNREACHABLE and w != src:
                if du + 1 >= 65535:
                    far = 65535
                else:
                    rows[b, w] = wp.uint16(du + 1)
                    if tail < n:
                        queue[b, tail] = w
                        tail += 1
    eccentricity[b] = far


@functools.cache
def cycle_kernels(n_dims: int) -> SimpleNamespace:
    """find_winners, move and smooth for weights with n_dims features (compiled once per n_dims)."""
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)
    rate8 = wp.types.vector(length=8, dtype=wp.float32)

    @wp.func
    def find_winners_of_block(
        weights: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: vec,
        keys: wp.array2d(dtype=wp.uint64),
        buf: int,
        block: int,
        lane: int,
        block_threads: int,
    ):
        """Step 1: u_c = argmin_v sum_j m_j (C_cj - W_vj)^2 over the block's neurons, then one atomic min per control.

        A thread per control scans the block's neurons (a CPU block is one thread: it scans all of them).
        """
        lo = block * block_threads
        if block_threads == 1:  # the CPU: one thread scans every neuron
            for c in range(n_controls):
                target = controls[c]
                best = wp.float32(0.0)
                best_v = int(-1)
                for v in range(weights.shape[0]):
                    diff = target - weights[v]
                    dist = wp.dot(wp.cw_mul(diff, metric), diff)
                    if best_v < 0 or dist < best:  # strict: the lowest index wins a tie
                        best = dist
                        best_v = v
                if best_v >= 0:
                    wp.atomic_min(keys, buf, c, winner_key(best, best_v))
        else:
            wp.tile_sum(wp.tile(0))  # barrier: the block's neurons were just written by its other threads
            for c in range(lane, n_controls, block_threads):
                target = controls[c]
                best = wp.float32(0.0)
                best_v = int(-1)
                for i in range(CUDA_BLOCK):  # unrolled: the loads overlap
                    v = lo + i
                    if v < weights.shape[0]:
                        diff = target - weights[v]
                        dist = wp.dot(wp.cw_mul(diff, metric), diff)
                        if best_v < 0 or dist < best:
                            best = dist
                            best_v = v
                if best_v >= 0:
                    wp.atomic_min(keys, buf, c, winner_key(best, best_v))

    @wp.kernel(enable_backward=False, module="unique", module_options={"max_unroll": 32})
    def find_winners(
        weights: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        keys: wp.array2d(dtype=wp.uint64),
        cycle: wp.array(dtype=wp.int32),
        block_threads: int,
        stride: int,
    ):
        """Winners of cycle s = cycle[0] from the current weights into keys[s % 3] (cleared beforehand)."""
        block, lane = wp.tid()
        find_winners_of_block(weights, controls, n_controls, metric[0], keys, cycle[0] % 3, block, lane, block_threads)

    @wp.kernel(enable_backward=False, module="unique", module_options={"max_unroll": 32})
    def move(
        weights_in: wp.array(dtype=vec),
        weights_out: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        table: wp.array2d(dtype=wp.float32),
        distances: wp.array2d(dtype=wp.uint16),
        keys: wp.array2d(dtype=wp.uint64),
        cycle_in: wp.array(dtype=wp.int32),
        cycle_out: wp.array(dtype=wp.int32),
        find_next: int,
        block_threads: int,
        stride: int,
    ):
        """Step 2 of cycle s: W_v <- W_v + L[s, D[u_c, v]] (C_c - W_v) for the controls in list order.

        With find_next (no smoothing) the same kernel finds the winners of cycle s + 1 on the moved weights, which
        each thread holds for its own neurons, and advances the cycle counter.
        """
        block, lane = wp.tid()
        s = cycle_in[0]
        buf = s % 3
        first = block * block_threads + lane
        last_d = table.shape[1] - 1
        if block_threads == 1:  # one thread walks all neurons (the CPU): control-major, contiguous row reads
            for v in range(first, weights_in.shape[0], stride):
                weights_out[v] = weights_in[v]
            for c in range(n_controls):
                target = controls[c]
                u = wp.int32(keys[buf, c] & INDEX_MASK)
                for v in range(first, weights_in.shape[0], stride):
                    d = distances[u, v]
                    if d != UNREACHABLE:
                        rate = table[s, wp.int32(d)]
                        if rate != 0.0:
                            w = weights_out[v]
                            weights_out[v] = w + rate * (target - w)
        else:  # a thread per neuron (CUDA): the row stays in registers; rates are gathered 8 controls at a time
            for v in range(first, weights_in.shape[0], stride):
                w = weights_in[v]
                for c0 in range(0, n_controls, 8):
                    rates = rate8()
                    for g in range(8):  # unrolled: eight independent key -> distance -> rate chains
                        c = wp.min(c0 + g, n_controls - 1)
                        d = distances[wp.int32(keys[buf, c] & INDEX_MASK), v]
                        r = table[s, wp.min(wp.int32(d), last_d)]
                        if d != UNREACHABLE and c0 + g < n_controls:
                            rates[g] = r
                    for g in range(8):
                        w = w + rates[g] * (controls[c0 + g] - w)
                weights_out[v] = w
        if find_next != 0:
            find_winners_of_block(weights_out, controls, n_controls, metric[0], keys, (s + 1) % 3, block, lane,
                                  block_threads)
        if block == 0 and lane == 0:
            if find_next != 0:
                clear_keys(keys, (s + 2) % 3, n_controls)
                cycle_out[0] = s + 1
            else:
                cycle_out[0] = s

    @wp.kernel(enable_backward=False, module="unique", module_options={"max_unroll": 32})
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
        block_threads: int,
        stride: int,
    ):
        """Step 3 of cycle s: one Jacobi step of uniform Laplacian smoothing on the masked dims,
        W_v <- W_v + lambda (mean of W over v's neighbours - W_v), all from the pre-smoothing weights; then the
        winners of cycle s + 1 and the counter advance, as in `move`.
        """
        block, lane = wp.tid()
        s = cycle_in[0]
        first = block * block_threads + lane
        pull = strength * mask[0]
        for v in range(first, weights_in.shape[0], stride):
            w = weights_in[v]
            lo = offsets[v]
            hi = offsets[v + 1]
            if hi > lo:
                total = vec()
                for e in range(lo, hi):
                    total += weights_in[neighbors[e]]
                w = w + wp.cw_mul(pull, total / wp.float32(hi - lo) - w)
            weights_out[v] = w
        find_winners_of_block(weights_out, controls, n_controls, metric[0], keys, (s + 1) % 3, block, lane,
                              block_threads)
        if block == 0 and lane == 0:
            clear_keys(keys, (s + 2) % 3, n_controls)
            cycle_out[0] = s + 1

    return SimpleNamespace(vec=vec, find_winners=find_winners, move=move, smooth=smooth)
