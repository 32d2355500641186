"""What a Som trains towards (warp.sim's Control): the controls C (k, n), each one's radius of influence, the
symmetry group whose copies of each control act with it (a mirror's pairs, or a radial group), and the strokes (runs
of controls that act as one). The effective controls are every control and its copies.

`Controls` is immutable: a change makes a new one, so a check that fails changes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import checks
from .cycle_kernels import MAX_CONTROLS, PAIRS, SCALED_PAIRS, SINGLES
from .schedule import MAX_RADIUS
from .symmetry import Symmetry, images, mirror_dims_of


def check_radii(radii, k: int) -> np.ndarray:
    """(k,) float32 radii of influence, each in [0, MAX_RADIUS] model units (None: k point controls, 0)."""
    if radii is None:
        return np.zeros(k, np.float32)
    r = checks.finite_array("radii", [radii] if np.isscalar(radii) else radii, 1)
    if r.shape[0] != k:
        raise ValueError(f"radii: expected one radius per control ({k}), got {r.shape[0]}")
    if (r < 0).any() or (r > MAX_RADIUS).any():
        raise ValueError(f"radii: each radius must lie in [0, {MAX_RADIUS:g}] (model units; 0 = a point "
                         f"control), got {r.tolist()}")
    return r


def check_group(symmetry, mirror, n_dims: int) -> tuple[Symmetry | None, tuple[int, ...]]:
    """(a radial group or None, the mirror dims): a mirror group is the engine's mirrored pairs of its position dim."""
    dims = checks.dims("mirror", mirror, n_dims)
    if symmetry is None:
        return None, dims
    if not isinstance(symmetry, Symmetry):
        raise ValueError(f"symmetry: expected a Symmetry (Symmetry.mirror(axis), Symmetry.radial(n, axis)) or "
                         f"None, got {type(symmetry).__name__}")
    if dims:
        raise ValueError("give either symmetry or mirror, not both (mirror is the shorthand for a mirror group)")
    symmetry.maps(n_dims)  # ValueError when its dims do not fit the weights
    if symmetry.kind == "mirror":
        return None, mirror_dims_of(symmetry) or ()
    return symmetry, ()


def check_values(controls, n_dims: int, order: int) -> np.ndarray:
    """(k, n) float32 controls (one control may come as (n,)): 1 to MAX_CONTROLS effective ones with `order`
    copies each."""
    c = np.asarray(controls) if not isinstance(controls, np.ndarray) else controls
    if c.ndim == 1:
        c = c[None, :]
    c = checks.finite_array("controls", c, 2)
    if c.shape[1] != n_dims:
        raise ValueError(f"controls: expected {n_dims} feature dimensions like the weights, got {c.shape[1]}")
    k_eff = c.shape[0] * order
    if c.shape[0] < 1 or k_eff > MAX_CONTROLS:
        raise ValueError(f"controls: expected 1 to {MAX_CONTROLS} controls counting symmetric copies, "
                         f"got {c.shape[0]} ({k_eff} with their copies)")
    return c


def check_strokes(strokes, k: int) -> tuple[int, ...]:
    return (1,) * k if strokes is None else checks.runs("strokes", strokes, k)


