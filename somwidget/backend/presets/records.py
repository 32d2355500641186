"""The records of a start shape: `FeatureLayout` (what each feature dim of a node means) and `Preset` (a start mesh
with its layout, controls and training settings; `make_som()` turns it into a `Som`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import checks
from ..cycle_kernels import MAX_CONTROLS
from ..schedule import BY_NAME, KEYS, SMOOTHING_RULES
from ..symmetry import Symmetry
from ..topology import Topology

#: Colour spaces and the number of colour dims each one takes.
COLOUR_SPACES = {"none": 0, "hue": 1, "hs": 2, "rgb": 3}
#: How a view draws a preset: a surface from the topology's faces, one line per node, or one point per node.
DISPLAYS = ("surface", "lines", "points")


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
#: The learning rates of the lattices of points: the space grid's (case study 1 of Felbrich et al. 2018), also the
#: lattice shape's.
LATTICE_RATES: dict[str, Any] = {"l_start": 0.3, "l_end": 0.03}


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
        from ..som import Som

        return Som(self.topology, self.weights, self.controls, smooth_dims=self.smooth_dims,
                   metric_weights=self.metric_weights, mirror=self.mirror, device=device,
                   radii=self.control_radii(), symmetry=self.symmetry, strokes=self.strokes,
                   smoothing_rule=self.smoothing_rule,
                   **{key: getattr(self, key) for key in KEYS}, **engine_options)


def effective_controls(controls, mirror=()) -> np.ndarray:
    """[originals..., mirrored copies...]: each copy has the `mirror` dims negated (som.py, step 2)."""
    c = np.asarray(controls, dtype=np.float32)
    if not mirror:
        return c.copy()
    copy = c.copy()
    copy[:, list(mirror)] *= -1.0
    return np.concatenate([c, copy])


def positions_of(weights, layout: FeatureLayout) -> np.ndarray:
    """(N, 3) float32 x, y, z of each node."""
    return np.ascontiguousarray(np.asarray(weights, np.float32)[:, list(layout.position)])
