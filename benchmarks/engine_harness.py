"""The engine benchmark's harness (`somwidget bench`, benchmarks/bench_engine.py): the Warp engine against a vectorised
numpy float32 baseline that does the same cycles. A baseline, not part of the package: it lives in a checkout.

Cases (the paper's case studies, backend/presets):
  space-grid         case study 1: 16^3 lattice, 8 controls, 3-D, S 1000, no smoothing
  space-grid-smooth  the same with the preset's Laplacian step each cycle (lambda 0.2)
  car                case study 2: 602 neurons, 9 controls mirrored = 18, 5-D
  big                a 256 x 256 open quad grid: 65,536 neurons (the dense table's cap, 8 GiB), 18 controls, 3-D

For each case: the engine's time per cycle over a whole run (`train()` from s = 0), its time per cycle when called
as the app calls it (`step(10)` between frames), the numpy baseline's time per cycle measured in the same process
(both of its updates are timed; the table shows the faster), and the ratio numpy / engine. Warm-up (kernel load or
compile, graph capture) is timed and reported apart. Then the engine and each baseline run cycle by cycle from the
start and their winners and weights are compared, so the figures are known to come from the same cycles. Last, the
shaping path's figures (bench_shaping.py: a handle's drag frame against the point path's, the car's single shaping
run in us a cycle).

Imports only numpy, warp, somwidget.backend and tests/reference.py (the float64 learning table, numpy only): it runs
on a GPU machine with nothing else installed. somwidget/cli.py
parses the arguments (`somwidget bench`, or bench_engine.py without an install) and calls `run`.
"""

from __future__ import annotations

import datetime as _dt
import importlib.util
import json
import math
import os
import platform
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import warp as wp

from somwidget.backend.device import resolve
from somwidget.backend.presets import get_preset
from somwidget.backend.som import Som
from somwidget.backend.topology import Topology

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
from reference import schedule_table  # noqa: E402  (the float64 learning table)

CASES = ("space-grid", "space-grid-smooth", "car", "big")
CPU_DEFAULT_CASES = ("space-grid", "space-grid-smooth", "car")
GPU_CYCLES = 1000
CPU_CYCLES = 1000  # the paper's cases take ~0.1-0.3 ms a cycle on one core: the default CPU run is ~10 s
FRAME_STEP = 10  # cycles per app frame
BIG_SIDE = 256
BIG_BASELINE_CYCLES = 100  # numpy at 65,536 neurons: per-cycle cost is flat in s, so fewer cycles suffice
UNREACHABLE = 65535
NEAR_TIE = 1e-5  # relative distance gap under which float32 rounding may pick either neuron


