"""An independent float64 reference of the somwidget engine, written from the algorithm alone (as backend/som.py
states it).

Nothing here imports or calls somwidget: topology edges, BFS distances, the learning table, mirroring,
winners, moves and smoothing are re-derived with plain Python and numpy in float64, so the tests can hold
the float32 Warp engine to the design rather than to itself.

Besides the reference, this module builds the small test meshes (lattice, torus grid, mixed mesh...) as
plain index lists, and measures the winner margin of every iteration so a test can assert that winners are
well separated (no near-tie that float32 could resolve the other way) instead of loosening tolerances.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Sequence

import numpy as np

UNREACHABLE = 65535
MAX_DENSE_VERTICES = 65536
MAX_CONTROLS = 256
MAX_DIMS = 32


# ----------------------------------------------------------------------------------------------- topology
def _canonical_edges(pairs: Iterable[tuple[int, int]]) -> np.ndarray:
    """Unique undirected edges (i < j), sorted, self-loops dropped, as an (E, 2) int64 array."""
    seen = set()
    for a, b in pairs:
        a, b = int(a), int(b)
        if a == b:
            continue
        seen.add((min(a, b), max(a, b)))
    if not seen:
        return np.zeros((0, 2), dtype=np.int64)
    return np.array(sorted(seen), dtype=np.int64)


def edges_from_faces(faces: Iterable[Sequence[int]]) -> np.ndarray:
    """Each face's consecutive vertices and its closing pair are edges; duplicates and self-loops ignored."""
    pairs = []
    for face in faces:
        face = [int(v) for v in face]
        k = len(face)
        for i in range(k):
            pairs.append((face[i], face[(i + 1) % k]))
    return _canonical_edges(pairs)


def edges_from_edges(edges) -> np.ndarray:
    """Canonical form of a raw edge list: duplicates (either orientation) and self-loops dropped."""
    return _canonical_edges((int(a), int(b)) for a, b in np.asarray(edges).reshape(-1, 2))


def adjacency(n_vertices: int, edges) -> list[list[int]]:
    """Sorted neighbour lists from canonical (or raw) edges."""
    nbrs: list[set[int]] = [set() for _ in range(n_vertices)]
    for a, b in edges_from_edges(edges):
        nbrs[a].add(b)
        nbrs[b].add(a)
    return [sorted(s) for s in nbrs]


def bfs_distances(n_vertices: int, edges) -> np.ndarray:
    """(N, N) uint16 BFS hop counts; 0 on the diagonal; 65535 where unreachable. Plain Python BFS."""
    nbrs = adjacency(n_vertices, edges)
    out = np.full((n_vertices, n_vertices), UNREACHABLE, dtype=np.int64)
    for src in range(n_vertices):
        dist = out[src]
        dist[src] = 0
        queue = deque([src])
        while queue:
            v = queue.popleft()
            for w in nbrs[v]:
                if dist[w] == UNREACHABLE:
                    dist[w] = dist[v] + 1
                    queue.append(w)
    assert out[out != UNREACHABLE].max(initial=0) < UNREACHABLE
    return out.astype(np.uint16)


def d_max_of(dist: np.ndarray) -> int:
    """Largest finite distance (0 for a graph without edges)."""
    finite = dist[dist != UNREACHABLE]
    return int(finite.max()) if finite.size else 0


# ----------------------------------------------------------------------------------------------- schedule
def sigma_of(d_max: int) -> float:
    return d_max / np.sqrt(2.0 * np.log(2.0))


def alpha(s, S: int, l_start: float, l_end: float):
    s = np.asarray(s, dtype=np.float64)
    return l_start * l_end / (l_end + (l_start - l_end) * s / S)


