"""The batched engine's kernel for controls with a radius of influence (batch.py): B variants of one mesh, a block of
threads per variant, a whole run in one launch, by the shaping rules of shaping_kernels.py (BENCHMARKS.md, "Shaping
rules", Choice).

A control of radius r > 0 carries the clay around its winner u (the node it grabbed at the restart): W_v += alpha(s)
g(v) (C - W_u), g = exp(-|x_v - x_u|^2 / (2 sigma^2)) of the rest positions (the variant's weights where its run
restarted), 0 in another connected part; sigma = max(r / 2, sqrt(h e / FIT_TURN)), fitted at the restart's first cycle
from the control's distance h from its winner and the start mesh's median edge e. A control of radius 0 keeps the
paper's rule, W_v += L[s, D[u, v]] (C - W_v). A control and its mirrored copy act as one group, scaled by 1 / max(1, sum
of their rates and falloffs); a group of carrying controls leaves v as it is where alpha sum_j g_j |C_j - W_uj| (largest
dim) is below the variant's floor (shaping_kernels.CARRY_CUT of the start shape's size). Radial groups and strokes are
not here: variants with them run as single Soms (variants.run_plan).

A cycle, as shaping_path.py runs it for one Som, in one block:
1. winners from the weights before the cycle (each thread its neurons, the block's least winner key: batch_kernels'
   keys, shared memory on CUDA); a barrier;
2. gather: each control's winner index and weights W_u, its largest offset |C - W_u|, and at the restart's first
   cycle its fitted 1 / (2 sigma^2); a carrying control keeps the winner it grabbed at the restart's first cycle
   (shaping_kernels.hold), a point control takes the one just found; a barrier (the move must not read a winner
   another thread already moved);
3. move: each thread moves its neurons group by group (the arithmetic of shaping_kernels.moved_by_group);
4. smoothing: one Jacobi step of lambda, and with `taubin` Taubin's mu after it (batch_kernels' steps).
At the first cycle of a restarted variant (`fresh`) its weights are first copied to its rest positions.
"""

import functools

import warp as wp

from .batch_kernels import _SHARED_WORDS, rate, read_key, variant_funcs
from .primitives import INDEX_MASK, sync_block
from .shaping_kernels import FIT_TURN


