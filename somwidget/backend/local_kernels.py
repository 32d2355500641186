"""The CPU's local cycle kernels (local_path.py runs them): the neurons in blocks of BLOCK consecutive indices and the
blocks in superblocks of SUPER, each with the bounding box of its weights, so that a cycle touches only the blocks
it changes and searches only the blocks that may hold a winner, looking at a block only where its superblock may
matter (the cost of a cycle: the neurons it moves and searches, plus N / (BLOCK x SUPER) per control). Every result
is the full computation's, bit for bit:

- `find`: u_c = argmin_v sum_j m_j (C_cj - W_vj)^2 (the lowest index on a tie), by the smallest winner key. The
  search starts in the block of the control's last winner, then scans every block whose box (and its superblock's)
  may hold a nearer neuron: a box's lower bound sum_j m_j gap_j^2 (gap_j: how far C_cj lies outside the box's range
  of dim j) never exceeds the distance of a neuron inside it (float rounding is monotonic; BOUND_SLACK covers a
  different rounding of the sums), so a skipped block holds no neuron whose key could win. A superblock's box holds
  its blocks' boxes (it grows with them as they move, and is made tight again once a run).
- `move`: step 2 of the paper's rule for the blocks with a neuron within reach_hops[s] hops of a winner (the rates
  past it are 0 in the cut table, schedule.NEIGHBOURHOOD_CUT), each neuron applying the controls in list order (with
  mirroring, pair by pair) exactly as cycle_kernels' move does, then the block's box again.
- `boxes`: the boxes of a range of superblocks from the weights (after smoothing, or when the weights were
  replaced); `tighten`: the superblocks' boxes from their blocks'.
- `search_row` (distance rows on the CPU): a winner's row up to a depth, with the least hop count of each block and
  superblock, which tell `move` where the winner's rates are non-zero.
"""

import functools
from types import SimpleNamespace

import warp as wp

from .cycle_kernels import SINGLES, cycle_kernels
from .primitives import FLOAT_MAX, INDEX_MASK, bits_float, winner_key

#: Neurons a block: its box is kept with it, and a cycle moves or searches whole blocks.
BLOCK = wp.constant(64)
#: Blocks a superblock (4,096 neurons): a cycle looks at a block only where its superblock's box or least hop count
#: says it may matter.
SUPER = wp.constant(64)
#: A block is searched unless its box's bound exceeds the best distance found times this (the bound and a neuron's
#: distance are sums of the same squares, rounded the same way up to the order of n <= 32 terms: a relative error
#: under 1e-5), plus BOUND_TINY (distances that underflow).
BOUND_SLACK = wp.constant(wp.float32(1.0001))
BOUND_TINY = wp.constant(wp.float32(1e-30))
#: Controls whose rates a neuron looks up together (kept in registers for a block).
GATHER = 8
#: No winner's row reaches this far: a block with no neuron within a row's searched depth.
FAR = wp.constant(1 << 30)


