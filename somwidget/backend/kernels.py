"""Warp kernels of the SOM engine: BFS grid distances, winner search, move and smoothing.

The cycle kernels are specialised per feature count n (a row of weights is a Warp vector of length n) and come in
two decompositions of the same cycle. On CUDA a thread per neuron moves it, a thread per control scans each block of
32 neurons (their new weights shared in the block) for the winners, and the whole cycle is one kernel (two with
smoothing), launched dependent on the one before where the GPU allows (see dependent_launch.py). Small meshes with
up to 32 controls use `spread_cycle_kernel` instead, which spreads the controls over the warps of a block, and with
smoothing `spread_smoothing_cycle_kernel`, which keeps the cycle in one kernel by moving each block's halo too;
these two take raw pointers rather than Warp arrays (fewer bytes of parameters to read at each launch). On the CPU,
where Warp runs a launch on one thread, each core replays its own graph: the neurons are split between the cores for
the move and smoothing, the controls for the winner search, with a spinning barrier between the phases.

Winner keys pack (distance bits << 32 | neuron index) into one uint64: distances are non-negative floats, whose
bit patterns order like the values, so the smallest key is the nearest neuron with the lowest index on a tie.
Keys live in three rotating buffers indexed by s % 3: cycle s reads buffer s, fills buffer s + 1 with the winners
of the next cycle and clears buffer s + 2, so a whole run replays from a captured graph with no host work.

Past the dense table (distance rows mode) the same cycle reads int32 distance rows that the host keeps for recent
winners; a cycle whose winner has no row stalls (see `cycle_kernels`), and BFS kernels compute rows on demand.
"""


import ctypes
import functools
from types import SimpleNamespace
from typing import Any

import warp as wp

UNREACHABLE = wp.constant(wp.uint16(65535))
KEY_NONE = wp.constant(wp.uint64(0xFFFFFFFFFFFFFFFF))
INDEX_MASK = wp.constant(wp.uint64(0xFFFFFFFF))
FLOAT_MAX = wp.constant(wp.float32(3.4028234663852886e38))
#: Threads per block on CUDA, a whole warp or more (the winner search shares the block's weights through a tile):
#: a thread per control scans the block's neurons.
CUDA_BLOCK = wp.constant(32)
#: Above this many neurons a block reads the current winner key before its atomic min (measured on an H200: the
#: 65,536-neuron cycle 14.4 -> 10.6 us; the extra read made the 602-neuron car slower, 5.8 -> 7.8 us).
CHECK_BEFORE_ATOMIC = wp.constant(2048)


@wp.func_native("union { float f; uint32_t u; } c; c.f = x; return c.u;")
def float_bits(x: wp.float32) -> wp.uint32: ...


@wp.func
def winner_key(distance: wp.float32, v: int) -> wp.uint64:
    return (wp.uint64(float_bits(distance)) << wp.uint64(32)) | wp.uint64(v)


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


@wp.func_native("""
#if defined(__CUDA_ARCH__)
return 0;
#else
long long ticket = __atomic_add_fetch(&counter[0], 1LL, __ATOMIC_ACQ_REL);
long long target = ((ticket - 1) / parties + 1) * parties;
for (long long spins = 0; __atomic_load_n(&counter[0], __ATOMIC_ACQUIRE) < target; ++spins) {
    if (spins < 2000 || yield_address == 0) {
#if defined(__x86_64__) || defined(__i386__)
        __builtin_ia32_pause();
#endif
    } else {  /* the other core is busy elsewhere: give this one away */
        typedef signed (*yield_fn)(void);  /* signed = int: Warp defines a macro int(x) */
        ((yield_fn)yield_address)();
    }
    if (spins > 50000000LL) return 1;  /* tens of seconds of yields: a core is gone, not just late */
}
return 0;
#endif
""")
def wait_for_cores(counter: wp.array(dtype=wp.int64), parties: wp.int64, yield_address: wp.uint64) -> int: ...


@wp.kernel(enable_backward=False)
def barrier(
    counter: wp.array(dtype=wp.int64), parties: wp.int64, yield_address: wp.uint64, failed: wp.array(dtype=wp.int32)
):
    """All CPU cores of a run meet here between the phases of a cycle. Real atomics (Warp's CPU ones are plain);
    after a short spin a waiting core calls yield_address (libc's sched_yield) so a busy machine is not starved.
    Once a core has given up waiting, every later meeting is skipped, so the run ends and the host reports it."""
    if failed[0] != 0:
        return
    if wait_for_cores(counter, parties, yield_address) != 0:
        failed[0] = 1


def sched_yield_address() -> int:
    """Address of libc's sched_yield, or 0 where there is none (then the barrier only spins)."""
    try:
        return ctypes.cast(ctypes.CDLL(None).sched_yield, ctypes.c_void_p).value or 0
    except (AttributeError, OSError, TypeError):
        return 0


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


# A barrier of the threads of a block: __syncthreads() on CUDA; on the CPU nothing (a block is one thread) or, with
# wp.config.enable_cpu_blocks, a switch between the block's cooperative fibers.
@wp.func_native("WP_TILE_SYNC();")
def sync_block(): ...


# Programmatic dependent launch (see dependent_launch.py): a kernel so launched may start before the one before it
# ends; it waits here before reading what that kernel writes. A no-op for an ordinary launch, and on the CPU.
@wp.func_native("#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900\n"
                'asm volatile("griddepcontrol.wait;" ::: "memory");\n#endif\n')
def wait_for_previous_grid(): ...


ids8 = wp.types.vector(length=8, dtype=wp.int32)


@wp.func
def expand_vertex(offsets: wp.array(dtype=wp.int32), neighbors: wp.array(dtype=wp.int32),
                  hops: wp.array2d(dtype=wp.int32), row: int, u: int, level: int, queue: wp.array2d(dtype=wp.int32),
                  b: int, end: int, size: wp.array2d(dtype=wp.int32)) -> int:
    """One step of a level-synchronous search: u's unvisited neighbours (hops[row, w] == -1) get level + 1 and are
    appended to queue[b] past `end`, counted in size[b, (level + 1) % 3]; returns how many this thread appended.
    Eight edges at a time: their loads overlap, and only the unvisited take a compare-and-swap."""
    added = int(0)
    lo = offsets[u]
    hi = offsets[u + 1]
    for e0 in range(lo, hi, 8):
        near = ids8()
        seen = ids8()
        for g in range(8):
            near[g] = neighbors[wp.min(e0 + g, hi - 1)]
        for g in range(8):
            seen[g] = hops[row, near[g]]
        for g in range(8):
            if e0 + g < hi and seen[g] < 0:
                if wp.atomic_cas(hops, row, near[g], -1, level + 1) == -1:
                    queue[b, end + wp.atomic_add(size, b, (level + 1) % 3, 1)] = near[g]
                    added += 1
    return added


