"""The cycle of small meshes on CUDA with up to 32 controls: `spread_cycle_kernel` spreads the controls over the
warps of a block, and with smoothing `spread_smoothing_cycle_kernel` keeps the cycle in one kernel by moving each
block's halo too (halos.py). They take raw pointers rather than Warp arrays (fewer bytes of parameters to read at
each launch).
"""

import functools
from types import SimpleNamespace

import warp as wp

from .cycle_kernels import SINGLES, cycle_kernels, row_missing
from .primitives import (
    INDEX_MASK,
    KEY_NONE,
    UNREACHABLE,
    float_bits,
    let_next_grid_launch,
    shared_get_float,
    shared_set_float,
    sync_block,
    sync_block_any,
    wait_for_previous_grid,
    warp_least_key,
    warp_shuffle,
)
from .smoothing_kernels import laplacian_step

#: Words of the learning table's row s that a spread cycle kernel copies into shared memory (tables with longer rows
#: are read from global memory instead).
SHARED_TABLE_WORDS = 1024


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
    (smoothing_kernels.laplacian_step, the sums in `smoothed`'s order), and lets the next kernel launch (H200:
    2.84 -> 2.78 us). Step 1 of cycle s + 1 from the smoothed weights. Only the controls, metric and mask are read
    before the wait: the block's lists read there too made the cycle slower (H200, with Warp array parameters: 3.22
    against 3.13 us).
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
            smooth = laplacian_step(smooth, total, count, pull)
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
