"""Start meshes and feature layouts: the paper's three case studies and a few general start shapes.

Coordinates: x points forward (the car's nose is at +x), y sideways, z up. The paper mirrors controls across the
xz-plane (y is negated), so every mirrored preset is centred on y = 0 and symmetric under y -> -y.

Every preset is deterministic (no randomness) and holds float32 arrays. `PRESETS` maps a name to a builder,
`get_preset(name)` builds one; `Preset.make_som()` turns it into a trainable `Som`.
"""

from __future__ import annotations

import colorsys
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from . import checks
from .metrics import bounding_diagonal
from .schedule import BY_NAME, KEYS, SMOOTHING_RULES
from .symmetry import Symmetry
from .topology import Topology

#: Colour spaces and the number of colour dims each one takes.
COLOUR_SPACES = {"none": 0, "hue": 1, "hs": 2, "rgb": 3}
#: How a view draws a preset: a surface from the topology's faces, one line per node, or one point per node.
DISPLAYS = ("surface", "lines", "points")
#: The engine's limit on effective controls (originals plus mirrored copies).
MAX_CONTROLS = 256
#: The vertex colour of a layout without colour dims.
NEUTRAL_GREY = (0.72, 0.72, 0.72)


# --------------------------------------------------------------------------------------------------------------
# Feature layout and preset records
# --------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FeatureLayout:
    """What each feature dimension of a node means.

    names:        one name per dim, e.g. ("x", "y", "z", "hue", "saturation")
    position:     the three dims that are x, y, z (in that order)
    colour:       the colour dims: none for "none", (hue,) for "hue", (hue, saturation) for "hs", (r, g, b) for "rgb"
    colour_space: "none" | "hue" | "hs" | "rgb"
    direction:    () or the three dims of a direction vector (case study 3)
    length:       None or the dim that scales the direction (case study 3)
    """

    names: tuple[str, ...]
    position: tuple[int, ...]
    colour: tuple[int, ...]
    colour_space: str
    direction: tuple[int, ...] = ()
    length: int | None = None

    def __post_init__(self):
        names = tuple(self.names) if not isinstance(self.names, str) else (self.names,)
        if not names or not all(isinstance(n, str) and n for n in names):
            raise ValueError(f"layout: names must be non-empty strings, got {self.names!r}")
        if len(set(names)) != len(names):
            raise ValueError(f"layout: names must be distinct, got {names}")
        n = len(names)
        position = _ordered_dims("layout.position", self.position, n)
        colour = _ordered_dims("layout.colour", self.colour, n)
        direction = _ordered_dims("layout.direction", self.direction, n)
        if len(position) != 3:
            raise ValueError(f"layout: position must name 3 dims (x, y, z), got {position}")
        if self.colour_space not in COLOUR_SPACES:
            raise ValueError(f"layout: colour_space must be one of {sorted(COLOUR_SPACES)}, got {self.colour_space!r}")
        if len(colour) != COLOUR_SPACES[self.colour_space]:
            raise ValueError(f"layout: colour_space {self.colour_space!r} takes {COLOUR_SPACES[self.colour_space]} "
                             f"colour dims, got {colour}")
        if len(direction) not in (0, 3):
            raise ValueError(f"layout: direction must be empty or name 3 dims, got {direction}")
        length = self.length
        if length is not None:
            length = _ordered_dims("layout.length", (length,), n)[0]
            if not direction:
                raise ValueError("layout: a length dim needs direction dims")
        used = list(position) + list(colour) + list(direction) + ([length] if length is not None else [])
        if len(set(used)) != len(used):
            raise ValueError(f"layout: a dim has two roles (position {position}, colour {colour}, "
                             f"direction {direction}, length {length})")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "colour", colour)
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "length", length)

    @property
    def n_dims(self) -> int:
        return len(self.names)


def _ordered_dims(name: str, value, n: int) -> tuple[int, ...]:
    """Dims in the order given (checks.dims sorts; position and direction must keep x, y, z order)."""
    out = tuple(value)
    for d in out:
        if isinstance(d, bool) or not isinstance(d, (int, np.integer)):
            raise ValueError(f"{name}: expected feature-dimension indices (ints), got {d!r}")
        if not 0 <= int(d) < n:
            raise ValueError(f"{name}: dimension {int(d)} is outside the {n} feature dimensions (0..{n - 1})")
    out = tuple(int(d) for d in out)
    if len(set(out)) != len(out):
        raise ValueError(f"{name}: dims must be distinct, got {out}")
    return out


XYZ = FeatureLayout(names=("x", "y", "z"), position=(0, 1, 2), colour=(), colour_space="none")


