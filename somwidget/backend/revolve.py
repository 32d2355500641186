"""Revolve (a lathe): the clay's nodes placed on the surface of revolution of a profile about an axis through the
origin, as every CAD tool's revolve makes it (DESIGN.md, Shaping: Revolve).

A point p is read in the meridian half-plane of an axis a: its height h = p[a] along the axis, its distance r from the
axis and its angle theta about it (from the next axis b = a + 1 towards c = a + 2, as Symmetry.radial turns). The
profile is a polyline of (r, h); its surface of revolution turns it through every theta.

Each node keeps its angle and takes the profile point at its place along the clay's own meridian: the nodes' (r, h)
projected on the main direction of their spread (the height along a tube, the radius across a disc, the slant of a
cone), scaled to [0, 1] and laid along the profile by arc length, the profile taken in the same sense (its end further
along that direction). So rings stay rings and keep their order, the faces keep their orientation, and the topology
is untouched: a tube closed around stays closed around. A node on the axis (a pole) stays on it, at its height.

An end of the profile drawn within AXIS_SNAP of the clay's size of the axis starts on it, as a CAD lathe snaps: the
form closes there (a round bottom) instead of leaving a hole or a flat ring about the pole.
"""

from __future__ import annotations

import numpy as np

from . import checks

#: A node closer to the axis than this share of the clay's size is on it (a pole): it stays on the axis.
ON_AXIS = 1e-6
#: An end of a profile closer to the axis than this share of the clay's size is put on the axis (`profile_of`).
AXIS_SNAP = 0.08  # (past a control sphere on the pole; in the view a press on that control starts the profile)


def axis_index(axis) -> int:
    """0, 1, 2 for "x", "y", "z" (or the index itself)."""
    if isinstance(axis, str) and axis.lower() in ("x", "y", "z"):
        return "xyz".index(axis.lower())
    return checks.integer("axis", axis, 0, 2)


def meridian(points, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r, h, theta) float64 of points (M, 3) about `axis`: distance from the axis, height along it, angle about it."""
    p = np.asarray(points, np.float64)
    b, c = (axis + 1) % 3, (axis + 2) % 3
    return np.hypot(p[:, b], p[:, c]), p[:, axis].copy(), np.arctan2(p[:, c], p[:, b])


def place(r, h, theta, axis: int) -> np.ndarray:
    """The points (M, 3) float64 at (r, h, theta) about `axis` (the inverse of `meridian`)."""
    out = np.empty((len(r), 3))
    b, c = (axis + 1) % 3, (axis + 2) % 3
    out[:, axis] = h
    out[:, b] = r * np.cos(theta)
    out[:, c] = r * np.sin(theta)
    return out


def profile_of(points, axis: int, snap: float = 0.0) -> tuple[np.ndarray, np.ndarray, float]:
    """(r, h, theta) of a drawn profile (M >= 2 points, x, y, z): its points' distances from the axis and heights,
    and the angle of the half-plane it was drawn in (the mean of its points' angles, each by its distance). Points
    closer together than ON_AXIS of the profile's size are merged; an end within `snap` of the axis is put on it
    (r = 0, its height kept). ValueError for a profile with no length or one lying on the axis."""
    p = checks.finite_array("profile points", points, 2, np.float64)
    if len(p) < 2 or p.shape[1] != 3:
        raise ValueError(f"profile points: expected at least 2 points of 3 (x, y, z), got shape {p.shape}")
    r, h, theta = meridian(p, axis)
    size = float(np.linalg.norm(np.ptp(p, axis=0)))
    if size == 0 or r.max() <= ON_AXIS * size:
        raise ValueError("profile points: the profile lies on the axis (or is one point): draw it beside the axis")
    keep = np.concatenate([[True], np.hypot(np.diff(r), np.diff(h)) > ON_AXIS * size])
    r, h = r[keep], h[keep]
    if len(r) < 2:
        raise ValueError("profile points: the profile has no length in its half-plane (it goes round the axis)")
    angle = float(np.arctan2((r * np.sin(theta[keep])).sum(), (r * np.cos(theta[keep])).sum()))
    r = r.copy()
    for end in (0, -1):
        if r[end] <= snap and r.max() > snap:
            r[end] = 0.0
    return r, h, angle


def main_direction(r, h) -> np.ndarray:
    """The unit direction (dr, dh) of the largest spread of the points (r, h), its larger component positive."""
    x = np.stack([r, h], axis=1)
    x = x - x.mean(axis=0)
    _, vectors = np.linalg.eigh(x.T @ x)
    d = vectors[:, -1]
    return d if d[np.argmax(np.abs(d))] > 0 else -d


def along(r, h) -> np.ndarray:
    """Each point's place in [0, 1] along the main direction of the points (r, h) (`main_direction`)."""
    s = np.stack([r, h], axis=1) @ main_direction(r, h)
    span = s.max() - s.min()
    if span <= 0:
        raise ValueError("revolve: the clay has no extent in its meridian (every node at one distance and height)")
    return (s - s.min()) / span


def arc_length(profile_r, profile_h) -> np.ndarray:
    """The arc length (M,) float64 from the profile's first point to each of its points."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(profile_r), np.diff(profile_h)))])


def node_arcs(positions, profile_r, profile_h, axis: int) -> np.ndarray:
    """Where along the profile (its arc length from its first point) `lathe` puts each of the positions (N, 3)."""
    r, h, _ = meridian(positions, axis)
    pr, ph = np.asarray(profile_r, np.float64), np.asarray(profile_h, np.float64)
    total = arc_length(pr, ph)[-1]
    at = along(r, h) * total
    # the profile taken in the sense of the clay's meridian (its end further along the main direction)
    return total - at if (np.array([pr[-1] - pr[0], ph[-1] - ph[0]]) @ main_direction(r, h)) < 0 else at


def lathe(positions, profile_r, profile_h, axis: int) -> np.ndarray:
    """The positions (N, 3) placed on the surface of revolution of the profile (profile_r, profile_h) about `axis`
    (see the module's docstring); float64."""
    r, _, theta = meridian(positions, axis)
    pr, ph = np.asarray(profile_r, np.float64), np.asarray(profile_h, np.float64)
    arc, at = arc_length(pr, ph), node_arcs(positions, pr, ph, axis)
    new_r, new_h = np.interp(at, arc, pr), np.interp(at, arc, ph)
    size = float(np.linalg.norm(np.ptp(np.asarray(positions, np.float64), axis=0))) or 1.0
    new_r[r <= ON_AXIS * size] = 0.0  # a pole stays on the axis
    return place(new_r, new_h, theta, axis)

