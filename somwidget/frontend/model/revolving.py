"""Revolve (`Session.revolve`): a profile drawn beside an axis lathes the clay, as every CAD tool's revolve does.

One undo step: the nodes are placed on the surface of revolution of the profile (backend/revolve.py; the weights
change, nothing trains), the symmetry becomes n-fold about the axis, and the profile's samples become the clay's
stroke control (its copies turned about the axis) in place of the controls of the form it replaces: PROFILE_SAMPLES
samples at most, and with their copies at most half of the engine's controls (so that as many can be added), each
sample on a node of the lathed clay (its place along the profile and its half-plane those of the nearest node: the
table shows no gap). An end drawn within AXIS_SNAP of the clay's size of the axis starts on it (backend/revolve.py).
Nothing trains until the person acts: dragging the profile then swells or pinches the whole form. The panels say
which controls the profile replaced (`Settings.notice`); one undo brings them back.
"""

from __future__ import annotations

import numpy as np

from ...backend import checks
from ...backend import revolve as lathe_rule
from ...backend.metrics import bounding_diagonal, median_edge
from ...backend.symmetry import MAX_RADIAL, Symmetry
from .controls import MAX_ABS_VALUE, MAX_CONTROLS, SPACING_SHARE, check_radius
from .history import Step
from .operations import Publish

#: The group a revolve makes where none is named: 16 copies about the axis (a smooth form under a dragged profile).
DEFAULT_COPIES = 16
#: The most samples a profile keeps (fewer where the group's copies would pass half the engine's controls): the vase
#: of tests/model/test_revolve.py, its profile dragged out by 0.15, creased to 40 degrees at most with 8 samples (as
#: with 4, the form following less), to 51 with 16 (under 8 copies), and 8 samples draw a quarter of the spheres.
PROFILE_SAMPLES = 8


def revolve(session, profile_points, axis="z", n: int = DEFAULT_COPIES, radius: float | None = None) -> int:
    """Lathe `session`'s clay around `axis` (x, y or z through the origin) with the profile `profile_points` (m >= 2
    points: x, y, z, or all the layout's features) under n-fold radial symmetry (2 to MAX_RADIAL). Returns the number
    of the profile's samples (the stroke control's). ValueError, the session unchanged, for a bad profile (on the
    axis, no length), axis or n, or a clay without faces."""
    state, timeline, trainer = session.modelling, session.timeline, session.trainer
    layout = state.layout
    a = lathe_rule.axis_index(axis)
    n = checks.integer("revolve: n", n, 2, MAX_RADIAL)
    pts = checks.finite_array("profile points", profile_points, 2, np.float64)
    if len(pts) < 2 or pts.shape[1] not in (3, layout.n_dims):
        raise ValueError(f"profile points: expected at least 2 points of 3 (x, y, z) or {layout.n_dims} values, got "
                         f"shape {pts.shape}")
    if np.abs(pts).max() > MAX_ABS_VALUE:
        raise ValueError(f"profile points: values must lie within +-{MAX_ABS_VALUE:g}")
    if not state.preset.topology.faces:
        raise ValueError("revolve: this clay has no faces (a lattice): revolve shapes a surface")
    position = list(layout.position)
    snap = _axis_snap(state.preset.weights[:, position], a)
    profile_r, profile_h, angle = lathe_rule.profile_of(pts[:, position] if pts.shape[1] != 3 else pts, a, snap)
    group = Symmetry.radial(n, a).on(layout.position, layout.direction)
    r = check_radius("revolve radius", state.preset.radius if radius is None else radius)
    with timeline.step("revolve"):
        with state.som_lock:
            trainer.drain()
            with state.lock:
                step = _lathed(state, profile_r, profile_h, angle, a, group, r, pts)
            replaced = len(state.controls) - sum(state.strokes) + len(state.strokes)  # as the table's rows
            timeline.put_back(step)
        with state.lock:
            trainer.enqueue(Publish(), intent=False)
    settings = session.settings
    settings.notice = (f"Revolve replaced the {replaced} control{'s' * (replaced != 1)} of {state.preset.title} with "
                       "the profile; Ctrl+Z brings them back")
    settings.notices += 1
    return len(step.controls)


