"""Symmetry groups of the controls: a mirror across a plane, n-fold rotation about an axis, or rotation with a mirror.

Each control gets one copy per element of the group but the identity, and every copy acts together with its control
(som.py, step 2: the group's rates from the same weights, scaled by 1 / max(1, their sum)), so a symmetric shape
stays symmetric. A group is a list of linear maps of the feature vector: each acts on the position dims (and on the
direction dims, where a layout has them) and leaves every other feature (colour, length) as it is.

    Symmetry.mirror(1)               # across the xz-plane (y negated): the paper's car
    Symmetry.radial(8, 2)            # eight copies around the z-axis: a vase, a rosette
    Symmetry.radial(6, 2, mirror=True)  # six rotations and their mirror images (12 copies)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from . import checks

#: Copies of a radial group: 2 to 32 rotations (a mirror doubles them).
MAX_RADIAL = 32
AXES = ("x", "y", "z")


def _axis(value) -> int:
    if isinstance(value, str) and value.lower() in AXES:
        return AXES.index(value.lower())
    return checks.integer("axis", value, 0, 2)


def images(controls: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """Controls (..., k, n) under each of a group's maps (order, n, n), stacked along the controls' axis:
    [originals (the identity first)..., first copies..., ...], in float64."""
    c = np.asarray(controls, np.float64)
    return np.concatenate([c @ m.T for m in maps], axis=-2)


@dataclass(frozen=True)
class Symmetry:
    """A symmetry group (see the module's docstring). kind "mirror": across the plane normal to `axis`; "radial": `n`
    rotations about `axis`, with their mirror images across the plane of `axis` and the next axis when `mirrored`."""

    kind: str
    axis: int
    n: int = 2
    mirrored: bool = False
    position: tuple[int, ...] = (0, 1, 2)  # the feature dims of a node's x, y, z
    direction: tuple[int, ...] = ()  # the dims of a direction vector that turns with the positions (case study 3)

    def __post_init__(self) -> None:
        if self.kind not in ("mirror", "radial"):
            raise ValueError(f"symmetry: kind must be 'mirror' or 'radial', got {self.kind!r}")
        object.__setattr__(self, "axis", _axis(self.axis))
        if self.kind == "radial":
            object.__setattr__(self, "n", checks.integer("symmetry: n", self.n, 2, MAX_RADIAL))
        for name in ("position", "direction"):
            dims = tuple(int(d) for d in getattr(self, name))
            if len(dims) not in ((3,) if name == "position" else (0, 3)):
                raise ValueError(f"symmetry: {name} must name 3 feature dims{' or none' if name == 'direction' else ''}"
                                 f", got {dims}")
            object.__setattr__(self, name, dims)

    def on(self, position: Sequence[int], direction: Sequence[int] = ()) -> Symmetry:
        """This group acting on the given position (and direction) dims of a layout."""
        return replace(self, position=tuple(position), direction=tuple(direction))

    @property
    def spec(self) -> str:
        """The group as text: "mirror-y", "radial-8-z", "radial-6-z-mirror" (`parse` reads it back)."""
        if self.kind == "mirror":
            return f"mirror-{AXES[self.axis]}"
        return f"radial-{self.n}-{AXES[self.axis]}" + ("-mirror" if self.mirrored else "")

    @classmethod
    def parse(cls, text: str) -> Symmetry | None:
        """The group a `spec` names ("none" or "" for none); ValueError naming what was expected."""
        t = str(text).strip().lower()
        if t in ("", "none", "off"):
            return None
        parts = t.split("-")
        try:
            if parts[0] == "mirror" and len(parts) == 2:
                return cls.mirror(parts[1])
            if parts[0] == "radial" and len(parts) in (3, 4) and parts[3:] in ([], ["mirror"]):
                return cls.radial(int(parts[1]), parts[2], mirror=len(parts) == 4)
        except ValueError as exc:
            raise ValueError(f"symmetry {text!r}: {exc}") from None
        raise ValueError(f"symmetry {text!r}: expected none, mirror-x|y|z or radial-<n>-x|y|z[-mirror] (n 2 to "
                         f"{MAX_RADIAL})")

    @classmethod
    def mirror(cls, axis=1) -> Symmetry:
        """Across the plane normal to `axis` (0, 1, 2 or "x", "y", "z"): that coordinate negated."""
        return cls("mirror", axis)

    @classmethod
    def radial(cls, n: int, axis=2, mirror: bool = False) -> Symmetry:
        """n rotations by 360/n degrees about `axis`; with `mirror`, each also mirrored (2n copies in all)."""
        return cls("radial", axis, n, bool(mirror))

    @property
    def order(self) -> int:
        """The group's size: the controls' copies including the control itself."""
        if self.kind == "mirror":
            return 2
        return 2 * self.n if self.mirrored else self.n

    def rotations(self) -> np.ndarray:
        """(order, 3, 3) float64: the group's maps of a position, the identity first."""
        a = self.axis
        b, c = (a + 1) % 3, (a + 2) % 3
        if self.kind == "mirror":
            flip = np.eye(3)
            flip[a, a] = -1.0
            return np.stack([np.eye(3), flip])
        out = []
        for k in range(self.n):
            t = 2.0 * math.pi * k / self.n
            r = np.eye(3)
            r[b, b], r[b, c], r[c, b], r[c, c] = math.cos(t), -math.sin(t), math.sin(t), math.cos(t)
            out.append(r)
        if self.mirrored:
            flip = np.eye(3)
            flip[c, c] = -1.0  # across the plane of the axis and the next one
            out += [r @ flip for r in out]
        return np.stack(out)

    def maps(self, n_dims: int) -> np.ndarray:
        """(order, n_dims, n_dims) float64: the group acting on feature vectors whose `position` (and `direction`)
        dims are 3-vectors; every other dim is kept."""
        position, direction = list(self.position), list(self.direction)
        if max(position + direction) >= n_dims:
            raise ValueError(f"symmetry: dims {position + direction} do not fit {n_dims} feature dims")
        out = np.repeat(np.eye(n_dims)[None], self.order, axis=0)
        for g, r in enumerate(self.rotations()):
            for dims in (position, direction):
                if len(dims) == 3:
                    out[g][np.ix_(dims, dims)] = r
        return out

    def images(self, controls: np.ndarray) -> np.ndarray:
        """The effective controls, as the engine orders them: [originals..., first copies..., ...] (float64)."""
        c = np.asarray(controls, np.float64)
        return images(c, self.maps(c.shape[-1]))

    def copies(self, controls: np.ndarray) -> np.ndarray:
        """(k * order, n) the effective controls, grouped: each control followed by its copies."""
        c = np.asarray(controls, np.float64)
        maps = self.maps(c.shape[1])
        return np.einsum("gij,kj->kgi", maps, c).reshape(-1, c.shape[1])

    def describe(self) -> str:
        name = AXES[self.axis]
        if self.kind == "mirror":
            return f"mirror across {name}"
        return f"{self.n}-fold about {name}" + (" with a mirror" if self.mirrored else "")


def mirror_dims_of(symmetry: Symmetry | None) -> tuple[int, ...] | None:
    """The dims a mirror group negates (the engine's mirrored pairs: `Som(mirror=...)`), or None for a group that is
    not a plain mirror."""
    if symmetry is None or symmetry.kind != "mirror":
        return None
    dims = [symmetry.position[symmetry.axis]]
    if symmetry.direction:
        dims.append(symmetry.direction[symmetry.axis])
    return tuple(sorted(dims))


def mirror_of_dims(dims: Sequence[int], position: Sequence[int] = (0, 1, 2),
                   direction: Sequence[int] = ()) -> Symmetry | None:
    """The mirror group whose negated dims are `dims` (a position axis, with its direction axis where there is one),
    or None when they are not such a mirror."""
    for axis in range(3):
        group = Symmetry.mirror(axis).on(position, direction)
        if mirror_dims_of(group) == tuple(sorted(dims)):
            return group
    return None
