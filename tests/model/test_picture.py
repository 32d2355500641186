"""Static pictures without a UI (somwidget.render): an off-screen pyvista render of a Som, Session or preset.

Headless: VTK's EGL window on Mesa (VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow, set by scripts/test.sh).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import somwidget  # noqa: E402
from somwidget import Som, Topology, presets  # noqa: E402
from somwidget.frontend.model import Session  # noqa: E402
from somwidget.frontend.model.picture import BACKGROUND, picture_of  # noqa: E402

SIZE = (320, 240)
BG = np.round(np.asarray(BACKGROUND) * 255).astype(int)


def drawn(img: np.ndarray) -> np.ndarray:
    """Mask of the pixels that are not background."""
    return np.abs(img.astype(int) - BG).sum(axis=2) > 12


def colourful(img: np.ndarray) -> np.ndarray:
    return (np.max(img, axis=2).astype(int) - np.min(img, axis=2)) > 80


def test_preset_name_picture_and_file(tmp_path):
    path = tmp_path / "sub" / "car.png"
    img = somwidget.render("car", path, size=SIZE)
    assert img.shape == (240, 320, 3) and img.dtype == np.uint8
    assert 0.05 < drawn(img).mean() < 0.9  # something is drawn, and it fits the frame
    from PIL import Image

    assert np.array_equal(np.asarray(Image.open(path).convert("RGB")), img)


def test_trained_som_shows_the_colours_of_its_layout():
    car = presets.get_preset("car")
    som = car.make_som(device="cpu")
    som.train()
    img = somwidget.render(som, layout=car.layout, size=SIZE, controls=False)
    assert colourful(img).mean() > 0.05  # the hue dims became colours
    grey = somwidget.render(som, size=SIZE, controls=False)  # a bare Som without layout: x, y, z and no colour
    assert colourful(grey).mean() == 0


def test_controls_weights_and_cameras():
    preset = presets.get_preset("sphere")
    with_controls = somwidget.render(preset, size=SIZE)
    without = somwidget.render(preset, size=SIZE, controls=False)
    assert colourful(with_controls).mean() > 0.005 and colourful(without).mean() == 0  # grey clay, coloured balls
    moved = preset.weights.copy()
    moved[:, 0] *= 3.0  # a long cigar instead of a sphere: seen from the top it fills the width
    top = somwidget.render(preset, size=SIZE, controls=False, weights=moved, camera="top")
    cols = np.flatnonzero(drawn(top).any(axis=0))
    rows = np.flatnonzero(drawn(top).any(axis=1))
    assert (cols[-1] - cols[0]) > 2 * (rows[-1] - rows[0])


def test_lines_points_and_sessions():
    lines = somwidget.render("lines", size=SIZE)
    assert drawn(lines).mean() > 0.05
    edges, pts = presets.lattice(4, 4, 4)
    som = Som(Topology.from_edges(edges, len(pts)), pts, [[3.0, 0.0, 0.0]], iterations=20, device="cpu")
    assert picture_of(som).display == "points"  # no faces: points and synapses
    assert drawn(somwidget.render(som, size=SIZE)).mean() > 0.01
    with Session("torus", device="cpu") as session:
        assert session.wait_idle(30)
        img = somwidget.render(session, size=SIZE, title="torus")
        assert drawn(img).mean() > 0.05
        assert picture_of(session).weights.shape == (session.preset.n_vertices, 3)


def test_refusals():
    with pytest.raises(ValueError, match="camera"):
        somwidget.render("torus", camera="below", size=SIZE)
    with pytest.raises(ValueError, match="weights have shape"):
        somwidget.render("torus", weights=np.zeros((3, 3)), size=SIZE)
    with pytest.raises(ValueError, match="expected a Som"):
        somwidget.render(42, size=SIZE)
    with pytest.raises(ValueError, match="unknown preset"):
        somwidget.render("no-such-preset", size=SIZE)
    with pytest.raises(ValueError, match="3 position dims"):
        edges = np.array([[0, 1]])
        somwidget.render(Som(Topology.from_edges(edges, 2), np.zeros((2, 2)), [[1.0, 0.0]], device="cpu"))