@wp.func
def search_levels(offsets: wp.array(dtype=wp.int32), neighbors: wp.array(dtype=wp.int32),
                  hops: wp.array2d(dtype=wp.int32), row: int, queue: wp.array2d(dtype=wp.int32), b: int,
                  size: wp.array2d(dtype=wp.int32), width: int, t: int, threads: int) -> int:
    """A breadth-first search by the `threads` threads of a block (t: this one), level by level with a block barrier
    between levels, into hops[row] (-1 = not reached), from the `width` sources at the head of queue[b] (at 0 in
    hops, size[b, 1] zeroed). Returns the largest distance found."""
    level = int(0)
    start = int(0)
    while width > 0:
        end = start + width
        for k in range(start + t, end, threads):
            expand_vertex(offsets, neighbors, hops, row, queue[b, k], level, queue, b, end, size)
        if t == 0:
            size[b, (level + 2) % 3] = 0  # the count of level + 2; nobody reads it any more (3 slots)
        sync_block()
        start = end
        width = size[b, (level + 1) % 3]
        level += 1
    return level - 1


@wp.kernel(enable_backward=False, module="unique")
def bfs_blocks(
    offsets: wp.array(dtype=wp.int32),
    neighbors: wp.array(dtype=wp.int32),
    table: wp.array2d(dtype=wp.uint16),
    hops: wp.array2d(dtype=wp.int32),
    queue: wp.array2d(dtype=wp.int32),
    size: wp.array2d(dtype=wp.int32),
    eccentricity: wp.array(dtype=wp.int32),
):
    """The dense table by a block of threads per search, level by level with a barrier between levels (CUDA).

    Block b searches from the sources b, b + B, b + 2 B, ... (B = hops.shape[0] blocks) and writes each whole row
    table[src] once: hop counts, 65535 where unreachable. Its scratch: hops[b] (int32, -1 = not reached; -1 again
    on return) and queue[b], whose level-L segment its threads share out, appending the vertices of level L + 1
    (counted in size[b, (L + 1) % 3]). eccentricity[src]: the largest finite distance (>= 65535: it overflowed).
    On the CPU a block is one thread (or cooperative fibers with wp.config.enable_cpu_blocks); blocks past B idle.
    """
    i = wp.tid()
    threads = wp.block_dim()
    b = i // threads
    t = i - b * threads
    blocks = hops.shape[0]
    n = table.shape[1]
    if b < blocks:
        for src in range(b, table.shape[0], blocks):
            if t == 0:
                hops[b, src] = 0
                queue[b, 0] = src
                size[b, 1] = 0
            sync_block()
            deepest = search_levels(offsets, neighbors, hops, b, queue, b, size, 1, t, threads)
            if t == 0:
                eccentricity[src] = deepest
            for v in range(t, n, threads):  # the row, written once and in order; the scratch back to -1
                d = hops[b, v]
                table[src, v] = wp.where(d >= 0, wp.uint16(wp.min(d, 65535)), UNREACHABLE)
                hops[b, v] = -1
            sync_block()


# -- distance rows past the dense table: int32 hop counts, -1 = unreachable ------------------------------------
@wp.func
def seed_row(sources: wp.array(dtype=wp.int32), first: wp.array(dtype=wp.int32), b: int, slot: int,
             rows: wp.array2d(dtype=wp.int32), queue: wp.array2d(dtype=wp.int32)) -> int:
    """Row b's sources first[b] .. first[b + 1] - 1 at distance 0 in rows[slot] and at the head of queue[b]; returns
    how many (a source listed twice counts once)."""
    tail = int(0)
    for j in range(first[b], first[b + 1]):
        src = sources[j]
        if rows[slot, src] < 0:
            rows[slot, src] = 0
            queue[b, tail] = src
            tail += 1
    return tail


@wp.kernel(enable_backward=False)
def bfs_wide(
    offsets: wp.array(dtype=wp.int32),
    neighbors: wp.array(dtype=wp.int32),
    sources: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    rows: wp.array2d(dtype=wp.int32),
    queue: wp.array2d(dtype=wp.int32),
    far: wp.array(dtype=wp.int32),
):
    """A breadth-first search per thread b into rows[slots[b]] from the sources first[b] .. first[b + 1] - 1 (the
    hops to the nearest of them; -1 where none is reachable). far[b]: the largest distance found."""
    b = wp.tid()
    slot = slots[b]
    for v in range(rows.shape[1]):
        rows[slot, v] = -1
    tail = seed_row(sources, first, b, slot, rows, queue)
    head = int(0)
    deepest = int(0)
    while head < tail:
        u = queue[b, head]
        head += 1
        du = rows[slot, u]
        deepest = du
        for e in range(offsets[u], offsets[u + 1]):
            w = neighbors[e]
            if rows[slot, w] < 0:
                rows[slot, w] = du + 1
                queue[b, tail] = w
                tail += 1
    far[b] = deepest


@wp.kernel(enable_backward=False, module="unique")
def bfs_row_blocks(
    offsets: wp.array(dtype=wp.int32),
    neighbors: wp.array(dtype=wp.int32),
    sources: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    rows: wp.array2d(dtype=wp.int32),
    queue: wp.array2d(dtype=wp.int32),
    size: wp.array2d(dtype=wp.int32),
    far: wp.array(dtype=wp.int32),
):
    """A block of threads per row (CUDA): block b searches from the sources first[b] .. first[b + 1] - 1 into
    rows[slots[b]] (the hops to the nearest of them, -1 where none is reachable), level by level with a barrier
    between levels, all in one launch. Its threads share out each level's segment of queue[b] and append the next
    level (counted in size[b, (L + 1) % 3]). far[b]: the largest distance found."""
    i = wp.tid()
    threads = wp.block_dim()
    b = i // threads
    t = i - b * threads
    slot = slots[b]
    for v in range(t, rows.shape[1], threads):
        rows[slot, v] = -1
    sync_block()
    if t == 0:
        size[b, 0] = seed_row(sources, first, b, slot, rows, queue)
        size[b, 1] = 0
        size[b, 2] = 0
    sync_block()
    deepest = search_levels(offsets, neighbors, rows, slot, queue, b, size, size[b, 0], t, threads)
    if t == 0:
        far[b] = deepest


