"""Design variants: what a sweep runs (`VariantPlan`), how its variants are drawn from a seed (`plan_variants`), and
running them in batches here or on a Dask cluster (`run_plan`), with the figures that compare them (`figures`).

numpy and Warp only: a Dask worker needs nothing else. A plan carries the mesh as an edge list, so it pickles small;
a worker rebuilds the topology once per mesh.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from . import checks, metrics
from .batch import MAX_BATCH_NEURONS, MAX_TABLE_ENTRIES, BatchSom
from .metrics import _face_arrays
from .schedule import BY_NAME, KEYS
from .symmetry import Symmetry
from .topology import Topology

FIGURES = ("gap", "spike", "symmetry", "size")


@dataclass(frozen=True)
class VariantPlan:
    """n variants of one mesh: their controls (n, k, dims) and schedules (each key of schedule.KEYS: (n,)).

    restart False: each variant is a whole run from `start` (as `Som.reset()` then `train()`); True: each is a local
    restart from `start` (a session's current weights), as a move of its controls would be. With controls that have
    a radius (handles), each variant is always its controls' typed move from `base` (the design's controls) on
    `start`: every moved control grabbed at its old place and released, the run from s0 to S (a whole run would
    bind nothing)."""

    n_vertices: int
    edges: np.ndarray
    start: np.ndarray
    controls: np.ndarray
    schedules: dict
    restart: bool = False
    mirror: tuple[int, ...] = ()
    smooth_dims: tuple[int, ...] | None = None
    metric_weights: np.ndarray | None = None
    position_dims: tuple[int, ...] = (0, 1, 2)
    radii: np.ndarray | None = None  # (k,) the controls' radii, the same in every variant (None: point controls)
    origin: np.ndarray | None = None  # with `restart`: the session's start mesh (its Som's start weights)
    strokes: tuple[int, ...] | None = None  # the runs of controls that act as one (None: each alone)
    symmetry: Symmetry | None = None  # a radial group (a mirror is `mirror`)
    smoothing_rule: str = "laplacian"
    base: np.ndarray | None = None  # (k, dims) the design's controls, where a typed move grabs (None: each variant's)
    faces: tuple[np.ndarray, np.ndarray] | None = None  # (every face's vertices in a row, each face's size): the
    # closed parts whose volume Taubin's smoothing keeps (None: a mesh of edges)

    @property
    def handles(self) -> bool:
        """Some control has a radius: each variant is a typed move of its controls from `base`."""
        return self.radii is not None and bool(np.any(np.asarray(self.radii) > 0))

    @property
    def singles(self) -> bool:
        """The variants run as single Soms, one after another: the shaping path's rules (controls with a radius, a
        radial group, Taubin's smoothing), strokes, or a mesh past a batch's dense table (batch.MAX_BATCH_NEURONS).
        The batched kernel runs the paper's rule only (batch.py)."""
        taubin = self.smoothing_rule == "taubin" and bool(np.any(self.schedules["smoothing"] > 0))
        return self.handles or taubin or self.symmetry is not None or bool(
            self.strokes and len(self.strokes) < self.controls.shape[1]) or self.n_vertices > MAX_BATCH_NEURONS

    @property
    def n_variants(self) -> int:
        return len(self.controls)

    def part(self, lo: int, hi: int) -> VariantPlan:
        """Variants lo .. hi - 1 as a plan of their own."""
        return replace(self, controls=self.controls[lo:hi],
                       schedules={key: values[lo:hi] for key, values in self.schedules.items()})

    def params(self, i: int) -> dict:
        """Variant i's schedule as a dict, as Som keeps it (iterations an int)."""
        return {key: BY_NAME[key].check(v[i], key) for key, v in self.schedules.items()}