# ----------------------------------------------------------------------------------------------------------------
# The numpy baseline
# ----------------------------------------------------------------------------------------------------------------
class NumpySom:
    """The SOM cycle (som.py, The cycle) in vectorised numpy, float32, with preallocated buffers and in-place ops.

    The weights are stored transposed, (n, N), so every elementwise pass runs along the long neuron axis.
    One cycle s:
      1. winners u_c = argmin_v sum_j m_j (C_cj - W_vj)^2 for all controls at once, from W before any move
         (np.argmin: the lowest index wins an exact tie);
      2. the controls in list order: W_v <- W_v + h_cv (C_c - W_v) with h_cv = L[s, D[u_c, v]] (0 if unreachable);
         with `paired` (controls = [originals..., mirrored copies...]) control c and its copy k + c act together at
         c's place, both rates scaled by 1 / max(1, h_c + h_c');
      3. with smoothing lambda > 0, one Jacobi step of uniform Laplacian smoothing on smooth_dims.

    update="fused" applies step 2 in closed form, the same recurrence unrolled over its units (a control, or a pair
    with its two scaled rates g):
      W <- W * prod_u (1 - g_u) + sum_u (sum of g_c C_c over u's controls) * prod_{u' > u} (1 - g_u')
    (a running product over the units and one (n, k) @ (k, N) product instead of 3k passes over W);
    update="sequential" loops over the units (k <= 256), a few in-place passes each. Neither loops over neurons
    in Python; they agree to float32 rounding, and "fused" is the faster on every case here.
    The neighbour sums of step 3 use a padded neighbour table (one gather, one sum) when the degrees are even
    enough, else CSR segments (np.add.reduceat).
    """

    def __init__(self, distances, offsets, neighbors, weights, controls, table, metric_weights=None,
                 smoothing: float = 0.0, smooth_dims=None, update: str = "fused", paired: bool = False):
        if update not in ("fused", "sequential"):
            raise ValueError(f"update: expected 'fused' or 'sequential', got {update!r}")
        self.update = update
        self.paired = bool(paired)
        self.D = np.ascontiguousarray(distances, dtype=np.uint16)
        start = np.asarray(weights, dtype=np.float32)
        n_neurons, n_dims = start.shape
        self.start_t = np.ascontiguousarray(start.T)
        # one spare zero column: the padded neighbour table points empty slots at it
        self._wt_ext = np.zeros((n_dims, n_neurons + 1), np.float32)
        self.WT = self._wt_ext[:, :n_neurons]  # (n, N) view, rows contiguous
        self.WT[...] = self.start_t
        self.C = np.ascontiguousarray(controls, dtype=np.float32)
        self.CT = np.ascontiguousarray(self.C.T)
        self.table = np.ascontiguousarray(table, dtype=np.float32)
        k = self.C.shape[0]
        if self.paired and k % 2:
            raise ValueError(f"controls: mirrored pairs need an even count (originals, then copies), got {k}")
        if self.D.shape != (n_neurons, n_neurons):
            raise ValueError(f"distances: expected shape {(n_neurons, n_neurons)}, got {self.D.shape}")
        if self.C.shape[1] != n_dims:
            raise ValueError(f"controls: expected {n_dims} dims like the weights, got {self.C.shape[1]}")
        self.iterations = self.table.shape[0]
        self.m = (np.ones(n_dims, np.float32) if metric_weights is None
                  else np.asarray(metric_weights, dtype=np.float32).reshape(n_dims))
        self.s = 0
        # L[s, d] for every uint16 d: 0 past d_max, so 65535 (unreachable) reads 0 without a test
        self._rate = np.zeros(UNREACHABLE + 1, np.float32)
        self._width = self.table.shape[1]
        # winner search
        self._diff = np.empty((n_dims, k, n_neurons), np.float32)
        self._dist = np.empty((k, n_neurons), np.float32)
        self._win = np.empty(k, np.intp)
        # move
        self._rows = np.empty((k, n_neurons), np.uint16)
        self._h = np.empty((k, n_neurons), np.float32)
        self._keep = np.empty((k, n_neurons), np.float32)
        self._coef = np.empty((k, n_neurons), np.float32)
        self._pull = np.empty((n_dims, n_neurons), np.float32)
        # smoothing
        self.smoothing = float(smoothing)
        dims = tuple(range(min(3, n_dims))) if smooth_dims is None else tuple(sorted(set(smooth_dims)))
        contiguous = bool(dims) and dims == tuple(range(dims[0], dims[-1] + 1))
        self._dims = slice(dims[0], dims[-1] + 1) if contiguous else np.array(dims, np.intp)
        offsets = np.asarray(offsets, np.intp)
        neighbors = np.asarray(neighbors, np.intp)[: offsets[-1]]
        degree = np.diff(offsets)
        self._has = degree > 0
        self._all_have = bool(self._has.all())
        self._any_edge = bool(self._has.any())
        self._degree = np.maximum(degree, 1).astype(np.float32)  # divides (as the engine does); 1 where alone
        self._mean = np.empty((len(dims), n_neurons), np.float32)
        max_degree = int(degree.max(initial=0))
        self._padded = self._any_edge and max_degree * n_neurons <= 2 * len(neighbors)
        if self._padded:  # table[j, v] = v's j-th neighbour, or the zero column past its degree
            self._table_nb = np.full((max_degree, n_neurons), n_neurons, np.intp)
            for j in range(max_degree):
                has = degree > j
                self._table_nb[j, has] = neighbors[offsets[:-1][has] + j]
            self._gathered = np.empty((len(dims), max_degree, n_neurons), np.float32)
        else:
            self._neighbors = neighbors
            self._starts = offsets[:-1][self._has]
            self._gathered = np.empty((len(dims), len(neighbors)), np.float32)
            self._sums = np.empty((len(dims), len(self._starts)), np.float32)

    @property
    def W(self) -> np.ndarray:
        """(N, n) float32 copy of the current weights."""
        return np.ascontiguousarray(self.WT.T)

    def reset(self) -> None:
        np.copyto(self.WT, self.start_t)
        self.s = 0

    def winners(self) -> np.ndarray:
        n_dims, k, n_neurons = self._diff.shape
        np.subtract(self.CT[:, :, None], self.WT[:, None, :], out=self._diff)
        np.multiply(self._diff, self._diff, out=self._diff)
        np.matmul(self.m, self._diff.reshape(n_dims, k * n_neurons), out=self._dist.reshape(k * n_neurons))
        np.argmin(self._dist, axis=1, out=self._win)
        return self._win

    def step(self, n: int = 1) -> int:
        n = max(0, min(n, self.iterations - self.s))
        WT, h = self.WT, self._h
        for _ in range(n):
            win = self.winners()
            self._rate[: self._width] = self.table[self.s]
            np.take(self.D, win, axis=0, out=self._rows)
            np.take(self._rate, self._rows, out=h)
            if self.paired:
                self._move_pairs(h)
            elif self.update == "fused":
                keep, coef = self._keep, self._coef
                np.subtract(np.float32(1.0), h, out=keep)
                for c in range(len(keep) - 2, -1, -1):  # keep[c] <- prod_{c' >= c} (1 - h_c')
                    np.multiply(keep[c], keep[c + 1], out=keep[c])
                np.multiply(h[:-1], keep[1:], out=coef[:-1])
                coef[-1] = h[-1]
                np.matmul(self.CT, coef, out=self._pull)
                WT *= keep[0]
                WT += self._pull
            else:
                pull = self._pull
                for c in range(self.C.shape[0]):
                    np.subtract(self.CT[:, c, None], WT, out=pull)
                    pull *= h[c]
                    WT += pull
            if self.smoothing > 0.0 and self._any_edge:
                self._smooth()
            self.s += 1
        return n

    def _move_pairs(self, h: np.ndarray) -> None:
        """Step 2 with mirrored pairs: h (k_eff, N) becomes the scaled rates g, then one unit per pair."""
        half = len(h) // 2
        first, second = h[:half], h[half:]
        scale = np.float32(1.0) / np.maximum(np.float32(1.0), first + second)
        first *= scale
        second *= scale
        WT, pull = self.WT, self._pull
        if self.update == "fused":
            keep, coef = self._keep[:half], self._coef
            np.subtract(np.float32(1.0), first, out=keep)
            keep -= second
            for u in range(half - 2, -1, -1):  # keep[u] <- prod_{u' >= u} (1 - g_u')
                np.multiply(keep[u], keep[u + 1], out=keep[u])
            np.multiply(first[:-1], keep[1:], out=coef[: half - 1])
            np.multiply(second[:-1], keep[1:], out=coef[half: 2 * half - 1])
            coef[half - 1] = first[-1]
            coef[2 * half - 1] = second[-1]
            np.matmul(self.CT, coef, out=pull)
            WT *= keep[0]
            WT += pull
        else:
            other = self._diff[:, 0, :]  # scratch (n, N): the winner search is done for this cycle
            for u in range(half):
                np.subtract(self.CT[:, u, None], WT, out=pull)
                pull *= first[u]
                np.subtract(self.CT[:, half + u, None], WT, out=other)
                other *= second[u]
                pull += other
                WT += pull

    def _smooth(self) -> None:
        lam, mean = np.float32(self.smoothing), self._mean
        src = self._wt_ext[self._dims]  # (d, N + 1): a view for contiguous dims, else a copy
        part = src[:, :-1]
        if self._padded:
            np.take(src, self._table_nb, axis=1, out=self._gathered)
            np.sum(self._gathered, axis=1, out=mean)  # adds the neighbours in CSR order, like the engine
        else:
            np.take(part, self._neighbors, axis=1, out=self._gathered)
            mean.fill(0.0)
            np.add.reduceat(self._gathered, self._starts, axis=1, out=self._sums)
            mean[:, self._has] = self._sums
        mean /= self._degree
        mean -= part
        mean *= lam
        if not self._all_have:
            mean *= self._has  # a neuron with no neighbour stays
        part += mean
        if not isinstance(self._dims, slice):
            self.WT[self._dims] = part

    def train(self) -> int:
        return self.step(self.iterations - self.s)