# -- a row search with its visited set and frontier in shared memory (CUDA) -------------------------------------
# A block's dynamic shared memory, reserved by one int32 tile (the kernel's only one, so it starts at offset 0),
# read and written by word index: the visited bitmap takes compare-free atomic ORs, the level counts atomic adds.
_SHARED = "extern __shared__ char dynamic_smem_base[]; "


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED
                + "return atomicOr(((unsigned int*)dynamic_smem_base) + word, bits);\n#else\nreturn 0;\n#endif\n")
def shared_or(word: int, bits: wp.uint32) -> wp.uint32: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED
                + "return atomicAdd(((int*)dynamic_smem_base) + word, value);\n#else\nreturn 0;\n#endif\n")
def shared_add(word: int, value: int) -> int: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED
                + "return ((int*)dynamic_smem_base)[word];\n#else\nreturn 0;\n#endif\n")
def shared_get(word: int) -> int: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED + "((int*)dynamic_smem_base)[word] = value;\n#endif\n")
def shared_set(word: int, value: int): ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED + "((float*)dynamic_smem_base)[word] = value;\n#endif\n")
def shared_set_float(word: int, value: wp.float32): ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED
                + "return ((float*)dynamic_smem_base)[word];\n#else\nreturn 0.0f;\n#endif\n")
def shared_get_float(word: int) -> wp.float32: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\nreturn __syncthreads_or(value);\n#else\nreturn value;\n#endif\n")
def sync_block_any(value: int) -> int:
    """A block barrier that also returns whether any thread passed a non-zero value."""
    ...


@wp.func_native("""
#if defined(__CUDA_ARCH__)
#if __CUDA_ARCH__ >= 800
unsigned int least = __reduce_min_sync(0xffffffffu, bits);
#else
unsigned int least = bits;
for (int offset = 16; offset > 0; offset >>= 1) least = min(least, __shfl_xor_sync(0xffffffffu, least, offset));
#endif
unsigned int lane = __ffs(__ballot_sync(0xffffffffu, bits == least)) - 1;
return ((unsigned long long)least << 32) | (unsigned long long)(first + (int)lane);
#else
return 0;
#endif
""")
def warp_least_key(bits: wp.uint32, first: int) -> wp.uint64:
    """The smallest winner key of a warp whose lane i holds the distance bits of neuron first + i: the lowest
    lane among equal distances, so the lowest index (lanes past the mesh repeat its last neuron). CUDA only."""
    ...


@wp.func_native("""
#if defined(__CUDA_ARCH__)
const int4* p = reinterpret_cast<const int4*>(ell.data) + 2 * (long long)u;
int4 a = __ldg(p);
int4 c = __ldg(p + 1);
wp::vec_t<8, wp::int32> r;
r.c[0] = a.x; r.c[1] = a.y; r.c[2] = a.z; r.c[3] = a.w; r.c[4] = c.x; r.c[5] = c.y; r.c[6] = c.z; r.c[7] = c.w;
return r;
#else
return wp::vec_t<8, wp::int32>();
#endif
""")
def ell_row(ell: wp.array2d(dtype=wp.int32), u: int) -> ids8:
    """Row u of an (N, 8) int32 array in two 16-byte reads through the read-only cache (a third faster than eight
    reads of 4 bytes in the row search, measured on an H200)."""
    ...


@wp.func
def visit8(near: ids8, rows: wp.array2d(dtype=wp.int32), slot: int, level: int, queue: wp.array2d(dtype=wp.int32),
           b: int, end: int, frontier: int, cap: int, count: int, t: int):
    """The vertices of `near` (-1: none), reached at level + 1, claimed in the shared visited bitmap (words 0 ..);
    those newly claimed get level + 1 in rows[slot] and join the next frontier, counted in shared word `count`: its
    i-th vertex in shared word frontier + i while i < cap, past that in queue[b, end + i]. The eight claims are
    branch-free (for an absent vertex thread t ORs nothing into word t % 32: a bank of its own in its warp), so they
    issue back to back."""
    fresh = ids8()
    added = int(0)
    for g in range(8):
        w = near[g]
        bit = wp.where(w >= 0, wp.uint32(1) << wp.uint32(w & 31), wp.uint32(0))
        old = shared_or(wp.where(w >= 0, w >> 5, t % 32), bit)
        got = wp.where(((old ^ bit) & bit) != wp.uint32(0), 1, 0)
        fresh[g] = got
        added += got
    if added > 0:
        i = shared_add(count, added)
        for g in range(8):
            if fresh[g] != 0:
                w = near[g]
                rows[slot, w] = level + 1
                if i < cap:
                    shared_set(frontier + i, w)
                else:
                    queue[b, end + i] = w
                i += 1


