"""What goes into and out of a session (`session.files`): its snapshot, the session file (backend/session_file.py's
versioned .npz: start mesh, layout, controls, settings and current weights), meshes exported with their colours, and
states made elsewhere put in place as one undo step (a loaded session file, a design variant).
"""

from __future__ import annotations

import datetime
import re
from collections.abc import Callable, Mapping

import numpy as np

from ...backend import checks, schedule, session_file
from ...backend import io as mesh_io
from ...backend.presets import Preset
from .state import ModellingState, held_settings
from .timeline import Timeline


def state_of(snapshot: dict) -> dict:
    """The state session_file.save_session writes, from a session's `snapshot()`."""
    preset: Preset = snapshot["preset"]
    params = snapshot["parameters"]
    return {
        "preset": preset.name, "display": preset.display, "topology": preset.topology, "layout": preset.layout,
        "start_weights": np.asarray(preset.weights, np.float32), "weights": snapshot["weights"],
        "controls": snapshot["controls"], "iteration": snapshot["iteration"], "smooth_dims": preset.smooth_dims,
        **{s.name: params[s.name] for s in session_file.kept_settings()},
        "metric_weights": np.asarray(params["metric_weights"], np.float32), "mirror": tuple(params["mirror"]),
        "radii": snapshot["radii"], "strokes": snapshot["strokes"], "smoothing_rule": snapshot["smoothing_rule"],
        "symmetry": group.spec if (group := snapshot["symmetry"]) is not None and group.kind == "radial" else "none",
    }


def export_stem(session_name: str) -> str:
    """The session's name as the start of a file name (its preset's, a loaded file's stem): letters, digits, "-",
    "_" and "." only."""
    return re.sub(r"[^A-Za-z0-9._-]+", "-", str(session_name).removeprefix("mesh:")).strip("-.")[:60] or "clay"


def export_name(session_name: str, ext: str, when: datetime.datetime | None = None) -> str:
    """The file an export or a save of a session is named: "<session>-<day>-<hhmm>.<ext>" ("sphere-2026-11-27-1042.obj",
    local time, default now), so two exports of a day do not collide. The web page names its downloads the same way
    from `export_stem` and the browser's clock (web/layout.py)."""
    stamp = f"{(when or datetime.datetime.now()):%Y-%m-%d-%H%M}"
    return f"{export_stem(session_name)}-{stamp}.{str(ext).lower().lstrip('.')}"


def read(path, max_vertices: int) -> dict:
    """A session file's state (session_file.load_session); ValueError naming the file and what is wrong."""
    return session_file.load_session(path, max_vertices=max_vertices, max_iterations=schedule.MAX_ITERATIONS)


def preset_of(state: dict) -> tuple[Preset, np.ndarray, int]:
    """(the start preset, the weights, s) a loaded session state describes; ValueError if it does not describe one."""
    try:
        preset = session_file.preset_from_session(state)
        weights = np.asarray(state["weights"], np.float32)
        iteration = int(state.get("iteration", 0))
    except (KeyError, TypeError) as exc:
        raise ValueError(f"session: missing or malformed entry ({exc})") from None
    if weights.shape != preset.weights.shape or not np.isfinite(weights).all():
        raise ValueError(f"session: weights have shape {weights.shape}, expected {preset.weights.shape}")
    return preset, weights, min(iteration, preset.iterations)


def check_variant(preset: Preset, controls, parameters: Mapping, weights):
    """(controls, schedule changes, weights) of a design variant checked against the mesh of `preset`; ValueError
    naming what does not fit."""
    w = checks.finite_array("weights", weights, 2)
    if w.shape != preset.weights.shape:
        raise ValueError(f"weights: expected shape {preset.weights.shape} (this session's mesh), got {w.shape}")
    n_dims = preset.layout.n_dims
    c = checks.finite_array("controls", controls, 2)
    if c.shape[1] != n_dims or not len(c):
        raise ValueError(f"controls: expected (k, {n_dims}) with k >= 1, got {c.shape}")
    unknown = sorted(set(parameters) - set(schedule.KEYS))
    if unknown:
        raise ValueError(f"parameters: unknown {unknown}; a variant sets some of {list(schedule.KEYS)}")
    return c, {name: schedule.BY_NAME[name].check(value) for name, value in parameters.items()}, w