@dataclass(frozen=True, eq=False)
class Controls:
    """values (k, n) float32; radii (k,) float32 (0: the paper's point control); strokes: run lengths summing to k;
    symmetry: a radial group or None; mirror: the dims a mirrored copy negates (() without); any_radius: whether a
    control has a radius (a handle), found when made (None) and kept by a move with the same radii."""

    values: np.ndarray
    radii: np.ndarray
    strokes: tuple[int, ...]
    symmetry: Symmetry | None
    mirror: tuple[int, ...]
    any_radius: bool | None = None

    def __post_init__(self) -> None:
        if self.any_radius is None:
            object.__setattr__(self, "any_radius", bool(self.radii.any()))

    @classmethod
    def make(cls, values, radii, strokes, group: tuple[Symmetry | None, tuple[int, ...]], n_dims: int) -> Controls:
        """Checked controls for a checked group (`check_group`): values, then radii, then strokes."""
        symmetry, mirror = group
        c = check_values(values, n_dims, symmetry.order if symmetry is not None else 2 if mirror else 1)
        return cls(c, check_radii(radii, len(c)), check_strokes(strokes, len(c)), symmetry, mirror)

    def moved(self, values, radii=None, strokes=None) -> Controls:
        """New values in the same group; radii and strokes kept where the count stays and not given, else as given
        (None: point controls, each alone)."""
        c = check_values(values, self.values.shape[1], self.order)
        same = len(c) == len(self.values)
        # a drag's every move gives the radii and strokes it had: the radii array (and what it says) kept
        kept = same and (radii is None or (isinstance(radii, np.ndarray) and np.array_equal(radii, self.radii)))
        return Controls(c, self.radii if kept else check_radii(radii, len(c)),
                        self.strokes if same and (strokes is None or tuple(strokes) == self.strokes)
                        else check_strokes(strokes, len(c)), self.symmetry, self.mirror,
                        self.any_radius if kept else None)

    def regrouped(self, group: tuple[Symmetry | None, tuple[int, ...]]) -> Controls:
        """The same controls in another group (checked: `check_group`)."""
        return Controls.make(self.values, self.radii, self.strokes, group, self.values.shape[1])

    def with_radii(self, radii) -> Controls:
        return Controls(self.values, check_radii(radii, len(self.values)), self.strokes, self.symmetry, self.mirror)

    @property
    def order(self) -> int:
        """Each control's group: the control and its copies."""
        if self.symmetry is not None:
            return self.symmetry.order
        return 2 if self.mirror else 1

    @property
    def n_slots(self) -> int:
        """The effective controls the paper's kernels take: each control, with a mirror its copy next to it."""
        return 2 * len(self.values) if self.mirror else len(self.values)

    def group_maps(self) -> np.ndarray:
        """(order, n, n) the group's maps of a control, the identity first."""
        n = self.values.shape[1]
        if self.symmetry is not None:
            return self.symmetry.maps(n)
        maps = np.repeat(np.eye(n)[None], self.order, axis=0)
        if self.mirror:
            maps[1][list(self.mirror), list(self.mirror)] = -1.0
        return maps

    def stroke_of(self, i: int) -> range:
        """The controls of control i's stroke (i alone when it is not a stroke's sample)."""
        i = checks.integer("control", i, 0, len(self.values) - 1)
        first = 0
        for length in self.strokes:
            if i < first + length:
                return range(first, first + length)
            first += length
        raise AssertionError("unreachable: the strokes cover every control")

    def effective(self) -> np.ndarray:
        """[originals..., their first copies..., their second copies...] (copy j is of control j mod k): a copy of
        those made once for these controls (values are this object's own copy, never changed in place; a frame reads
        them every round)."""
        kept = self.__dict__.get("_effective")
        if kept is None:
            kept = self.values if self.order == 1 else images(self.values, self.group_maps()).astype(np.float32)
            self.__dict__["_effective"] = kept  # frozen: set past __setattr__, as functools.cached_property does
        return kept.copy()

    def from_slots(self, found: np.ndarray) -> np.ndarray:
        """Per-slot values (a mirrored pair side by side, `n_slots`) in the order of `effective`."""
        return np.concatenate([found[0::2], found[1::2]]) if self.mirror else found

    def shaping(self, smoothing_steps: int) -> bool:
        """Whether the shaping path runs the cycles: radii (handles), a radial group, or a second smoothing step
        (Taubin's); else the paper's rule (cpu_path.py, cuda_path.py, rows_path.py, local_path.py). Strokes only say
        which controls a hand takes together."""
        return self.any_radius or self.symmetry is not None or smoothing_steps > 1

    def pairs(self, table_max: float) -> int:
        """How step 2 applies the controls (cycle_kernels.SINGLES, PAIRS, SCALED_PAIRS): with a mirror in mirrored
        pairs, scaled only where the table has a rate above 0.5 (two rates may then sum past 1)."""
        if not self.mirror:
            return SINGLES
        return SCALED_PAIRS if table_max > 0.5 else PAIRS
