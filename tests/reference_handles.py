"""Handles: the normative float64 reference of modelling by hand (issue 34, item 1; DESIGN.md "Handles").

Like reference.py (whose paper's rule it reuses for the point controls) this module is written from the rule alone:
nothing here imports somwidget, so the Warp kernels can be held to it. `HandleSom` is the reference; `Rule` names the
choices benchmarks/bench_handles.py compared, and its defaults are the chosen rule, specified here.

INPUTS
  faces (any size; their consecutive nodes and closing pairs are the edges) or edges, over N nodes; weights W (N, n)
  float64; controls C (k, n); radii r (k,) in model units (0: the paper's point control); a symmetry group as maps
  M (G, n, n), the identity first (control c acts as its G members M_g C_c); the position dims P (default 0, 1, 2);
  the schedule (S, l_start, l_end, reach, smoothing lambda, Taubin's rule or the paper's Laplacian); metric weights m
  (the winner search's, default 1). Derived once: the box, lo / hi (n,): the bounding box of the start weights and of
  every place any member has been (updated whenever controls are set), grown on the position dims by the largest
  radius and BOX_MARGIN of the start's size (its position dims' bounding diagonal).

A BINDING (one member g of a control c of radius r > 0) holds: its winner u (fixed while it lives), its place
  p (n,) (where it carries its patch this step), its patch (node indices) with weights w, its winner's anchor a_u (n,).
  Every node has one anchor A_v (n,); anchors (A of every node, a_u of every binding) are re-taken from W whenever a
  binding is made, re-bound or ends, so a node's target never jumps.
  The patch around u, from W as it is: every node joined to u through nodes whose straight distance (position dims)
  from W_u is below its reach R (a flood over the edges inside that ball: the other wall of a thin part is not taken
  unless the clay joins it inside the ball); weight w_v = f(|W_v - W_u| / R), f(t) = (1 - t^2)^2 (f(0) = 1, flat at
  t = 0 and t = 1). The reach is r at the grab and R = max(r, WIDEN |p - p(grab)|) once the place p has been
  carried (a lift taller than r rolls rather than standing up in a step with a crease at its foot).

EVENTS (what the person does; a control of radius 0 binds nothing and stays the paper's, re-choosing its winner)
  grab(c)          for every member g: u = argmin_v sum_j m_j (M_g C_c - W_v)_j^2 (lowest index on a tie), place
                   p = W_u, the patch; the binding is held. Nothing moves; no restart.
  set_controls(C)  first the released bindings end. A control of radius > 0 that moved while not held is grabbed
                   at its old place and released at once (a typed position is a whole drag in one move). Then the
                   schedule restarts locally: s = s0 = floor((1 - reach) S), clamped to S - 1.
  release(c)       c's bindings are no longer held: they still carry the patch to where the hand left it, until the
                   run reaches S or the next restart (any set_controls, a parameter change), then end. No restart,
                   no cycle: nothing re-trains.
  restart()        (a parameter change) the released bindings end; s = s0.
  An unbound control of radius > 0 does nothing: between drags no control pulls the clay back or carries it again.

ONE CYCLE s (s0 <= s < S), in this order:
  1. winners of the point members (radius 0) from W before the cycle (reference.py, step 1);
  2. the paper's rule for each point control and its copies, in control order (reference.py, step 2);
  3. the handles: (a) every binding whose place p differs from its member m = M_g C_c steps towards it, p <- p +
     (m - p) min(1, STEP r / |m - p|_P) (|.|_P: the length in the position dims), and is bound again (the same
     winner u, its patch and weights from W now); if any was, every anchor is re-taken; (b) every bound node goes
     to its target T_v = A_v + W_v^c sum_b w_bv D_b / sum_b w_bv, over the bindings b that hold it, D_b = p_b -
     a_u,b, W_v^c = 1 - prod_b (1 - w_bv) (so one binding gives A_v + w_v D_b, its winner lands on p exactly; a
     node several hold takes their weighted mean displacement, never more than the longest). T_v is a convex blend
     of A_v and points p_b + (A_v - a_u,b) within R of a place the control has been, clamped into the box without
     BOX_MARGIN (where R > r the rim of a widened patch could leave it): no bound node leaves the box;
  4. smoothing, when lambda > 0, of the nodes no binding holds, on the smooth dims (default P), every neighbour's
     W after step 3 counting: lambda's Jacobi step of the uniform Laplacian (W_v += lambda (mean of v's neighbours -
     W_v), a node without a neighbour stays); with Taubin's rule then mu = 1 / (PASS_BAND - 1 / lambda) the same
     way (lambda capped at TAUBIN_MOST: past about 0.72 the pair amplifies the checkerboard mode of a quad mesh and
     the clay blows up), then, for every closed connected part (each edge of its faces on exactly two faces), the
     volume put back: its signed volume V (sum over its triangles, each face fanned from its first node, of
     p0 . (p1 x p2) / 6) before step 4 and V' after; its free nodes move by (V - V') g_v / sum_free |g|^2 along
     g_v = dV/dp_v (sum over v's triangles of (p_next x p_prev) / 6);
  5. with Taubin's rule, every node clamped into the box (the only steps that can leave it are Taubin's mu and the
     volume's, by far less than BOX_MARGIN on any mesh measured: the clamp is a guarantee, not a shaping step).
  s += 1; when s reaches S the released bindings end.

STROKES (`strokes`: run lengths of controls that act as one, the samples of a polyline; None: each control alone)
  The bindings of one stroke's samples for one copy g are one group, and a group enters step 3 (b) as one binding:
  its weight w_Gv = max over its bindings of w_bv, its displacement D_Gv = sum w_bv D_b / sum w_bv. So a stroke's
  clay falls off across it as one sample's does (the product of many overlapping samples' (1 - w) would make a
  flat top with steep walls), and T_v is still a convex blend within r of a place a member has been. A group of
  one binding is the rule above, unchanged.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, replace

import numpy as np
from reference import (
    UNREACHABLE,
    adjacency,
    bfs_distances,
    d_max_of,
    edges_from_edges,
    edges_from_faces,
    learning_table,
    restart_iteration,
    winner_margins,
    winners,
)

#: Taubin's pass band (the engine's shaping_path.PASS_BAND).
PASS_BAND = 0.015
#: Taubin's lambda is capped here: (1 - 2 lambda)(1 - 2 mu) must stay above -1 for the checkerboard mode (Laplacian
#: eigenvalue 2) of a bipartite mesh; at 0.75 a quad torus grew 7.7 times in 100 cycles, at 0.8 by 3e10.
TAUBIN_MOST = 0.7
#: A binding steps to its member's place by at most this share of its radius a cycle, and binds again at each step.
STEP = 0.25
#: The box is grown by this share of the start's size beyond the largest radius.
BOX_MARGIN = 0.01
#: A binding carried farther than half its radius binds its patch this many times as wide as it has been carried
#: (its reach R = max(r, WIDEN |p - p(grab)|)): a lift taller than the radius rolls instead of standing up in a step.
WIDEN = 2.0


# ----------------------------------------------------------------------------------------------- falloffs
def quartic(t):
    """(1 - t^2)^2: flat at 0 and at 1; f''(0) = -4, f''(1) = 8."""
    t = np.clip(t, 0.0, 1.0)
    return (1.0 - t * t) ** 2


def cosine(t):
    """(1 + cos(pi t)) / 2: flat at both ends, |f''| <= pi^2 / 2."""
    t = np.clip(t, 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * t))


def spline(t):
    """1 - 2 t^2 to t = 1/2, then 2 (1 - t)^2: the least curvature a fall from 1 to 0 flat at both ends can have
    (|f''| = 4); C1."""
    t = np.clip(t, 0.0, 1.0)
    return np.where(t < 0.5, 1.0 - 2.0 * t * t, 2.0 * (1.0 - t) ** 2)


def smootherstep(t):
    """1 - (6 t^5 - 15 t^4 + 10 t^3): flat to second order at both ends (|f''| <= 5.8)."""
    t = np.clip(t, 0.0, 1.0)
    return 1.0 - t * t * t * (t * (6.0 * t - 15.0) + 10.0)


def wendland(t):
    """Wendland's C2 function (1 - t)^4 (4 t + 1): flat to second order at the rim, a sharp top (f''(0) = -20)."""
    t = np.clip(t, 0.0, 1.0)
    return (1.0 - t) ** 4 * (4.0 * t + 1.0)


