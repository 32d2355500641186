"""The batched engine's kernel (batch.py): B variants of one mesh, a block of threads per variant, a whole run in
one launch.

A variant's cycles depend on each other only through its own weights, so one block can run all of them with block
barriers in between, and B blocks run side by side with no host work and no grid-wide step. A cycle is the
algorithm's three steps (som.py, The cycle; the same arithmetic as cycle_kernels.py):

1. winners: each thread scans its neurons (v = t, t + T, ...) for each control, the block takes the least winner
   key (distance bits << 32 | index: the lowest index on a tie) with a warp reduction and one atomic min a warp in
   shared memory; a barrier;
2. move: each thread moves its neurons by the controls in list order, W_v <- W_v + L[s, D[u_c, v]] (C_c - W_v), or
   a mirrored pair at once (`move_pair`, scaled by 1 / max(1, l1 + l2));
3. smoothing (a variant with lambda > 0): the moved weights go to a scratch array, a barrier, then one Jacobi step
   (smoothing_kernels.smoothed on the variant's row). (Taubin's rule and controls with a radius follow the shaping
   path's rules, handles included, which run as single Soms: batch.py.)

Winner keys rotate through three buffers (cycle s fills buffer s % 3 and clears buffer s + 1), so one barrier a
cycle is enough without smoothing. On the CPU, where Warp runs a block as one thread, the keys live in a global
array instead of shared memory and the warp reduction is the thread's own minimum.
"""


import functools
from types import SimpleNamespace

import warp as wp

from .cycle_kernels import MAX_CONTROLS
from .primitives import INDEX_MASK, KEY_NONE, UNREACHABLE, sync_block, winner_key
from .smoothing_kernels import smoothed

#: int32 words of the winner keys a block holds in shared memory: three buffers of MAX_CONTROLS uint64 keys.
_SHARED_WORDS = 3 * MAX_CONTROLS * 2
_SHARED = "extern __shared__ char dynamic_smem_base[]; unsigned long long* shared_keys = " \
          "(unsigned long long*)dynamic_smem_base; "


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED + """
unsigned long long least = (unsigned long long)key;
for (int offset = 16; offset > 0; offset >>= 1) {
    unsigned long long other = __shfl_xor_sync(0xffffffffu, least, offset);
    least = other < least ? other : least;
}
if ((threadIdx.x & 31) == 0) atomicMin(shared_keys + slot, least);
#else
if (key < keys.data[base + slot]) keys.data[base + slot] = key;
#endif
""")
def offer_key(keys: wp.array(dtype=wp.uint64), base: int, slot: int, key: wp.uint64):
    """The block's winner key of `slot` becomes the least of it and every thread's `key` (all 32 lanes of each warp
    call this: T is a multiple of 32)."""
    ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED + "return shared_keys[slot];\n#else\n"
                "return keys.data[base + slot];\n#endif\n")
def read_key(keys: wp.array(dtype=wp.uint64), base: int, slot: int) -> wp.uint64: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED + "shared_keys[slot] = ~0ull;\n#else\n"
                "keys.data[base + slot] = ~0ull;\n#endif\n")
def clear_key(keys: wp.array(dtype=wp.uint64), base: int, slot: int): ...


@wp.func
def rate(tables: wp.array2d(dtype=wp.float32), row: int, hops: wp.uint16) -> wp.float32:
    """L[s, d] from the variant's table row; 0 for a neuron the winner cannot reach."""
    if hops == UNREACHABLE:
        return wp.float32(0.0)
    return tables[row, int(hops)]


#: Controls whose rates a thread looks up at once (their loads overlap), and whose winners it searches for at once.
GATHER = 8
SEARCH = 4


