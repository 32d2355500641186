"""Grid distances by BFS on the device: the dense table's rows, distance rows on demand for the current winners (in
blocks, in shared memory where the graph fits), and connected components.
"""

import functools

import warp as wp

from .primitives import UNREACHABLE, shared_add, shared_get, shared_or, shared_set, sync_block


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
    levels: int,
):
    """A breadth-first search per thread b into rows[slots[b]] from the sources first[b] .. first[b + 1] - 1 (the
    hops to the nearest of them, up to `levels`; -1 where none is reachable so). far[b]: the largest distance
    found."""
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
        if du >= levels:
            continue
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
