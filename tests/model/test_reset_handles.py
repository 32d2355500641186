"""Reset on the car under handles, as the web panel's Reset does it (Session.reset): the body grows again from its
ellipsoid to where the controls are, whatever their radii (a handle binds only what a grab takes, so before the fix a
reset with every control's radius at 0.5 grew nothing: the ellipsoid stayed, and with the Laplacian smoothing on the
body shrank to volume 0).
"""

from __future__ import annotations

import numpy as np
import pytest

from somwidget.backend import metrics
from somwidget.backend.presets import car as car_preset
from somwidget.backend.refine import subdivide
from somwidget.frontend.model import Session


def settle(session) -> None:
    assert session.wait_applied(120) and session.wait_idle(120), session.error


def body(session) -> tuple[np.ndarray, float]:
    """(positions, enclosed volume) of the clay now."""
    frame = session.frame
    p = np.asarray(frame.positions, np.float64)
    return p, metrics.mesh_volume(p, frame.preset.topology.faces)


@pytest.fixture(scope="module")
def fresh():
    """A fresh car's body, and its size."""
    s = Session("car", device="cpu", autosave=False)
    try:
        settle(s)
        p, volume = body(s)
        return p, volume, metrics.bounding_diagonal(p)
    finally:
        s.close()


@pytest.fixture
def car():
    s = Session("car", device="cpu", autosave=False)
    settle(s)
    yield s
    s.close()


def test_reset_right_after_start_is_the_fresh_car(car, fresh):
    p0, v0, size = fresh
    car.reset()
    settle(car)
    p, v = body(car)
    assert abs(v / v0 - 1.0) < 0.01
    assert np.abs(p - p0).max() < 0.01 * size


def reset_car(radius: float, smoothing: float | None) -> np.ndarray:
    """The car's positions after 'all radii' `radius`, smoothing (if given) and Reset."""
    s = Session("car", device="cpu", autosave=False)
    try:
        settle(s)
        s.set_control_radius(None, radius)
        if smoothing is not None:
            s.set_parameter("smoothing", smoothing)
        settle(s)
        s.reset()
        settle(s)
        assert s.frame.iteration == s.frame.iterations
        assert np.allclose(s.frame.radii, radius)  # the radii stay: the controls are handles again
        return body(s)[0]
    finally:
        s.close()


@pytest.mark.parametrize("smoothing", [None, 0.3])
def test_reset_with_every_radius_grows_the_car_again(fresh, smoothing):
    """The panel's 'all radii' 0.5 (and smoothing 0.3, the car brief's), then Reset: the car the same Reset grows from
    point controls (the paper's case study), not its ellipsoid (or the ellipsoid shrunk by the smoothing)."""
    p0, v0, size = fresh
    p = reset_car(0.5, smoothing)
    points = p0 if smoothing is None else reset_car(0.0, smoothing)
    faces = car_preset().topology.faces
    v, v_points = metrics.mesh_volume(p, faces), metrics.mesh_volume(points, faces)
    assert abs(v / v_points - 1.0) < 0.02, f"volume {v:.3f} after Reset, {v_points:.3f} with point controls"
    assert np.abs(p - points).max() < 0.01 * size
    if smoothing is None:
        assert abs(v / v0 - 1.0) < 0.02


def test_reset_after_a_handle_drag_grows_the_car_to_the_dragged_control(car, fresh):
    """A drag of the nose (radius 0.5) by a hand, then Reset: the car again, its nose out at the control, its tail
    where a fresh car's is; then a drag of the roof is a handle's again (the roof goes down, the nose stays)."""
    p0, v0, size = fresh
    car.set_control_radius(None, 0.5)
    settle(car)
    hands = car.hands
    hand = hands.join("desktop")
    nose = car.control_ids[2]
    hands.grab(hand, nose)
    start = car.controls[2][:3].copy()
    for k in range(1, 5):
        with hands.acting(hand, nose):
            car.move_control_id(nose, start + np.float32([0.8, 0.0, 0.0]) * k / 4)
    hands.release(hand, nose)
    settle(car)
    car.reset()
    settle(car)
    p, v = body(car)
    assert 0.97 < v / v0 < 1.2, f"volume {v:.3f} after Reset, a fresh car's {v0:.3f}"
    assert p[:, 0].max() > start[0] + 0.8 - 0.03 * size  # the nose reaches the dragged control
    tail = p[:, 0] < -1.0  # the far end: the fresh car's surface there (its nodes may slide along it)
    faces, dense = car_preset().topology.faces, p0
    for _ in range(2):
        faces, dense = subdivide(faces, dense)
    gap = np.sqrt(((p[tail][:, None, :] - dense[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
    assert gap.max() < 0.02 * size
    assert abs(p[:, 0].min() - p0[:, 0].min()) < 0.005 * size
    before = p.copy()
    roof = car.control_ids[4]
    hands.grab(hand, roof)
    place = car.controls[4][:3] - np.float32([0.0, 0.0, 0.3])
    with hands.acting(hand, roof):
        car.move_control_id(roof, place)
    hands.release(hand, roof)
    settle(car)
    p, _ = body(car)
    assert np.sqrt(((p - place) ** 2).sum(axis=1)).min() < 0.01 * size  # the roof's clay went with the hand
    assert np.abs(p[:, 0].max() - before[:, 0].max()) < 0.01 * size
