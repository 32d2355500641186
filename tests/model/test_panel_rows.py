"""The controls table's rows (model/panel.py, PanelModel.control_rows) as a person reads them: a coordinate within
ZERO_SHARE of the clay's size of zero prints as 0 (no "3.69e-17"), and a control off the clay (its gap over OFF_CLAY
of the clay's size) is marked. The frames are a real session's, with the controls placed by hand."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from somwidget.frontend.model import Session
from somwidget.frontend.model.frames import nearest_gaps
from somwidget.frontend.model.panel import OFF_CLAY, ZERO_SHARE, PanelModel, clay_size


@pytest.fixture(scope="module")
def grid_frame():
    session = Session("grid", device="cpu")
    try:
        session.pause()
        assert session.wait_idle(30)
        yield session.frame
    finally:
        session.close()


def placed(frame, points) -> object:
    """`frame` with its controls at `points` (position dims), the rest of each control as it was."""
    points = np.asarray(points, np.float32)
    controls = np.array(frame.controls[: len(points)], np.float32)
    controls[:, list(frame.layout.position)] = points
    return dataclasses.replace(frame, controls=controls, control_positions=points, effective_controls=controls,
                               effective_positions=points, control_colours=frame.control_colours[: len(points)],
                               effective_colours=frame.effective_colours[: len(points)],
                               radii=np.zeros(len(points), np.float32), strokes=(1,) * len(points),
                               control_ids=tuple(range(len(points))))


def test_float_noise_in_a_position_prints_as_zero(grid_frame):
    size = clay_size(grid_frame.preset)
    tiny = 0.5 * ZERO_SHARE * size  # noise: shown as 0
    small = 20 * ZERO_SHARE * size  # a real (if small) offset: shown as it is
    frame = placed(grid_frame, [[-0.301, 3.69e-17, -1.04], [tiny, -tiny, 0.0], [small, 0.25, -2e-30]])
    rows = PanelModel.control_rows(frame)
    assert [r["position"] for r in rows] == ["-0.301, 0, -1.04", "0, 0, 0", f"{np.float32(small):.3g}, 0.25, 0"]


def test_a_control_off_the_clay_is_marked_one_on_it_is_not(grid_frame):
    size = clay_size(grid_frame.preset)
    node = np.asarray(grid_frame.positions[len(grid_frame.positions) // 2], np.float64)
    up = np.array([0.0, 0.0, 1.0])
    points = [node, node + 0.5 * OFF_CLAY * size * up, node + 2.0 * OFF_CLAY * size * up]
    frame = placed(grid_frame, points)
    # an independent float64 reference of each gap, the grid's nodes all at z = 0 around `node`
    reference = np.sqrt(((grid_frame.positions[None].astype(np.float64) - np.asarray(points)[:, None]) ** 2)
                        .sum(-1)).min(1)
    np.testing.assert_allclose(nearest_gaps(frame.positions, frame.effective_positions), reference, atol=1e-6)
    rows = PanelModel.control_rows(frame)
    assert [r["off"] for r in rows] == [False, False, True]
    assert rows[2]["gap"] == f"{reference[2]:.3f}"
