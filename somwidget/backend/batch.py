"""B variants of one mesh trained together: the same algorithm as `Som` (som.py), B runs in the same launches.

Each variant has its own weights, controls and schedule (a value of each of schedule.KEYS); the topology, the
feature count, the mirror, smooth_dims and the metric weights are shared. Variant b equals the single run
`Som(topology, weights[b], controls[b], ..., **schedule of b)` driven the same way: `train()` after construction is a
whole run from the given weights; `restart()` first makes it the local restart a move of the controls would be (from
s0 = floor((1 - reach) S)).

On CUDA a block of threads runs one variant's whole schedule (batch_kernels.py): a cycle of a mesh of a few
thousand neurons is too short to fill a GPU, B of them side by side do. On the CPU the variants are shared among
the cores, each running its variants one after another. A batch takes the paper's rule: point controls, a mirror,
the Laplacian step. Controls with a radius (handles: bound at a grab, DESIGN.md "Handles") and Taubin's smoothing
(the free nodes only, the volume put back) follow the shaping path's rules, which keep per-variant bindings and
floods that one block per variant does not hold: such variants run as single Soms (variants.run_plan), each equal to
its own run by construction.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp
from numpy.typing import ArrayLike

from . import checks
from .batch_kernels import GATHER, SEARCH, copy_rows, variants_kernel
from .cycle_kernels import MAX_CONTROLS
from .device import resolve, usable_cores, warp_exclusive, warp_lock
from .schedule import BY_NAME, KEYS, SMOOTHING_RULES, TABLE_KEYS, learning_table
from .som_controls import check_radii
from .som_model import MAX_DIMS
from .som_schedule import restart_iteration
from .topology import Topology

#: Learning-table entries (rows of every distinct schedule x (d_max + 1), float32) a batch may hold: 2 GiB.
MAX_TABLE_ENTRIES = 1 << 29
#: Meshes a batch takes: its dense distance table (N x N uint16) is shared by every variant.
MAX_BATCH_NEURONS = 16384


def _per_variant(name: str, value, n: int) -> np.ndarray:
    """A scalar or n values of one schedule parameter, each checked as Som checks it (its Setting)."""
    values = np.asarray(value, dtype=np.float64)
    if values.ndim == 0:
        values = np.full(n, values)
    if values.shape != (n,):
        raise ValueError(f"{name}: expected one value or {n} (one per variant), got shape {values.shape}")
    setting = BY_NAME[name]
    for i, x in enumerate(values.tolist()):
        setting.check(x, f"{name}[{i}]")
    return values


class BatchSom:
    """B variants of one mesh (see the module's docstring).

    weights: (N, n) shared start weights, or (B, N, n); controls: (B, k, n), the same k for every variant.
    **schedule: each of schedule.KEYS (S, the learning rates, smoothing, reach) one value for all or one per variant
    (a key left out: its default). device: "cpu", "cuda:N" or
    None (the GPU when there is one). cpu_cores: cores the CPU shares the variants among (None: those this process
    may use, at most 8 and at most OMP_NUM_THREADS where that is set). smoothing_rule: "laplacian" (the paper's
    step); "taubin" with smoothing above 0 is refused, as are radii above 0 (the module's docstring: such variants,
    like radial symmetry groups, run as single Soms through variants.run_plan). radii (k,): all 0 (None), kept for a
    plan's arguments.
    """

    @warp_exclusive
    def __init__(
        self,
        topology: Topology,
        weights: ArrayLike,
        controls: ArrayLike,
        smooth_dims: Sequence[int] | None = None,
        metric_weights: ArrayLike | None = None,
        mirror: Sequence[int] = (),
        device: str | None = None,
        *,
        cpu_cores: int | None = None,
        smoothing_rule: str = "laplacian",
        radii: ArrayLike | None = None,
        **schedule: float | ArrayLike,
    ) -> None:
        unknown = sorted(set(schedule) - set(KEYS))
        if unknown:
            raise TypeError(f"BatchSom: unknown keyword(s) {unknown}; a schedule takes {list(KEYS)}")
        if not isinstance(topology, Topology):
            raise ValueError(f"topology: expected a Topology, got {type(topology).__name__}")
        if topology.n_vertices > MAX_BATCH_NEURONS:
            raise ValueError(f"topology: a batch takes meshes of at most {MAX_BATCH_NEURONS:,} vertices (every "
                             f"variant reads one dense distance table), this one has {topology.n_vertices:,}")
        self.device = resolve(device)
        self.topology = topology
        c = np.asarray(controls, dtype=np.float64) if not isinstance(controls, np.ndarray) else controls
        if c.ndim != 3:
            raise ValueError(f"controls: expected an array (variants, controls, dims), got shape {np.shape(c)}")
        if c.shape[0] < 1:
            raise ValueError("controls: expected at least one variant, got 0")
        B, k, n = c.shape
        c = checks.finite_array("controls", c.reshape(B, -1), 2).reshape(B, k, n)
        self.n_variants: int = B
        if not 1 <= n <= MAX_DIMS:
            raise ValueError(f"controls: expected 1 to {MAX_DIMS} feature dimensions, got {n}")
        self.n_neurons, self.n_dims = topology.n_vertices, n
        w = np.asarray(weights)
        w = checks.finite_array("weights", w.reshape(-1, w.shape[-1]) if w.ndim >= 2 else w, 2)
        if w.shape[1] != n:
            raise ValueError(f"weights: expected {n} feature dimensions like the controls, got {w.shape[1]}")
        self._shared_start = w.shape[0] == self.n_neurons
        if self._shared_start:
            w = np.broadcast_to(w, (self.n_variants, self.n_neurons, n))
        elif w.shape[0] == self.n_variants * self.n_neurons:
            w = w.reshape(self.n_variants, self.n_neurons, n)
        else:
            raise ValueError(f"weights: expected ({self.n_neurons}, {n}) shared weights or ({self.n_variants}, "
                             f"{self.n_neurons}, {n}), one set per variant; got {np.shape(weights)}")
        self._start = np.ascontiguousarray(w, dtype=np.float32)
        self._mirror = checks.dims("mirror", mirror, n)
        k_eff = k * (2 if self._mirror else 1)
        if k < 1 or k_eff > MAX_CONTROLS:
            raise ValueError(f"controls: expected 1 to {MAX_CONTROLS} controls counting mirrored copies, got {k} "
                             f"({k_eff} with mirroring)")
        self._controls = c.astype(np.float32)
        self._radii = check_radii(radii, k)
        if self._radii.any():
            raise ValueError("radii: a batch runs point controls only; controls with a radius are handles, bound at a "
                             "grab, and such variants run as single Soms (variants.run_plan does so)")
        B = self.n_variants
        # each variant's schedule: a column of B values per key (iterations as integers)
        self._columns = {key: _per_variant(key, schedule.get(key, BY_NAME[key].default), B) for key in KEYS}
        self._columns["iterations"] = self._columns["iterations"].astype(np.int64)
        self._iterations = self._columns["iterations"]
        self._smoothing = self._columns["smoothing"]
        self._reach = self._columns["reach"]
        checks.choice("smoothing_rule", smoothing_rule, SMOOTHING_RULES)
        if smoothing_rule == "taubin" and (self._smoothing > 0).any():
            raise ValueError("smoothing_rule: a batch takes the paper's Laplacian step; Taubin's rule smooths the "
                             "nodes no handle holds and puts the volume back, and such variants run as single Soms "
                             "(variants.run_plan does so)")
        self.smoothing_rule = smoothing_rule
        smooth = tuple(range(min(3, n))) if smooth_dims is None else checks.dims("smooth_dims", smooth_dims, n)
        metric = np.ones(n, np.float32) if metric_weights is None else checks.finite_array(
            "metric_weights", metric_weights, 1)
        if metric.shape != (n,) or (metric < 0).any() or not (metric > 0).any():
            raise ValueError(f"metric_weights: expected {n} weights >= 0, at least one positive; got "
                             f"{np.asarray(metric).tolist()}")
        self._metric = metric.astype(np.float32)
        self._unit_metric = bool((self._metric == 1.0).all())
        mask = np.zeros(n, np.float32)
        mask[list(smooth)] = 1.0

        dev = self.device
        self._tables, rows = self._build_tables()
        vec = wp.types.vector(length=n, dtype=wp.float32)
        self._pairs = bool(self._mirror)
        self._distances = topology.distance_table(dev)
        self._offsets = wp.array(topology.offsets, dtype=wp.int32, device=dev)
        neighbors = topology.neighbors if len(topology.neighbors) else np.zeros(1, np.int32)
        self._neighbors = wp.array(neighbors, dtype=wp.int32, device=dev)
        self._w = wp.array(self._start, dtype=vec, device=dev)
        self._moved = wp.empty_like(self._w) if (self._smoothing > 0).any() else wp.empty((B, 1), dtype=vec,
                                                                                           device=dev)
        self._c = wp.array(self._effective(self._controls), dtype=vec, device=dev)
        self._k_eff = k_eff
        self._m = wp.array(self._metric[None, :], dtype=vec, device=dev)
        self._mask = wp.array(mask[None, :], dtype=vec, device=dev)
        self._table_row = wp.array(rows, dtype=wp.int32, device=dev)
        self._lam = wp.array(self._smoothing.astype(np.float32), dtype=wp.float32, device=dev)
        self._keys = wp.zeros(B * 3 * k_eff if dev == "cpu" else 1, dtype=wp.uint64, device=dev)
        self._s = np.zeros(B, np.int64)
        self._cores = self._plan_cores(cpu_cores)
        self._anchor: wp.array | None = None  # each variant's anchored weights (`put`), made at the first
        self._to_anchor: set[int] = set()  # variants whose weights go back to their anchor's before the next step
        self._controls_moved = False  # `_controls` changed since they went up
        self._pool: ThreadPoolExecutor | None = None  # the CPU's threads for the variants' parts, made at the first
        self._staging = _PinnedStaging(self._c, self._w, B) if self._w.device.is_cuda else None

    # -- set-up -------------------------------------------------------------------------------------------
    def _effective(self, controls: np.ndarray) -> np.ndarray:
        """(B, k_eff, n): with mirroring each original next to its copy (the mirror dims negated), as pairs."""
        if not self._mirror:
            return np.ascontiguousarray(controls, np.float32)
        copies = controls.copy()
        copies[:, :, list(self._mirror)] *= -1.0
        B, k, n = controls.shape
        return np.ascontiguousarray(np.stack([controls, copies], axis=2).reshape(B, 2 * k, n), np.float32)

    def _build_tables(self) -> tuple[wp.array, np.ndarray]:
        """One learning table per distinct schedule.TABLE_KEYS, stacked; each variant's first row in it."""
        d_max = self.topology.d_max
        distinct: dict[tuple, int] = {}
        first = np.empty(self.n_variants, np.int64)
        order = []
        total = 0
        for b in range(self.n_variants):
            key = tuple(self._columns[name][b].item() for name in TABLE_KEYS)  # (S, the learning rates)
            if key not in distinct:
                distinct[key] = total
                order.append(key)
                total += key[0]
            first[b] = distinct[key]
        if total * (d_max + 1) > MAX_TABLE_ENTRIES:
            raise ValueError(f"iterations: the variants' {len(order)} distinct schedules need {total:,} table rows of "
                             f"{d_max + 1} entries, past the batch's {MAX_TABLE_ENTRIES:,}; run fewer variants at "
                             f"once or vary {', '.join(TABLE_KEYS)} over fewer values")
        if total >= 2**31:
            raise ValueError(f"iterations: {total:,} table rows in all, past 2^31")
        table = np.empty((total, d_max + 1), np.float32)
        for key in order:
            S = key[0]
            table[distinct[key]: distinct[key] + S] = learning_table(d_max=d_max, **dict(zip(TABLE_KEYS, key)))
        return wp.array(table, dtype=wp.float32, device=self.device), first.astype(np.int32)

    def _plan_cores(self, cpu_cores: int | None) -> int:
        if self.device != "cpu":
            return 1
        if cpu_cores is not None:
            return min(checks.integer("cpu_cores", cpu_cores, 1, 64), self.n_variants)
        available = usable_cores()
        # a thread cap the process was given (a Dask worker's nanny sets OMP_NUM_THREADS=1: one core a worker)
        cap = os.environ.get("OMP_NUM_THREADS", "")
        if cap.isdigit() and int(cap) > 0:
            available = min(available, int(cap))
        return max(1, min(available, 8, self.n_variants))

    # -- state --------------------------------------------------------------------------------------------
    @property
    def iteration(self) -> np.ndarray:
        """(B,) each variant's s."""
        return self._s.copy()

    @property
    def iterations(self) -> np.ndarray:
        return self._iterations.copy()

    @property
    def controls(self) -> np.ndarray:
        """(B, k, n) each variant's controls (originals; mirrored copies are implied by `mirror`)."""
        return self._controls.copy()

    @property
    def mirror(self) -> tuple[int, ...]:
        return self._mirror

    @property
    def radii(self) -> np.ndarray:
        """(k,) each control's radius of influence, the same in every variant (0: the paper's point control)."""
        return self._radii.copy()

    @property
    def params(self) -> list[dict]:
        """Each variant's schedule: a value of each of schedule.KEYS, as Som keeps it (iterations an int)."""
        columns = self._columns
        return [{key: BY_NAME[key].check(values[b], key) for key, values in columns.items()}
                for b in range(self.n_variants)]

    @property
    @warp_exclusive
    def weights(self) -> np.ndarray:
        """(B, N, n) float32 host copy (one transfer from a GPU)."""
        self._settle()
        return _weights_down(self._staging, self._w).reshape(self.n_variants, self.n_neurons, self.n_dims)

    def restart(self) -> None:
        """Every variant continues from its current weights at s0 = floor((1 - reach) S): the local restart that a
        move of its controls (or a change of its schedule) makes in a Som."""
        self._s = np.array([restart_iteration(float(r), int(S)) for r, S in zip(self._reach, self._iterations)],
                           np.int64)

    def reset(self) -> None:
        """The start weights and s = 0: the whole schedule again."""
        with warp_lock:
            self._w.assign(self._start)
        self._to_anchor.clear()
        self._s[:] = 0

    @warp_exclusive
    def load(self, weights: ArrayLike, iteration: ArrayLike, controls: ArrayLike) -> None:
        """Put every variant's weights (B, N, n), cycle s (B,) and controls (B, k, n) in place, as `Som.restore` and
        a `set_controls` without its restart would: the next step goes on from there. What lets B separate Soms be
        stepped in one launch (the studio's rooms: their states in, `step_to`, `weights` back out). Point controls
        only (a batch takes no radii)."""
        B, N, n, k = self.n_variants, self.n_neurons, self.n_dims, self._controls.shape[1]
        w = np.asarray(weights)
        if w.shape != (B, N, n):
            raise ValueError(f"weights: expected shape {(B, N, n)} (each variant's), got {w.shape}")
        w = checks.finite_array("weights", w.reshape(B * N, n), 2)
        s = np.asarray(iteration)
        if s.shape != (B,) or not np.issubdtype(s.dtype, np.integer) or (s < 0).any() or (s > self._iterations).any():
            raise ValueError(f"iteration: expected {B} whole numbers, each from 0 to its variant's S; got {s.tolist()}")
        c = np.asarray(controls)
        if c.shape != (B, k, n):
            raise ValueError(f"controls: expected shape {(B, k, n)} (each variant's), got {c.shape}")
        c = checks.finite_array("controls", c.reshape(B, k * n), 2).reshape(B, k, n)
        self._w.assign(np.ascontiguousarray(w, np.float32).reshape(B, N, n))
        self._controls = c.astype(np.float32)
        self._c.assign(self._effective(self._controls))
        self._controls_moved = False
        self._to_anchor.clear()
        self._s = s.astype(np.int64)

    # -- one variant at a time (the studio's rooms: each keeps its variant between rounds) ------------------------
    @warp_exclusive
    def put(self, b: int, weights: ArrayLike, iteration: int, controls: ArrayLike,
            anchor: wp.array | None = None) -> None:
        """Variant b's weights (N, n), cycle s and controls (k, n) from now on, the others' unchanged; `anchor`: the
        device weights (N vectors: those a Som's `anchor()` kept) that `move_rows(..., from_anchor)` goes back to. As
        `load` for one variant: what a Som's state becomes when a batch holds it between steps."""
        b = checks.integer("variant", b, 0, self.n_variants - 1)
        w = np.asarray(weights)
        if w.shape != (self.n_neurons, self.n_dims):
            raise ValueError(f"weights: expected shape {(self.n_neurons, self.n_dims)}, got {w.shape}")
        self._w[b].assign(np.ascontiguousarray(checks.finite_array("weights", w, 2), np.float32))
        self._to_anchor.discard(b)
        if anchor is not None:
            if anchor.shape != (self.n_neurons,):
                raise ValueError(f"anchor: expected {self.n_neurons} weight vectors, got shape {anchor.shape}")
            if self._anchor is None:
                self._anchor = wp.empty_like(self._w)
            wp.copy(self._anchor[b], anchor)
        self.move_rows(np.array([b]), checks.finite_array("controls", controls, 2)[None], np.array([iteration]),
                       np.array([False]))

    def move_rows(self, rows: np.ndarray, controls: np.ndarray, iteration: np.ndarray, from_anchor: np.ndarray) -> None:
        """Variants' controls (m, k, n) and cycles s (m,) from now on (their Soms' `set_controls`: a restart), rows (m,)
        distinct variants, with `from_anchor` (m,) bools from the weights `put` anchored (a studio's round: every held
        room's move in one call). They reach the device with the next step, every variant's controls in one copy."""
        rows = np.asarray(rows, np.int64)
        if rows.ndim != 1 or ((rows < 0) | (rows >= self.n_variants)).any():
            raise ValueError(f"rows: expected variants 0 to {self.n_variants - 1}, got {rows.tolist()}")
        m, shape = len(rows), self._controls.shape[1:]
        if controls.shape != (m, *shape):
            raise ValueError(f"controls: expected shape {(m, *shape)}, got {controls.shape}")
        iteration = np.asarray(iteration, np.int64)
        if ((iteration < 0) | (iteration > self._iterations[rows])).any():
            raise ValueError(f"iteration: expected 0 to each variant's S, got {iteration.tolist()}")
        anchored = rows[np.asarray(from_anchor, bool)]
        if len(anchored) and self._anchor is None:
            raise ValueError(f"variants {anchored.tolist()}: a restart from the anchor, but `put` was given none")
        self._controls[rows] = controls
        self._controls_moved = True
        self._s[rows] = iteration
        self._to_anchor.update(anchored.tolist())

    def restarts_from_anchor(self, b: int) -> bool:
        """Whether variant b's next step starts by going back to its anchor's weights (a `move` left it waiting)."""
        return b in self._to_anchor

    def forget(self, b: int) -> bool:
        """Variant b is no longer used (its state went back to its Som): a restart from its anchor that `move` left
        for the next step is dropped; whether there was one."""
        pending = b in self._to_anchor
        self._to_anchor.discard(b)
        return pending

    @warp_exclusive
    def take_over(self, other: BatchSom) -> None:
        """Every variant of `other` (a batch of this mesh and schedule with at most as many variants) as the first of
        this batch's: a studio's batch grown for more rooms."""
        B = other.n_variants
        if B > self.n_variants or other.n_neurons != self.n_neurons or other.n_dims != self.n_dims:
            raise ValueError(f"take_over: {B} variants of {other.n_neurons} x {other.n_dims} do not fit "
                             f"{self.n_variants} of {self.n_neurons} x {self.n_dims}")
        other._settle()
        count = B * self.n_neurons
        wp.copy(self._w, other._w, count=count)
        if other._anchor is not None:
            if self._anchor is None:
                self._anchor = wp.empty_like(self._w)
            wp.copy(self._anchor, other._anchor, count=count)
        self._controls[:B] = other._controls
        self._s[:B] = other._s
        self._controls_moved = True

    def _settle(self) -> None:
        """What `move` left for the device: the moved controls up (one copy), the weights of the variants restarted
        from their anchor back to it (one launch)."""
        if self._controls_moved:
            _controls_up(self._staging, self._c, self._effective(self._controls))
            self._controls_moved = False
        if self._to_anchor:
            anchor = self._anchor
            assert anchor is not None, "move_rows refuses a restart from the anchor before `put` kept one"
            rows = wp.array(sorted(self._to_anchor), dtype=wp.int32, device=self.device)
            self._to_anchor.clear()
            width = self.n_neurons * self.n_dims
            flat = [wp.array(ptr=a.ptr, dtype=wp.float32, shape=(self.n_variants, width), device=self.device)
                    for a in (self._w, anchor)]
            wp.launch(copy_rows, dim=(rows.shape[0], width), inputs=[flat[0], flat[1], rows], device=self.device)

    # -- training -----------------------------------------------------------------------------------------
    def step_to(self, to: ArrayLike) -> int:
        """Run variant b's cycles up to to[b] (none past its S, none back: to[b] below s[b] runs none); returns the
        most cycles any variant ran."""
        to = np.asarray(to)
        if to.shape != (self.n_variants,) or not np.issubdtype(to.dtype, np.integer):
            raise ValueError(f"to: expected {self.n_variants} whole numbers (each variant's last cycle), got {to!r}")
        to = np.clip(to.astype(np.int64), self._s, self._iterations)
        ran = int((to - self._s).max(initial=0))
        with warp_lock:
            self._settle()
        if ran:
            self._launch(to)
        return ran

    def step(self, n: int = 1) -> int:
        """Run up to n cycles of every variant (none past its S); returns the most cycles any variant ran."""
        n = checks.integer("n", n, 0)
        to = np.minimum(self._s + n, self._iterations)
        ran = int((to - self._s).max(initial=0))
        with warp_lock:
            self._settle()
        if ran:
            self._launch(to)
        return ran

    def train(self) -> int:
        """Run every variant to the end of its schedule; returns the most cycles any variant ran."""
        return self.step(int(self._iterations.max()))

    @warp_exclusive
    def _launch(self, to: np.ndarray) -> None:
        dev, B = self.device, self.n_variants
        s_from, s_to = _cycles_up(self._staging, self._s, to, dev)

        def inputs(first: int) -> list:
            return [self._w, self._moved, self._c, self._k_eff, self._m, self._mask, self._tables, self._table_row,
                    self._lam, s_from, s_to, self._distances, self._offsets, self._neighbors, self._keys, first]

        if dev == "cpu":
            bounds = np.linspace(0, B, self._cores + 1).astype(int)
            parts = [(int(lo), int(hi)) for lo, hi in zip(bounds[:-1], bounds[1:]) if hi > lo]
            kernel = self._kernel(False, {"threads": 1})

            def run(part) -> None:
                lo, hi = part
                wp.launch_tiled(kernel, dim=[hi - lo], block_dim=1, device=dev, inputs=inputs(lo))

            if len(parts) == 1:
                run(parts[0])
            else:
                if self._pool is None:  # kept: a round of a studio's rooms launches every frame
                    self._pool = ThreadPoolExecutor(self._cores, thread_name_prefix="som-variants")
                list(self._pool.map(run, parts))
        else:
            shape = cuda_shape(self.n_neurons)
            kernel = self._kernel(True, shape)
            wp.launch_tiled(kernel, dim=[B], block_dim=shape["threads"], device=dev, inputs=inputs(0))
        self._s = to.astype(np.int64)

    def _kernel(self, cuda: bool, shape: dict):
        """The paper's kernel for a launch shape."""
        return variants_kernel(self.n_dims, self._pairs, cuda, unit_metric=self._unit_metric, **(shape if cuda else {}))


class _PinnedStaging:
    """A GPU batch's round through page-locked host buffers: the controls and cycles go up and the weights come down
    as copies queued on the device's stream, one wait a round (the weights' read). A copy from pageable memory waits
    for the stream's earlier work first, and on a GPU shared by many processes (a studio's workers) each such wait
    also waits for the other processes' turns on the GPU. A buffer is written again only after its last copy ran."""

    def __init__(self, controls: wp.array, weights: wp.array, n_variants: int) -> None:
        dev = weights.device
        self.stream = wp.get_stream(dev)
        self.controls = wp.empty(controls.shape, dtype=controls.dtype, device="cpu", pinned=True)
        self.cycles = wp.empty((2, n_variants), dtype=wp.int32, device="cpu", pinned=True)
        self.cycles_dev = wp.empty((2, n_variants), dtype=wp.int32, device=dev)
        self.weights_host = wp.empty(weights.shape, dtype=weights.dtype, device="cpu", pinned=True)
        self._sent: dict[str, wp.Event] = {}

    def _reuse(self, name: str) -> None:
        event = self._sent.pop(name, None)
        if event is not None:
            wp.synchronize_event(event)

    def send_controls(self, dest: wp.array, values: np.ndarray) -> None:
        self._reuse("controls")
        self.controls.numpy()[...] = values.reshape(self.controls.numpy().shape)
        wp.copy(dest, self.controls, stream=self.stream)
        self._sent["controls"] = self.stream.record_event()

    def send_cycles(self, s_from: np.ndarray, s_to: np.ndarray) -> tuple[wp.array, wp.array]:
        self._reuse("cycles")
        host = self.cycles.numpy()
        host[0], host[1] = s_from, s_to
        wp.copy(self.cycles_dev, self.cycles, stream=self.stream)
        self._sent["cycles"] = self.stream.record_event()
        return self.cycles_dev[0], self.cycles_dev[1]

    def weights(self, source: wp.array) -> np.ndarray:
        """The weights (a host copy of their own: frames keep it) after the work queued so far."""
        wp.copy(self.weights_host, source, stream=self.stream)
        wp.synchronize_stream(self.stream)
        self._sent.clear()  # every earlier copy ran
        return self.weights_host.numpy().copy()


def _weights_down(staging: _PinnedStaging | None, weights: wp.array) -> np.ndarray:
    """A host copy of the weights of their own (a GPU's through the page-locked buffer)."""
    return weights.numpy().copy() if staging is None else staging.weights(weights)


def _controls_up(staging: _PinnedStaging | None, dest: wp.array, values: np.ndarray) -> None:
    if staging is None:
        dest.assign(values)
    else:
        staging.send_controls(dest, values)


def _cycles_up(staging: _PinnedStaging | None, s_from: np.ndarray, s_to: np.ndarray, device) -> tuple:
    """Each variant's first and last cycle of a launch, on the device."""
    if staging is not None:
        return staging.send_cycles(s_from, s_to)
    return (wp.array(s_from.astype(np.int32), dtype=wp.int32, device=device),
            wp.array(s_to.astype(np.int32), dtype=wp.int32, device=device))


def cuda_shape(n_neurons: int) -> dict:
    """The CUDA kernel's shape for a mesh (batch_kernels.variants_kernel's arguments), chosen by measurement on an
    H200 (BENCHMARKS.md, "Variants"): up to 1,024 neurons blocks of 64 threads, eight to an SM in the launch bounds
    (registers enough for six controls' places and winner keys at once: the car); past that 512 threads a block,
    two to an SM (the space grid)."""
    if n_neurons <= 1024:
        return {"threads": 64, "min_blocks": 8, "gather": 6, "searched": 6}
    return {"threads": 512, "min_blocks": 2, "gather": GATHER, "searched": SEARCH}