@functools.cache
def shaping_variants_kernel(n_dims: int, pairs: bool, cuda: bool, threads: int = 1024, min_blocks: int = 1,
                            searched: int = 4, unit_metric: bool = False, taubin: bool = False):
    """The kernel for weights of n_dims features; with `pairs` the effective controls come as mirrored pairs (each
    original next to its copy: a group of two), else each control is a group of one. `cuda`, `threads`,
    `min_blocks`, `searched`, `unit_metric`, `taubin`: as batch_kernels.variants_kernel's."""
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)
    order = 2 if pairs else 1
    options = {"max_unroll": 32}
    steps = variant_funcs(n_dims, searched, unit_metric, taubin)

    @wp.func
    def moved_by_group(w: vec, b: int, v: int, lo: int, rest: wp.array2d(dtype=vec),
                       controls: wp.array2d(dtype=vec), winners: wp.array2d(dtype=vec),
                       winner: wp.array2d(dtype=wp.int32), inv_two_sigma2: wp.array2d(dtype=wp.float32),
                       largest: wp.array2d(dtype=wp.float32), component: wp.array(dtype=wp.int32),
                       tables: wp.array2d(dtype=wp.float32), row: int, distances: wp.array2d(dtype=wp.uint16),
                       position: vec, floor: wp.float32) -> vec:
        """Step 2 of the group lo .. lo + order - 1 for variant b's neuron v of weights w (the module's docstring;
        the same operations in the same order as shaping_kernels.moved_by_group)."""
        alpha = tables[row, 0]
        step = vec()
        total = wp.float32(0.0)
        carried = wp.float32(0.0)
        pulled = int(0)
        for j in range(lo, lo + wp.static(order)):
            u = winner[b, j]
            k = inv_two_sigma2[b, j]
            if k == wp.float32(0.0):  # the paper's point control: towards the control
                r = rate(tables, row, distances[u, v])
                step += r * (controls[b, j] - w)
                total += r
                pulled = wp.where(r > wp.float32(0.0), 1, pulled)
            elif component[u] == component[v]:  # a control with a radius: along with its winner
                apart = wp.cw_mul(rest[b, v] - rest[b, u], position)
                falloff = wp.exp(-k * wp.dot(apart, apart))
                step += (alpha * falloff) * (controls[b, j] - winners[b, j])
                total += falloff
                carried += falloff * largest[b, j]
        if pulled == 0 and alpha * carried < floor:
            return w
        if wp.static(pairs):
            step = step / wp.max(wp.float32(1.0), total)
        return w + step

    @wp.kernel(enable_backward=False, module="unique", module_options=options, launch_bounds=(threads, min_blocks))
    def train_shaping_variants(
        weights: wp.array2d(dtype=vec),
        moved: wp.array2d(dtype=vec),
        rest: wp.array2d(dtype=vec),
        controls: wp.array2d(dtype=vec),
        n_controls: int,
        metric: wp.array(dtype=vec),
        mask: wp.array(dtype=vec),
        tables: wp.array2d(dtype=wp.float32),
        table_row: wp.array(dtype=wp.int32),
        smoothing: wp.array(dtype=wp.float32),
        second: wp.array(dtype=wp.float32),
        s_from: wp.array(dtype=wp.int32),
        s_to: wp.array(dtype=wp.int32),
        fresh: wp.array(dtype=wp.int32),
        distances: wp.array2d(dtype=wp.uint16),
        offsets: wp.array(dtype=wp.int32),
        neighbors: wp.array(dtype=wp.int32),
        component: wp.array(dtype=wp.int32),
        sigma: wp.array(dtype=wp.float32),
        edge: wp.array(dtype=wp.float32),
        floor: wp.array(dtype=wp.float32),
        position: vec,
        winner: wp.array2d(dtype=wp.int32),
        winners: wp.array2d(dtype=vec),
        largest: wp.array2d(dtype=wp.float32),
        inv_two_sigma2: wp.array2d(dtype=wp.float32),
        keys: wp.array(dtype=wp.uint64),
        first: int,
    ):
        """Cycles s_from[b] .. s_to[b] - 1 of variant b = first + block by the shaping rules; with fresh[b] the run
        restarted: the weights become the rest positions and the first cycle fits each carrying control's width.
        `winner`, `winners`, `largest`, `inv_two_sigma2` hold each control's winner, its weights, its largest
        offset and its falloff (kept from one launch to the next); `keys` the winner keys on the CPU."""
        block, t = wp.tid()
        b = first + block
        threads = wp.block_dim()
        if wp.static(cuda):
            reserved = wp.tile_zeros(shape=(_SHARED_WORDS,), dtype=wp.int32, storage="shared")  # noqa: F841 (keys)
        n = weights.shape[1]
        k = n_controls
        base = b * 3 * k  # the variant's keys in `keys` (CPU only)
        m = metric[0]
        lam = smoothing[b]
        into_moved = int(lam > wp.float32(0.0))
        row0 = table_row[b]
        floor_b = floor[b]
        fit = fresh[b]
        if fit != 0:
            for v in range(t, n, threads):
                rest[b, v] = weights[b, v]
        steps.start_run(keys, base, s_from[b], k, t)
        for s in range(s_from[b], s_to[b]):
            buf = (s % 3) * k
            steps.find_winners(weights, controls, b, k, m, t, threads, keys, base, s)  # 1. winners from W(s)
            # 2. each control's winner, its weights and offset before any move; at a restart its falloff's width
            for c in range(t, k, threads):
                u = int(read_key(keys, base, buf + c) & INDEX_MASK)
                if fit == 0 and inv_two_sigma2[b, c] > wp.float32(0.0):  # a carrying control keeps its grabbed node
                    u = winner[b, c]
                w_u = weights[b, u]
                winner[b, c] = u
                winners[b, c] = w_u
                apart = controls[b, c] - w_u
                most = wp.float32(0.0)
                for i in range(wp.static(n_dims)):
                    most = wp.max(most, wp.abs(apart[i]))
                largest[b, c] = most
                if fit != 0:  # shaping_kernels.fit
                    s_min = sigma[c]
                    if s_min > wp.float32(0.0):
                        along = wp.cw_mul(apart, position)
                        width = wp.max(s_min, wp.sqrt(wp.length(along) * edge[b] / wp.float32(FIT_TURN)))
                        inv_two_sigma2[b, c] = wp.float32(1.0) / (wp.float32(2.0) * width * width)
                    else:
                        inv_two_sigma2[b, c] = wp.float32(0.0)
            fit = 0
            sync_block()
            # 3. every neuron applies the groups in list order
            row = row0 + s
            for v in range(t, n, threads):
                w = weights[b, v]
                for g in range(0, k, wp.static(order)):
                    w = moved_by_group(w, b, v, g, rest, controls, winners, winner, inv_two_sigma2, largest,
                                       component, tables, row, distances, position, floor_b)
                if into_moved != 0:
                    moved[b, v] = w
                else:
                    weights[b, v] = w
            if into_moved != 0:  # 4. smoothing from the moved weights (and Taubin's second step)
                steps.smooth(weights, moved, b, t, threads, offsets, neighbors, lam * mask[0], second[b] * mask[0])

    return train_shaping_variants