# ----------------------------------------------------------------------------------------------------------------
# Cases
# ----------------------------------------------------------------------------------------------------------------
def _big_som(device: str, cycles: int, cpu_cores: int | None = None) -> tuple[Som, Topology]:
    """A 256 x 256 open quad grid in the plane z = 0, spanning [-1, 1]^2, pulled by 18 controls (9 mirrored)."""
    side = BIG_SIDE
    idx = np.arange(side * side, dtype=np.int64).reshape(side, side)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], axis=-1).reshape(-1, 4)
    u = np.linspace(-1.0, 1.0, side, dtype=np.float32)
    gy, gx = np.meshgrid(u, u, indexing="ij")
    weights = np.stack([gx.ravel(), gy.ravel(), np.zeros(side * side, np.float32)], axis=1)
    controls = np.array([
        [0.55, 0.40, 0.70], [-0.60, 0.45, -0.50], [0.75, 0.70, 0.35], [-0.70, 0.65, 0.55], [0.05, 0.90, -0.40],
        [-0.05, 0.20, 0.60], [0.95, 0.05, -0.30], [-0.95, 0.10, 0.25], [0.30, 0.85, 0.45],
    ], np.float32)  # 9 controls mirrored across y = 0: 18, as in the paper's car
    topo = Topology.from_faces(quads, side * side)
    return Som(topo, weights, controls, iterations=cycles, mirror=(1,), device=device, cpu_cores=cpu_cores), topo


