"""Mesh topology: faces or edges -> undirected adjacency (CSR) -> BFS grid distances (paper section III-D).

Up to 65,536 vertices the distances form one dense uint16 table. Past that the engine computes distance rows on
demand for its current winners (`RowSearch`, int32), and d_max comes from an exact diameter search (`diameter`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import warp as wp

from . import checks, distance_kernels
from .device import resolve, warp_exclusive

#: Vertices a topology may have (int32 CSR indices; rows mode trains meshes of millions of vertices).
MAX_VERTICES = 1 << 27
#: The dense distance table holds at most 2^16 neurons (the paper's cap: 8 GiB of uint16).
MAX_DENSE_NEURONS = 65536
UNREACHABLE = 65535
#: Rows computed per BFS launch; bounds the int32 queue to BATCH x N entries.
_BFS_BATCH = 4096
#: Threads per search of the dense build on CUDA (a block each), least and most; see Topology._block_threads.
_BLOCK_THREADS = (32, 256)
#: Bytes of scratch (an int32 row of hops and one of queue per block) the dense build on CUDA may hold.
_BLOCK_SCRATCH_BYTES = 2 << 30
#: Bytes of BFS queue a RowSearch may hold (a row's queue has N int32 entries).
_QUEUE_BYTES = {"cpu": 64 << 20, "cuda": 512 << 20}
#: Threads per row of a level-synchronous search on CUDA; they share out each level's vertices.
_LEVEL_THREADS = 1024
#: Threads of a block-per-row search on CUDA, and the widest mean level (vertices / levels) it takes: a block per row
#: runs every level in one launch, so it wins wherever levels are narrow enough for one SM (see RowSearch.method).
_ROW_BLOCK_THREADS = 512
_ROW_BLOCK_WIDEST = 16 * _ROW_BLOCK_THREADS
#: The shared-memory row search: threads per block, and vertices of a level kept in shared memory (most, and the
#: least worth it; a wider level spills the rest to global memory).
_SHARED_THREADS = 512
_SHARED_FRONTIER_MOST = 8192
_SHARED_FRONTIER_LEAST = 1024
#: A level launch costs about as much as a thread visiting this many vertices and edges (see RowSearch.method);
#: on an H200, 1M-vertex grid: a level 7 us, a thread 0.17 us per vertex or edge.
_LEVEL_COST = 40
#: iFUB rounds (one search per component each) run on the CPU before batches move to a CUDA device.
_ROUNDS_ON_CPU = 4
#: Centres tried per component in the diameter search (each costs two BFS sweeps).
_CENTRE_TRIES = 3


class Topology:
    """The neurons (vertices) and synapses (edges) of the map. Build with `from_faces` or `from_edges`."""

    def __init__(self, n_vertices: int, edges: np.ndarray, faces: Sequence[np.ndarray] | None = None) -> None:
        self.n_vertices = int(n_vertices)
        self.edges = edges
        self.faces = faces
        both = np.concatenate([edges, edges[:, ::-1]]) if len(edges) else np.zeros((0, 2), np.int64)
        order = np.lexsort((both[:, 1], both[:, 0]))
        both = both[order]
        counts = np.bincount(both[:, 0], minlength=self.n_vertices) if len(both) else np.zeros(self.n_vertices, int)
        self.offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        self.neighbors = both[:, 1].astype(np.int32)
        self._tables: dict[str, wp.array] = {}
        self._d_max: int | None = None

    # -- construction -------------------------------------------------------------------------------------
    @classmethod
    def from_faces(cls, faces, n_vertices: int | None = None) -> Topology:
        """Faces of any size (triangles, quads, n-gons), as a list of index sequences or an (F, k) int array.

        Each face's consecutive vertices and its closing pair are edges; duplicates and self-loops are dropped. An
        array is kept as it is (`Faces`: no Python object per face, which a mesh of millions would take seconds to
        make).
        """
        if isinstance(faces, np.ndarray):
            arr = checks.index_array("faces", faces)
            if arr.ndim != 2:
                raise ValueError(f"faces: an array of faces must have shape (F, k), got {arr.shape}")
            n = _vertex_count(arr.ravel(), n_vertices, "faces")
            pairs = np.stack([arr.ravel(), np.roll(arr, -1, axis=1).ravel()], axis=1)
            return cls(n, _clean_edges(pairs), Faces(arr))
        face_list = _face_list(faces)
        flat = np.concatenate(face_list) if face_list else np.zeros(0, np.int64)
        n = _vertex_count(flat, n_vertices, "faces")
        sizes = np.array([len(f) for f in face_list], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]) if len(sizes) else sizes
        nxt = np.arange(1, len(flat) + 1)
        last = starts + sizes - 1
        nxt[last[sizes > 0]] = starts[sizes > 0]  # closing pair of each face
        edges = _clean_edges(np.stack([flat, flat[nxt]], axis=1) if len(flat) else np.zeros((0, 2), np.int64))
        return cls(n, edges, face_list)

    @classmethod
    def from_edges(cls, edges, n_vertices: int) -> Topology:
        """An (E, 2) integer edge list over `n_vertices` vertices; duplicates and self-loops are dropped."""
        arr = checks.index_array("edges", edges)
        if arr.size == 0:
            arr = arr.reshape(0, 2)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"edges: expected shape (E, 2), got {arr.shape}")
        n = checks.integer("n_vertices", n_vertices, 1)
        _vertex_count(arr.ravel(), n, "edges")
        return cls(n, _clean_edges(arr))

    # -- queries ------------------------------------------------------------------------------------------
    def degree(self) -> np.ndarray:
        return np.diff(self.offsets)

    @property
    def d_max(self) -> int:
        """The largest finite grid distance (0 for a graph without edges): from the dense table up to 65,536
        vertices, from `diameter()` past that."""
        if self._d_max is None:
            if self.n_vertices > MAX_DENSE_NEURONS:
                return self.diameter()
            self.distance_table(None)
        assert self._d_max is not None  # the table sets it
        return self._d_max

    @warp_exclusive
    def diameter(self, device: str | None = None) -> int:
        """d_max without the dense table: exact, by the iFUB method (Crescenzi et al. 2013) over each connected
        component. A few BFS sweeps on the CPU settle most meshes; a highly symmetric one (a torus) can need a
        search from half its vertices, which then run in batches on `device` (None = best available)."""
        if self._d_max is None:
            self._d_max = _diameter(self, resolve(device))
        return self._d_max

    def grid_distances(self) -> np.ndarray:
        """(N, N) uint16 BFS hop counts, 0 on the diagonal, 65535 between separate components."""
        return self.distance_table(None).numpy()

    @warp_exclusive
    def distance_table(self, device: str | None) -> wp.array:
        """The dense table as a Warp array on `device`, computed there once (one BFS per neuron) and cached."""
        device = resolve(device)
        if device in self._tables:
            return self._tables[device]
        if self.n_vertices > MAX_DENSE_NEURONS:
            raise ValueError(
                f"topology: {self.n_vertices:,} vertices exceed the dense distance table's limit of "
                f"{MAX_DENSE_NEURONS:,} (2^16 neurons, 8 GiB of uint16); past that size the engine computes distance "
                "rows on demand for the current winners (Som(..., distances='rows'), its default there), and "
                "Topology.d_max still works; for the whole table use a coarser mesh (decimate it)"
            )
        if self._tables:  # computed on another device already: copy rather than search again
            table = wp.clone(next(iter(self._tables.values())), device=device)
        else:
            table = self._bfs_table(device)
        self._tables[device] = table
        return table

    def _bfs_table(self, device: str, method: str | None = None, threads: int | None = None,
                   blocks: int | None = None) -> wp.array:
        """One BFS per neuron into a new (N, N) uint16 table on `device`; sets d_max.

        method: "thread" = a thread per source, a serial queue each (the CPU's); "block" = a block of threads per
        source, level-synchronous (CUDA's: on an H200, 256 x 256 grid, 0.5 s against 3.8 s for a thread per source).
        None picks by device; tests and benchmarks force one, with `threads` per block and `blocks` at once."""
        n = self.n_vertices
        method = method or ("thread" if device == "cpu" else "block")
        offsets = wp.array(self.offsets, dtype=wp.int32, device=device)
        neighbors = wp.array(self.neighbors if len(self.neighbors) else np.zeros(1, np.int32), dtype=wp.int32,
                             device=device)
        far = wp.zeros(n, dtype=wp.int32, device=device)
        if method == "thread":
            table = wp.full((n, n), UNREACHABLE, dtype=wp.uint16, device=device)
            batch = min(n, _BFS_BATCH)
            queue = wp.empty((batch, n), dtype=wp.int32, device=device)
            sources = wp.array(np.arange(n, dtype=np.int32), device=device)
            for start in range(0, n, batch):
                stop = min(n, start + batch)
                wp.launch(distance_kernels.bfs_rows, dim=stop - start, device=device,
                          inputs=[offsets, neighbors, sources[start:stop], table[start:stop], queue, far[start:stop]])
        elif method == "block":
            threads = threads or self._block_threads()
            blocks = blocks or _block_count(n, threads, device)
            table = wp.empty((n, n), dtype=wp.uint16, device=device)  # every entry is written once
            hops = wp.full((blocks, n), -1, dtype=wp.int32, device=device)
            queue = wp.empty((blocks, n), dtype=wp.int32, device=device)
            size = wp.zeros((blocks, 3), dtype=wp.int32, device=device)
            wp.launch(distance_kernels.bfs_blocks, dim=blocks * threads, block_dim=threads, device=device,
                      inputs=[offsets, neighbors, table, hops, queue, size, far])
        else:
            raise ValueError(f"method: expected None, 'thread' or 'block', got {method!r}")
        d_max = int(far.numpy().max(initial=0))
        if d_max >= UNREACHABLE:
            raise ValueError(f"topology: a grid distance reaches {UNREACHABLE}, which the uint16 table reserves for "
                             "'unreachable'; the graph is a path too long for the dense table")
        self._d_max = d_max
        return table

    def _block_threads(self) -> int:
        """Threads per search of the "block" build: the power of two at or above the vertices per BFS level (N over
        the levels of a search from each component's lowest vertex: one CPU sweep), within _BLOCK_THREADS."""
        _, hops, _ = _components(self)
        width = self.n_vertices / (int(hops.max(initial=0)) + 1)
        lo, hi = _BLOCK_THREADS
        return int(min(hi, max(lo, 1 << max(0, int(np.ceil(np.log2(width)))))))

    def __repr__(self) -> str:
        return f"Topology(n_vertices={self.n_vertices}, edges={len(self.edges)})"


class RowSearch:
    """Distance rows on demand: BFS hop counts (int32, -1 = unreachable) from given sources into rows of a device
    array. On the CPU one search per row (a thread, O(N + E)). On CUDA a block per row, all levels in one launch,
    with its visited set and frontier in shared memory where they fit (up to about 1.8 million vertices on an H200);
    for graphs whose levels are too wide for one SM, the rows of a batch go level by level (a captured graph of
    `levels` launches), or one thread per row where those launches would cost more (see `method`)."""

    def __init__(self, topology: Topology, device: str) -> None:
        self.device = device
        self.n = n = topology.n_vertices
        self._cost = len(topology.neighbors) + n
        #: the adjacency on the device (CSR: offsets, neighbours), which the CPU's row searches read too
        self.offsets = wp.array(topology.offsets, dtype=wp.int32, device=device)
        neighbors = topology.neighbors if len(topology.neighbors) else np.zeros(1, np.int32)
        self.neighbors = wp.array(neighbors, dtype=wp.int32, device=device)
        budget = _QUEUE_BYTES["cpu" if device == "cpu" else "cuda"]
        #: rows per launch (the queue holds a row of N int32 per search)
        self.batch = int(max(1, min(256, budget // (4 * n))))
        self._shared = _shared_plan(n, device)
        #: rows a batch searches in about the time of one: those that run at once on the device
        self.alongside = self.batch if device == "cpu" else min(self.batch, _rows_at_once(self._shared, device))
        if self._shared is not None:  # each vertex's first eight neighbours in one row, padded with -1
            degree = np.diff(topology.offsets)
            k = np.arange(len(topology.neighbors)) - np.repeat(topology.offsets[:-1], degree)
            first8 = k < 8
            ell = np.full((n, 8), -1, np.int32)
            ell[np.repeat(np.arange(n), degree)[first8], k[first8]] = topology.neighbors[first8]
            self._ell = wp.array(ell, dtype=wp.int32, device=device)
        self._buffers: dict[str, wp.array] | None = None
        self._graphs: dict[tuple, object] = {}

    def method(self, levels: int) -> str:
        """How a batch of rows is searched: on the CPU a thread per row ("thread"); on CUDA a block per row running
        every level in one launch where the mean level is narrow, its visited bitmap and frontier in shared memory
        ("shared") or, past what shared memory holds, in global memory ("block"); else a launch per level shared by
        all rows ("levels"), or a thread per row where those `levels` launches cost more than walking the graph."""
        if self.device == "cpu":
            return "thread"
        if self.n <= _ROW_BLOCK_WIDEST * (levels + 1):
            return "block" if self._shared is None else "shared"
        return "levels" if levels * _LEVEL_COST <= self._cost else "thread"

    @warp_exclusive
    def run(self, sources, slots, rows: wp.array, levels: int, far: bool = False) -> np.ndarray | None:
        """rows[slots[i]] = hops to the nearest of sources[i] (a sequence of vertices), -1 where none is reachable.
        levels bounds the depth of every search (d_max will do). far=True returns each row's largest distance."""
        out = [self._run_batch(sources[lo : lo + self.batch], slots[lo : lo + self.batch], rows, levels, far)
               for lo in range(0, len(sources), self.batch)]
        return np.concatenate([o for o in out if o is not None]) if far else None

    def _run_batch(self, sources, slots, rows: wp.array, levels: int, far: bool) -> np.ndarray | None:
        count = len(sources)
        flat = np.concatenate([np.asarray(s, dtype=np.int32).ravel() for s in sources])
        first = np.concatenate([[0], np.cumsum([np.size(s) for s in sources])]).astype(np.int32)
        b = self._buffer()
        b["sources"][: len(flat)].assign(flat)
        b["first"][: count + 1].assign(first)
        b["slots"][:count].assign(np.asarray(slots, dtype=np.int32))
        method = self.method(levels)
        if method == "shared":
            assert self._shared is not None  # method() picks "shared" only where it fits
            words, cap = self._shared
            kernel = distance_kernels.shared_row_search(words, cap, _SHARED_THREADS)
            wp.launch_tiled(kernel, dim=[count], block_dim=_SHARED_THREADS, device=self.device,
                            inputs=[self._ell, self.offsets, self.neighbors, b["sources"], b["first"], b["slots"],
                                    rows, b["queue"], b["far"]])
        elif method == "block":
            wp.launch(distance_kernels.bfs_row_blocks, dim=count * _ROW_BLOCK_THREADS, block_dim=_ROW_BLOCK_THREADS,
                      device=self.device, inputs=[self.offsets, self.neighbors, b["sources"], b["first"], b["slots"],
                                                  rows, b["queue"], b["size"], b["far"]])
        elif method == "levels":
            b["count"].fill_(count)
            key = (levels, rows.ptr)
            graph = self._graphs.get(key)
            if graph is None:
                with wp.ScopedCapture(device=self.device) as capture:
                    self._record_levels(rows, levels)
                graph = self._graphs[key] = capture.graph
            wp.capture_launch(graph)
        else:
            wp.launch(distance_kernels.bfs_wide, dim=count, device=self.device,
                      inputs=[self.offsets, self.neighbors, b["sources"], b["first"], b["slots"], rows, b["queue"],
                              b["far"], levels])
        return b["far"].numpy()[:count] if far else None

    def _record_levels(self, rows: wp.array, levels: int) -> None:
        b, dev = self._buffer(), self.device
        wp.launch(distance_kernels.bfs_clear, dim=self.n, device=dev, inputs=[rows, b["slots"], b["count"]])
        wp.launch(distance_kernels.bfs_seed, dim=self.batch, device=dev,
                  inputs=[b["sources"], b["first"], b["slots"], b["count"], rows, b["queue"], b["base"], b["size"],
                          b["far"]])
        for level in range(levels):
            wp.launch(distance_kernels.bfs_level, dim=(self.batch, _LEVEL_THREADS), device=dev,
                      inputs=[self.offsets, self.neighbors, b["slots"], b["count"], rows, b["queue"], b["base"],
                              b["size"], b["far"], level, _LEVEL_THREADS])

    def _buffer(self) -> dict[str, wp.array]:
        if self._buffers is None:
            dev, k = self.device, self.batch
            self._buffers = {
                "sources": wp.empty(self.n, dtype=wp.int32, device=dev),
                "first": wp.empty(k + 1, dtype=wp.int32, device=dev),
                "slots": wp.empty(k, dtype=wp.int32, device=dev),
                "count": wp.zeros(1, dtype=wp.int32, device=dev),
                "queue": wp.empty((k, self.n), dtype=wp.int32, device=dev),
                "base": wp.zeros((3, k), dtype=wp.int32, device=dev),
                "size": wp.zeros((k, 3), dtype=wp.int32, device=dev),
                "far": wp.zeros(k, dtype=wp.int32, device=dev),
            }
        return self._buffers


def _shared_plan(n: int, device: str) -> tuple[int, int] | None:
    """(bitmap words, frontier capacity) of the shared-memory row search for n vertices on a CUDA device, or None
    where the visited bitmap and two frontiers of _SHARED_FRONTIER_LEAST vertices do not fit a block's shared
    memory (or on the CPU). Bitmap words come in steps of 256, so meshes of similar size share a kernel."""
    if device == "cpu":
        return None
    words = -(-n // 8192) * 256
    room = wp.get_device(device).max_shared_memory_per_block // 4 - words - 3
    cap = min(_SHARED_FRONTIER_MOST, room // 2)
    return (words, cap) if cap >= _SHARED_FRONTIER_LEAST else None


def _rows_at_once(plan: tuple[int, int] | None, device: str) -> int:
    """Row searches that run at once on a CUDA device: a block each, as many blocks per multiprocessor as their
    shared memory allows (the shared-memory search) or its 2,048 threads (the global one)."""
    d = wp.get_device(device)
    if plan is None:
        per_sm = 2048 // _ROW_BLOCK_THREADS
    else:
        per_sm = max(1, d.max_shared_memory_per_block // (4 * (plan[0] + 2 * plan[1] + 3)))
    return d.sm_count * per_sm


def _block_count(n: int, threads: int, device: str) -> int:
    """Blocks of the dense build: as many as the device keeps resident at once (at most 32 per multiprocessor and
    2,048 threads), within _BLOCK_SCRATCH_BYTES and n; on the CPU, where a launch runs on one thread, a few."""
    if device == "cpu":
        return min(n, 8)
    resident = wp.get_device(device).sm_count * min(32, 2048 // threads)
    return max(1, min(n, resident, _BLOCK_SCRATCH_BYTES // (8 * n)))


def _components(topology: Topology) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(labels, hops from each component's lowest vertex, vertices grouped by component), one CPU thread."""
    n = topology.n_vertices
    offsets = wp.array(topology.offsets, dtype=wp.int32, device="cpu")
    neighbors = wp.array(topology.neighbors if len(topology.neighbors) else np.zeros(1, np.int32), dtype=wp.int32,
                         device="cpu")
    out = [wp.empty(n, dtype=wp.int32, device="cpu") for _ in range(3)]
    wp.launch(distance_kernels.label_components, dim=1, device="cpu", inputs=[offsets, neighbors, *out])
    return tuple(a.numpy().copy() for a in out)  # (a CPU array's numpy() is a view of memory freed with it)


def _diameter(topology: Topology, device: str) -> int:
    """The largest finite BFS distance, exactly, by iFUB (Crescenzi, Grossi, Habib, Lanzi, Marino 2013).

    Per component: sweeps from far-apart vertices give a lower bound (their eccentricities) and a centre u (least
    largest distance to the sweeps' sources, refined by a sweep from the vertex farthest from it). Vertices are then
    taken by falling distance i from u, each search adding its eccentricity, until the bound reaches 2 i: any two
    vertices left lie within 2 i of each other through u. The bound is shared: it prunes every component. The
    searches of a step (one per component) share one multi-source BFS.
    """
    n = topology.n_vertices
    if len(topology.edges) == 0:
        return 0
    labels, hops, order = _components(topology)
    sizes = np.bincount(labels)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    cpu = RowSearch(topology, "cpu")
    row = wp.empty((1, n), dtype=wp.int32, device="cpu")

    def sweep(sources: np.ndarray) -> np.ndarray:
        cpu.run([sources], [0], row, n)
        return row.numpy()[0].copy()

    def pick(d: np.ndarray, largest: bool) -> tuple[np.ndarray, np.ndarray]:
        """Per component: the first vertex (in `order`) where d is largest (or least), and that value."""
        in_order = d[order]
        best = (np.maximum if largest else np.minimum).reduceat(in_order, starts)
        hit = np.flatnonzero(in_order == np.repeat(best, sizes))
        comp = labels[order[hit]]
        return order[hit[np.r_[True, comp[1:] != comp[:-1]]]], best

    a, _ = pick(hops, True)
    swept = [sweep(a)]
    swept.append(sweep(pick(swept[0], True)[0]))
    lower = int(max(d.max() for d in swept))
    centre_hops, centre_ecc = None, None
    for _ in range(_CENTRE_TRIES):
        u, _ = pick(np.maximum.reduce(swept), False)
        du = sweep(u)
        far, ecc = pick(du, True)
        lower = max(lower, int(ecc.max()))
        if centre_hops is None or centre_ecc is None:
            centre_hops, centre_ecc = du, ecc
        else:
            better = ecc < centre_ecc
            centre_hops = np.where(better[labels], du, centre_hops)
            centre_ecc = np.minimum(ecc, centre_ecc)
        if (2 * centre_ecc <= lower + 1).all():  # at most the outermost level of a centre is left
            break
        swept.append(sweep(far))
        lower = max(lower, int(swept[-1].max()))
    assert centre_hops is not None and centre_ecc is not None  # set by the first try
    key = np.lexsort((-centre_hops, labels))  # by component, then by falling distance from its centre
    level = centre_hops[key]
    pos, end = starts.copy(), starts + sizes
    depth = int(2 * centre_ecc.max())  # no eccentricity exceeds twice that of a component's centre
    search, buf, width = cpu, row, 1
    for rounds in range(n + 1):
        active = np.flatnonzero((pos < end) & (2 * level[np.minimum(pos, n - 1)] > lower))
        if not active.size:
            return lower
        if rounds == _ROUNDS_ON_CPU and device != "cpu":  # a symmetric graph: batches of searches on the device
            search = RowSearch(topology, device)
            buf, width = wp.empty((search.batch, n), dtype=wp.int32, device=device), search.batch
        take = np.minimum(width, end[active] - pos[active])
        sources = [key[pos[active[take > j]] + j] for j in range(int(take.max()))]
        lower = max(lower, int(search.run(sources, np.arange(len(sources)), buf, depth, far=True).max()))
        pos[active] += take
    raise AssertionError("unreachable: every round takes a vertex")


def _face_list(faces) -> list[np.ndarray]:
    if isinstance(faces, np.ndarray):
        arr = checks.index_array("faces", faces)
        if arr.ndim != 2:
            raise ValueError(f"faces: an array of faces must have shape (F, k), got {arr.shape}")
        return list(arr)
    if not isinstance(faces, Sequence) or isinstance(faces, (str, bytes)):
        raise ValueError(f"faces: expected a list of index sequences or an (F, k) array, got {type(faces).__name__}")
    out = []
    for i, face in enumerate(faces):
        try:
            arr = checks.index_array(f"faces[{i}]", face, ndim=1)
        except ValueError as exc:
            raise ValueError(f"faces: face {i} is not a sequence of integer vertex indices ({exc})") from None
        out.append(arr)
    return out


def _vertex_count(flat: np.ndarray, n_vertices: int | None, name: str) -> int:
    if flat.size and flat.min() < 0:
        raise ValueError(f"{name}: vertex indices must be >= 0, found {int(flat.min())}")
    if n_vertices is None:
        if not flat.size:
            raise ValueError(f"{name}: no vertex index given; pass n_vertices")
        if flat.max() >= MAX_VERTICES:
            raise ValueError(f"{name}: vertex index {int(flat.max()):,} is beyond the {MAX_VERTICES:,} vertices a "
                             "topology may have")
        return int(flat.max()) + 1
    n = checks.integer("n_vertices", n_vertices, 1, MAX_VERTICES)
    if flat.size and flat.max() >= n:
        raise ValueError(f"{name}: vertex index {int(flat.max())} is out of range for n_vertices={n}")
    return n


def _clean_edges(pairs: np.ndarray) -> np.ndarray:
    """Sorted unique undirected edges (i < j), self-loops dropped (sorted as one int64 key a pair: fast)."""
    pairs = np.sort(pairs.astype(np.int64), axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    if not len(pairs):
        return np.zeros((0, 2), np.int64)
    width = int(pairs[:, 1].max()) + 1
    keys = np.sort(pairs[:, 0] * width + pairs[:, 1])
    keys = keys[np.concatenate([[True], keys[1:] != keys[:-1]])]
    return np.stack([keys // width, keys % width], axis=1)


class Faces(Sequence):
    """Faces of one size held as an (F, k) int64 array (`array`), seen as the sequence of its rows: what
    `Topology.faces` is for an array given to `from_faces`."""

    def __init__(self, array: np.ndarray) -> None:
        self.array = array

    def __len__(self) -> int:
        return len(self.array)

    def __getitem__(self, i):
        return self.array[i]

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter(self.array)