@dataclass
class Preset:
    """A start mesh with its feature layout, default controls and training settings.

    Besides the contract's fields: `smooth_dims` (None = the position dims) goes to the Som, `reach` is the Som's
    (the radius a local restart begins with), and `meta` holds free-form facts such as the source file and
    normalising transform of a mesh loaded by `io.load_mesh`.

    grow: True for the paper's case studies, which grow a shape from a generic start mesh: a session runs their
    whole schedule when they are chosen. False for a shape that is the person's own (a general shape, an uploaded
    mesh): it is shown as it is and nothing trains until the person acts (som.py, Restarts).
    """

    name: str
    title: str
    description: str
    topology: Topology
    weights: np.ndarray
    controls: np.ndarray
    layout: FeatureLayout
    # the schedule (schedule.KEYS), its defaults those of schedule.SETTINGS
    iterations: int = BY_NAME["iterations"].default
    l_start: float = BY_NAME["l_start"].default
    l_end: float = BY_NAME["l_end"].default
    smoothing: float = BY_NAME["smoothing"].default
    mirror: tuple[int, ...] = ()
    metric_weights: np.ndarray | None = None
    display: str = "surface"
    smooth_dims: tuple[int, ...] | None = None
    reach: float = BY_NAME["reach"].default
    grow: bool = False
    meta: dict = field(default_factory=dict)
    radius: float = 0.0  # the radius of influence of its controls (and of new ones), model units (0: a point control)
    radii: np.ndarray | None = None  # each control's own radius, where they differ (a saved session); else `radius`
    symmetry: Symmetry | None = None  # a radial group of its controls (a mirror is `mirror`'s dims)
    strokes: tuple[int, ...] | None = None  # the lengths of the runs of controls that act as one (None: each alone)
    smoothing_rule: str = "laplacian"  # or "taubin" (keeps the volume): schedule.SMOOTHING_RULES

    def __post_init__(self):
        if not isinstance(self.topology, Topology):
            raise ValueError(f"preset {self.name!r}: topology must be a Topology, got {type(self.topology).__name__}")
        if not isinstance(self.layout, FeatureLayout):
            raise ValueError(f"preset {self.name!r}: layout must be a FeatureLayout")
        n = self.layout.n_dims
        self.weights = checks.finite_array(f"preset {self.name!r}: weights", self.weights, 2)
        controls = np.asarray(self.controls)
        if controls.size == 0:
            controls = np.zeros((0, n), np.float32)
        self.controls = checks.finite_array(f"preset {self.name!r}: controls", controls, 2)
        if self.weights.shape != (self.topology.n_vertices, n):
            raise ValueError(f"preset {self.name!r}: weights have shape {self.weights.shape}, expected "
                             f"({self.topology.n_vertices}, {n}) (topology vertices, layout dims)")
        if self.controls.shape[1] != n:
            raise ValueError(f"preset {self.name!r}: controls have {self.controls.shape[1]} dims, the layout has {n}")
        for key in KEYS:  # a schedule parameter without a field here takes its default
            setting = BY_NAME[key]
            setattr(self, key, setting.check(getattr(self, key, setting.default), f"preset {self.name!r}: {key}"))
        self.grow = bool(self.grow)
        self.radius = checks.real(f"preset {self.name!r}: radius", self.radius, 0.0, 1e6)
        if self.radii is not None:
            radii = checks.finite_array(f"preset {self.name!r}: radii", self.radii, 1)
            if radii.shape != (len(self.controls),) or (radii < 0).any():
                raise ValueError(f"preset {self.name!r}: radii must be {len(self.controls)} values >= 0, got {radii}")
            self.radii = radii
        if self.strokes is not None:
            self.strokes = checks.runs(f"preset {self.name!r}: strokes", self.strokes, len(self.controls))
        if self.symmetry is not None:
            if not isinstance(self.symmetry, Symmetry):
                raise ValueError(f"preset {self.name!r}: symmetry must be a Symmetry, got {self.symmetry!r}")
            if self.mirror:
                raise ValueError(f"preset {self.name!r}: give either a symmetry or mirror dims, not both")
            self.symmetry = self.symmetry.on(self.layout.position, self.layout.direction)
        checks.choice(f"preset {self.name!r}: smoothing_rule", self.smoothing_rule, SMOOTHING_RULES)
        self.mirror = checks.dims(f"preset {self.name!r}: mirror", self.mirror, n)
        if self.smooth_dims is not None:
            self.smooth_dims = checks.dims(f"preset {self.name!r}: smooth_dims", self.smooth_dims, n)
        if self.metric_weights is not None:
            mw = checks.finite_array(f"preset {self.name!r}: metric_weights", self.metric_weights, 1)
            if mw.shape != (n,) or (mw < 0).any():
                raise ValueError(f"preset {self.name!r}: metric_weights must be {n} values >= 0, got {mw}")
            self.metric_weights = mw
        k_eff = len(self.controls) * (self.symmetry.order if self.symmetry else 2 if self.mirror else 1)
        if k_eff > MAX_CONTROLS:
            raise ValueError(f"preset {self.name!r}: {k_eff} effective controls exceed the limit of {MAX_CONTROLS}")
        if self.display not in DISPLAYS:
            raise ValueError(f"preset {self.name!r}: display must be one of {DISPLAYS}, got {self.display!r}")
        if self.display == "lines" and not self.layout.direction:
            raise ValueError(f"preset {self.name!r}: display 'lines' needs a layout with direction dims")
        if self.display == "surface" and not self.topology.faces:
            raise ValueError(f"preset {self.name!r}: display 'surface' needs a topology with faces")

    @property
    def n_vertices(self) -> int:
        return self.topology.n_vertices

    def effective_controls(self) -> np.ndarray:
        """The controls the engine trains on: originals, then their symmetric copies (by the group's elements)."""
        if self.symmetry is not None:
            return self.symmetry.images(self.controls).astype(np.float32)
        return effective_controls(self.controls, self.mirror)

    def control_radii(self) -> np.ndarray:
        """(k,) the radius each control starts with."""
        return (self.radii if self.radii is not None else np.full(len(self.controls), self.radius)).astype(np.float32)

    def make_som(self, device=None, **engine_options):
        """A fresh `Som` at s = 0 with this preset's topology, start weights, controls and settings;
        `engine_options` go to `Som` as they are (cpu_cores, distances, cache_rows). A session shows a preset
        that does not `grow` as it is: it then puts s at S (`Som.restore`) so that nothing trains."""
        from .som import Som

        return Som(self.topology, self.weights, self.controls, smooth_dims=self.smooth_dims,
                   metric_weights=self.metric_weights, mirror=self.mirror, device=device,
                   radii=self.control_radii(), symmetry=self.symmetry, strokes=self.strokes,
                   smoothing_rule=self.smoothing_rule,
                   **{key: getattr(self, key) for key in KEYS}, **engine_options)