def block_count(n_neurons: int) -> int:
    """Blocks of BLOCK neurons covering n_neurons."""
    return -(-n_neurons // int(BLOCK))


def super_count(n_neurons: int) -> int:
    """Superblocks of SUPER blocks covering n_neurons."""
    return -(-block_count(n_neurons) // int(SUPER))


@wp.func
def blocks_of(sb: int, n_blocks: int) -> wp.vec2i:
    """The blocks of superblock sb: [first, end)."""
    return wp.vec2i(sb * SUPER, wp.min(sb * SUPER + SUPER, n_blocks))


@wp.kernel(enable_backward=False)
def search_row(offsets: wp.array(dtype=wp.int32), neighbors: wp.array(dtype=wp.int32), source: int, slot: int,
               rows: wp.array2d(dtype=wp.int32), near: wp.array2d(dtype=wp.int32),
               super_near: wp.array2d(dtype=wp.int32), queue: wp.array(dtype=wp.int32), depth: int, fresh: int):
    """rows[slot]: the hops from `source` up to `depth` (-1 past it); near[slot, b] and super_near[slot, sb]: the
    least of them in block b and superblock sb (FAR for none). A breadth-first search that costs what it visits: the
    row's earlier entries are cleared block by block where its earlier `near` says it had any (all of it when
    `fresh`, a slot never used)."""
    n = rows.shape[1]
    n_blocks = near.shape[1]
    if fresh != 0:
        for v in range(n):
            rows[slot, v] = -1
        for b in range(n_blocks):
            near[slot, b] = FAR
    else:
        for sb in range(super_near.shape[1]):
            if super_near[slot, sb] < FAR:
                span = blocks_of(sb, n_blocks)
                for b in range(span[0], span[1]):
                    if near[slot, b] < FAR:
                        for v in range(b * BLOCK, wp.min(b * BLOCK + BLOCK, n)):
                            rows[slot, v] = -1
                        near[slot, b] = FAR
    for sb in range(super_near.shape[1]):
        super_near[slot, sb] = FAR
    rows[slot, source] = 0
    near[slot, source // BLOCK] = 0
    super_near[slot, source // (BLOCK * SUPER)] = 0
    queue[0] = source
    head = int(0)
    tail = int(1)
    while head < tail:
        u = queue[head]
        head += 1
        du = rows[slot, u]
        if du < depth:
            for e in range(offsets[u], offsets[u + 1]):
                w = neighbors[e]
                if rows[slot, w] < 0:
                    rows[slot, w] = du + 1
                    b = w // BLOCK
                    near[slot, b] = wp.min(near[slot, b], du + 1)
                    super_near[slot, b // SUPER] = wp.min(super_near[slot, b // SUPER], du + 1)
                    queue[tail] = w
                    tail += 1


@functools.cache
def local_kernels(n_dims: int, pairs: int = SINGLES) -> SimpleNamespace:
    """The local cycle's kernels for weights of n_dims features; with `pairs` the controls come as mirrored pairs
    (cycle_kernels.PAIRS, SCALED_PAIRS)."""
    vec = wp.types.vector(length=n_dims, dtype=wp.float32)
    held = wp.types.matrix(shape=(GATHER, n_dims), dtype=wp.float32)
    slots8 = wp.types.vector(length=GATHER, dtype=wp.int32)
    cycle = cycle_kernels(n_dims, 8, pairs)
    distance, move_pair = cycle.distance, cycle.move_pair
    options = {"max_unroll": 32}

    @wp.func
    def box_bound(target: vec, lo: vec, hi: vec, metric: vec) -> wp.float32:
        """A lower bound of the metric distance from target to any point of the box [lo, hi]."""
        gap = wp.max(wp.max(lo - target, target - hi), vec())
        return wp.dot(wp.cw_mul(gap, metric), gap)

    @wp.func
    def nearest_in_block(weights: wp.array(dtype=vec), target: vec, metric: vec, b: int) -> wp.uint64:
        """The smallest winner key of block b's neurons for target."""
        lo = b * BLOCK
        hi = wp.min(lo + BLOCK, weights.shape[0])
        best = FLOAT_MAX
        best_v = lo
        for v in range(lo, hi):
            dist = distance(target, weights[v], metric)
            nearer = dist < best  # strict: the lowest index wins a tie
            best = wp.where(nearer, dist, best)
            best_v = wp.where(nearer, v, best_v)
        return winner_key(best, best_v)

    @wp.func
    def update_box(weights: wp.array(dtype=vec), lo_box: wp.array(dtype=vec), hi_box: wp.array(dtype=vec), b: int):
        """Block b's box from its neurons' weights."""
        lo = b * BLOCK
        hi = wp.min(lo + BLOCK, weights.shape[0])
        w = weights[lo]
        low = w
        high = w
        for v in range(lo + 1, hi):
            w = weights[v]
            low = wp.min(low, w)
            high = wp.max(high, w)
        lo_box[b] = low
        hi_box[b] = high

    @wp.func
    def moved_block(weights: wp.array(dtype=vec), lo_box: wp.array(dtype=vec), hi_box: wp.array(dtype=vec),
                    super_lo: wp.array(dtype=vec), super_hi: wp.array(dtype=vec), moved: wp.array(dtype=wp.int32),
                    super_moved: wp.array(dtype=wp.int32), b: int):
        """After block b moved: its box again, its superblock's grown to hold it, both marked moved."""
        update_box(weights, lo_box, hi_box, b)
        sb = b // SUPER
        super_lo[sb] = wp.min(super_lo[sb], lo_box[b])
        super_hi[sb] = wp.max(super_hi[sb], hi_box[b])
        moved[b] = 1
        super_moved[sb] = 1

    @wp.func
    def tighten_super(lo_box: wp.array(dtype=vec), hi_box: wp.array(dtype=vec), super_lo: wp.array(dtype=vec),
                      super_hi: wp.array(dtype=vec), sb: int):
        span = blocks_of(sb, lo_box.shape[0])
        low = lo_box[span[0]]
        high = hi_box[span[0]]
        for b in range(span[0] + 1, span[1]):
            low = wp.min(low, lo_box[b])
            high = wp.max(high, hi_box[b])
        super_lo[sb] = low
        super_hi[sb] = high

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def boxes(weights: wp.array(dtype=vec), lo_box: wp.array(dtype=vec), hi_box: wp.array(dtype=vec),
              super_lo: wp.array(dtype=vec), super_hi: wp.array(dtype=vec), sb_lo: int, sb_hi: int):
        """The boxes of superblocks sb_lo .. sb_hi - 1 and of their blocks."""
        for sb in range(sb_lo, sb_hi):
            span = blocks_of(sb, lo_box.shape[0])
            for b in range(span[0], span[1]):
                update_box(weights, lo_box, hi_box, b)
            tighten_super(lo_box, hi_box, super_lo, super_hi, sb)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def tighten(lo_box: wp.array(dtype=vec), hi_box: wp.array(dtype=vec), super_lo: wp.array(dtype=vec),
                super_hi: wp.array(dtype=vec)):
        """Every superblock's box from its blocks' (as tight as they are)."""
        for sb in range(super_lo.shape[0]):
            tighten_super(lo_box, hi_box, super_lo, super_hi, sb)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def find(weights: wp.array(dtype=vec), controls: wp.array(dtype=vec), first: int, step: int, n_controls: int,
             metric: wp.array(dtype=vec), keys: wp.array(dtype=wp.uint64), hint_at: int, out_at: int,
             lo_box: wp.array(dtype=vec), hi_box: wp.array(dtype=vec), super_lo: wp.array(dtype=vec),
             super_hi: wp.array(dtype=vec)):
        """Step 1 for controls first, first + step, ...: each one's winner key into keys[out_at + c], starting from the
        block of the neuron in keys[hint_at + c] (any value will do: it only speeds the search)."""
        m = metric[0]
        n = weights.shape[0]
        n_blocks = lo_box.shape[0]
        for c in range(first, n_controls, step):
            target = controls[c]
            hint = wp.int32(keys[hint_at + c] & INDEX_MASK)
            start = wp.where(hint >= 0 and hint < n, hint, 0) // BLOCK
            best = nearest_in_block(weights, target, m, start)
            best_d = bits_float(wp.uint32(best >> wp.uint64(32)))
            for sb in range(super_lo.shape[0]):
                if box_bound(target, super_lo[sb], super_hi[sb], m) <= best_d * BOUND_SLACK + BOUND_TINY:
                    span = blocks_of(sb, n_blocks)
                    for b in range(span[0], span[1]):
                        if b != start:
                            if box_bound(target, lo_box[b], hi_box[b], m) <= best_d * BOUND_SLACK + BOUND_TINY:
                                key = nearest_in_block(weights, target, m, b)
                                if key < best:
                                    best = key
                                    best_d = bits_float(wp.uint32(best >> wp.uint64(32)))
            keys[out_at + c] = best

    @wp.func
    def within_reach(near: wp.array2d(dtype=wp.int32), slot_of: wp.array(dtype=wp.int32),
                     keys: wp.array(dtype=wp.uint64), at: int, c_lo: int, c_hi: int, b: int, reach: int) -> int:
        """1 when block (or superblock, with super_near for near) b holds a neuron within `reach` hops of a winner
        of controls c_lo .. c_hi - 1."""
        for c in range(c_lo, c_hi):
            if near[slot_of[wp.int32(keys[at + c] & INDEX_MASK)], b] <= reach:
                return 1
        return 0

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def move(weights: wp.array(dtype=vec), controls: wp.array(dtype=vec), c_lo: int, c_hi: int,
             table: wp.array2d(dtype=wp.float32), s: int, reach_hops: wp.array(dtype=wp.int32),
             rows: wp.array2d(dtype=wp.int32), slot_of: wp.array(dtype=wp.int32), near: wp.array2d(dtype=wp.int32),
             super_near: wp.array2d(dtype=wp.int32), keys: wp.array(dtype=wp.uint64), at: int,
             lo_box: wp.array(dtype=vec), hi_box: wp.array(dtype=vec), super_lo: wp.array(dtype=vec),
             super_hi: wp.array(dtype=vec), moved: wp.array(dtype=wp.int32), super_moved: wp.array(dtype=wp.int32),
             sb_lo: int, sb_hi: int, every: int):
        """Step 2 of cycle s for controls c_lo .. c_hi - 1 (winners in keys[at + c], their rows cached with `near`
        and `super_near`: each block's and superblock's least hop count) in the blocks of superblocks
        sb_lo .. sb_hi - 1 that hold a neuron within reach (all of them with `every`), in place; then those blocks'
        boxes (`moved_block`)."""
        last = table.shape[1] - 1
        reach = reach_hops[s]
        n = weights.shape[0]
        for sb in range(sb_lo, sb_hi):
            if every == 0 and within_reach(super_near, slot_of, keys, at, c_lo, c_hi, sb, reach) == 0:
                continue
            span = blocks_of(sb, lo_box.shape[0])
            for b in range(span[0], span[1]):
                if every != 0 or within_reach(near, slot_of, keys, at, c_lo, c_hi, b, reach) != 0:
                    v_lo = b * BLOCK
                    v_hi = wp.min(v_lo + BLOCK, n)
                    for c0 in range(c_lo, c_hi, GATHER):
                        targets = held()
                        slots = slots8()
                        for g in range(GATHER):
                            c = wp.min(c0 + g, c_hi - 1)
                            targets[g] = controls[c]
                            slots[g] = wp.where(c0 + g < c_hi, slot_of[wp.int32(keys[at + c] & INDEX_MASK)], -1)
                        for v in range(v_lo, v_hi):
                            w = weights[v]
                            if wp.static(pairs != SINGLES):
                                for g in range(0, GATHER, 2):
                                    if slots[g] >= 0:
                                        da = rows[slots[g], v]
                                        db = rows[slots[g + 1], v]
                                        ra = wp.where(da >= 0, table[s, wp.min(da, last)], wp.float32(0.0))
                                        rb = wp.where(db >= 0, table[s, wp.min(db, last)], wp.float32(0.0))
                                        w = move_pair(w, ra, rb, targets[g], targets[g + 1])
                            else:
                                for g in range(GATHER):
                                    if slots[g] >= 0:
                                        d = rows[slots[g], v]
                                        rate = wp.where(d >= 0, table[s, wp.min(d, last)], wp.float32(0.0))
                                        w = w + rate * (targets[g] - w)
                            weights[v] = w
                    moved_block(weights, lo_box, hi_box, super_lo, super_hi, moved, super_moved, b)

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def back_to_anchor(weights: wp.array(dtype=vec), anchor: wp.array(dtype=vec), lo_box: wp.array(dtype=vec),
                       hi_box: wp.array(dtype=vec), super_lo: wp.array(dtype=vec), super_hi: wp.array(dtype=vec),
                       anchor_lo: wp.array(dtype=vec), anchor_hi: wp.array(dtype=vec),
                       anchor_super_lo: wp.array(dtype=vec), anchor_super_hi: wp.array(dtype=vec),
                       moved: wp.array(dtype=wp.int32), super_moved: wp.array(dtype=wp.int32)):
        """The anchored weights and boxes back into the blocks marked `moved` (the others hold them still), and the
        superblocks' anchored boxes."""
        n = weights.shape[0]
        for sb in range(super_moved.shape[0]):
            if super_moved[sb] != 0:
                span = blocks_of(sb, moved.shape[0])
                for b in range(span[0], span[1]):
                    if moved[b] != 0:
                        for v in range(b * BLOCK, wp.min(b * BLOCK + BLOCK, n)):
                            weights[v] = anchor[v]
                        lo_box[b] = anchor_lo[b]
                        hi_box[b] = anchor_hi[b]
                        moved[b] = 0
                super_lo[sb] = anchor_super_lo[sb]
                super_hi[sb] = anchor_super_hi[sb]
                super_moved[sb] = 0

    return SimpleNamespace(vec=vec, box_bound=box_bound, nearest_in_block=nearest_in_block, update_box=update_box,
                           moved_block=moved_block, boxes=boxes, tighten=tighten, find=find, move=move,
                           back_to_anchor=back_to_anchor)