def _draw(name: str, spec, base, n: int, rng: np.random.Generator) -> np.ndarray:
    """n values of one parameter: the base value (spec None), uniform in a (low, high) range, or drawn from a list;
    int64 for a whole-number parameter (iterations), else float64."""
    setting = BY_NAME[name]
    whole = setting.kind == "int"
    dtype = np.int64 if whole else np.float64

    def check(x):
        return setting.check(x, f"params[{name!r}]")

    if spec is None:
        return np.full(n, check(base), dtype)
    if isinstance(spec, tuple):
        if len(spec) != 2:
            raise ValueError(f"params[{name!r}]: a range is (low, high), got {spec!r}")
        lo, hi = check(spec[0]), check(spec[1])
        if lo > hi:
            raise ValueError(f"params[{name!r}]: the range's low {lo} is above its high {hi}")
        if whole:
            return rng.integers(lo, hi + 1, n).astype(dtype)
        return rng.uniform(lo, hi, n)
    if isinstance(spec, (list, np.ndarray)):
        values = [check(x) for x in list(spec)]
        if not values:
            raise ValueError(f"params[{name!r}]: the list of values is empty")
        return np.asarray(values, dtype)[rng.integers(0, len(values), n)]
    return np.full(n, check(spec), dtype)


def plan_variants(topology: Topology, start, controls, base_params: Mapping, n: int, jitter: float = 0.05,
                  params: Mapping | None = None, seed: int = 0, restart: bool = False, mirror: Sequence[int] = (),
                  smooth_dims=None, metric_weights=None, position_dims: Sequence[int] = (0, 1, 2), radii=None,
                  symmetry: Symmetry | None = None, smoothing_rule: str = "laplacian", origin=None,
                  strokes=None) -> VariantPlan:
    """n variants around one design. Each control moves by up to `jitter` times the model's size (its bounding
    diagonal), in a direction and by a share drawn uniformly in a ball; `params` maps a schedule parameter to a
    (low, high) range, a list of values or one value (the others keep `base_params`). The same seed gives the same
    variants."""
    n = checks.integer("n", n, 1, 1_000_000)
    jitter = checks.real("jitter", jitter, 0.0, 1.0)
    params = dict(params or {})
    unknown = sorted(set(params) - set(KEYS))
    if unknown:
        raise ValueError(f"params: unknown parameter(s) {unknown}; expected some of {list(KEYS)}")
    start = checks.finite_array("weights", start, 2)
    base = checks.finite_array("controls", controls, 2)
    dims = [d for d in position_dims if d < start.shape[1]]
    size = metrics.bounding_diagonal(start[:, dims]) or 1.0
    rng = np.random.default_rng(checks.integer("seed", seed, 0))
    k = len(base)
    direction = rng.normal(size=(n, k, len(dims)))
    direction /= np.maximum(np.linalg.norm(direction, axis=2, keepdims=True), 1e-12)
    radius = jitter * size * rng.uniform(size=(n, k, 1)) ** (1.0 / max(1, len(dims)))
    out = np.repeat(base[None].astype(np.float64), n, axis=0)
    out[:, :, dims] += direction * radius
    schedules = {key: _draw(key, params.get(key), base_params[key], n, rng) for key in KEYS}
    edges = np.ascontiguousarray(np.asarray(topology.edges, np.int32).reshape(-1, 2))
    faces = None
    if topology.faces is not None:
        flat, sizes = _face_arrays(getattr(topology.faces, "array", topology.faces))
        faces = (flat.astype(np.int32), sizes.astype(np.int32))
    return VariantPlan(n_vertices=topology.n_vertices, edges=edges, start=start, controls=out.astype(np.float32),
                       schedules=schedules, restart=bool(restart), mirror=tuple(mirror),
                       smooth_dims=None if smooth_dims is None else tuple(smooth_dims),
                       metric_weights=None if metric_weights is None else np.asarray(metric_weights, np.float32),
                       position_dims=tuple(dims), radii=None if radii is None else np.asarray(radii, np.float32),
                       symmetry=symmetry, smoothing_rule=smoothing_rule,
                       origin=None if origin is None else np.asarray(origin, np.float32),
                       strokes=None if strokes is None else tuple(strokes), base=base.astype(np.float32), faces=faces)


@functools.lru_cache(maxsize=4)
def _topology(n_vertices: int, edges_bytes: bytes, flat: bytes | None, sizes: bytes | None) -> Topology:
    if flat is None or sizes is None:
        edges = np.frombuffer(edges_bytes, np.int32).reshape(-1, 2)
        return Topology.from_edges(edges, n_vertices)
    cuts = np.cumsum(np.frombuffer(sizes, np.int32))[:-1]
    return Topology.from_faces(np.split(np.frombuffer(flat, np.int32).astype(np.int64), cuts), n_vertices)