@functools.cache
def variant_funcs(n_dims: int, searched: int, unit_metric: bool) -> SimpleNamespace:
    """The steps of the batched kernel, for variant b run by a block of `threads` threads (thread t): `start_run`
    (the keys of its first cycle cleared), `find_winners` (step 1 of cycle s: `searched` controls at a time over each
    thread's neurons, offered to the block's keys; `unit_metric` skips the metric weights) and `smooth` (step 3 from
    the moved weights, smoothing_kernels.smoothed on the variant's row)."""
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)
    keys_of = wp.types.vector(length=searched, dtype=wp.uint64)
    targets_of = wp.types.matrix(shape=(searched, n_dims), dtype=wp.float32)

    @wp.func
    def distance(target: vec, w: vec, metric: vec) -> wp.float32:
        diff = target - w
        if wp.static(unit_metric):
            return wp.dot(diff, diff)
        return wp.dot(wp.cw_mul(diff, metric), diff)

    @wp.func
    def search(weights: wp.array2d(dtype=vec), controls: wp.array2d(dtype=vec), b: int, c0: int, k: int, m: vec,
               t: int, threads: int, keys: wp.array(dtype=wp.uint64), base: int, buf: int):
        """Step 1 for controls c0 .. c0 + searched - 1 (past k: the last one again) over this thread's neurons."""
        best = keys_of()
        targets = targets_of()
        for g in range(searched):
            best[g] = KEY_NONE
            targets[g] = controls[b, wp.min(c0 + g, k - 1)]
        for v in range(t, weights.shape[1], threads):
            w = weights[b, v]
            for g in range(searched):
                best[g] = wp.min(best[g], winner_key(distance(targets[g], w, m), v))
        for g in range(searched):
            if c0 + g < k:
                offer_key(keys, base, buf + c0 + g, best[g])

    @wp.func
    def start_run(keys: wp.array(dtype=wp.uint64), base: int, s0: int, k: int, t: int):
        """Before the first cycle s0: its keys cleared, then a barrier."""
        if t == 0:
            for c in range(k):
                clear_key(keys, base, (s0 % 3) * k + c)
        sync_block()

    @wp.func
    def find_winners(weights: wp.array2d(dtype=vec), controls: wp.array2d(dtype=vec), b: int, k: int, m: vec,
                     t: int, threads: int, keys: wp.array(dtype=wp.uint64), base: int, s: int):
        """Step 1 of cycle s from W(s) into keys buffer s % 3 (buffer s + 1 cleared for the next), then a barrier."""
        if t == 0:
            for c in range(k):
                clear_key(keys, base, ((s + 1) % 3) * k + c)
        for c0 in range(0, k, searched):
            search(weights, controls, b, c0, k, m, t, threads, keys, base, (s % 3) * k)
        sync_block()

    @wp.func
    def smooth(weights: wp.array2d(dtype=vec), moved: wp.array2d(dtype=vec), b: int, t: int, threads: int,
               offsets: wp.array(dtype=wp.int32), neighbors: wp.array(dtype=wp.int32), pull: vec):
        """Step 3: `moved` (the moved weights) smoothed into `weights` by pull = lambda mask, after a barrier."""
        n = weights.shape[1]
        sync_block()
        for v in range(t, n, threads):
            weights[b, v] = smoothed(moved[b], v, offsets, neighbors, pull)

    return SimpleNamespace(distance=distance, start_run=start_run, find_winners=find_winners, smooth=smooth)