def _make(case: str, device: str, cycles: int, cpu_cores: int | None = None) -> tuple[Som, Topology]:
    if case == "big":
        return _big_som(device, cycles, cpu_cores)
    preset = get_preset("car" if case == "car" else "space-grid")
    som = preset.make_som(device, cpu_cores=cpu_cores)
    if case == "space-grid":
        som.smoothing = 0.0
    elif case == "space-grid-smooth" and som.smoothing <= 0.0:
        raise ValueError("benchmark: the space-grid preset has no smoothing; space-grid-smooth needs lambda > 0")
    som.iterations = cycles
    return som, preset.topology


# ----------------------------------------------------------------------------------------------------------------
# Timing
# ----------------------------------------------------------------------------------------------------------------
@dataclass
class CaseResult:
    case: str
    device: str
    neurons: int
    controls: int
    dims: int
    cycles: int
    smoothing: float
    build_s: float = 0.0  # Som construction: topology, BFS distance table, uploads
    first_step_s: float = 0.0  # first step(1): kernel load / compile and graph capture
    first_train_s: float = 0.0  # first train(): graph capture of the run's chunks, plus the run
    engine_run_us: float = math.nan  # per cycle, train() from s = 0, median of repeats
    engine_frame_us: float = math.nan  # per cycle, step(10) frames each followed by a device synchronise
    engine_frame_ms: float = math.nan  # per frame: step(10) + synchronise
    readback_ms: float = math.nan  # per frame: som.weights (device -> host copy) after the step
    numpy_us: float = math.nan  # per cycle, the numpy baseline (the faster update), median of repeats
    numpy_cycles: int = 0
    numpy_update: str = ""  # which update numpy_us is: "fused" or "sequential"
    numpy_variants_us: dict = field(default_factory=dict)  # per cycle, each update
    ratio_run: float = math.nan  # numpy_us / engine_run_us
    ratio_frame: float = math.nan  # numpy_us / engine_frame_us
    agree_cycles: int = 0  # cycles in lockstep with identical winners in the engine and the timed baseline
    agree_of: int = 0  # cycles compared
    max_abs_diff: float = math.nan  # max |engine - numpy| weights over those cycles (float32 rounding only)
    tie_gap: float = math.nan  # at the first differing winner: |d(engine's) - d(numpy's)| / d, in float64
    agreement: dict = field(default_factory=dict)  # the same three figures for each update
    table_max_diff: float = math.nan  # |engine learning_table() - the baseline's own table from the formulas|
    run_times_s: list = field(default_factory=list)
    numpy_times_s: list = field(default_factory=list)


def _sync(device: str) -> None:
    wp.synchronize_device(device)