@functools.cache
def shared_row_search(words: int, cap: int, block_threads: int):
    """The row search kernel for graphs of at most 32 * words vertices whose visited bitmap (words int32) and two
    frontier buffers (cap vertices each; a wider level spills to global memory) fit a block's shared memory, in
    blocks of block_threads (registers capped to fit them)."""
    total = words + 2 * cap + 3

    @wp.kernel(enable_backward=False, module="unique", launch_bounds=(block_threads, 1))
    def bfs_rows_shared(
        ell: wp.array2d(dtype=wp.int32),
        offsets: wp.array(dtype=wp.int32),
        neighbors: wp.array(dtype=wp.int32),
        sources: wp.array(dtype=wp.int32),
        first: wp.array(dtype=wp.int32),
        slots: wp.array(dtype=wp.int32),
        rows: wp.array2d(dtype=wp.int32),
        queue: wp.array2d(dtype=wp.int32),
        far: wp.array(dtype=wp.int32),
    ):
        """A block per row (CUDA): block b searches from the sources first[b] .. first[b + 1] - 1 into
        rows[slots[b]] (hops to the nearest of them, -1 where none is reachable), level by level with a block
        barrier between levels. A vertex's first eight neighbours come in one read of ell (its CSR row padded
        with -1), any more from the CSR. far[b]: the largest distance found."""
        b, t = wp.tid()
        threads = wp.block_dim()
        scratch = wp.tile_zeros(shape=(total,), dtype=wp.int32, storage="shared")  # noqa: F841 (the words below)
        n = rows.shape[1]
        slot = slots[b]
        counts = words + 2 * cap  # three level counts, rotating
        if t == 0:
            width = int(0)
            for j in range(first[b], first[b + 1]):
                src = sources[j]
                bit = wp.uint32(1) << wp.uint32(src & 31)
                if (shared_or(src >> 5, bit) & bit) == wp.uint32(0):
                    rows[slot, src] = 0
                    if width < cap:
                        shared_set(words + width, src)
                    else:
                        queue[b, width] = src
                    width += 1
            shared_set(counts, width)
        sync_block()
        level = int(0)
        start = int(0)
        width = shared_get(counts)
        while width > 0:
            now = words + (level % 2) * cap
            following = words + ((level + 1) % 2) * cap
            count = counts + (level + 1) % 3
            end = start + width
            for k in range(t, width, threads):
                u = int(0)
                if k < cap:
                    u = shared_get(now + k)
                else:
                    u = queue[b, start + k]
                near = ell_row(ell, u)
                visit8(near, rows, slot, level, queue, b, end, following, cap, count, t)
                if near[7] >= 0:  # eight neighbours or more (rare on meshes): the rest from the CSR
                    hi = offsets[u + 1]
                    for e0 in range(offsets[u] + 8, hi, 8):
                        for g in range(8):
                            near[g] = wp.where(e0 + g < hi, neighbors[wp.min(e0 + g, hi - 1)], -1)
                        visit8(near, rows, slot, level, queue, b, end, following, cap, count, t)
            if t == 0:
                shared_set(counts + (level + 2) % 3, 0)  # the count of level + 2; nobody reads it any more
            sync_block()
            start = end
            width = shared_get(count)
            level += 1
        for word in range(t, (n + 31) // 32, threads):  # never reached: -1 (the row was not cleared before)
            bits = wp.uint32(shared_get(word))
            if bits != wp.uint32(0xFFFFFFFF):
                for j in range(32):
                    v = word * 32 + j
                    if v < n and (bits & (wp.uint32(1) << wp.uint32(j))) == wp.uint32(0):
                        rows[slot, v] = -1
        if t == 0:
            far[b] = level - 1

    return bfs_rows_shared


@wp.kernel(enable_backward=False)
def bfs_clear(rows: wp.array2d(dtype=wp.int32), slots: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    """Level-synchronous search, step 0: rows[slots[b]] = -1 for the count[0] rows of the batch."""
    v = wp.tid()
    for b in range(count[0]):
        rows[slots[b], v] = -1


@wp.kernel(enable_backward=False)
def bfs_seed(
    sources: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
    rows: wp.array2d(dtype=wp.int32),
    queue: wp.array2d(dtype=wp.int32),
    base: wp.array2d(dtype=wp.int32),
    size: wp.array2d(dtype=wp.int32),
    far: wp.array(dtype=wp.int32),
):
    """Step 1: row b's sources at distance 0 form level 0 of its queue."""
    b = wp.tid()
    if b < count[0]:
        slot = slots[b]
        base[0, b] = 0
        size[b, 0] = seed_row(sources, first, b, slot, rows, queue)
        size[b, 1] = 0
        size[b, 2] = 0
        far[b] = 0


@wp.kernel(enable_backward=False)
def bfs_level(
    offsets: wp.array(dtype=wp.int32),
    neighbors: wp.array(dtype=wp.int32),
    slots: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
    rows: wp.array2d(dtype=wp.int32),
    queue: wp.array2d(dtype=wp.int32),
    base: wp.array2d(dtype=wp.int32),
    size: wp.array2d(dtype=wp.int32),
    far: wp.array(dtype=wp.int32),
    level: int,
    threads: int,
):
    """Step 2 + level: row b's `threads` threads share out its vertices at distance `level` (a segment of its
    queue) and append their unvisited neighbours at level + 1. Segment starts and sizes rotate through three slots."""
    b, t = wp.tid()
    if b < count[0]:
        now = level % 3
        slot = slots[b]
        start = base[now, b]
        end = start + size[b, now]
        for i in range(start + t, end, threads):
            if expand_vertex(offsets, neighbors, rows, slot, queue[b, i], level, queue, b, end, size) > 0:
                far[b] = level + 1
        if t == 0:
            base[(level + 1) % 3, b] = end
            size[b, (level + 2) % 3] = 0


@wp.kernel(enable_backward=False)
def label_components(
    offsets: wp.array(dtype=wp.int32),
    neighbors: wp.array(dtype=wp.int32),
    labels: wp.array(dtype=wp.int32),
    hops: wp.array(dtype=wp.int32),
    order: wp.array(dtype=wp.int32),
):
    """One thread: connected components numbered by their lowest vertex, hops from that vertex, and `order` = the
    vertices grouped by component (a breadth-first order within each)."""
    n = labels.shape[0]
    for v in range(n):
        labels[v] = -1
    count = int(0)
    head = int(0)
    tail = int(0)
    for r in range(n):
        if labels[r] < 0:
            labels[r] = count
            hops[r] = 0
            order[tail] = r
            tail += 1
            while head < tail:
                u = order[head]
                head += 1
                for e in range(offsets[u], offsets[u + 1]):
                    w = neighbors[e]
                    if labels[w] < 0:
                        labels[w] = count
                        hops[w] = hops[u] + 1
                        order[tail] = w
                        tail += 1
            count += 1


@wp.kernel(enable_backward=False)
def assign_slots(slot_of: wp.array(dtype=wp.int32), neurons: wp.array(dtype=wp.int32),
                 slots: wp.array(dtype=wp.int32)):
    """slot_of[neurons[i]] = slots[i]: the cache row of each neuron (-1 = not cached)."""
    i = wp.tid()
    slot_of[neurons[i]] = slots[i]


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
    def smoothed(
        weights: wp.array(dtype=vec), v: int, offsets: wp.array(dtype=wp.int32), neighbors: wp.array(dtype=wp.int32),
        pull: vec,
    ) -> vec:
        """One Jacobi step of uniform Laplacian smoothing: W_v + lambda (mean of W over v's neighbours - W_v) on the
        masked dims (pull = lambda * mask), from the pre-smoothing weights; a neuron without neighbours stays."""
        w = weights[v]
        lo = offsets[v]
        hi = offsets[v + 1]
        if hi > lo:
            total = vec()
            for e in range(lo, hi):
                total += weights[neighbors[e]]
            w = w + wp.cw_mul(pull, total / wp.float32(hi - lo) - w)
        return w

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
        """Step 3 of cycle s (smoothing, see `smoothed`), then the winners of cycle s + 1 and the counter advance;
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


#: Words of the learning table's row s that a spread cycle kernel copies into shared memory (tables with longer rows
#: are read from global memory instead).
SHARED_TABLE_WORDS = 1024


@wp.func_native("#if defined(__CUDA_ARCH__)\nreturn __shfl_sync(0xffffffffu, value, lane);\n"
                "#else\nreturn value;\n#endif\n")
def warp_shuffle(value: int, lane: int) -> int:
    """`value` of lane `lane` of the warp (CUDA; every lane must take part)."""
    ...


@wp.func
def key_row(distances: wp.array2d(dtype=wp.uint16), slot_of: wp.array(dtype=wp.int32), key: wp.uint64) -> int:
    """The row of `distances` that holds D[u, .] for the winner u of `key`: u's own row of the dense table."""
    return wp.int32(key & INDEX_MASK)


@wp.func
def key_row(distances: wp.array2d(dtype=wp.int32), slot_of: wp.array(dtype=wp.int32),  # noqa: F811 (overload)
            key: wp.uint64) -> int:
    """The cache row holding the distances from the winner of `key`, -1 when it has none."""
    return slot_of[wp.int32(key & INDEX_MASK)]


@wp.func
def hops(distances: wp.array2d(dtype=wp.uint16), row: int, v: int) -> int:
    """D[u, v] from u's row, -1 where v is unreachable."""
    d = distances[row, v]
    return wp.where(d != UNREACHABLE, wp.int32(d), -1)


@wp.func
def hops(distances: wp.array2d(dtype=wp.int32), row: int, v: int) -> int:  # noqa: F811 (overload)
    """D[u, v] from cache row `row`, -1 where v is unreachable; a missing row (-1) reads row 0, whose rate the stalled
    cycle never applies."""
    return distances[wp.max(row, 0), v]


@wp.func
def sync_block_missing(distances: wp.array2d(dtype=wp.uint16), row: int) -> int:
    """A block barrier; the dense table has every row, so none is missing."""
    sync_block()
    return 0


@wp.func
def sync_block_missing(distances: wp.array2d(dtype=wp.int32), row: int) -> int:  # noqa: F811 (overload)
    """A block barrier that also returns 1 when any thread's cache row is missing (-1), else 0."""
    return sync_block_any(row_missing(distances, row))


@wp.func_native("""
const char* at = reinterpret_cast<const char*>(keys.data) + (long long)c * keys.strides[1];
#if defined(__CUDA_ARCH__)
unsigned long long key0, key1, key2;
asm volatile("ld.global.u64 %0, [%1];" : "=l"(key0) : "l"(at));
asm volatile("ld.global.u64 %0, [%1];" : "=l"(key1) : "l"(at + keys.strides[0]));
asm volatile("ld.global.u64 %0, [%1];" : "=l"(key2) : "l"(at + 2LL * keys.strides[0]));
const int buf = s % 3;
return buf == 0 ? key0 : (buf == 1 ? key1 : key2);
#else
return *reinterpret_cast<const unsigned long long*>(at + (long long)(s % 3) * keys.strides[0]);
#endif
""")
def key_of_cycle(keys: wp.array2d(dtype=wp.uint64), s: int, c: int) -> wp.uint64:
    """keys[s % 3, c], the winner key of control c in cycle s. On CUDA all three buffers are read, each by a load
    the compiler may not make conditional, so that the reads need not wait for s (as plain reads and a select they
    became a read of one buffer, then of another once s had come, in ncu's SASS; whole runs timed the same)."""
    ...


@functools.cache
def _spread_parts(n_dims: int, warps: int, per_warp: int, controls_at: int, table_at: int,
                  pairs: int) -> SimpleNamespace:
    """The steps the spread kernels share: warp g of `warps` is in charge of the controls g, g + warps, ... (at
    most `per_warp` of them), whose copies sit in shared memory from word `controls_at`; the table's row s sits
    there from word `table_at` (rows up to SHARED_TABLE_WORDS long), or, with table_at < 0, is read from the
    table. With `pairs` the controls are mirrored pairs (slots 2i, 2i + 1; warps x per_warp even)."""
    ks = cycle_kernels(n_dims, 8, pairs)
    vec, distance, move_pair = ks.vec, ks.distance, ks.move_pair
    threads = 32 * warps
    slots = warps * per_warp
    if pairs != SINGLES and slots % 2:
        raise ValueError(f"_spread_parts: mirrored pairs need an even number of control slots, got {slots}")

    @wp.func
    def shared_vec(word: int) -> vec:
        """n_dims floats from shared memory, from `word` on."""
        v = vec()
        for j in range(n_dims):
            v[j] = shared_get_float(word + j)
        return v

    @wp.func
    def stage_controls(controls: wp.array(dtype=vec), n_controls: int, t: int):
        """Copy the controls into shared memory (slots past the last repeat it): thread t copies slot t."""
        if t < slots:
            control = controls[wp.min(t, n_controls - 1)]
            for j in range(n_dims):
                shared_set_float(controls_at + t * n_dims + j, control[j])

    @wp.func
    def staged_control(c: int) -> vec:
        """Control c, from its copy in shared memory."""
        return shared_vec(controls_at + c * n_dims)

    @wp.func
    def stage_table_row(table: wp.array2d(dtype=wp.float32), s: int, t: int):
        """Copy the table's row s into shared memory (nothing without a shared row)."""
        if wp.static(table_at >= 0):
            for j in range(t, table.shape[1], threads):
                shared_set_float(table_at + j, table[s, j])

    @wp.func
    def stage_rate(table: wp.array2d(dtype=wp.float32), s: int, hop: int, c: int, n_controls: int, word: int):
        """L[s, D[u_c, v]], control c's rate for a neuron `hop` hops from its winner, into shared word `word`: 0 for an
        unreachable neuron (hop < 0) and for c past the last control, which then leaves the neuron as it is."""
        d = wp.clamp(hop, 0, table.shape[1] - 1)
        rate = float(0.0)
        if wp.static(table_at >= 0):
            rate = shared_get_float(table_at + d)
        else:
            rate = table[s, d]
        shared_set_float(word, wp.where(hop >= 0 and c < n_controls, rate, wp.float32(0.0)))

    @wp.func
    def apply_rates(w: vec, word: int) -> vec:
        """Step 2 for one neuron: W <- W + rate_c (C_c - W) for every slot in list order (with `pairs`, a pair at a
        time: `move_pair`), the rates from shared words word, word + 32, ..."""
        if wp.static(pairs != SINGLES):
            for c in range(0, slots, 2):  # unrolled
                w = move_pair(w, shared_get_float(word + c * 32), shared_get_float(word + (c + 1) * 32),
                              staged_control(c), staged_control(c + 1))
        else:
            for c in range(slots):  # unrolled
                w = w + shared_get_float(word + c * 32) * (staged_control(c) - w)
        return w

    @wp.func
    def lane_key(keys: wp.array2d(dtype=wp.uint64), s: int, n_controls: int, lane: int) -> wp.uint64:
        """Lane i's control's winner key of cycle s (lanes past the last control: the last)."""
        return key_of_cycle(keys, s, wp.min(lane, n_controls - 1))

    @wp.func
    def publish_winners(keys: wp.array2d(dtype=wp.uint64), s: int, n_controls: int, w: vec, metric: vec, first: int,
                        block: int, t: int):
        """Step 1 of cycle s + 1: warp g's nearest of the block's 32 new weights w (lane i: neuron first + i) to
        each of its controls, by one warp-wide minimum each, published by its lanes with one atomic min each; block
        0 clears the keys of cycle s + 2."""
        g = t // 32
        lane = t % 32
        best = KEY_NONE
        for j in range(per_warp):
            c = g + warps * j
            if c < n_controls:
                key = warp_least_key(float_bits(distance(staged_control(c), w, metric)), first)
                best = wp.where(lane == j, key, best)
        if lane < per_warp and g + warps * lane < n_controls:
            wp.atomic_min(keys, (s + 1) % 3, g + warps * lane, best)
        if block == 0:
            for c in range(t, n_controls, threads):
                keys[(s + 2) % 3, c] = KEY_NONE

    return SimpleNamespace(shared_vec=shared_vec, stage_controls=stage_controls,
                           stage_table_row=stage_table_row, stage_rate=stage_rate, apply_rates=apply_rates,
                           lane_key=lane_key, publish_winners=publish_winners)


# Programmatic dependent launch (see dependent_launch.py): from here on the next kernel in the stream may be launched;
# it still waits in wait_for_previous_grid until this one has ended and its writes are visible.
@wp.func_native("#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900\n"
                'asm volatile("griddepcontrol.launch_dependents;" ::: "memory");\n#endif\n')
def let_next_grid_launch(): ...


def _contiguous(*arrays: wp.array) -> None:
    for a in arrays:
        if not a.is_contiguous:
            raise ValueError(f"spread cycle kernels take contiguous arrays; got one of shape {a.shape} and strides "
                             f"{a.strides}")


@functools.cache
def spread_cycle_kernel(n_dims: int, warps: int, per_warp: int, shared_table: bool, rows: bool,
                        pairs: int = SINGLES) -> wp.Kernel:
    """The cycle kernel of small meshes (CUDA): a block of `warps` warps per 32 neurons, warp g in charge of the
    controls g, g + warps, ... (`per_warp` of them), so that the latency-bound steps of a cycle run side by side
    rather than one after another in one warp. Same results as `cycle_kernels(n_dims).move` with find_next for a whole
    cycle, bit for bit (n_controls <= warps * per_warp <= 32), from the dense table or (`rows`) distance rows. With
    `shared_table` the rates are read from a copy of the table's row s in shared memory (rows up to
    SHARED_TABLE_WORDS long).

    Its parameters are raw pointers and sizes, made by `spread_cycle_inputs`: a kernel's parameters sit in constant
    memory, which each launch of a graph reads cold, and Warp's array parameters (56 bytes each) take about six times
    the bytes (H200: case study 1 2.45 -> 2.2 us a cycle, with smoothing 3.13 -> 2.74).

    Before it waits for the previous kernel the block copies the controls into shared memory (nothing in a run
    writes them). Then step 2, W_v <- W_v + L[s, D[u_c, v]] (C_c - W_v): lane i of each warp reads control i's
    winner key, the warp looks up its controls' hop counts for the block's 32 neurons, then their rates into shared
    memory; after a barrier every warp applies all the rates in list order to its own copy of the 32 neurons. Then
    it lets the next kernel launch, whose blocks are placed while this one finishes (H200: the car 2.78 -> 2.43 us).
    Step 1 of cycle s + 1: warp g finds the nearest of the block's new weights to each of its controls with one
    warp-wide minimum, and its lanes publish them with one atomic min each.
    """
    vec = cycle_kernels(n_dims).vec
    slots = warps * per_warp
    if slots > 32:
        raise ValueError(f"spread_cycle_kernel: warps x per_warp = {slots} controls, at most 32 (a lane each)")
    table_words = SHARED_TABLE_WORDS if shared_table else 0
    # shared memory, in 4-byte words: the rates (32 neurons x slots), the table's row s, the controls
    table_at = 32 * slots
    controls_at = table_at + table_words
    words = controls_at + slots * n_dims
    hop_counts = wp.types.vector(length=per_warp, dtype=wp.int32)
    hop_type = wp.int32 if rows else wp.uint16
    parts = _spread_parts(n_dims, warps, per_warp, controls_at, table_at if shared_table else -1, pairs)

    @wp.func
    def cycle(
        block: int,
        t: int,
        weights_in: wp.array(dtype=vec),
        weights_out: wp.array(dtype=vec),
        controls: wp.array(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        table: wp.array2d(dtype=wp.float32),
        distances: wp.array2d(dtype=hop_type),
        slot_of: wp.array(dtype=wp.int32),
        keys: wp.array2d(dtype=wp.uint64),
        cycle_in: wp.array(dtype=wp.int32),
        cycle_out: wp.array(dtype=wp.int32),
        stalled: wp.array(dtype=wp.int32),
    ):
        g = t // 32
        lane = t % 32
        m = metric[0]
        parts.stage_controls(controls, n_controls, t)
        wait_for_previous_grid()
        s = cycle_in[0]
        row = key_row(distances, slot_of, parts.lane_key(keys, s, n_controls, lane))
        first = block * 32
        n = weights_in.shape[0]
        u = wp.min(first + lane, n - 1)
        w = weights_in[u]
        hop = hop_counts()
        for j in range(per_warp):  # unrolled: the reads overlap
            hop[j] = hops(distances, warp_shuffle(row, wp.min(g + warps * j, n_controls - 1)), u)
        parts.stage_table_row(table, s, t)
        missing = sync_block_missing(distances, row)  # lanes past n_controls repeat its last control
        for j in range(per_warp):
            c = g + warps * j
            parts.stage_rate(table, s, hop[j], c, n_controls, c * 32 + lane)
        sync_block()
        w = parts.apply_rates(w, lane)
        let_next_grid_launch()
        if missing == 0:
            if g == 0 and first + lane < n:
                weights_out[first + lane] = w
            parts.publish_winners(keys, s, n_controls, w, m, first, block, t)
            if block == 0 and t == 0:
                cycle_out[0] = s + 1
        elif block == 0 and t == 0:
            stalled[0] = 1
            cycle_out[0] = s

    @wp.kernel(enable_backward=False, module="unique", module_options={"max_unroll": 32})
    def move_spread(
        weights_in: wp.uint64,
        weights_out: wp.uint64,
        n: int,
        controls: wp.uint64,
        n_controls: int,
        metric: wp.uint64,
        table: wp.uint64,
        table_rows: int,
        table_columns: int,
        distances: wp.uint64,
        distance_rows: int,
        slot_of: wp.uint64,
        keys: wp.uint64,
        key_columns: int,
        cycle_in: wp.uint64,
        cycle_out: wp.uint64,
        stalled: wp.uint64,
    ):
        block, t = wp.tid()
        scratch = wp.tile_empty(shape=(words,), dtype=wp.float32, storage="shared")  # noqa: F841 (used by word)
        cycle(block, t, wp.array(ptr=weights_in, shape=(n,), dtype=vec),
              wp.array(ptr=weights_out, shape=(n,), dtype=vec),
              wp.array(ptr=controls, shape=(n_controls,), dtype=vec), n_controls,
              wp.array(ptr=metric, shape=(1,), dtype=vec),
              wp.array(ptr=table, shape=(table_rows, table_columns), dtype=wp.float32),
              wp.array(ptr=distances, shape=(distance_rows, n), dtype=hop_type),
              wp.array(ptr=slot_of, shape=(n,), dtype=wp.int32),
              wp.array(ptr=keys, shape=(3, key_columns), dtype=wp.uint64),
              wp.array(ptr=cycle_in, shape=(1,), dtype=wp.int32), wp.array(ptr=cycle_out, shape=(1,), dtype=wp.int32),
              wp.array(ptr=stalled, shape=(1,), dtype=wp.int32))

    return move_spread


def spread_cycle_inputs(weights_in: wp.array, weights_out: wp.array, controls: wp.array, n_controls: int,
                        metric: wp.array, table: wp.array, distances: wp.array, slot_of: wp.array, keys: wp.array,
                        cycle_in: wp.array, cycle_out: wp.array, stalled: wp.array) -> list:
    """The parameters of `spread_cycle_kernel`'s kernel for these arrays (the move kernel's, less c_lo, c_hi and
    find_next), which must outlive any graph that captures the launch."""
    _contiguous(weights_in, weights_out, controls, metric, table, distances, slot_of, keys, cycle_in, cycle_out,
                stalled)
    return [weights_in.ptr, weights_out.ptr, weights_in.shape[0], controls.ptr, n_controls, metric.ptr, table.ptr,
            table.shape[0], table.shape[1], distances.ptr, distances.shape[0], slot_of.ptr, keys.ptr, keys.shape[1],
            cycle_in.ptr, cycle_out.ptr, stalled.ptr]


@functools.cache
def spread_smoothing_cycle_kernel(n_dims: int, warps: int, per_warp: int, shared_table: bool, chunks: int,
                                  width: int, pairs: int = SINGLES) -> wp.Kernel:
    """A whole cycle with smoothing in one kernel for small meshes (CUDA): `spread_cycle_kernel`'s blocks, each of
    which also moves its halo (halos.py: `chunks` chunks of 32 neurons, its own first, chunks <= warps; neurons of
    at most `width` neighbours), so that it can smooth its own neurons without waiting for the other blocks. The
    weights go from weights_in to weights_out (two arrays: other blocks still read weights_in). Same weights and
    winners, bit for bit, as the move kernel followed by `cycle_kernels(n_dims).smooth`; dense table only. Its
    parameters are raw pointers and sizes, as `spread_cycle_kernel`'s are (`spread_smoothing_cycle_inputs`).

    Step 2 as in `spread_cycle_kernel`, for every chunk: warp g looks up the rates of its controls for all chunks,
    then moves chunk g into shared memory. Step 3: every warp smooths the block's own neurons from the moved weights
    (the same sums in the same order as `smoothed`), and lets the next kernel launch (H200: 2.84 -> 2.78 us). Step 1
    of cycle s + 1 from the smoothed weights. Only the controls, metric and mask are read before the wait: the
    block's lists read there too made the cycle slower (H200, with Warp array parameters: 3.22 against 3.13 us).
    """
    vec = cycle_kernels(n_dims).vec
    slots = warps * per_warp
    if slots > 32 or chunks > warps:
        raise ValueError(f"spread_smoothing_cycle_kernel: {slots} controls (at most 32), {chunks} chunks for "
                         f"{warps} warps (at most one each)")
    table_words = SHARED_TABLE_WORDS if shared_table else 0
    # shared memory, in 4-byte words: the rates (chunks x slots x 32 neurons), the table's row s, the controls, the
    # moved weights (chunks x 32 neurons)
    table_at = chunks * slots * 32
    controls_at = table_at + table_words
    moved_at = controls_at + slots * n_dims
    words = moved_at + chunks * 32 * n_dims
    hop_counts = wp.types.matrix(shape=(chunks, per_warp), dtype=wp.int32)
    chunk_neurons = wp.types.vector(length=chunks, dtype=wp.int32)
    near_ones = wp.types.vector(length=width, dtype=wp.int32)
    parts = _spread_parts(n_dims, warps, per_warp, controls_at, table_at if shared_table else -1, pairs)
    shared_vec = parts.shared_vec

    @wp.func
    def moved_weight(i: int) -> vec:
        """The moved weights of the block's i-th listed neuron, from shared memory."""
        return shared_vec(moved_at + i * n_dims)

    @wp.func
    def cycle(
        block: int,
        t: int,
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
        listed: wp.array2d(dtype=wp.int32),
        local: wp.array2d(dtype=wp.int32),
        offsets: wp.array(dtype=wp.int32),
        mask: wp.array(dtype=vec),
        strength: wp.float32,
    ):
        g = t // 32
        lane = t % 32
        m = metric[0]
        pull = strength * mask[0]
        parts.stage_controls(controls, n_controls, t)
        wait_for_previous_grid()
        s = cycle_in[0]
        row = wp.int32(parts.lane_key(keys, s, n_controls, lane) & INDEX_MASK)
        x = chunk_neurons()
        for ch in range(chunks):
            x[ch] = listed[block, ch * 32 + lane]
        first = block * 32
        n = weights_in.shape[0]
        u = wp.min(first + lane, n - 1)
        near = near_ones()
        for j in range(width):
            near[j] = local[u, j]
        count = offsets[u + 1] - offsets[u]
        w = weights_in[listed[block, wp.min(g, chunks - 1) * 32 + lane]]  # the neuron this thread moves
        hop = hop_counts()
        for ch in range(chunks):  # unrolled: the reads overlap
            for j in range(per_warp):
                hop[ch, j] = hops(distances, warp_shuffle(row, wp.min(g + warps * j, n_controls - 1)), x[ch])
        parts.stage_table_row(table, s, t)
        sync_block()
        for ch in range(chunks):
            for j in range(per_warp):
                c = g + warps * j
                parts.stage_rate(table, s, hop[ch, j], c, n_controls, (ch * slots + c) * 32 + lane)
        sync_block()
        if g < chunks:
            w = parts.apply_rates(w, g * slots * 32 + lane)
            for j in range(n_dims):
                shared_set_float(moved_at + (g * 32 + lane) * n_dims + j, w[j])
        sync_block()
        smooth = moved_weight(lane)
        if count > 0:
            total = vec()
            for j in range(width):  # the neighbours in the topology's order; past the last, + 0 changes nothing
                total += wp.where(j < count, moved_weight(wp.max(near[j], 0)), vec())
            smooth = smooth + wp.cw_mul(pull, total / wp.float32(count) - smooth)
        let_next_grid_launch()
        if g == 0 and first + lane < n:
            weights_out[first + lane] = smooth
        parts.publish_winners(keys, s, n_controls, smooth, m, first, block, t)
        if block == 0 and t == 0:
            cycle_out[0] = s + 1

    @wp.kernel(enable_backward=False, module="unique", module_options={"max_unroll": 32})
    def move_smooth_spread(
        weights_in: wp.uint64,
        weights_out: wp.uint64,
        n: int,
        controls: wp.uint64,
        n_controls: int,
        metric: wp.uint64,
        table: wp.uint64,
        table_rows: int,
        table_columns: int,
        distances: wp.uint64,
        keys: wp.uint64,
        key_columns: int,
        cycle_in: wp.uint64,
        cycle_out: wp.uint64,
        listed: wp.uint64,
        blocks: int,
        local: wp.uint64,
        offsets: wp.uint64,
        mask: wp.uint64,
        strength: wp.float32,
    ):
        block, t = wp.tid()
        scratch = wp.tile_empty(shape=(words,), dtype=wp.float32, storage="shared")  # noqa: F841 (used by word)
        cycle(block, t, wp.array(ptr=weights_in, shape=(n,), dtype=vec),
              wp.array(ptr=weights_out, shape=(n,), dtype=vec),
              wp.array(ptr=controls, shape=(n_controls,), dtype=vec), n_controls,
              wp.array(ptr=metric, shape=(1,), dtype=vec),
              wp.array(ptr=table, shape=(table_rows, table_columns), dtype=wp.float32),
              wp.array(ptr=distances, shape=(n, n), dtype=wp.uint16),
              wp.array(ptr=keys, shape=(3, key_columns), dtype=wp.uint64),
              wp.array(ptr=cycle_in, shape=(1,), dtype=wp.int32), wp.array(ptr=cycle_out, shape=(1,), dtype=wp.int32),
              wp.array(ptr=listed, shape=(blocks, chunks * 32), dtype=wp.int32),
              wp.array(ptr=local, shape=(n, width), dtype=wp.int32),
              wp.array(ptr=offsets, shape=(n + 1,), dtype=wp.int32), wp.array(ptr=mask, shape=(1,), dtype=vec),
              strength)

    return move_smooth_spread


def spread_smoothing_cycle_inputs(weights_in: wp.array, weights_out: wp.array, controls: wp.array, n_controls: int,
                                  metric: wp.array, table: wp.array, distances: wp.array, keys: wp.array,
                                  cycle_in: wp.array, cycle_out: wp.array, listed: wp.array, local: wp.array,
                                  offsets: wp.array, mask: wp.array, strength: float) -> list:
    """The parameters of `spread_smoothing_cycle_kernel`'s kernel for these arrays (listed and local: halos.py's
    BlockHalos), which must outlive any graph that captures the launch."""
    _contiguous(weights_in, weights_out, controls, metric, table, distances, keys, cycle_in, cycle_out, listed, local,
                offsets, mask)
    return [weights_in.ptr, weights_out.ptr, weights_in.shape[0], controls.ptr, n_controls, metric.ptr, table.ptr,
            table.shape[0], table.shape[1], distances.ptr, keys.ptr, keys.shape[1], cycle_in.ptr, cycle_out.ptr,
            listed.ptr, listed.shape[0], local.ptr, offsets.ptr, mask.ptr, strength]