@functools.cache
def variants_kernel(n_dims: int, pairs: bool, cuda: bool, threads: int = 1024, min_blocks: int = 1,
                    gather: int = GATHER, searched: int = SEARCH, unit_metric: bool = False):
    """The kernel for weights of n_dims features; with `pairs` the effective controls come as mirrored pairs, each
    original next to its copy. `cuda`: the keys in shared memory (on the CPU Warp's shared tiles are one static
    buffer, which concurrent launches on several cores would share), blocks of at most `threads` threads of which
    `min_blocks` fit an SM at once (the compiler's register budget); `gather`, `searched`: GATHER, SEARCH.
    `unit_metric`: every metric weight is 1, so the winner search skips multiplying by them (the same bits)."""
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)
    rates = wp.types.vector(length=gather, dtype=wp.float32)
    group_of = wp.types.matrix(shape=(gather, n_dims), dtype=wp.float32)
    group_ints = wp.types.vector(length=gather, dtype=wp.int32)
    options = {"max_unroll": 32}
    steps = variant_funcs(n_dims, searched, unit_metric)

    @wp.func
    def move_pair(w: vec, l1: wp.float32, l2: wp.float32, a: vec, b: vec) -> vec:
        """W + (l1 (A - W) + l2 (B - W)) / max(1, l1 + l2), in the mirror-exact form of cycle_kernels.py."""
        m = wp.float32(0.5) * (l1 + l2)
        h = wp.float32(0.5) * (l1 - l2)
        step = m * ((a + b) - wp.float32(2.0) * w) + h * (a - b)
        if l1 + l2 > wp.float32(1.0):  # else a division by 1, which changes no bit
            step = step / (l1 + l2)
        return w + step

    @wp.func
    def move_group(weights: wp.array2d(dtype=vec), moved: wp.array2d(dtype=vec), into_moved: int, c0: int, b: int,
                   controls: wp.array2d(dtype=vec), k: int, tables: wp.array2d(dtype=wp.float32), row: int,
                   distances: wp.array2d(dtype=wp.uint16), keys: wp.array(dtype=wp.uint64), base: int, buf: int,
                   t: int, threads: int):
        """Step 2 for controls c0 .. c0 + gather - 1 on this thread's neurons (past k a rate of 0, which leaves a
        weight as it is): their winners and places read once, then each neuron's rates looked up together and
        applied in list order (pairs at once). The first group reads `weights`; the result goes to `moved` with
        `into_moved` (smoothing follows), else back to `weights`."""
        winners = group_ints()
        places = group_of()
        for g in range(gather):
            c = wp.min(c0 + g, k - 1)
            winners[g] = int(read_key(keys, base, buf + c) & INDEX_MASK)
            places[g] = controls[b, c]
        for v in range(t, weights.shape[1], threads):
            w = weights[b, v]
            if into_moved != 0 and c0 > 0:
                w = moved[b, v]
            r = rates()
            for g in range(gather):
                r[g] = wp.where(c0 + g < k, rate(tables, row, distances[winners[g], v]), wp.float32(0.0))
            if wp.static(pairs):
                for g in range(0, gather, 2):
                    w = move_pair(w, r[g], r[g + 1], places[g], places[g + 1])
            else:
                for g in range(gather):
                    w = w + r[g] * (places[g] - w)
            if into_moved != 0:
                moved[b, v] = w
            else:
                weights[b, v] = w

    @wp.kernel(enable_backward=False, module="unique", module_options=options, launch_bounds=(threads, min_blocks))
    def train_variants(
        weights: wp.array2d(dtype=vec),
        moved: wp.array2d(dtype=vec),
        controls: wp.array2d(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        mask: wp.array(dtype=vec),
        tables: wp.array2d(dtype=wp.float32),
        table_row: wp.array(dtype=wp.int32),
        smoothing: wp.array(dtype=wp.float32),
        s_from: wp.array(dtype=wp.int32),
        s_to: wp.array(dtype=wp.int32),
        distances: wp.array2d(dtype=wp.uint16),
        offsets: wp.array(dtype=wp.int32),
        neighbors: wp.array(dtype=wp.int32),
        keys: wp.array(dtype=wp.uint64),
        first: int,
    ):
        """Cycles s_from[b] .. s_to[b] - 1 of variant b = first + block (weights[b], controls[b], its table from row
        table_row[b], its smoothing). `moved` is scratch for smoothing; `keys`
        holds the winner keys on the CPU."""
        block, t = wp.tid()
        b = first + block
        threads = wp.block_dim()
        if wp.static(cuda):
            reserved = wp.tile_zeros(shape=(_SHARED_WORDS,), dtype=wp.int32, storage="shared")  # noqa: F841 (keys)
        k = n_controls
        base = b * 3 * k  # the variant's keys in `keys` (CPU only)
        m = metric[0]
        lam = smoothing[b]
        into_moved = int(lam > wp.float32(0.0))
        steps.start_run(keys, base, s_from[b], k, t)
        for s in range(s_from[b], s_to[b]):
            steps.find_winners(weights, controls, b, k, m, t, threads, keys, base, s)  # 1. winners from W(s)
            # 2. every neuron applies the controls in list order (pairs at once)
            row = table_row[b] + s
            for c0 in range(0, k, gather):
                move_group(weights, moved, into_moved, c0, b, controls, k, tables, row, distances, keys, base,
                           (s % 3) * k, t, threads)
            if into_moved != 0:  # 3. smoothing from the moved weights
                steps.smooth(weights, moved, b, t, threads, offsets, neighbors, lam * mask[0])

    return train_variants


@wp.kernel
def copy_rows(dest: wp.array2d(dtype=wp.float32), src: wp.array2d(dtype=wp.float32), rows: wp.array(dtype=wp.int32)):
    """dest[r] = src[r] for each r of `rows` (a variant's weights back to those its anchor kept: one launch for every
    variant whose controls moved from its anchor this round)."""
    i, j = wp.tid()
    r = rows[i]
    dest[r, j] = src[r, j]
