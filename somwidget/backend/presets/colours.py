"""Colours: a node's RGB from its layout's colour dims (hue, hue and saturation, or RGB), the way back for a colour
picked in a view, hex text, and the palette of controls when the layout has no colour dims.
"""

from __future__ import annotations

import colorsys

import numpy as np

from .. import checks
from .records import FeatureLayout

#: The vertex colour of a layout without colour dims.
NEUTRAL_GREY = (0.72, 0.72, 0.72)


def hsv_to_rgb(h, s, v) -> np.ndarray:
    """HSV -> RGB for arrays of equal shape (h taken mod 1, s and v clipped to [0, 1]); returns (..., 3) float32.
    Channel n of (r, g, b) is v (1 - s ramp(k)), k = (n' + 6 h) mod 6 for n' = 5, 3, 1 and ramp(k) =
    clip(min(k, 4 - k), 0, 1): the sextants' table without a branch (a frame's colours: a few numpy calls, in place;
    k lies in [1, 12), so its mod 6 is k - 6 from 6 on, exactly; 1 - s ramp and v times it stay in [0, 1])."""
    h = np.mod(np.asarray(h, np.float64), 1.0)
    s = np.clip(np.asarray(s, np.float64), 0.0, 1.0)
    v = np.clip(np.asarray(v, np.float64), 0.0, 1.0)
    h = np.broadcast_to(h, np.broadcast_shapes(h.shape, s.shape, v.shape))
    k = np.add(_CHANNEL_OFFSETS, 6.0 * h[..., None])
    k -= 6.0 * (k >= 6.0)
    ramp = np.subtract(4.0, k)
    np.minimum(k, ramp, out=ramp)
    np.clip(ramp, 0.0, 1.0, out=ramp)
    if s.ndim or s != 1.0:
        ramp *= s[..., None] if s.ndim else s
    np.subtract(1.0, ramp, out=ramp)
    if v.ndim or v != 1.0:
        ramp *= v[..., None] if v.ndim else v
    return ramp.astype(np.float32)


_CHANNEL_OFFSETS = np.array([5.0, 3.0, 1.0])


#: Control colours for layouts without colour dims (the nodes are all grey there, the controls need not be).
CONTROL_PALETTE = np.array([[0.90, 0.30, 0.25], [0.25, 0.55, 0.90], [0.30, 0.75, 0.35], [0.95, 0.70, 0.20],
                            [0.65, 0.40, 0.85], [0.20, 0.75, 0.75], [0.90, 0.45, 0.70], [0.55, 0.55, 0.25]],
                           np.float32)


def palette_colours(k: int, k_eff: int, ids=None) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) and (k_eff, 3) float32 display colours of k controls and their k_eff effective copies (copy j takes
    control j mod k's colour) from `CONTROL_PALETTE`, for layouts without colour dims: by the controls' stable `ids`
    when given (a colour stays with its control while others come and go), else by index."""
    keys = np.arange(k) if ids is None else np.asarray(ids, np.int64).reshape(k)
    own = CONTROL_PALETTE[keys % len(CONTROL_PALETTE)]
    return own, own[np.arange(k_eff) % max(k, 1)]


def colours_of(weights_or_controls, layout: FeatureLayout) -> np.ndarray:
    """(M, 3) float32 RGB in [0, 1] from the colour dims of weights or controls (M, n); a single row (n,) is taken
    as M = 1. "hue": HSV(h mod 1, 1, 1); "hs": HSV(h mod 1, clip(s), 1); "rgb": clipped; "none": NEUTRAL_GREY."""
    values = np.asarray(weights_or_controls, np.float32)
    if values.ndim == 1:
        values = values[None, :]
    if values.ndim != 2 or values.shape[1] != layout.n_dims:
        raise ValueError(f"colours_of: expected shape (M, {layout.n_dims}), got {np.shape(weights_or_controls)}")
    m = len(values)
    space = layout.colour_space
    if space == "none":
        return np.tile(np.asarray(NEUTRAL_GREY, np.float32), (m, 1))
    cols = values[:, list(layout.colour)].astype(np.float64)
    if space == "hue":
        return hsv_to_rgb(cols[:, 0], 1.0, 1.0)
    if space == "hs":
        return hsv_to_rgb(cols[:, 0], cols[:, 1], 1.0)
    return np.clip(cols, 0.0, 1.0).astype(np.float32)  # "rgb"


def rgb_to_colour_dims(rgb, layout: FeatureLayout) -> np.ndarray:
    """The inverse of `colours_of` for one colour: RGB in [0, 1] -> the values of the layout's colour dims."""
    rgb = checks.finite_vector("colour", rgb, 3).astype(np.float64)
    if (rgb < 0).any() or (rgb > 1).any():
        raise ValueError(f"colour: RGB values must lie in [0, 1], got {rgb.tolist()}")
    space = layout.colour_space
    if space == "none":
        raise ValueError("colour: this preset's features have no colour dimensions")
    h, s, _v = colorsys.rgb_to_hsv(*rgb)
    if space == "hue":
        return np.array([h], np.float32)
    if space == "hs":
        return np.array([h, s], np.float32)
    return rgb.astype(np.float32)  # "rgb"


def parse_hex_colour(text: str) -> np.ndarray:
    """'#rrggbb' (or '#rrggbbaa', alpha ignored) -> RGB float32 in [0, 1]; ValueError otherwise."""
    if not isinstance(text, str):
        raise ValueError(f"colour: expected '#rrggbb', got {text!r}")
    t = text.strip().lstrip("#")
    if len(t) not in (6, 8) or any(c not in "0123456789abcdefABCDEF" for c in t):
        raise ValueError(f"colour: expected '#rrggbb', got {text!r}")
    return np.array([int(t[i:i + 2], 16) / 255.0 for i in (0, 2, 4)], np.float32)


def hex_colour(rgb) -> str:
    """RGB in [0, 1] (clipped) -> '#rrggbb'."""
    r, g, b = (int(round(float(np.clip(c, 0.0, 1.0)) * 255)) for c in rgb[:3])
    return f"#{r:02x}{g:02x}{b:02x}"