def _time_engine(som: Som, res: CaseResult, repeats: int) -> None:
    dev, cycles = som.device, res.cycles
    t = time.perf_counter()
    som.step(1)
    _sync(dev)
    res.first_step_s = time.perf_counter() - t
    som.reset()
    _sync(dev)
    t = time.perf_counter()
    som.train()
    _sync(dev)
    res.first_train_s = time.perf_counter() - t

    for _ in range(repeats):
        som.reset()
        _sync(dev)
        t = time.perf_counter()
        ran = som.train()
        _sync(dev)
        res.run_times_s.append(time.perf_counter() - t)
        if ran != cycles or som.iteration != cycles:
            raise RuntimeError(f"benchmark: train() ran {ran} cycles, ending at s={som.iteration}; expected {cycles}")
    res.engine_run_us = statistics.median(res.run_times_s) / cycles * 1e6

    # frames as the app makes them: step(10), then the view reads the weights
    som.reset()
    som.step(FRAME_STEP)  # warm-up: captures the step(10) graphs
    som.step(FRAME_STEP)
    _sync(dev)
    per_cycle, per_frame, readback = [], [], []
    for _ in range(repeats):
        som.reset()
        _sync(dev)
        steps, copies, done = [], [], 0
        while som.iteration < cycles:
            t0 = time.perf_counter()
            done += som.step(FRAME_STEP)
            _sync(dev)
            t1 = time.perf_counter()
            _ = som.weights  # the host copy a view makes each frame
            copies.append(time.perf_counter() - t1)
            steps.append(t1 - t0)
        per_cycle.append(sum(steps) / done)
        per_frame.append(statistics.median(steps))
        readback.append(statistics.median(copies))
    res.engine_frame_us = statistics.median(per_cycle) * 1e6
    res.engine_frame_ms = statistics.median(per_frame) * 1e3
    res.readback_ms = statistics.median(readback) * 1e3


def _time_numpy(som: Som, topo: Topology, start: np.ndarray, res: CaseResult, repeats: int,
                cycles: int) -> dict[str, NumpySom]:
    """Both updates of the baseline, timed in turn; numpy_us is the faster (the baseline at its best)."""
    table = som.learning_table()
    own = schedule_table(som, topo.d_max).astype(np.float32)  # from the formulas (tests/reference.py)
    res.table_max_diff = float(np.abs(own - table).max()) if own.shape == table.shape else math.inf
    distances = topo.grid_distances()
    variants = {}
    for update in ("fused", "sequential"):
        base = NumpySom(distances, topo.offsets, topo.neighbors, start, som.effective_controls, table,
                        metric_weights=som.metric_weights, smoothing=som.smoothing, smooth_dims=som.smooth_dims,
                        update=update, paired=bool(som.mirror))
        base.step(2)  # warm-up: first touch of the buffers
        times = []
        for _ in range(repeats):
            base.reset()
            t = time.perf_counter()
            base.step(cycles)
            times.append(time.perf_counter() - t)
        res.numpy_variants_us[update] = statistics.median(times) / cycles * 1e6
        if update == "fused":
            res.numpy_times_s = times
        variants[update] = base
    res.numpy_update = min(res.numpy_variants_us, key=res.numpy_variants_us.get)
    res.numpy_us = res.numpy_variants_us[res.numpy_update]
    res.numpy_cycles = cycles
    return variants