def effective_controls(controls, mirror=()) -> np.ndarray:
    """[originals..., mirrored copies...]: each copy has the `mirror` dims negated (som.py, Mirrored pairs)."""
    c = np.asarray(controls, dtype=np.float32)
    if not mirror:
        return c.copy()
    copy = c.copy()
    copy[:, list(mirror)] *= -1.0
    return np.concatenate([c, copy])


def farthest_points(points, k: int) -> np.ndarray:
    """Indices of k points spread over a point set (farthest-point sampling): the point nearest the centroid first,
    then each time the point farthest from those taken (the lowest index on a tie). Deterministic."""
    pts = np.asarray(points, np.float64)
    k = min(checks.integer("k", k, 1), len(pts))
    taken = [int(np.argmin(np.linalg.norm(pts - pts.mean(axis=0), axis=1)))]
    nearest = np.linalg.norm(pts - pts[taken[0]], axis=1)
    while len(taken) < k:
        i = int(np.argmax(nearest))
        taken.append(i)
        nearest = np.minimum(nearest, np.linalg.norm(pts - pts[i], axis=1))
    return np.asarray(taken, np.int64)


def controls_on(weights, k: int = 6) -> np.ndarray:
    """k controls sitting on a shape's own nodes, spread over it (farthest-point samples): a shape kept as it is
    has its controls on it, so that nothing pulls it before the person does."""
    w = np.asarray(weights, np.float32)
    return w[farthest_points(w[:, :3], k)].copy()


