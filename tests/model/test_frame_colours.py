"""A frame's node and control colours: made again only when their colour dims changed (frames.FrameStream), always
equal to colours_of of the frame's own weights; hsv_to_rgb against colorsys (float64) and its earlier form."""

import colorsys
import threading

import numpy as np

from somwidget.backend import presets
from somwidget.backend.presets.colours import hsv_to_rgb
from somwidget.frontend.model.frames import FrameStream


def _status():
    return {"paused": False, "held": False, "applied": (), "history": (), "control_ids": ()}


def test_node_colours_follow_the_colour_dims_and_are_kept_while_they_stay():
    preset = presets.get_preset("car")
    som = preset.make_som(device="cpu")
    layout = preset.layout
    dims = list(layout.colour)
    stream = FrameStream(threading.Condition())
    w0 = np.asarray(som.weights, np.float32)

    def frame(w):
        return stream.make(som, preset, 0, cycles=0, cycle_time=0.0, status=_status, weights=w)

    first = frame(w0)
    np.testing.assert_array_equal(first.colours, presets.colours_of(w0, layout))
    moved = w0.copy()
    moved[:, :3] += 0.25  # positions only: the colours stay, the array is the one made before
    second = frame(moved)
    assert second.colours is first.colours
    np.testing.assert_array_equal(second.positions, moved[:, :3])
    recoloured = moved.copy()
    recoloured[5, dims[0]] = (recoloured[5, dims[0]] + 0.5) % 1.0  # one node's hue: its colour changes
    third = frame(recoloured)
    np.testing.assert_array_equal(third.colours, presets.colours_of(recoloured, layout))
    assert not np.array_equal(third.colours[5], second.colours[5])
    np.testing.assert_array_equal(third.colours[6:], second.colours[6:])
    assert not third.colours.flags.writeable
    back = frame(w0)  # back to the first weights: their colours again
    np.testing.assert_array_equal(back.colours, first.colours)


def test_hsv_to_rgb_against_colorsys_and_its_edges():
    rng = np.random.default_rng(7)
    h, s, v = rng.uniform(-2, 3, 500), rng.uniform(-0.5, 1.5, 500), rng.uniform(-0.5, 1.5, 500)
    h[:7] = [0.0, 1 / 6, 2 / 6, 0.5, 4 / 6, 5 / 6, np.nextafter(1.0, 0.0)]
    got = hsv_to_rgb(h, s, v)
    want = np.array([colorsys.hsv_to_rgb(hh % 1.0, min(max(ss, 0), 1), min(max(vv, 0), 1))
                     for hh, ss, vv in zip(h, s, v)])
    assert got.dtype == np.float32 and got.shape == (500, 3)
    np.testing.assert_allclose(got, want, atol=2e-6)
    assert hsv_to_rgb(0.25, 1.0, 1.0).shape == (3,)  # scalars broadcast as before
    assert hsv_to_rgb(rng.uniform(0, 1, (4, 5)), 1.0, 0.5).shape == (4, 5, 3)