class SessionFiles:
    """A session's files and the states it takes from elsewhere (see the module's docstring).

    build(preset) -> (preset, Som) on the session's device; install(built, hold): make it the session's (the caller
    records the undo step)."""

    def __init__(self, state: ModellingState, timeline: Timeline, build: Callable, install: Callable,
                 max_vertices: int) -> None:
        self.state = state
        self.timeline = timeline
        self.build = build
        self.install = install
        self.max_vertices = max_vertices

    def snapshot(self) -> dict:
        """A consistent copy of the session's state (for export and save): taken between training steps."""
        state = self.state
        with state.som_lock, state.lock:
            return {"preset": state.preset, "weights": np.asarray(state.som.weights, np.float32),
                    "controls": state.controls.copy(), "radii": state.radii.copy(), "symmetry": state.symmetry,
                    "strokes": tuple(state.strokes), "smoothing_rule": state.som.smoothing_rule,
                    "iteration": int(state.som.iteration), "parameters": state.parameters()}

    def session_state(self) -> dict:
        """The state session_file.save_session writes: the start mesh, the current weights, controls and settings."""
        return state_of(self.snapshot())

    def save(self, path) -> None:
        """Save the session (session_file.save_session: a versioned .npz, written whole or not at all)."""
        session_file.save_session(path, self.session_state())

    def load(self, path) -> None:
        """Load a session saved by `save` exactly as it was saved, training nothing until the next intent; one undo
        step. ValueError for a bad file, session unchanged. A setting the file lacks (declared since) takes its
        default."""
        self.restore(read(path, self.max_vertices))

    def restore(self, saved: dict) -> None:
        """Rebuild the session from a loaded session state: its start mesh, controls and settings, its weights and s
        exactly as saved, nothing training until the next intent. ValueError if the state does not describe a
        session."""
        preset, weights, iteration = preset_of(saved)
        built = self.build(preset)
        built[1].restore(weights, iteration)
        own = {s.name: s.check(saved.get(s.name, s.default)) for s in held_settings()
               if s.scope == "session" and s.saved}  # the session's own settings the file keeps
        with self.timeline.step("session"):
            self.install(built, hold=True)
            with self.state.lock:
                self.state.params.update(own)

    def export_mesh(self, path, units: str = mesh_io.DEFAULT_UNITS) -> None:
        """Write the current mesh (io.EXPORT_FORMATS by extension: OBJ, PLY, STL, glTF, GLB, .3dm) with its vertex
        colours, and its controls where the format keeps them (glTF / GLB nodes, .3dm points); a loaded mesh goes
        back in its file's original frame (io.load_mesh normalised it)."""
        snap = self.snapshot()
        preset = snap["preset"]
        mesh_io.export_mesh(path, snap["weights"], preset.topology, preset.layout, display=preset.display,
                            transform=preset.meta.get("transform"), controls=snap["controls"], radii=snap["radii"],
                            units=units)

    def export_name(self, ext: str) -> str:
        """The name a download of this session's export (or save) gets now: "sphere-2026-11-27-1042.obj"."""
        return export_name(self.state.preset.name, ext)

    def apply_variant(self, controls, parameters: dict, weights) -> None:
        """Make a design variant (somwidget.sweep) the current state: its controls, its schedule and its trained
        weights, at the end of its schedule, nothing training until the next intent; one undo step. ValueError if it
        does not fit this session's mesh."""
        c, checked, w = check_variant(self.state.preset, controls, parameters, weights)
        with self.timeline.step("variant"):
            self.timeline.jump(c, checked, w)