def _agreement(som: Som, variants: dict[str, NumpySom], res: CaseResult, cycles: int) -> None:
    """Engine and baselines cycle by cycle from the start: same winners, weights equal to float32 rounding.

    Over long runs two nearly equidistant neurons can swap: a different order of float32 operations
    breaks a near-tie another way. The first such cycle ends the comparison for that baseline, and its relative
    distance gap is kept, so a real difference is told apart from a near-tie. The sequential update does the
    engine's operations in the engine's order and usually stays bit-identical to the CPU engine.
    """
    som.reset()
    live = dict(variants)
    for base in live.values():
        base.reset()
    worst = dict.fromkeys(live, 0.0)
    res.agree_of = cycles
    for s in range(cycles + 1):
        if not live:
            break
        ours = som.winners() if s < cycles else None
        for update, base in list(live.items()):
            if s == cycles:
                res.agreement[update] = {"agree_cycles": cycles, "max_abs_diff": worst[update], "tie_gap": math.nan}
                continue
            theirs = base.winners()
            if not np.array_equal(ours, theirs):
                w, c, m = base.W.astype(np.float64), base.C.astype(np.float64), base.m.astype(np.float64)
                d_ours = ((c - w[ours]) ** 2 * m).sum(axis=1)
                d_theirs = ((c - w[theirs]) ** 2 * m).sum(axis=1)
                gap = np.abs(d_ours - d_theirs) / np.maximum(np.minimum(d_ours, d_theirs), 1e-30)
                res.agreement[update] = {"agree_cycles": s, "max_abs_diff": worst[update],
                                         "tie_gap": float(gap[ours != theirs].max())}
                del live[update]
        if s == cycles or not live:
            break
        som.step(1)
        weights = som.weights
        for update, base in live.items():
            base.step(1)
            worst[update] = max(worst[update], float(np.abs(weights - base.W).max()))
    timed = res.agreement[res.numpy_update]
    res.agree_cycles, res.max_abs_diff, res.tie_gap = timed["agree_cycles"], timed["max_abs_diff"], timed["tie_gap"]


def device_name(device: str) -> str:
    if device.startswith("cuda"):
        return wp.get_device(device).name
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return f"{line.split(':', 1)[1].strip()} ({os.cpu_count()} cores)"
    except OSError:
        pass
    return f"{platform.processor() or platform.machine()} ({os.cpu_count()} cores)"


def run_case(case: str, device: str, cycles: int, repeats: int = 3, baseline: bool = True,
             cpu_cores: int | None = None) -> CaseResult:
    if case not in CASES:
        raise ValueError(f"bench: unknown case {case!r}; cases: {', '.join(CASES)}")
    t = time.perf_counter()
    som, topo = _make(case, device, cycles, cpu_cores)
    _sync(som.device)
    build = time.perf_counter() - t
    start = som.weights
    res = CaseResult(case=case, device=som.device, neurons=som.n_neurons, controls=som.effective_controls.shape[0],
                     dims=som.n_dims, cycles=cycles, smoothing=som.smoothing, build_s=build)
    _time_engine(som, res, repeats)
    if baseline:
        np_cycles = min(cycles, BIG_BASELINE_CYCLES) if case == "big" else cycles
        variants = _time_numpy(som, topo, start, res, repeats, np_cycles)
        res.ratio_run = res.numpy_us / res.engine_run_us
        res.ratio_frame = res.numpy_us / res.engine_frame_us
        _agreement(som, variants, res, np_cycles)
    return res


# ----------------------------------------------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------------------------------------------
COLUMNS = ("case", "device", "N", "controls", "dims", "cycles", "engine us/cycle (run)",
           "engine us/cycle (step(10) frames)", "numpy us/cycle", "ratio (run)", "ratio (frames)",
           "frame ms (step(10))", "readback ms", "same winners", "max abs dW")


def _fmt(x: float, digits: int = 1) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:,.{digits}f}"


def _row(r: CaseResult) -> list[str]:
    np_cycles = "" if r.numpy_cycles in (0, r.cycles) else f" ({r.numpy_cycles} cycles)"
    return [r.case, r.device, f"{r.neurons:,}", str(r.controls), str(r.dims), str(r.cycles),
            _fmt(r.engine_run_us), _fmt(r.engine_frame_us), _fmt(r.numpy_us) + np_cycles,
            _fmt(r.ratio_run, 2), _fmt(r.ratio_frame, 2), _fmt(r.engine_frame_ms, 3), _fmt(r.readback_ms, 3),
            f"{r.agree_cycles}/{r.agree_of}" if r.agree_of else "n/a",
            "n/a" if not math.isfinite(r.max_abs_diff) else f"{r.max_abs_diff:.1e}"]


def _agreement_note(a: dict, of: int) -> str:
    if a["agree_cycles"] >= of:
        same = "bit-identical" if a["max_abs_diff"] == 0.0 else f"max abs dW {a['max_abs_diff']:.1e}"
        return f"same winners {of}/{of} ({same})"
    head = f"same winners for {a['agree_cycles']} cycles (max abs dW {a['max_abs_diff']:.1e}), then "
    if a["tie_gap"] < NEAR_TIE:
        return head + f"a near-tie broken the other way (relative distance gap {a['tie_gap']:.1e})"
    return head + f"DIFFERENT WINNERS, not a near-tie (relative distance gap {a['tie_gap']:.1e}): check the code"