def theta(d, s, S: int, d_max: int):
    """Neighbourhood factor; theta(0, s) = 1 always; d == 65535 (unreachable) -> 0."""
    d = np.asarray(d, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    sigma = sigma_of(d_max)
    c = sigma - sigma * s / S
    d, c = np.broadcast_arrays(d, c)
    out = np.zeros(d.shape, dtype=np.float64)
    zero = d == 0
    out[zero] = 1.0
    rest = (~zero) & (d != UNREACHABLE)
    # c > 0 for every s < S when d_max > 0; a d > 0 only exists when d_max > 0.
    out[rest] = np.exp(-(d[rest] ** 2) / (2.0 * c[rest] ** 2))
    return out


#: Past the dense table (distance rows) the neighbourhood is cut: theta below 2^-24 counts as 0.
ROWS_CUT = 2.0**-24
#: A group of carrying controls leaves node v as it is where alpha * sum_j g_j(v) * max_d |C_jd - W_u_j,d| (the most
#: it could move v in a dim) is below CARRY_CUT times the start shape's bounding diagonal.
CARRY_CUT = 2.0**-24


def learning_table(S: int, d_max: int, l_start: float = 0.25, l_end: float = 0.03, cut: float = 0.0) -> np.ndarray:
    """L[s, d] = alpha(s) * theta(d, s), s = 0 .. S-1, d = 0 .. d_max, float64; theta < cut taken as 0."""
    s = np.arange(S, dtype=np.float64)[:, None]
    d = np.arange(d_max + 1, dtype=np.float64)[None, :]
    t = theta(d, s, S, d_max)
    return alpha(s, S, l_start, l_end) * np.where(t >= cut, t, 0.0)


def schedule_table(schedule, d_max: int, cut: float = 0.0) -> np.ndarray:
    """`learning_table` of a schedule given as a mapping or an object of iterations (S), l_start and l_end (somwidget's
    Schedule, a Preset, a Som)."""
    get = schedule.__getitem__ if hasattr(schedule, "__getitem__") else lambda key: getattr(schedule, key)
    return learning_table(get("iterations"), d_max, get("l_start"), get("l_end"), cut)


def restart_iteration(reach: float, S: int) -> int:
    """s0 = floor((1 - reach) S), clamped to S - 1: where a local restart begins."""
    return min(int(np.floor((1.0 - reach) * S)), S - 1)


# ----------------------------------------------------------------------------------------------- controls
def effective_controls(controls, mirror: Sequence[int] = ()) -> np.ndarray:
    """[originals..., mirrored copies...] where each copy has the `mirror` dims negated; no mirror -> originals."""
    c = np.array(controls, dtype=np.float64, copy=True)
    if len(tuple(mirror)) == 0:
        return c
    m = c.copy()
    m[:, list(mirror)] *= -1.0
    return np.concatenate([c, m], axis=0)


def default_smooth_dims(n_dims: int) -> tuple[int, ...]:
    return tuple(d for d in (0, 1, 2) if d < n_dims)


def metric_distances(weights, controls, metric_weights=None) -> np.ndarray:
    """(k, N) float64 weighted squared distances sum_j m_j (C_cj - W_vj)^2."""
    w = np.asarray(weights, dtype=np.float64)
    c = np.asarray(controls, dtype=np.float64)
    m = np.ones(w.shape[1]) if metric_weights is None else np.asarray(metric_weights, dtype=np.float64)
    diff = c[:, None, :] - w[None, :, :]
    return np.einsum("kvj,j->kv", diff * diff, m)


def winners(weights, controls, metric_weights=None) -> np.ndarray:
    """argmin per control; np.argmin returns the lowest index on an exact tie, as the design asks."""
    return np.argmin(metric_distances(weights, controls, metric_weights), axis=1).astype(np.int64)


def winner_margins(weights, controls, metric_weights=None) -> np.ndarray:
    """(k,) relative gap (d2 - d1) / d2 between best and second-best weighted squared distance per control.

    0 means an exact tie. A float32 distance is good to a few eps (1.2e-7) relative, and a weight drift
    delta moves it by about 2 delta / sqrt(d) relative, so a margin of 1e-4 (~840 eps) or more cannot be
    flipped by float32 noise on short runs. A single neuron has no competitor: margin +inf.
    """
    d = metric_distances(weights, controls, metric_weights)
    if d.shape[1] < 2:
        return np.full(d.shape[0], np.inf)
    part = np.partition(d, 1, axis=1)
    d1, d2 = part[:, 0], part[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(d2 > 0, (d2 - d1) / d2, 0.0)
    return rel


# ----------------------------------------------------------------------------------------------- SOM
class ReferenceSom:
    """float64 mirror of the public Som semantics (the algorithm and the public API of backend/som.py).

    `margins` records, for every iteration run, the (k_eff,) winner margins used to pick the winners.
    """

    def __init__(
        self,
        n_vertices: int,
        edges,
        weights,
        controls,
        iterations: int = 1000,
        l_start: float = 0.25,
        l_end: float = 0.03,
        smoothing: float = 0.0,
        smooth_dims=None,
        metric_weights=None,
        mirror: Sequence[int] = (),
        reach: float = 0.08,  # the engine's default (chosen by measurement)
        radii=None,
        group_maps=None,
        smoothing_rule: str = "laplacian",
        strokes=None,
        cut: float = 0.0,
    ):
        self.n_vertices = int(n_vertices)
        self.cut = float(cut)  # ROWS_CUT for the engine's distance rows mode
        self.reach = float(reach)
        self.edges = edges_from_edges(edges)
        self.dist = bfs_distances(self.n_vertices, self.edges)
        self.d_max = d_max_of(self.dist)
        self.neighbours = adjacency(self.n_vertices, self.edges)
        # uniform Laplacian: the mean over v's neighbours as a dense (N, N) averaging operator (N is small here)
        self._mean_op = np.zeros((self.n_vertices, self.n_vertices))
        for v, nb in enumerate(self.neighbours):
            if nb:
                self._mean_op[v, nb] = 1.0 / len(nb)
        self._has_nb = np.array([len(nb) > 0 for nb in self.neighbours], dtype=bool)
        self.start_weights = np.array(weights, dtype=np.float64, copy=True)
        assert self.start_weights.shape[0] == self.n_vertices
        self.W = self.start_weights.copy()
        self.smoothing = float(smoothing)
        self.smooth_dims = smooth_dims
        self.metric_weights = None if metric_weights is None else np.asarray(metric_weights, dtype=np.float64)
        self.mirror = tuple(mirror)
        self._iterations = int(iterations)
        self._l_start = float(l_start)
        self._l_end = float(l_end)
        self.controls = np.array(controls, dtype=np.float64, copy=True)
        self.iteration = 0
        self.margins: list[np.ndarray] = []
        self._table()
        # the shaping rules (a radius per control, groups of any order, Taubin's smoothing): stated in
        # backend/shaping_kernels.py's docstring; `group_maps` (G, n, n) maps each control to its copies, identity first
        self.radii = np.zeros(len(self.controls)) if radii is None else np.array(radii, dtype=np.float64)
        self.group_maps = None if group_maps is None else np.asarray(group_maps, dtype=np.float64)
        self.smoothing_rule = smoothing_rule
        self.strokes = [1] * len(self.controls) if strokes is None else list(strokes)
        self.rest = self.W.copy()
        self.sigmas = None  # the carrying controls' widths, fitted at a restart's first cycle
        self.grabbed = None  # the winners found at a restart's first cycle (a carrying control keeps its own)
        p = self.start_weights[:, :min(3, self.n_dims)]
        lengths = np.linalg.norm(p[self.edges[:, 0]] - p[self.edges[:, 1]], axis=1) if len(self.edges) else [1.0]
        self.edge = float(np.median(lengths)) or 1.0
        # a carrying group leaves a node where the most it could move it is below 2^-24 of the start shape's size
        self.floor = CARRY_CUT * (float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) or 1.0)

    # schedule parameters: changing one restarts at s0 from the latest weights
    def _restart(self):
        self.iteration = restart_iteration(self.reach, self._iterations)
        self.rest = self.W.copy()
        self.sigmas = None
        self.grabbed = None

    def restart(self):
        """A local restart from the latest weights (what a change of smoothing or metric weights does)."""
        self._restart()

    def _table(self):
        self.L = learning_table(self._iterations, self.d_max, self._l_start, self._l_end, self.cut)

    @property
    def iterations(self):
        return self._iterations

    @iterations.setter
    def iterations(self, value):
        self._iterations = int(value)
        self._table()
        self._restart()

    @property
    def l_start(self):
        return self._l_start

    @l_start.setter
    def l_start(self, value):
        self._l_start = float(value)
        self._table()
        self._restart()

    @property
    def l_end(self):
        return self._l_end

    @l_end.setter
    def l_end(self, value):
        self._l_end = float(value)
        self._table()
        self._restart()

    @property
    def n_dims(self) -> int:
        return self.W.shape[1]

    @property
    def weights(self) -> np.ndarray:
        return self.W.copy()

    @property
    def effective_controls(self) -> np.ndarray:
        return effective_controls(self.controls, self.mirror)

    def learning_table(self) -> np.ndarray:
        return self.L.copy()

    def winners(self) -> np.ndarray:
        return winners(self.W, self.effective_controls, self.metric_weights)

    def set_controls(self, controls, radii=None, strokes=None):
        self.controls = np.array(controls, dtype=np.float64, copy=True)
        if radii is not None:
            self.radii = np.array(radii, dtype=np.float64)
        if strokes is not None or len(self.strokes) and sum(self.strokes) != len(self.controls):
            self.strokes = [1] * len(self.controls) if strokes is None else list(strokes)
        self._restart()

    def set_weights(self, weights):
        self.W = np.array(weights, dtype=np.float64, copy=True)
        self._restart()

    def restore(self, weights, iteration):
        self.W = np.array(weights, dtype=np.float64, copy=True)
        self.iteration = int(iteration)
        self.rest = self.W.copy()
        self.sigmas = None
        self.grabbed = None

    def reset(self):
        self.W = self.start_weights.copy()
        self.iteration = 0
        self.rest = self.W.copy()
        self.sigmas = None
        self.grabbed = None

    @property
    def shaping(self) -> bool:
        return bool(self.radii.any()) or self.group_maps is not None or len(self.strokes) < len(self.controls) or (
            self.smoothing_rule == "taubin" and self.smoothing > 0)

    def _smooth_dims(self) -> tuple[int, ...]:
        if self.smooth_dims is None:
            return default_smooth_dims(self.n_dims)
        return tuple(int(d) for d in self.smooth_dims)

    def _one_shaping_iteration(self):
        """The shaping rules: a control of radius r > 0 carries its winner's region, W_v += alpha(s) g (C - W_u), g =
        exp(-|x_v - x_u|^2 / (2 sigma^2)) of the rest positions (where the restart began), 0 in another connected part;
        sigma = max(r / 2, sqrt(h e / 18 degrees)) with h the control's distance from its winner at the restart's first
        cycle and e the start mesh's median edge, u the winner the control grabbed at that first cycle (kept for the
        rest of the run; a point control's winner is found every cycle); radius 0 is the paper's rule; a control and its
        copies act together, scaled when there are copies by 1 / max(1, sum of their rates), a carrying group by its
        falloffs' sum; smoothing is lambda, then Taubin's mu."""
        s = self.iteration
        W = self.W
        maps = self.group_maps if self.group_maps is not None else np.eye(self.n_dims)[None]
        if self.group_maps is None and self.mirror:
            flip = np.eye(self.n_dims)
            flip[list(self.mirror), list(self.mirror)] = -1.0
            maps = np.stack([np.eye(self.n_dims), flip])
        G = len(maps)
        # each group: a stroke's samples (or one control) and their copies, their rates from the same W
        groups, first = [], 0
        for length in self.strokes:
            groups.append([(c, g) for g in range(G) for c in range(first, first + length)])
            first += length
        slots = [slot for group in groups for slot in group]
        members = np.array([maps[g] @ self.controls[c] for c, g in slots])
        margins = winner_margins(W, members, self.metric_weights)
        win = winners(W, members, self.metric_weights)
        carrying = np.array([self.radii[c] > 0 for c, _ in slots])
        if self.grabbed is None:  # the restart's first cycle: each control grabs its winner
            self.grabbed = win.copy()
        else:  # a carrying control keeps the node it grabbed (its search no longer matters)
            win = np.where(carrying, self.grabbed, win)
            margins = np.where(carrying, np.inf, margins)
        self.margins.append(margins)
        wu = W[win].copy()
        alpha = self.L[s, 0]
        pos = list(range(min(3, self.n_dims)))
        if self.sigmas is None:  # the restart's first cycle: each carrying control's width for its pull
            h = np.linalg.norm((members - wu)[:, pos], axis=1)
            base = np.array([0.5 * self.radii[c] for c, _ in slots])
            self.sigmas = np.where(base > 0, np.maximum(base, np.sqrt(h * self.edge / (np.pi / 10))), 0.0)
        j = 0
        for number, group in enumerate(groups):
            step = np.zeros_like(W)
            total = np.zeros(self.n_vertices)
            nearest = np.zeros(self.n_vertices)
            carried = np.zeros(self.n_vertices)  # sum of falloff x the member's largest offset
            pulled = np.zeros(self.n_vertices, bool)  # a point member with a rate
            for c, _g in group:
                d = self.dist[win[j]].astype(np.int64)
                ok = d != UNREACHABLE
                rate = np.zeros(self.n_vertices)
                if self.radii[c] == 0:
                    rate[ok] = self.L[s, d[ok]]
                    step += rate[:, None] * (members[j][None, :] - W)
                    total += rate
                    pulled |= rate > 0
                else:
                    sigma = self.sigmas[j]
                    apart = self.rest[:, pos] - self.rest[win[j], pos]
                    falloff = np.where(ok, np.exp(-np.sum(apart**2, axis=1) / (2 * sigma**2)), 0.0)
                    step += (alpha * falloff)[:, None] * (members[j] - wu[j])[None, :]
                    total += falloff
                    nearest = np.maximum(nearest, falloff)
                    carried += falloff * np.abs(members[j] - wu[j]).max()
                j += 1
            if self.strokes[number] > 1:  # a stroke: the falloff-weighted mean offset, times the nearest falloff
                with np.errstate(invalid="ignore", divide="ignore"):
                    step *= np.where(total > 0, nearest / total, 0.0)[:, None]
            elif len(group) > 1:
                step /= np.maximum(1.0, total)[:, None]
            step[~pulled & (alpha * carried < self.floor)] = 0.0  # too little to move the node
            W += step
        dims = list(self._smooth_dims())
        lams = [] if self.smoothing <= 0 else [self.smoothing]
        if lams and self.smoothing_rule == "taubin":
            lams.append(1.0 / (0.015 - 1.0 / self.smoothing))  # mu of Taubin's pair, pass band 0.015
        for lam in lams:
            old = W[:, dims].copy()
            mean = self._mean_op @ old
            W[:, dims] = np.where(self._has_nb[:, None], old + lam * (mean - old), old)
        self.iteration += 1

    def _one_iteration(self):
        if self.shaping:
            return self._one_shaping_iteration()
        s = self.iteration
        C = self.effective_controls
        W = self.W
        # 1. all winners from W(s) before any move
        self.margins.append(winner_margins(W, C, self.metric_weights))
        win = winners(W, C, self.metric_weights)
        # 2. every neuron applies the controls in list order; with mirroring, control c and its copy k + c act
        #    together at c's place: both rates from the same W, scaled by 1 / max(1, l1 + l2)
        def rate(c):
            d = self.dist[win[c]].astype(np.int64)
            out = np.zeros(self.n_vertices)
            reach = d != UNREACHABLE
            out[reach] = self.L[s, d[reach]]
            return out

        k = self.controls.shape[0]
        if self.mirror:
            for c in range(k):
                l1, l2 = rate(c), rate(k + c)
                scale = 1.0 / np.maximum(1.0, l1 + l2)
                W += (l1 * scale)[:, None] * (C[c][None, :] - W) + (l2 * scale)[:, None] * (C[k + c][None, :] - W)
        else:
            for c in range(C.shape[0]):
                W += rate(c)[:, None] * (C[c][None, :] - W)
        # 3. one Jacobi step of uniform Laplacian smoothing on smooth_dims
        lam = self.smoothing
        dims = list(self._smooth_dims())
        if lam > 0 and dims:
            old = W[:, dims].copy()
            mean = self._mean_op @ old  # rows of neurons without a neighbour are 0 and masked out below
            W[:, dims] = np.where(self._has_nb[:, None], old + lam * (mean - old), old)
        self.iteration += 1

    def step(self, n: int = 1) -> int:
        run = max(0, min(int(n), self._iterations - self.iteration))
        for _ in range(run):
            self._one_iteration()
        return run

    def train(self) -> int:
        return self.step(self._iterations - self.iteration)

    def min_margin(self) -> float:
        """Smallest winner margin over every iteration run so far (inf if none)."""
        if not self.margins:
            return float("inf")
        return float(min(np.min(m) for m in self.margins))


# ----------------------------------------------------------------------------------------------- meshes
def lattice_edges(nx: int, ny: int, nz: int) -> tuple[np.ndarray, np.ndarray]:
    """6-neighbour lattice: (edges (E, 2), points (N, 3)); vertex index i + nx * (j + ny * k)."""

    def idx(i, j, k):
        return i + nx * (j + ny * k)

    edges = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                if i + 1 < nx:
                    edges.append((idx(i, j, k), idx(i + 1, j, k)))
                if j + 1 < ny:
                    edges.append((idx(i, j, k), idx(i, j + 1, k)))
                if k + 1 < nz:
                    edges.append((idx(i, j, k), idx(i, j, k + 1)))
    kk, jj, ii = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    points = np.stack([ii.ravel(), jj.ravel(), kk.ravel()], axis=1).astype(np.float64)
    return np.array(edges, dtype=np.int64), points


def lattice_quads(nx: int, ny: int, nz: int) -> np.ndarray:
    """(F, 4) quads: every unit square of the lattice in the three axis planes (same edges as lattice_edges)."""

    def idx(i, j, k):
        return i + nx * (j + ny * k)

    quads = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                if i + 1 < nx and j + 1 < ny:
                    quads.append((idx(i, j, k), idx(i + 1, j, k), idx(i + 1, j + 1, k), idx(i, j + 1, k)))
                if i + 1 < nx and k + 1 < nz:
                    quads.append((idx(i, j, k), idx(i + 1, j, k), idx(i + 1, j, k + 1), idx(i, j, k + 1)))
                if j + 1 < ny and k + 1 < nz:
                    quads.append((idx(i, j, k), idx(i, j + 1, k), idx(i, j + 1, k + 1), idx(i, j, k + 1)))
    return np.array(quads, dtype=np.int64)


def torus_quads(nu: int, nv: int) -> np.ndarray:
    """(nu * nv, 4) quads of a periodic nu x nv grid; vertex index i + nu * j."""
    quads = []
    for j in range(nv):
        for i in range(nu):
            a = i + nu * j
            b = (i + 1) % nu + nu * j
            c = (i + 1) % nu + nu * ((j + 1) % nv)
            d = i + nu * ((j + 1) % nv)
            quads.append((a, b, c, d))
    return np.array(quads, dtype=np.int64)


def torus_points(nu: int, nv: int, R: float = 2.0, r: float = 0.7) -> np.ndarray:
    u = 2 * np.pi * np.arange(nu) / nu
    v = 2 * np.pi * np.arange(nv) / nv
    vv, uu = np.meshgrid(v, u, indexing="ij")
    x = (R + r * np.cos(vv)) * np.cos(uu)
    y = (R + r * np.cos(vv)) * np.sin(uu)
    z = r * np.sin(vv)
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def grid_quads(nx: int, ny: int, offset: int = 0) -> np.ndarray:
    """(F, 4) quads of an open nx x ny grid, vertex index offset + i + nx * j."""
    quads = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = offset + i + nx * j
            quads.append((a, a + 1, a + 1 + nx, a + nx))
    return np.array(quads, dtype=np.int64)


def mixed_faces() -> list[list[int]]:
    """A strip of 14 vertices made of triangles, quads, a pentagon and a hexagon (faces of different lengths)."""
    return [
        [0, 1, 2],  # triangle
        [1, 3, 4, 2],  # quad
        [3, 5, 6, 7, 4],  # pentagon
        [5, 8, 9, 6],  # quad
        [8, 10, 9],  # triangle
        [9, 10, 11, 12, 13, 6],  # hexagon
        [6, 13, 7],  # triangle sharing edges with the hexagon and the pentagon
    ]