FALLOFFS = {"quartic": quartic, "cosine": cosine, "spline": spline, "smootherstep": smootherstep,
            "wendland": wendland}
#: The largest |f''| of each falloff (the fit's curvature bound).
CURVATURE = {"quartic": 8.0, "cosine": np.pi**2 / 2, "spline": 4.0, "smootherstep": 10.0 / np.sqrt(3.0),
             "wendland": 20.0}


@dataclass(frozen=True)
class Rule:
    """The choices of the handle rule; the defaults are the chosen ones (the module's docstring).

    falloff   a name of FALLOFFS
    distance  "euclid": straight distance over the part of the ball joined to the winner; "geodesic": Dijkstra over
              the edges and the faces' diagonals; "edges": Dijkstra over the edges; "hops": the BFS hop count times
              the mean length of the winner's edges (no bound: a hop can be shorter than the straight distance)
    blend     "or": the weighted mean displacement times 1 - prod (1 - w); "sum": sum w D / max(1, sum w) (DESIGN.md's:
              a ring of copies moves as one, but the target has a kink where the sum crosses 1: sawtooth creases)
    carry     "steps": bound again at every step of at most STEP r; "grab": bound once, at the grab, the target
              W(grab) + w (C - W_u(grab)) (DESIGN.md's first statement)
    rate      "hard": a bound node goes to its target (kappa 1); "schedule": by alpha(s) of the way
    others    "inert": an unbound control of radius > 0 does nothing; "paper": while any binding lives it pulls by
              the paper's rule as a point control
    volume    put the volume back after Taubin's smoothing (closed parts)
    """

    falloff: str = "quartic"
    distance: str = "euclid"
    blend: str = "or"
    carry: str = "steps"
    rate: str = "hard"
    others: str = "inert"
    volume: bool = True
    fit: float | None = None  # radians an edge: widen a binding's radius so its bump turns no more at any node
    widen: float | None = WIDEN  # the reach R = max(r, widen |p - p(grab)|) (None: the radius alone, or the fit)

    def but(self, **changes) -> Rule:
        return replace(self, **changes)