def format_table(results: list[CaseResult]) -> str:
    """A Markdown table (paste it into BENCHMARKS.md)."""
    rows = [list(COLUMNS)] + [_row(r) for r in results]
    widths = [max(len(row[i]) for row in rows) for i in range(len(COLUMNS))]
    lines = ["| " + " | ".join(cell.ljust(widths[i]) for i, cell in enumerate(row)) + " |" for row in rows]
    lines.insert(1, "|" + "|".join("-" * (w + 2) for w in widths) + "|")
    return "\n".join(lines)


def meta(device: str) -> dict:
    return {
        "device": device,
        "device_name": device_name(device),
        "warp": wp.config.version,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "host": platform.node(),
        "cpu_count": os.cpu_count(),
        "date": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
    }


def shaping_figures(device: str, repeats: int, out=print) -> dict:
    """The shaping path's figures (benchmarks/bench_shaping.py, issue 34): a handle's drag frame against the point
    path's and the car's single shaping run, the card named; printed with `out` and returned."""
    path = Path(__file__).with_name("bench_shaping.py")
    spec = importlib.util.spec_from_file_location("somwidget_bench_shaping", path)
    bench_shaping = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench_shaping)
    figures = bench_shaping.figures(device, frames=20 * repeats, repeats=repeats)
    out("")
    out(f"handles, the shaping path on {figures['card']} [{device}] (benchmarks/bench_shaping.py):")
    for line in bench_shaping.report(figures):
        out(line)
    return figures


def run(device: str | None = "auto", cases=None, cycles: int | None = None, repeats: int = 3,
        baseline: bool = True, json_path: str | None = None, out=print, cpu_cores: int | None = None
        ) -> list[CaseResult]:
    """Run the cases, print the report with `out`, optionally write JSON; returns the results."""
    dev = resolve(device)
    on_gpu = dev.startswith("cuda")
    if cases is None:
        cases = list(CASES if on_gpu else CPU_DEFAULT_CASES)
    for case in cases:
        if case not in CASES:
            raise ValueError(f"bench: unknown case {case!r}; cases: {', '.join(CASES)}")
    if cycles is None:
        cycles = GPU_CYCLES if on_gpu else CPU_CYCLES
    if cycles < 1:
        raise ValueError(f"bench: --cycles must be at least 1, got {cycles}")
    if repeats < 1:
        raise ValueError(f"bench: --repeats must be at least 1, got {repeats}")
    info = meta(dev)
    out(f"somwidget bench: {info['device_name']} [{dev}], warp {info['warp']}, numpy {info['numpy']}, "
        f"python {info['python']}, {info['date']}")
    cores = "" if dev != "cpu" else f"CPU cores {cpu_cores or 'chosen by the engine'}; "
    out(f"{cores}cycles {cycles}, frames of step({FRAME_STEP}), median of {repeats} repeats; "
        "ratio = numpy us/cycle / engine us/cycle; readback = som.weights after a frame")
    results = []
    for case in cases:
        res = run_case(case, dev, cycles, repeats, baseline, cpu_cores)
        results.append(res)
        out(f"  {case}: build {res.build_s:.2f} s; warm-up: first step(1) {res.first_step_s * 1e3:.1f} ms (kernel "
            f"load or compile, graph capture), first train() {res.first_train_s * 1e3:.1f} ms (capture + run)")
        if baseline:
            for u, us in res.numpy_variants_us.items():
                out(f"    numpy {u} update, {res.numpy_cycles} cycles: {us:,.1f} us/cycle"
                    f"{' (in the table)' if u == res.numpy_update else ''}; "
                    f"{_agreement_note(res.agreement[u], res.agree_of)}")
            out(f"    own learning table vs engine's: max diff {res.table_max_diff:.1e}")
    out("")
    out(format_table(results))
    handles = shaping_figures(dev, repeats, out)
    if json_path:
        with open(json_path, "w") as f:
            json.dump({"meta": info, "cycles": cycles, "frame_step": FRAME_STEP, "repeats": repeats,
                       "results": [asdict(r) for r in results], "handles": handles}, f, indent=2, allow_nan=True)
        out(f"\nwrote {json_path}")
    return results

