"""The chair shell as the first-time user of 2026-11-27 made it (docs/modelling.md, "Five shapes, step by step"),
through the Session API: the grid, symmetry mirror across x (the two sides pair up), a stroke along the back edge
lifted for the back, then a stroke along a side edge lifted. The sides rose in a step with a crease (54 degrees at
radius 0.4, 104 with the back lifted first): a lift rolled only where the radius was at least its height. Now a
binding carried farther than half its radius widens its patch as it goes (shaping_kernels.WIDEN), so the lift rolls
at any radius while a small push still dents locally. Real Warp kernels on the CPU; the angles are
metrics.dihedral_angles, computed in float64 from the frame's positions."""

from __future__ import annotations

import numpy as np
import pytest

from somwidget.backend import metrics
from somwidget.frontend.model import Session

#: The largest angle between adjacent faces a roll may have (the issue's crease bound for a push through a sphere).
ROLL_MOST = 45.0
BACK = [(-1.0, 1.0, 0.0), (1.0, 1.0, 0.0)]
SIDE = [(1.0, -1.0, 0.0), (1.0, 0.4, 0.0)]


def settle(session: Session) -> None:
    assert session.wait_applied(300) and session.wait_idle(300), session.error


def positions(session: Session) -> np.ndarray:
    return np.asarray(session.frame.positions, np.float64)[:, :3]


def crease(session: Session) -> float:
    """The largest dihedral angle of the clay, degrees (its quads fanned into the triangles a renderer draws)."""
    angles = metrics.dihedral_angles(positions(session), metrics.triangles_of(session.frame.preset.topology.faces))
    assert np.isfinite(angles).all()
    return float(angles.max())


def lift(session: Session, first: int, height: float) -> None:
    """A Shift-drag of a stroke (by its first sample) straight up by `height`: one typed move."""
    c = np.asarray(session.controls[first, :3], np.float64)
    session.move_control(first, [c[0], c[1], c[2] + height])
    settle(session)


@pytest.fixture
def grid():
    s = Session("grid", device="cpu", autosave=False)
    settle(s)
    yield s
    s.close()


@pytest.mark.parametrize("radius", [None, 0.4], ids=["preset-radius", "radius-0.4"])
def test_the_chair_shells_sides_roll(grid, radius):
    """The person's chair at the preset's radius and at the 0.4 the trial had: the back up by 1, a side up by 0.6;
    no angle between faces over 45 degrees, the seat's middle stays flat and low, the back and the side reach their
    strokes."""
    grid.settings.set_symmetry("mirror-x")
    settle(grid)
    back = grid.add_stroke(np.array(BACK), radius=radius)
    settle(grid)
    lift(grid, back, 1.0)
    assert crease(grid) <= ROLL_MOST
    side = grid.add_stroke(np.array(SIDE), radius=radius)
    settle(grid)
    lift(grid, side, 0.6)
    assert crease(grid) <= ROLL_MOST
    p = positions(grid)
    seat = (np.abs(p[:, 0]) <= 0.3) & (p[:, 1] <= -0.2)
    assert seat.sum() > 100
    assert p[seat, 2].max() <= 0.15  # a seat: its middle stays near the floor (0.6 and 1.0 lifted beside it)
    assert p[:, 2].max() >= 0.99
    for first in (back, side):  # each stroke's samples lie on the clay
        samples = np.asarray(grid.controls[first:first + 3, :3], np.float64)
        assert metrics.nearest_distances(samples, p).max() <= 0.03 * metrics.bounding_diagonal(p)


@pytest.mark.parametrize("height", [0.6, 1.0])
def test_a_side_lifted_taller_than_its_radius_rolls(grid, height):
    """A side edge's stroke at radius 0.4 lifted 0.6 (the trial's 54 degrees) and 1.0: the patch widens as it goes,
    no crease over 45 degrees, and the edge reaches the stroke."""
    side = grid.add_stroke(np.array([(1.0, -1.0, 0.0), (1.0, 1.0, 0.0)]), radius=0.4)
    settle(grid)
    lift(grid, side, height)
    assert crease(grid) <= ROLL_MOST
    assert positions(grid)[:, 2].max() == pytest.approx(height, abs=0.01)


def test_a_small_push_still_dents_locally(grid):
    """A deliberate push: a control of radius 0.15 at the middle pushed down 0.3. The clay under it reaches it, the
    dent stays within its widened reach (0.15 widened by twice the 0.3 carried: 0.6, plus an edge), and every node
    beyond stays where it was."""
    start = positions(grid)
    c = grid.add_control([0.0, 0.0, 0.0], radius=0.15)
    settle(grid)
    grid.move_control(c, [0.0, 0.0, -0.3])
    settle(grid)
    p = positions(grid)
    assert p[:, 2].min() == pytest.approx(-0.3, abs=0.005)
    far = np.hypot(start[:, 0], start[:, 1]) > 0.6 + 2.0 / 31.0
    assert np.abs(p[far] - start[far]).max() <= 1e-6
    near = np.hypot(start[:, 0], start[:, 1]) < 0.1
    assert (p[near, 2] < -0.2).all()  # a dent, not a spike: the clay around the winner went down with it