@dataclass
class Binding:
    """One member (copy g) of a grabbed control c: its winner, place, patch and weights, winner's anchor."""

    control: int
    copy: int
    winner: int
    place: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    held: bool = True
    anchor: np.ndarray | None = None
    start: np.ndarray | None = None  # W_u at the grab
    edge: float = 0.0  # the mean length of the winner's edges at the grab


# ----------------------------------------------------------------------------------------------- mesh helpers
def face_lists(faces) -> list[np.ndarray]:
    return [np.asarray(f, np.int64).ravel() for f in faces]


def fan_triangles(faces) -> np.ndarray:
    """(T, 3) the faces fanned from their first node, in face order."""
    out = [(f[0], f[j], f[j + 1]) for f in face_lists(faces) for j in range(1, len(f) - 1)]
    return np.array(out, np.int64).reshape(-1, 3)


def components(n: int, edges: np.ndarray) -> np.ndarray:
    """(N,) the connected part of every node, named by its lowest node."""
    parent = np.arange(n)

    def root(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in edges:
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    return np.array([root(a) for a in range(n)])


def closed_parts(n: int, faces, edges: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(nodes, triangles)] of every closed connected part: every edge of its faces is on exactly two faces."""
    if faces is None:
        return []
    part = components(n, edges)
    uses: dict[tuple[int, int], int] = {}
    for f in face_lists(faces):
        for i in range(len(f)):
            a, b = int(f[i]), int(f[(i + 1) % len(f)])
            if a != b:
                uses[(min(a, b), max(a, b))] = uses.get((min(a, b), max(a, b)), 0) + 1
    open_parts = {part[a] for (a, _b), count in uses.items() if count != 2}
    tris = fan_triangles(faces)
    return [(np.flatnonzero(part == p), tris[part[tris[:, 0]] == p])
            for p in (np.unique(part[tris[:, 0]]) if len(tris) else []) if p not in open_parts]


def signed_volume(p: np.ndarray, tris: np.ndarray) -> float:
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def volume_gradient(p: np.ndarray, tris: np.ndarray, n: int) -> np.ndarray:
    """(n, 3) dV/dp_v of the signed volume."""
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    terms = np.concatenate([np.cross(b, c), np.cross(c, a), np.cross(a, b)]) / 6.0
    at = tris.T.ravel()
    return np.stack([np.bincount(at, terms[:, j], minlength=n) for j in range(3)], axis=1)


def diagonal_links(n: int, faces, edges: np.ndarray) -> list[list[int]]:
    """Neighbour lists of the edges and every pair of nodes of a face."""
    nb = [set(x) for x in adjacency(n, edges)]
    for f in face_lists(faces or []):
        for i in f:
            nb[int(i)].update(int(j) for j in f if j != i)
    return [sorted(s) for s in nb]


def dijkstra(source: int, positions: np.ndarray, nbrs: list[list[int]], cutoff: float) -> dict[int, float]:
    """Shortest path lengths from `source` over the links (each as long as its segment), those below `cutoff`."""
    best = {source: 0.0}
    heap = [(0.0, source)]
    while heap:
        d, v = heapq.heappop(heap)
        if d > best.get(v, np.inf):
            continue
        for w in nbrs[v]:
            nd = d + float(np.linalg.norm(positions[w] - positions[v]))
            if nd < cutoff and nd < best.get(w, np.inf):
                best[w] = nd
                heapq.heappush(heap, (nd, w))
    return best


def flood_in_ball(source: int, positions: np.ndarray, nbrs: list[list[int]], radius: float) -> np.ndarray:
    """The nodes joined to `source` through nodes whose straight distance from it is below `radius` (sorted)."""
    inside = np.linalg.norm(positions - positions[source], axis=1) < radius
    seen = {source}
    frontier = [source]
    while frontier:
        frontier = sorted({w for v in frontier for w in nbrs[v] if inside[w] and w not in seen})
        seen.update(frontier)
    return np.array(sorted(seen), np.int64)


# ----------------------------------------------------------------------------------------------- the reference
class HandleSom:
    """The handle rule in float64 (the module's docstring is its specification)."""

    def __init__(self, weights, controls, radii=None, faces=None, edges=None, maps=None, position=(0, 1, 2),
                 iterations: int = 1000, l_start: float = 0.25, l_end: float = 0.03, reach: float = 0.3,
                 smoothing: float = 0.0, smoothing_rule: str = "taubin", smooth_dims=None, metric_weights=None,
                 rule: Rule = Rule(), strokes=None):
        self.W = np.array(weights, np.float64, copy=True)
        self.n = len(self.W)
        self.faces = None if faces is None else face_lists(faces)
        self.edges = edges_from_faces(self.faces) if edges is None else edges_from_edges(edges)
        self.controls = np.array(controls, np.float64, copy=True).reshape(-1, self.W.shape[1])
        k, dims = self.controls.shape
        self.radii = np.zeros(k) if radii is None else np.array(radii, np.float64)
        self.maps = np.eye(dims)[None] if maps is None else np.asarray(maps, np.float64)
        self.position = list(position)
        self.S, self.l_start, self.l_end, self.reach = int(iterations), float(l_start), float(l_end), float(reach)
        self.smoothing, self.smoothing_rule = float(smoothing), smoothing_rule
        self.smooth_dims = self.position if smooth_dims is None else list(smooth_dims)
        self.metric_weights = metric_weights
        self.rule = rule
        runs = [1] * k if strokes is None else [int(x) for x in strokes]
        self.stroke_of = np.repeat(np.arange(len(runs)), runs)  # each control's stroke
        self.iteration = self.S  # a kept shape: nothing trains until the person acts
        self.neighbours = adjacency(self.n, self.edges)
        self._src = np.repeat(np.arange(self.n), [len(nb) for nb in self.neighbours])
        self._dst = np.array([w for nb in self.neighbours for w in nb], np.int64)
        self._degree = np.array([len(nb) for nb in self.neighbours], np.float64)
        self._links = diagonal_links(self.n, self.faces, self.edges) if rule.distance == "geodesic" else \
            self.neighbours
        self._closed = closed_parts(self.n, self.faces, self.edges)
        self._dist = None  # the BFS table, built when a point control first needs it
        self.L = None
        self.bindings: list[Binding] = []
        self.anchor = self.W.copy()
        start = self.W[:, self.position]
        self.size = float(np.linalg.norm(start.max(axis=0) - start.min(axis=0))) or 1.0
        self._lo, self._hi = self.W.min(axis=0), self.W.max(axis=0)  # the start and every member's place
        self._grow_box()
        self.margins: list[np.ndarray] = []
        self.excess = 0.0  # the farthest any node stood outside the box grown by the largest radius alone

    # -- the box
    def _grow_box(self) -> None:
        members = np.einsum("gij,kj->kgi", self.maps, self.controls).reshape(-1, self.controls.shape[1])
        if len(members):
            self._lo = np.minimum(self._lo, members.min(axis=0))
            self._hi = np.maximum(self._hi, members.max(axis=0))

    def box(self, margin: float = BOX_MARGIN) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi): the start's and every member's places, grown on the position dims by the largest radius and
        `margin` of the start's size."""
        grow = np.zeros(self.W.shape[1])
        grow[self.position] = self.radii.max(initial=0.0) + margin * self.size
        return self._lo - grow, self._hi + grow

    def member(self, c: int, g: int) -> np.ndarray:
        return self.maps[g] @ self.controls[c]

    # -- bindings
    def _patch(self, u: int, r: float) -> tuple[np.ndarray, np.ndarray]:
        p = self.W[:, self.position]
        kind = self.rule.distance
        if kind == "euclid":
            nodes = flood_in_ball(u, p, self.neighbours, r)
            return nodes, FALLOFFS[self.rule.falloff](np.linalg.norm(p[nodes] - p[u], axis=1) / r)
        if kind == "hops":
            nb = self.neighbours[u]
            unit = float(np.mean(np.linalg.norm(p[nb] - p[u], axis=1))) if nb else r
            d, frontier, h = {u: 0.0}, [u], 0
            while frontier and (h + 1) * unit < r:
                h += 1
                frontier = sorted({w for v in frontier for w in self.neighbours[v] if w not in d})
                d.update((w, h * unit) for w in frontier)
        else:
            d = dijkstra(u, p, self._links, r)
        nodes = np.array(sorted(d), np.int64)
        return nodes, FALLOFFS[self.rule.falloff](np.array([d[v] for v in nodes]) / r)

    def _reanchor(self) -> None:
        self.anchor = self.W.copy()
        for b in self.bindings:
            b.anchor = self.W[b.winner].copy()

    def _radius(self, b: Binding, place: np.ndarray) -> float:
        """The binding's reach: its radius, widened for how far its place has been carried (WIDEN, or the fit)."""
        r = float(self.radii[b.control])
        travel = float(np.linalg.norm((place - b.start)[self.position]))
        if self.rule.fit is None:
            return r if self.rule.widen is None else max(r, self.rule.widen * travel)
        return max(r, float(np.sqrt(travel * CURVATURE[self.rule.falloff] * b.edge / self.rule.fit)))

    def _bind(self, c: int, at: np.ndarray, held: bool) -> None:
        p = self.W[:, self.position]
        for g in range(len(self.maps)):
            u = int(winners(self.W, (self.maps[g] @ at)[None], self.metric_weights)[0])
            nb = self.neighbours[u]
            edge = float(np.max(np.linalg.norm(p[nb] - p[u], axis=1))) if nb else 0.0
            place = self.W[u].copy() if self.rule.carry == "steps" else None
            b = Binding(c, g, u, place, np.zeros(0, np.int64), np.zeros(0), held, start=self.W[u].copy(), edge=edge)
            b.nodes, b.weights = self._patch(u, float(self.radii[c]))
            self.bindings.append(b)
        self._reanchor()

    def _end_released(self) -> None:
        kept = [b for b in self.bindings if b.held]
        if len(kept) != len(self.bindings):
            self.bindings = kept
            self._reanchor()

    def held(self, c: int) -> bool:
        return any(b.control == c and b.held for b in self.bindings)

    # -- events
    def grab(self, c: int) -> None:
        if self.radii[c] > 0 and not self.held(c):
            self._bind(c, self.controls[c], held=True)

    def release(self, c: int) -> None:
        for b in self.bindings:
            if b.control == c:
                b.held = False

    def restart(self) -> None:
        self._end_released()
        self.iteration = restart_iteration(self.reach, self.S)

    def set_controls(self, controls) -> None:
        new = np.array(controls, np.float64).reshape(self.controls.shape)
        self._end_released()
        for c in np.flatnonzero(np.any(new != self.controls, axis=1)):
            if self.radii[c] > 0 and not self.held(c):
                self._bind(int(c), self.controls[c], held=False)  # a move with nothing held: grab, move, release
        self.controls = new
        self._grow_box()
        self.iteration = restart_iteration(self.reach, self.S)

    def move(self, c: int, place) -> None:
        new = self.controls.copy()
        new[c] = place
        self.set_controls(new)

    # -- the cycle
    def _table(self):
        if self._dist is None:
            self._dist = bfs_distances(self.n, self.edges)
            self.L = learning_table(self.S, d_max_of(self._dist), self.l_start, self.l_end)
        return self._dist

    def _point_groups(self) -> list[int]:
        bound = {b.control for b in self.bindings}
        return [c for c in range(len(self.controls)) if self.radii[c] == 0 or (
            self.rule.others == "paper" and bound and c not in bound)]

    def _paper_step(self, s: int, groups: list[int]) -> None:
        """reference.py's step 1 and 2 for these controls and their copies."""
        dist = self._table()
        W = self.W
        G = len(self.maps)
        members = np.array([self.member(c, g) for c in groups for g in range(G)])
        self.margins.append(winner_margins(W, members, self.metric_weights))
        win = winners(W, members, self.metric_weights)
        for i in range(len(groups)):
            step = np.zeros_like(W)
            total = np.zeros(self.n)
            for g in range(G):
                d = dist[win[i * G + g]].astype(np.int64)
                rate = np.where(d != UNREACHABLE, self.L[s, np.minimum(d, self.L.shape[1] - 1)], 0.0)
                step += rate[:, None] * (members[i * G + g][None, :] - W)
                total += rate
            if G > 1:
                step /= np.maximum(1.0, total)[:, None]
            W += step

    def _advance(self) -> None:
        """Step 3 (a): each binding steps its place towards its member and binds again."""
        moved = False
        for b in self.bindings:
            m = self.member(b.control, b.copy)
            if b.place is None or np.array_equal(b.place, m):
                continue
            r = float(self.radii[b.control])
            gap = float(np.linalg.norm((m - b.place)[self.position]))
            b.place = m.copy() if gap <= STEP * r else b.place + (m - b.place) * (STEP * r / gap)
            b.nodes, b.weights = self._patch(b.winner, self._radius(b, b.place))
            moved = True
        if moved:
            self._reanchor()

    def _carry(self, s: int) -> np.ndarray:
        """Step 3 (b); returns the mask of bound nodes."""
        num = np.zeros_like(self.W)
        den = np.zeros(self.n)
        miss = np.ones(self.n)
        groups: dict[tuple[int, int], list[Binding]] = {}  # a stroke's samples, one copy: one binding (STROKES)
        for b in self.bindings:
            groups.setdefault((int(self.stroke_of[b.control]), b.copy), []).append(b)
        for group in groups.values():
            if len(group) > 1:
                most, gnum, gden = np.zeros(self.n), np.zeros_like(self.W), np.zeros(self.n)
                for b in group:
                    place = self.member(b.control, b.copy) if b.place is None else b.place
                    most[b.nodes] = np.maximum(most[b.nodes], b.weights)
                    gnum[b.nodes] += b.weights[:, None] * (place - b.anchor)[None, :]
                    gden[b.nodes] += b.weights
                held = gden > 0
                num[held] += most[held, None] * gnum[held] / gden[held, None]
                den[held] += most[held]
                miss[held] *= 1.0 - most[held]
                continue
            (b,) = group
            place = self.member(b.control, b.copy) if b.place is None else b.place
            num[b.nodes] += b.weights[:, None] * (place - b.anchor)[None, :]
            den[b.nodes] += b.weights
            miss[b.nodes] *= 1.0 - b.weights
        bound = den > 0
        if not bound.any():
            return bound
        if self.rule.blend == "or":
            scale = (1.0 - miss[bound]) / den[bound]
        else:
            scale = 1.0 / np.maximum(1.0, den[bound])
        lo, hi = self.box(margin=0.0)
        target = np.clip(self.anchor[bound] + num[bound] * scale[:, None], lo, hi)  # (a widened patch's rim)
        kappa = 1.0 if self.rule.rate == "hard" else \
            self.l_start * self.l_end / (self.l_end + (self.l_start - self.l_end) * s / self.S)
        self.W[bound] += kappa * (target - self.W[bound])
        return bound

    def _smooth(self, bound: np.ndarray) -> None:
        """Step 4 on the nodes `bound` leaves free."""
        if self.smoothing <= 0:
            return
        taubin = self.smoothing_rule == "taubin"
        lam = min(self.smoothing, TAUBIN_MOST) if taubin else self.smoothing
        free = (self._degree > 0) & ~bound
        dims, pos = self.smooth_dims, self.position
        before = [signed_volume(self.W[:, pos], tris) for _nodes, tris in self._closed] if taubin else []
        for f in [lam, 1.0 / (PASS_BAND - 1.0 / lam)] if taubin else [lam]:
            old = self.W[:, dims]
            total = np.stack([np.bincount(self._src, old[self._dst, j], minlength=self.n)
                              for j in range(len(dims))], axis=1)
            mean = total / np.maximum(self._degree, 1.0)[:, None]
            self.W[:, dims] = np.where(free[:, None], old + f * (mean - old), old)
        if not (taubin and self.rule.volume):
            return
        for (nodes, tris), v0 in zip(self._closed, before):
            moving = nodes[~bound[nodes]]
            p = self.W[:, pos]
            g = volume_gradient(p, tris, self.n)[moving]
            norm = float(np.einsum("ij,ij->", g, g))
            if norm > 0:
                self.W[np.ix_(moving, pos)] += (v0 - signed_volume(p, tris)) / norm * g

    def _one_cycle(self) -> None:
        s = self.iteration
        groups = self._point_groups()
        if groups:
            self._paper_step(s, groups)
        self._advance()
        bound = self._carry(s)
        self._smooth(bound)
        lo, hi = self.box(margin=0.0)
        self.excess = max(self.excess, float(np.maximum(lo - self.W, self.W - hi).max()))
        if self.smoothing > 0 and self.smoothing_rule == "taubin":
            lo, hi = self.box()
            np.clip(self.W, lo, hi, out=self.W)
        self.iteration += 1
        if self.iteration >= self.S:
            self._end_released()

    def step(self, cycles: int = 1) -> int:
        run = max(0, min(int(cycles), self.S - self.iteration))
        for _ in range(run):
            self._one_cycle()
        return run

    def train(self) -> int:
        return self.step(self.S - self.iteration)

    def train_from_start(self) -> int:
        """The whole schedule from s = 0 (a case study's growth)."""
        self.iteration = 0
        return self.train()

    # -- a drag as the app makes it
    def drag(self, c: int, place, frames: int = 8, frame_cycles: int = 10, settle: bool = True) -> None:
        """Grab control c, move it to `place` in `frames` even steps (set_controls, then `frame_cycles` cycles each,
        as the app's drag frames do), release it, and (with `settle`) run the rest of the run."""
        start = self.controls[c].copy()
        self.grab(c)
        for f in range(1, frames + 1):
            self.move(c, start + (np.asarray(place, np.float64) - start) * f / frames)
            self.step(frame_cycles)
        self.release(c)
        if settle:
            self.train()

    @property
    def weights(self) -> np.ndarray:
        return self.W.copy()