def _axis_snap(start_positions, axis: int) -> float:
    """How close to the axis a profile's end is put on it: AXIS_SNAP of the clay's size where the clay has a pole (a
    node on the axis, as the bowl's bottom), else 0: a tube's end ring drawn onto the axis would fold its faces flat."""
    size = bounding_diagonal(start_positions)
    r, _, _ = lathe_rule.meridian(start_positions, axis)
    return lathe_rule.AXIS_SNAP * size if bool((r <= lathe_rule.ON_AXIS * size).any()) else 0.0


def _lathed(state, profile_r, profile_h, angle, axis, group, radius, pts) -> Step:
    """The state after the revolve, as a step to put back (caller holds both locks)."""
    layout, som = state.layout, state.som
    position = list(layout.position)
    weights = np.asarray(som.weights, np.float32).copy()
    arcs = lathe_rule.node_arcs(weights[:, position], profile_r, profile_h, axis)
    weights[:, position] = lathe_rule.lathe(weights[:, position], profile_r, profile_h, axis)
    spacing = max(median_edge(weights[:, position], state.preset.topology.edges), SPACING_SHARE * radius, 1e-6)
    most = min(PROFILE_SAMPLES, MAX_CONTROLS // group.order // 2)  # room left for as many controls again
    arc = lathe_rule.arc_length(profile_r, profile_h)
    at = _sample_arcs(arc[-1], arcs, spacing, most)
    angle = _node_angle(weights[:, position], angle, axis)
    # the profile in its own half-plane (so its samples lie on the form), its other features the last control's
    # (or those given)
    samples = np.repeat(state.controls[-1:].astype(np.float64), len(at), axis=0)
    samples[:, position] = lathe_rule.place(np.interp(at, arc, profile_r), np.interp(at, arc, profile_h),
                                            np.full(len(at), angle), axis)
    if pts.shape[1] != 3:
        others = [d for d in range(layout.n_dims) if d not in position]
        samples[:, others] = pts[0, others]
    samples = samples.astype(np.float32)
    params = {name: list(v) if isinstance(v, list) else v for name, v in state.params.items()}
    return Step(preset=state.preset, controls=samples, parameters=params, weights=weights,
                iteration=int(som.iterations), radii=np.full(len(samples), radius, np.float32), symmetry=group,
                strokes=(len(samples),), control_ids=state.run_ids((len(samples),)))


def _sample_arcs(length: float, node_arcs: np.ndarray, spacing: float, most: int) -> np.ndarray:
    """Where the profile's samples lie along it (arc lengths, its ends included): about `spacing` apart, 2 to `most`
    of them, each moved to the nearest place a node of the lathed clay lies (so that the clay passes through every
    sample), none twice."""
    count = int(np.clip(np.ceil(length / spacing) + 1, 2, max(2, most)))
    places = np.unique(node_arcs)
    wanted = np.linspace(0.0, length, count)
    return np.unique(places[np.abs(places[None, :] - wanted[:, None]).argmin(axis=1)])


def _node_angle(points: np.ndarray, angle: float, axis: int) -> float:
    """The angle about `axis` of the lathed clay's node (off the axis) nearest in angle to `angle`: the profile's
    half-plane turned onto the nodes' (at most half a longitude's turn)."""
    r, _, theta = lathe_rule.meridian(points, axis)
    off = r > lathe_rule.ON_AXIS * (r.max() or 1.0)
    if not off.any():
        return angle
    turn = np.angle(np.exp(1j * (theta[off] - angle)))
    return float(angle + turn[np.abs(turn).argmin()])
