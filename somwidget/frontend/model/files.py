"""A session's files: the session file (io.save_session's versioned .npz: start mesh, layout, controls, schedule and
current weights), meshes exported with their colours, and reading a session file back into a preset and its Som.
Pure functions over a session's snapshot; the Session calls them (save, load, export_mesh, recover).
"""

from __future__ import annotations

import numpy as np

from ...backend import io as sw_io
from ...backend.presets import Preset
from ...backend.schedule import KEYS as SCHEDULE_KEYS
from ...backend.schedule import MAX_ITERATIONS


def state_of(snapshot: dict) -> dict:
    """The state io.save_session writes, from a session's `snapshot()`."""
    preset: Preset = snapshot["preset"]
    params = snapshot["parameters"]
    return {
        "preset": preset.name, "display": preset.display, "topology": preset.topology, "layout": preset.layout,
        "start_weights": np.asarray(preset.weights, np.float32), "weights": snapshot["weights"],
        "controls": snapshot["controls"], "iteration": snapshot["iteration"], "smooth_dims": preset.smooth_dims,
        **{name: params[name] for name in SCHEDULE_KEYS},
        "metric_weights": np.asarray(params["metric_weights"], np.float32), "mirror": tuple(params["mirror"]),
        "radii": snapshot["radii"], "strokes": snapshot["strokes"], "smoothing_rule": snapshot["smoothing_rule"],
        "symmetry": group.spec if (group := snapshot["symmetry"]) is not None and group.kind == "radial" else "none",
    }


def write(path, state: dict) -> None:
    """Write a session state (io.save_session: a temporary file renamed into place)."""
    sw_io.save_session(path, state)


def read(path, max_vertices: int) -> dict:
    """A session file's state (io.load_session); ValueError naming the file and what is wrong."""
    return sw_io.load_session(path, max_vertices=max_vertices, max_iterations=MAX_ITERATIONS)


def preset_of(state: dict) -> tuple[Preset, np.ndarray, int]:
    """(the start preset, the weights, s) a loaded session state describes; ValueError if it does not describe one."""
    try:
        preset = sw_io.preset_from_session(state)
        weights = np.asarray(state["weights"], np.float32)
        iteration = int(state.get("iteration", 0))
    except (KeyError, TypeError) as exc:
        raise ValueError(f"session: missing or malformed entry ({exc})") from None
    if weights.shape != preset.weights.shape or not np.isfinite(weights).all():
        raise ValueError(f"session: weights have shape {weights.shape}, expected {preset.weights.shape}")
    return preset, weights, min(iteration, preset.iterations)


def export_mesh(path, snapshot: dict) -> None:
    """Write the snapshot's mesh (OBJ, PLY, GLB by extension) with its vertex colours; a loaded mesh goes back in
    its file's original frame (io.load_mesh normalised it)."""
    preset = snapshot["preset"]
    sw_io.export_mesh(path, snapshot["weights"], preset.topology, preset.layout, display=preset.display,
                      transform=preset.meta.get("transform"))