def topology_of(plan: VariantPlan) -> Topology:
    """The plan's mesh (with its faces where it has them), built once per process (a Dask worker keeps it for the
    next batch)."""
    flat, sizes = (None, None) if plan.faces is None else (plan.faces[0].tobytes(), plan.faces[1].tobytes())
    return _topology(plan.n_vertices, plan.edges.tobytes(), flat, sizes)


def run_batch(plan: VariantPlan, device: str | None = None) -> tuple[np.ndarray, dict]:
    """Train every variant of `plan` in one batch on `device` (None: this process's GPU when there is one):
    (weights (n, N, dims) float32, figures: each of FIGURES an (n,) array)."""
    s = plan.schedules
    if plan.singles:
        weights = _run_singles(plan, device)
        return weights, figures(plan, weights)
    som = BatchSom(topology_of(plan), plan.start, plan.controls, smooth_dims=plan.smooth_dims,
                   metric_weights=plan.metric_weights, mirror=plan.mirror, device=device,
                   smoothing_rule=plan.smoothing_rule, **{key: s[key] for key in KEYS})
    if plan.restart:
        som.restart()
    som.train()
    weights = som.weights
    return weights, figures(plan, weights)


def _run_singles(plan: VariantPlan, device: str | None) -> np.ndarray:
    """The variants one Som after another (the shaping path's rules, strokes, big meshes): each is its own run. A
    local restart (or any variant with handles) is the variant's controls set on the design's shape: a typed move
    from `base` of each control with a radius, a local restart for the point controls."""
    from .som import Som

    topology, out = topology_of(plan), []
    origin = plan.start if plan.origin is None else plan.origin
    typed = plan.restart or plan.handles
    for i in range(plan.n_variants):
        places = plan.base if typed and plan.base is not None else plan.controls[i]
        som = Som(topology, origin, places, **plan.params(i), smooth_dims=plan.smooth_dims,
                  metric_weights=plan.metric_weights, mirror=plan.mirror, radii=plan.radii, symmetry=plan.symmetry,
                  strokes=plan.strokes, smoothing_rule=plan.smoothing_rule, device=device)
        if typed:
            som.restore(plan.start, som.iterations)
            som.set_controls(plan.controls[i])
        som.train()
        out.append(som.weights)
    return np.stack(out)