# --------------------------------------------------------------------------------------------------------------
# Geometry builders
# --------------------------------------------------------------------------------------------------------------
def lattice(nx: int, ny: int, nz: int, spacing: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A 3-D grid of nx * ny * nz points centred on the origin, with its 6-neighbour edges.

    Unlike the other builders this returns (edges (E, 2) int64, points (N, 3) float32): a solid lattice has no
    faces to draw, so build its topology with `Topology.from_edges(edges, len(points))`. Vertex (i, j, k) has
    index (i * ny + j) * nz + k and sits at ((i - (nx - 1) / 2) * spacing, ...). d_max = nx + ny + nz - 3.
    """
    for name, v in (("nx", nx), ("ny", ny), ("nz", nz)):
        checks.integer(name, v, 1)
    idx = np.arange(nx * ny * nz, dtype=np.int64).reshape(nx, ny, nz)
    edges = np.concatenate([
        np.stack([idx[:-1, :, :].ravel(), idx[1:, :, :].ravel()], axis=1),
        np.stack([idx[:, :-1, :].ravel(), idx[:, 1:, :].ravel()], axis=1),
        np.stack([idx[:, :, :-1].ravel(), idx[:, :, 1:].ravel()], axis=1),
    ])
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    pts = np.stack([i - (nx - 1) / 2, j - (ny - 1) / 2, k - (nz - 1) / 2], axis=-1).reshape(-1, 3) * spacing
    return edges, pts.astype(np.float32)


def open_grid(nx: int, ny: int, size: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """An open sheet of (nx - 1) * (ny - 1) quads in the xy-plane (z = 0), centred on the origin.

    Returns (faces (F, 4) int64, points (nx * ny, 3) float32). Vertex (i, j) (i along x) has index j * nx + i;
    the spacing is size / (max(nx, ny) - 1), so the longer side spans [-size / 2, size / 2]. The quads face +z
    (counter-clockwise seen from above). Being centred, the sheet is symmetric under y -> -y.
    """
    checks.integer("nx", nx, 2)
    checks.integer("ny", ny, 2)
    step = size / (max(nx, ny) - 1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")  # shape (ny, nx): index j * nx + i
    pts = np.stack([(i - (nx - 1) / 2) * step, (j - (ny - 1) / 2) * step, np.zeros_like(i, float)], axis=-1)
    v = np.arange(nx * ny, dtype=np.int64).reshape(ny, nx)
    faces = np.stack([v[:-1, :-1], v[:-1, 1:], v[1:, 1:], v[1:, :-1]], axis=-1).reshape(-1, 4)
    return faces, pts.reshape(-1, 3).astype(np.float32)


def uv_ellipsoid(n_lon: int, n_rings: int, radii=(1.0, 1.0, 1.0)) -> tuple[list[tuple[int, ...]], np.ndarray]:
    """A UV ellipsoid around the z-axis: `n_rings` rings of `n_lon` vertices plus two poles.

    Returns (faces, points (n_lon * n_rings + 2, 3) float32). Index 0 is the top pole (+z), then ring r's
    vertex j at 1 + r * n_lon + j, and the bottom pole last. Ring r lies at polar angle pi (r + 1) / (n_rings + 1),
    vertex j at longitude 2 pi j / n_lon measured from +x towards +y, so the point set is symmetric under
    y -> -y. Faces: quads between neighbouring rings, triangles at the poles, all wound counter-clockwise seen
    from outside. 25 longitudes x 24 rings gives the paper's 602 vertices (575 quads, 50 triangles).
    """
    checks.integer("n_lon", n_lon, 3)
    checks.integer("n_rings", n_rings, 1)
    a, b, c = (float(r) for r in radii)
    theta = np.pi * (np.arange(n_rings) + 1) / (n_rings + 1)
    phi = 2 * np.pi * np.arange(n_lon) / n_lon
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack([a * st * np.cos(phi), b * st * np.sin(phi), c * ct * np.ones_like(phi)], axis=-1)
    pts = np.concatenate([[[0.0, 0.0, c]], ring.reshape(-1, 3), [[0.0, 0.0, -c]]])
    pts[np.abs(pts) < 1e-12] = 0.0  # exact zeros (sin(pi) and friends) keep the mirror symmetry exact
    south = n_lon * n_rings + 1

    def vid(r: int, j: int) -> int:
        return 1 + r * n_lon + j % n_lon

    faces: list[tuple[int, ...]] = [(0, vid(0, j), vid(0, j + 1)) for j in range(n_lon)]
    for r in range(n_rings - 1):
        faces += [(vid(r, j), vid(r + 1, j), vid(r + 1, j + 1), vid(r, j + 1)) for j in range(n_lon)]
    faces += [(south, vid(n_rings - 1, j + 1), vid(n_rings - 1, j)) for j in range(n_lon)]
    return faces, pts.astype(np.float32)


def torus(n_major: int, n_minor: int, R: float = 1.0, r: float = 0.35) -> tuple[np.ndarray, np.ndarray]:
    """A closed (periodic) quad torus around the z-axis, major radius R, tube radius r.

    Returns (faces (n_major * n_minor, 4) int64, points (n_major * n_minor, 3) float32); vertex (i, j) (i around
    the axis, j around the tube) has index i * n_minor + j. Quads face outward; symmetric under y -> -y.
    """
    checks.integer("n_major", n_major, 3)
    checks.integer("n_minor", n_minor, 3)
    u = 2 * np.pi * np.arange(n_major) / n_major
    v = 2 * np.pi * np.arange(n_minor) / n_minor
    uu, vv = np.meshgrid(u, v, indexing="ij")
    rad = R + r * np.cos(vv)
    pts = np.stack([rad * np.cos(uu), rad * np.sin(uu), r * np.sin(vv)], axis=-1).reshape(-1, 3)
    pts[np.abs(pts) < 1e-12] = 0.0
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    i1, j1 = (i + 1) % n_major, (j + 1) % n_minor
    faces = np.stack([i * n_minor + j, i1 * n_minor + j, i1 * n_minor + j1, i * n_minor + j1], axis=-1)
    return faces.reshape(-1, 4).astype(np.int64), pts.astype(np.float32)


def ellipsoid_normals(points, radii) -> np.ndarray:
    """Outward unit normals of the ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 at `points` (N, 3)."""
    g = np.asarray(points, np.float64) / np.asarray(radii, np.float64) ** 2
    return (g / np.linalg.norm(g, axis=1, keepdims=True)).astype(np.float32)


# --------------------------------------------------------------------------------------------------------------
# Colours and display meshes (used by the views and by io.export_mesh)
# --------------------------------------------------------------------------------------------------------------
def hsv_to_rgb(h, s, v) -> np.ndarray:
    """HSV -> RGB for arrays of equal shape (h taken mod 1, s and v clipped to [0, 1]); returns (..., 3) float32."""
    h = np.mod(np.asarray(h, np.float64), 1.0)
    s = np.clip(np.asarray(s, np.float64), 0.0, 1.0)
    v = np.clip(np.asarray(v, np.float64), 0.0, 1.0)
    h, s, v = np.broadcast_arrays(h, s, v)
    h6 = h * 6.0
    sector = np.floor(h6)
    f = h6 - sector
    sector = sector.astype(np.int64) % 6  # h mod 1 can round to 1.0 for tiny negative h: sector 6 == 0
    p = v * (1.0 - s)
    q = v * (1.0 - s * f)
    t = v * (1.0 - s * (1.0 - f))
    r = np.choose(sector, [v, q, p, p, t, v])
    g = np.choose(sector, [t, v, v, q, p, p])
    b = np.choose(sector, [p, p, t, v, v, q])
    return np.clip(np.stack([r, g, b], axis=-1), 0.0, 1.0).astype(np.float32)


#: Control colours for layouts without colour dims (the nodes are all grey there, the controls need not be).
CONTROL_PALETTE = np.array([[0.90, 0.30, 0.25], [0.25, 0.55, 0.90], [0.30, 0.75, 0.35], [0.95, 0.70, 0.20],
                            [0.65, 0.40, 0.85], [0.20, 0.75, 0.75], [0.90, 0.45, 0.70], [0.55, 0.55, 0.25]],
                           np.float32)


def palette_colours(k: int, k_eff: int, ids=None) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) and (k_eff, 3) float32 display colours of k controls and their k_eff effective copies (copy j takes
    control j mod k's colour) from `CONTROL_PALETTE`, for layouts without colour dims: by the controls' stable `ids`
    when given (a colour stays with its control while others come and go), else by index."""
    keys = np.arange(k) if ids is None else np.asarray(ids, np.int64).reshape(k)
    own = CONTROL_PALETTE[keys % len(CONTROL_PALETTE)]
    return own, own[np.arange(k_eff) % max(k, 1)]


def colours_of(weights_or_controls, layout: FeatureLayout) -> np.ndarray:
    """(M, 3) float32 RGB in [0, 1] from the colour dims of weights or controls (M, n); a single row (n,) is taken
    as M = 1. "hue": HSV(h mod 1, 1, 1); "hs": HSV(h mod 1, clip(s), 1); "rgb": clipped; "none": NEUTRAL_GREY."""
    values = np.asarray(weights_or_controls, np.float32)
    if values.ndim == 1:
        values = values[None, :]
    if values.ndim != 2 or values.shape[1] != layout.n_dims:
        raise ValueError(f"colours_of: expected shape (M, {layout.n_dims}), got {np.shape(weights_or_controls)}")
    m = len(values)
    space = layout.colour_space
    if space == "none":
        return np.tile(np.asarray(NEUTRAL_GREY, np.float32), (m, 1))
    cols = values[:, list(layout.colour)].astype(np.float64)
    if space == "hue":
        return hsv_to_rgb(cols[:, 0], 1.0, 1.0)
    if space == "hs":
        return hsv_to_rgb(cols[:, 0], cols[:, 1], 1.0)
    return np.clip(cols, 0.0, 1.0).astype(np.float32)  # "rgb"


def positions_of(weights, layout: FeatureLayout) -> np.ndarray:
    """(N, 3) float32 x, y, z of each node."""
    return np.ascontiguousarray(np.asarray(weights, np.float32)[:, list(layout.position)])


def rgb_to_colour_dims(rgb, layout: FeatureLayout) -> np.ndarray:
    """The inverse of `colours_of` for one colour: RGB in [0, 1] -> the values of the layout's colour dims."""
    rgb = checks.finite_vector("colour", rgb, 3).astype(np.float64)
    if (rgb < 0).any() or (rgb > 1).any():
        raise ValueError(f"colour: RGB values must lie in [0, 1], got {rgb.tolist()}")
    space = layout.colour_space
    if space == "none":
        raise ValueError("colour: this preset's features have no colour dimensions")
    h, s, _v = colorsys.rgb_to_hsv(*rgb)
    if space == "hue":
        return np.float32([h])
    if space == "hs":
        return np.float32([h, s])
    return rgb.astype(np.float32)  # "rgb"


def parse_hex_colour(text: str) -> np.ndarray:
    """'#rrggbb' (or '#rrggbbaa', alpha ignored) -> RGB float32 in [0, 1]; ValueError otherwise."""
    if not isinstance(text, str):
        raise ValueError(f"colour: expected '#rrggbb', got {text!r}")
    t = text.strip().lstrip("#")
    if len(t) not in (6, 8) or any(c not in "0123456789abcdefABCDEF" for c in t):
        raise ValueError(f"colour: expected '#rrggbb', got {text!r}")
    return np.float32([int(t[i:i + 2], 16) / 255.0 for i in (0, 2, 4)])


def hex_colour(rgb) -> str:
    """RGB in [0, 1] (clipped) -> '#rrggbb'."""
    r, g, b = (int(round(float(np.clip(c, 0.0, 1.0)) * 255)) for c in rgb[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


def line_display_mesh(weights, topology: Topology, layout: FeatureLayout) -> tuple[np.ndarray, np.ndarray]:
    """The lines display of case study 3: each node is a line from its root to its tip, neighbours joined by quads.

    Returns (points (2N, 3) float32, faces (E, 4) int64): the N roots (layout.position), then the N tips
    (root + direction * length; length 1 when the layout has no length dim), and one quad
    (root_a, root_b, tip_b, tip_a) per topology edge (a, b). Vertex colours for both halves: tile colours_of twice.

    For the 602-vertex "lines" preset this gives 1204 vertices, as in the paper, and 1225 quads: one per edge of
    the UV ellipsoid (600 along the rings, 575 between rings, 50 to the poles), i.e. 2450 triangles. The paper
    reports 2400 faces for its display mesh, exactly twice the 1200 triangles of the car's surface (575 quads as
    two triangles each, plus 50 pole triangles); its exact face set is not published, so ours follows the rule
    above (one quad per synapse) rather than matching that count.
    """
    if not layout.direction:
        raise ValueError("line_display_mesh: the layout has no direction dims")
    w = np.asarray(weights, np.float32)
    if w.ndim != 2 or w.shape != (topology.n_vertices, layout.n_dims):
        raise ValueError(f"line_display_mesh: weights have shape {w.shape}, expected "
                         f"({topology.n_vertices}, {layout.n_dims})")
    roots = w[:, list(layout.position)]
    direction = w[:, list(layout.direction)]
    length = w[:, layout.length:layout.length + 1] if layout.length is not None else 1.0
    tips = roots + direction * length
    n = len(w)
    e = np.asarray(topology.edges, np.int64).reshape(-1, 2)
    faces = np.stack([e[:, 0], e[:, 1], e[:, 1] + n, e[:, 0] + n], axis=1)
    return np.concatenate([roots, tips]).astype(np.float32), faces


# --------------------------------------------------------------------------------------------------------------
# The presets
# --------------------------------------------------------------------------------------------------------------
#: The car body: an ellipsoid 4 long (x), 1.7 wide (y), 1.2 high (z); 25 x 24 + 2 = 602 vertices.
CAR_RADII = (2.0, 0.85, 0.6)
CAR_LON, CAR_RINGS = 25, 24


#: lambda of the space grid's Laplacian step: enough to keep the lattice even without holding it back from the
#: controls (at 0.2 it stopped 12% of its size short of them, and every restart shrank it further).
SPACE_GRID_SMOOTHING = 0.02
#: Shapes kept as they are (the general shapes, uploaded meshes) are shaped by controls with a radius of influence
#: (som.py): each starts at this share of the shape's size (its bounding diagonal: the controls that stay hold the
#: far half within 2% where 0.2 let it move 2.6%), and a restart runs this reach of
#: the schedule, enough cycles for a moved control's winner to reach it (BENCHMARKS.md, "Shaping rules"); any
#: smoothing keeps their volume (Taubin's rule).
KEPT_SHAPE_RADIUS = 0.25
KEPT_SHAPE_REACH = 0.3


def kept_shape(points) -> dict:
    """The Preset fields of a shape kept as it is, for its start positions: its controls' radius, reach and
    smoothing rule."""
    return dict(radius=KEPT_SHAPE_RADIUS * bounding_diagonal(np.asarray(points)[:, :3]), reach=KEPT_SHAPE_REACH,
                smoothing_rule="taubin")


def space_grid() -> Preset:
    """Case study 1: a 16^3 lattice (6-neighbour synapses, d_max 45) pulled by 8 three-dimensional controls."""
    edges, pts = lattice(16, 16, 16, spacing=1.0)
    controls = np.array([
        [9.5, 2.0, -3.0],
        [-9.0, -3.5, 4.5],
        [3.0, 9.5, 5.5],
        [-2.5, -9.5, -5.0],
        [5.5, -4.0, 9.5],
        [-5.0, 5.0, -9.0],
        [8.5, 7.5, 8.0],
        [-8.5, -6.5, -8.0],
    ], np.float32)
    return Preset(
        name="space-grid", title="Space grid",
        description="Case study 1 of Felbrich et al. 2018: a 16 x 16 x 16 lattice of neurons joined to their six "
                    "neighbours, shaped by 8 controls, with one Laplacian smoothing step per cycle.",
        topology=Topology.from_edges(edges, len(pts)), weights=pts, controls=controls, layout=XYZ,
        iterations=1000, l_start=0.3, l_end=0.03, smoothing=SPACE_GRID_SMOOTHING, display="points", grow=True)


def _car_start() -> tuple[Topology, np.ndarray]:
    faces, pts = uv_ellipsoid(CAR_LON, CAR_RINGS, CAR_RADII)
    return Topology.from_faces(faces, len(pts)), pts


def car() -> Preset:
    """Case study 2: an ellipsoid car body with 5-D nodes (x, y, z, hue, saturation) and 9 mirrored controls."""
    topo, pts = _car_start()
    start = np.concatenate([pts, np.tile(np.float32([0.0, 0.08]), (len(pts), 1))], axis=1)  # near-white
    #                    x     y      z     hue   sat
    controls = np.array([
        [1.30, 0.95, -0.75, 0.62, 0.85],  # front wheel (blue)
        [-1.30, 0.95, -0.75, 0.72, 0.85],  # rear wheel (indigo)
        [2.60, 0.25, -0.20, 0.00, 0.90],  # nose (red)
        [-2.50, 0.30, -0.05, 0.08, 0.90],  # tail (orange)
        [-0.30, 0.45, 0.95, 0.15, 0.85],  # roof (yellow)
        [1.55, 0.50, 0.30, 0.93, 0.75],  # bonnet (rose)
        [0.65, 0.45, 0.70, 0.50, 0.70],  # windscreen (cyan)
        [-1.35, 0.45, 0.60, 0.80, 0.60],  # rear window (violet)
        [0.00, 1.05, -0.20, 0.33, 0.80],  # door sill (green)
    ], np.float32)
    layout = FeatureLayout(names=("x", "y", "z", "hue", "saturation"), position=(0, 1, 2), colour=(3, 4),
                           colour_space="hs")
    return Preset(
        name="car", title="Car",
        description="Case study 2 of Felbrich et al. 2018: an ellipsoid of 602 vertices (quads and pole triangles) "
                    "with 5-D nodes (x, y, z, hue, saturation); 9 controls mirrored across the xz-plane make 18, "
                    "and the body takes on their colours.",
        topology=topo, weights=start, controls=controls, layout=layout,
        iterations=1000, l_start=0.25, l_end=0.03, mirror=(1,), display="surface", grow=True)


def lines() -> Preset:
    """Case study 3: the car's topology with 8-D nodes (root x, y, z, direction x, y, z, hue, length)."""
    topo, pts = _car_start()
    normals = ellipsoid_normals(pts, CAR_RADII)
    n = len(pts)
    start = np.concatenate([pts, normals, np.full((n, 1), 0.58, np.float32), np.full((n, 1), 0.3, np.float32)],
                           axis=1)

    def control(root, direction, hue, length):
        d = np.asarray(direction, np.float64)
        return [*root, *(d / np.linalg.norm(d)), hue, length]

    controls = np.array([
        control((1.40, 0.95, -0.55), (0.2, 0.6, -0.8), 0.00, 0.70),  # front flank, long red lines down
        control((-1.40, 0.95, -0.55), (-0.2, 0.6, -0.8), 0.08, 0.70),  # rear flank, orange
        control((2.45, 0.20, 0.00), (1.0, 0.1, 0.3), 0.15, 0.90),  # nose, yellow spikes forward
        control((-2.40, 0.25, 0.10), (-1.0, 0.2, 0.4), 0.33, 0.50),  # tail, green
        control((0.00, 0.35, 0.85), (0.0, 0.2, 1.0), 0.50, 1.00),  # roof, tall cyan crest
        control((1.20, 0.45, 0.55), (0.6, 0.2, 0.8), 0.62, 0.35),  # bonnet, blue
        control((-1.10, 0.50, 0.55), (-0.5, 0.3, 0.8), 0.80, 0.25),  # rear deck, violet
        control((0.00, 1.10, 0.00), (0.0, 1.0, 0.0), 0.93, 0.15),  # side, short rose bristles
    ], np.float32)
    layout = FeatureLayout(names=("x", "y", "z", "dx", "dy", "dz", "hue", "length"), position=(0, 1, 2),
                           colour=(6,), colour_space="hue", direction=(3, 4, 5), length=7)
    return Preset(
        name="lines", title="Lines",
        description="Case study 3 of Felbrich et al. 2018: the car's 602-vertex topology with 8-D nodes (root, "
                    "direction, hue, length), drawn as coloured lines whose neighbours are joined by quads; 8 "
                    "controls mirrored across the xz-plane (root y and direction y) make 16.",
        topology=topo, weights=start, controls=controls, layout=layout,
        iterations=1000, l_start=0.25, l_end=0.03, mirror=(1, 4), display="lines", grow=True)


# The general shapes below are kept as they are (grow False): each is shown as built, with controls on its own nodes
# (controls_on), and trains only when the person moves, adds or removes a control, changes a setting or presses
# Train. They have no smoothing: a Laplacian step shrinks any curved shape a little at every restart.
def lattice_preset() -> Preset:
    """A small 8^3 lattice spanning [-1, 1]^3 with 6 controls on its nodes."""
    edges, pts = lattice(8, 8, 8, spacing=2.0 / 7.0)
    return Preset(
        name="lattice", title="Lattice", description="An 8 x 8 x 8 lattice (6-neighbour synapses) with 6 controls "
                                                     "on its nodes: drag one to pull the lattice.",
        topology=Topology.from_edges(edges, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
        l_start=0.3, display="points", **kept_shape(pts))


def grid_preset() -> Preset:
    """An open 32 x 32 sheet in the xy-plane (z = 0), spanning [-1, 1]^2, with 6 controls on it."""
    faces, pts = open_grid(32, 32)
    return Preset(
        name="grid", title="Grid", description="An open 32 x 32 quad sheet lying in the xy-plane, with 6 controls on "
                                               "it: drag one up or down to shape the sheet.",
        topology=Topology.from_faces(faces, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
        **kept_shape(pts))


def sphere_preset() -> Preset:
    """A unit UV sphere (32 longitudes x 15 rings + 2 poles = 482 vertices) with 6 controls on it."""
    faces, pts = uv_ellipsoid(32, 15, (1.0, 1.0, 1.0))
    return Preset(
        name="sphere", title="Sphere", description="A UV sphere of quads and pole triangles, with 6 controls on it: "
                                                   "drag one to push or pull the surface.",
        topology=Topology.from_faces(faces, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
        **kept_shape(pts))


def torus_preset() -> Preset:
    """A closed quad torus (48 x 16 = 768 vertices, R 1, r 0.35) with 6 controls on it."""
    faces, pts = torus(48, 16, 1.0, 0.35)
    return Preset(
        name="torus", title="Torus", description="A periodic quad torus around the z-axis, with 6 controls on it: "
                                                 "drag one to reshape the ring.",
        topology=Topology.from_faces(faces, len(pts)), weights=pts, controls=controls_on(pts), layout=XYZ,
        **kept_shape(pts))


PRESETS: dict[str, Callable[[], Preset]] = {
    "space-grid": space_grid,
    "car": car,
    "lines": lines,
    "lattice": lattice_preset,
    "grid": grid_preset,
    "sphere": sphere_preset,
    "torus": torus_preset,
}
#: The presets' names in menus (the web app's preset list, the notebook panel's dropdown); unknown names show as is.
PRESET_LABELS: dict[str, str] = {
    "space-grid": "Case study 1: space grid (16^3 lattice)",
    "car": "Case study 2: car (602 nodes, colours)",
    "lines": "Case study 3: lines (8-D nodes)",
    "lattice": "Lattice 8^3",
    "grid": "Open grid 32 x 32",
    "sphere": "Sphere",
    "torus": "Torus",
}


def get_preset(name: str) -> Preset:
    """Build the preset called `name` (a fresh object each call)."""
    try:
        builder = PRESETS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown preset {name!r}; known presets: {', '.join(PRESETS)}") from None
    return builder()