def figures(plan: VariantPlan, weights: np.ndarray) -> dict:
    """Per variant, over the model's size where a length: `gap` the largest distance from a control (mirrored copies
    included) to its nearest node, `spike` the largest spike figure of those nearest nodes (metrics.spike_figures:
    the distance to the mean of the one-ring over the median edge length), `symmetry` the mirror error
    (metrics.symmetry_error; 0 without a mirrored position dim), `size` the bounding diagonal. All variants at once,
    in float64."""
    dims = list(plan.position_dims)
    topology = topology_of(plan)
    mirror_dims = [dims.index(m) for m in plan.mirror if m in dims]
    pairing = metrics.mirror_map(plan.start[:, dims], mirror_dims[0]) if mirror_dims else None
    p = np.asarray(weights, np.float64)[:, :, dims]
    n = len(p)
    size = np.linalg.norm(p.max(axis=1) - p.min(axis=1), axis=1)
    size = np.where(size > 0, size, 1.0)
    controls = plan.controls.astype(np.float64)
    if plan.symmetry is not None:
        controls = plan.symmetry.images(controls)
    elif plan.mirror:
        image = controls.copy()
        image[:, :, list(plan.mirror)] *= -1.0
        controls = np.concatenate([controls, image], axis=1)
    targets = controls[:, :, dims]
    rows = np.arange(n)[:, None]
    nearest = np.zeros(targets.shape[:2], np.int64)
    block = max(1, 8_000_000 // max(1, targets.shape[1] * p.shape[1]))
    for lo in range(0, n, block):
        diff = targets[lo:lo + block, :, None, :] - p[lo:lo + block, None, :, :]
        nearest[lo:lo + block] = np.einsum("bknd,bknd->bkn", diff, diff).argmin(axis=2)
    gap = np.linalg.norm(targets - p[rows, nearest], axis=2).max(axis=1) / size
    spike = np.zeros(n)
    edges = np.asarray(topology.edges, np.int64).reshape(-1, 2)
    degree = np.diff(topology.offsets)
    if len(edges):
        median_edge = np.median(np.linalg.norm(p[:, edges[:, 0]] - p[:, edges[:, 1]], axis=2), axis=1)
        median_edge = np.where(median_edge > 0, median_edge, 1.0)
        # the one-rings of the nearest nodes only, padded to the largest degree among them
        ring_degree = degree[nearest]
        width = max(1, int(ring_degree.max()))
        slot = np.arange(width)
        index = topology.offsets[nearest][..., None] + np.minimum(slot, np.maximum(ring_degree[..., None] - 1, 0))
        ring = topology.neighbors[np.minimum(index, max(0, len(topology.neighbors) - 1))]
        inside = slot < ring_degree[..., None]
        ring_points = p[rows[:, :, None], ring] * inside[..., None]
        ring_mean = ring_points.sum(axis=2) / np.maximum(ring_degree, 1)[..., None]
        offset = np.where(ring_degree > 0, np.linalg.norm(p[rows, nearest] - ring_mean, axis=2), 0.0)
        spike = offset.max(axis=1) / median_edge
    symmetry = np.zeros(n)
    if pairing is not None:
        image = p.copy()
        image[:, :, mirror_dims[0]] *= -1.0
        symmetry = np.linalg.norm(image - p[:, pairing], axis=2).max(axis=1) / size
    return {"gap": gap, "spike": spike, "symmetry": symmetry, "size": size}


def batch_size_for(plan: VariantPlan, device: str) -> int:
    """Variants a batch holds: on a GPU as many as the table limit allows (the whole plan, mostly); on the CPU a few
    per core, so that progress shows."""
    per_variant = int(plan.schedules["iterations"].max()) * (int(topology_of(plan).d_max) + 1)
    most = max(1, MAX_TABLE_ENTRIES // max(1, per_variant))
    return min(most, 4096 if device != "cpu" else 32)


Progress = Callable[[int, int], None]


def run_plan(plan: VariantPlan, device: str | None = None, client=None, batch_size: int | None = None,
             progress: Progress | None = None) -> tuple[np.ndarray, dict]:
    """Every variant of `plan`, in batches: here on `device`, or with a `dask.distributed.Client` on its workers
    (each batch one task; a worker trains on its own GPU when it has one, unless `device` says otherwise). The
    results are the same either way. progress(done, total) is called as variants finish."""
    from .device import resolve

    n = plan.n_variants
    if client is None:
        device = resolve(device)
    size = batch_size or (batch_size_for(plan, resolve(device)) if client is None else _dask_batch(plan, client))
    size = checks.integer("batch_size", size, 1)
    bounds = [(lo, min(n, lo + size)) for lo in range(0, n, size)]
    weights = np.empty((n, plan.n_vertices, plan.start.shape[1]), np.float32)
    figs = {name: np.zeros(n) for name in FIGURES}
    done = 0

    def collect(lo: int, result) -> None:
        nonlocal done
        w, f = result
        weights[lo:lo + len(w)] = w
        for name in FIGURES:
            figs[name][lo:lo + len(w)] = f[name]
        done += len(w)
        if progress is not None:
            progress(done, n)

    if client is None:
        for lo, hi in bounds:
            collect(lo, run_batch(plan.part(lo, hi), device))
        return weights, figs
    from distributed import as_completed

    futures = {client.submit(run_batch, plan.part(lo, hi), device, pure=False): lo for lo, hi in bounds}
    try:
        for future in as_completed(futures):
            collect(futures[future], future.result())
    finally:
        for future in futures:
            future.cancel()
    return weights, figs


def _dask_batch(plan: VariantPlan, client) -> int:
    """Four batches a worker (at least one variant each), so a slow worker does not hold the end up."""
    workers = max(1, len(client.scheduler_info().get("workers", {})))
    return max(1, math.ceil(plan.n_variants / (4 * workers)))
