"""One modelling session: the single source of truth that every view (web app, notebook, WebXR) shares.

A `Session` owns the clay (clay.py: the preset, its Som, the controls and parameters) and composes its parts: the
training thread (trainer.py), the frames it publishes (frames.py), the undo history (timeline.py), the autosave
(autosave.py) and the files (files.py). Views send *intents* (move control i, set a parameter, reset, train, pause,
load a preset) and receive *frames* through listeners:

    view --intent--> Session --Operation--> training thread (som.step(k)) --Frame--> every listener

Intents are validated in the caller's thread before anything changes: a bad index, NaN, inf or a wrong length
raises ValueError with a message and leaves the session as it was. A valid intent changes the session's own view at
once (so `session.controls` reflects it immediately) and queues an operation (operations.py) for the training
thread. Listeners run on the training thread: they must return quickly.

Clay rules (backend/som.py, Restarts): a control move, an added or removed control and a parameter change restart the
schedule locally (the Som's `reach`); `reset()` runs the whole schedule from the start mesh; a preset that grows (the
paper's case studies) runs its whole schedule when chosen, any other shape (a general shape, an uploaded mesh) is
shown as it is until the person acts; undo, redo, a loaded session and a recovered one put everything back exactly
and train nothing until the next intent.

This module must not import trame, pyvista or any other UI package.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import weakref
from pathlib import Path

import numpy as np

from ...backend import checks
from ...backend import presets as _presets
from ...backend.presets import FeatureLayout, Preset, parse_hex_colour, rgb_to_colour_dims
from ...backend.schedule import KEYS as SCHEDULE_KEYS
from ...backend.schedule import MAX_ITERATIONS
from ...backend.som import _MAX_TABLE_ENTRIES
from . import autosave as _autosave
from . import files
from .clay import GPU_MAX_VERTICES, Clay, build, default_mirror, max_vertices_for
from .frames import Frame, FrameListener, FrameStream
from .history import Step
from .operations import Publish, Reset, Restart, SetControls, SetMetricWeights, SetMirror, SetParameter
from .parameters import BY_NAME as _PARAM
from .parameters import METRIC_WEIGHT, SYMMETRY
from .timeline import Timeline
from .trainer import Trainer

log = logging.getLogger(__name__)

#: The engine's cap on its learning table, S x (d_max + 1) float32 entries (2 GiB): backend/som.py, _build_table.
MAX_TABLE_ENTRIES = _MAX_TABLE_ENTRIES
#: The engine's limit on effective controls (originals plus mirrored copies).
MAX_CONTROLS = _presets.MAX_CONTROLS
#: Largest |value| accepted for a control coordinate or feature.
MAX_ABS_VALUE = 1e6

_LIVE: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _close_live_sessions() -> None:
    """A process that ends normally closes its sessions cleanly (their autosaves go); a crash leaves them."""
    for session in list(_LIVE):
        try:
            session.close(timeout=2.0)
        except Exception:  # pragma: no cover - nothing must stop the exit
            pass


def _check_index(name: str, value, count: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer index, got {value!r}")
    i = int(value)
    if not 0 <= i < count:
        raise ValueError(f"{name}: index {i} is out of range (there are {count} controls: 0..{count - 1})")
    return i


class Session:
    """A live modelling session: one Som, its controls and a background training thread.

    preset:     a preset name (presets.PRESETS), a Preset, or None for "car"
    device:     Warp device for the Som: "auto"/None (best available), "cpu", "cuda", "cuda:N"
    frame_rate: frames per second the training thread aims at while training
    step_fraction: share of each frame interval spent in som.step (the rest is left to rendering)
    start:      start the training thread now (else call `start()`)
    paused:     begin paused (no training until `train()`)
    autosave:   keep each completed step on disk (autosave.py) so that `Session.recover()` can bring it back after a
                crash; False for a session nothing should outlive
    """

    def __init__(self, preset: str | Preset | None = "car", device: str | None = "auto", frame_rate: float = 60.0,
                 step_fraction: float = 0.6, start: bool = True, paused: bool = False,
                 max_vertices: int | None = None, autosave: bool = True):
        frame_rate = checks.real("frame_rate", frame_rate, 0.0, 1000.0, low_open=True)
        step_fraction = checks.real("step_fraction", step_fraction, 0.0, 1.0, low_open=True)
        self.device = "auto" if device is None else device
        if max_vertices is None:
            max_vertices = max_vertices_for(self.device)
        self.max_vertices = checks.integer_text("max_vertices", max_vertices, 1, GPU_MAX_VERTICES)
        self.recovered: dict | None = None  # set by `recover()`: where the state came from and when it was saved
        self.clay = Clay(*build(preset, self.device, self.max_vertices), paused=paused)
        self.frames = FrameStream(self.clay.wake)
        self.trainer = Trainer(self.clay, self.frames, self._make_frame, self._after_turn, frame_rate, step_fraction)
        self.timeline = Timeline(self.clay, self.trainer, self._rebuild, self._install_frame)
        self.frames.install(self._make_frame(0))
        self.autosave = (_autosave.SessionAutosave(self.clay, self.session_state, files.write, self._settled)
                         if autosave else None)
        _LIVE.add(self)
        if start:
            self.start()

    # -- parts -------------------------------------------------------------------------------------------------
    def _make_frame(self, cycles: int) -> Frame:
        """A frame of the Som now (quiescent: under the Som's lock, or before the thread starts)."""
        clay = self.clay

        def status() -> dict:  # read under the clay's lock with the frame's number
            if len(clay.applied_ids) != len(clay.som.controls):  # cannot happen: ids travel with their controls
                clay.applied_ids = clay.fresh_ids(len(clay.som.controls))
            return {"paused": clay.paused, "held": clay.hold, "applied": self.trainer.applied,
                    "history": self.timeline.counts, "control_ids": clay.applied_ids}

        return self.frames.make(clay.som, clay.preset, clay.generation, cycles=cycles,
                                cycle_time=self.trainer.cycle_time, status=status)

    def _install_frame(self) -> None:
        self.frames.install(self._make_frame(0))

    def _after_turn(self) -> None:
        if self.autosave is not None:
            self.autosave.if_due(self.trainer.closed)

    def _settled(self) -> bool:
        return not self.trainer.should_step() and not self.trainer.ops

    def _rebuild(self, preset: Preset) -> None:
        """Install `preset`'s Som (caller holds the Som's lock)."""
        built = build(preset, self.device, self.max_vertices)
        with self.clay.lock:
            self.clay.install(*built)
            self.trainer.reset_pace()

    def _replace(self, built: tuple[Preset, object], hold: bool = False) -> None:
        """Make a built preset and Som the session's (one undo step is the caller's)."""
        clay = self.clay
        with clay.som_lock, clay.lock:
            if self.trainer.closed:
                raise RuntimeError("session is closed")
            self.trainer.discard_queued()  # they belonged to the old mesh
            clay.install(*built)
            self.trainer.reset_pace()
            clay.hold = hold
            clay.error = None
            self._install_frame()  # `frame` matches `preset` at once; listeners get the next one
            self.trainer.enqueue(Publish())

    def _enqueue_controls(self, controls: np.ndarray) -> None:
        """Queue new controls (caller holds clay.lock); inside a drag they restart from the shape it began with."""
        self.trainer.enqueue(SetControls(controls, self.timeline.drag_anchor(), self.clay.control_ids))

    # -- lifetime ----------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the training thread (idempotent)."""
        self.trainer.start()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the training thread; the session accepts no more intents. A clean close: its autosave goes."""
        if not self.trainer.close(timeout):
            return
        _LIVE.discard(self)
        if self.autosave is not None:
            self.autosave.close()
        self.timeline.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def closed(self) -> bool:
        return self.trainer.closed

    @property
    def frame_rate(self) -> float:
        """Frames a second the training thread aims at while training."""
        return self.trainer.frame_rate

    @property
    def step_fraction(self) -> float:
        """The share of each frame interval spent in som.step."""
        return self.trainer.step_fraction

    # -- frames ------------------------------------------------------------------------------------------------
    def add_listener(self, callback: FrameListener, replay: bool = True) -> FrameListener:
        """Call `callback(frame)` for every new frame (on the training thread); replay the latest one now."""
        return self.frames.add_listener(callback, replay)

    def remove_listener(self, callback: FrameListener) -> None:
        self.frames.remove_listener(callback)

    @property
    def frame(self) -> Frame:
        """The latest frame."""
        return self.frames.latest

    @property
    def frames_per_second(self) -> float:
        """Frames published per second over the last few frames (0 when idle)."""
        return self.frames.per_second

    def wait_idle(self, timeout: float = 10.0) -> bool:
        """Block until every queued intent is applied and training has stopped (s = S or paused); False at the
        timeout, and at once if the training thread has stopped on an error (see `error`)."""
        return self.trainer.wait_idle(timeout)

    def wait_applied(self, timeout: float = 10.0) -> bool:
        """Block until every intent queued so far has reached the Som and a published frame shows it (`frame` then
        has it). An intent the engine refused counts as handled: `error` says why. False at the timeout, and at
        once if the training thread is not running (never started, closed, or stopped on an error)."""
        return self.trainer.wait_applied(timeout)

    # -- read-only state ---------------------------------------------------------------------------------------
    @property
    def preset(self) -> Preset:
        return self.clay.preset

    @property
    def layout(self) -> FeatureLayout:
        return self.clay.layout

    @property
    def topology(self):
        return self.clay.preset.topology

    @property
    def display(self) -> str:
        return self.clay.preset.display

    @property
    def generation(self) -> int:
        return self.clay.generation

    @property
    def controls(self) -> np.ndarray:
        """(k, n) the controls as the session holds them now (intents already applied here)."""
        with self.clay.lock:
            return self.clay.controls.copy()

    @property
    def n_controls(self) -> int:
        with self.clay.lock:
            return int(self.clay.controls.shape[0])

    @property
    def n_dims(self) -> int:
        return self.clay.layout.n_dims

    @property
    def parameters(self) -> dict:
        with self.clay.lock:
            return self.clay.parameters()

    @property
    def paused(self) -> bool:
        return self.clay.paused

    @property
    def error(self) -> str | None:
        """The latest failure (a refused intent, a failed step), or why the training thread stopped."""
        return self.trainer.thread_error or self.clay.error

    @property
    def training_device(self) -> str:
        """The Warp device the map trains on: "cpu" or "cuda:N" (what `device="auto"` chose)."""
        with self.clay.som_lock:
            return str(self.clay.som.device)

    @property
    def history(self) -> tuple[int, int]:
        """(undo steps, redo steps) available now."""
        with self.clay.lock:
            return self.timeline.counts

    @property
    def control_ids(self) -> tuple[int, ...]:
        """The stable id of each control, in index order (an id stays with its control; a new control gets a new
        one). Views hold controls by id (`index_of_control`), so a removal elsewhere cannot redirect a drag."""
        with self.clay.lock:
            return tuple(self.clay.control_ids)

    def index_of_control(self, control_id) -> int:
        """The index of the control with this id now; ValueError when it is gone (removed, or a preset, undo or
        load replaced the controls)."""
        if isinstance(control_id, bool) or not isinstance(control_id, (int, np.integer)):
            raise ValueError(f"control id: expected an integer, got {control_id!r}")
        with self.clay.lock:
            try:
                return self.clay.control_ids.index(int(control_id))
            except ValueError:
                raise ValueError(f"control {int(control_id)} no longer exists (it was removed, or the controls "
                                 "were replaced)") from None

    def state(self, positions: bool = False) -> dict:
        """A JSON-friendly summary (for debug routes and tests); `positions` adds every node's x, y, z."""
        frame, clay = self.frame, self.clay
        with clay.lock:
            controls, params, pending = clay.controls.copy(), clay.parameters(), len(self.trainer.ops)
        layout, preset = clay.layout, clay.preset
        out = {
            "preset": preset.name, "title": preset.title, "display": preset.display, "generation": frame.generation,
            "n_vertices": int(preset.n_vertices), "n_dims": layout.n_dims, "feature_names": list(layout.names),
            "position_dims": list(layout.position), "colour_dims": list(layout.colour),
            "colour_space": layout.colour_space, "controls": controls.tolist(), "parameters": params,
            "paused": clay.paused, "pending_intents": pending,
            "frame": {
                "seq": frame.seq, "iteration": frame.iteration, "iterations": frame.iterations,
                "running": frame.running, "cycle_time": frame.cycle_time,
                "controls": frame.controls.tolist(), "effective_controls": frame.effective_controls.tolist(),
                "gaps": frame.gaps.tolist(), "centroid": frame.positions.mean(axis=0).tolist(),
            },
            "frames_per_second": self.frames_per_second, "error": self.error,
            "history": list(frame.history), "held": frame.held, "recovered": self.recovered is not None,
        }
        if positions:
            out["frame"]["positions"] = frame.positions.tolist()
        return out

    # -- undo, redo and gestures -------------------------------------------------------------------------------
    def begin_gesture(self) -> None:
        """A gesture starts (a drag's press): the intents until `end_gesture()` make one undo step, recorded with
        the state before the first of them. A gesture left open (a tab closed mid-drag) ends at the next one."""
        self.timeline.begin_gesture()

    def end_gesture(self) -> None:
        """The gesture ends (a drag's release): the step is complete and goes to the autosave."""
        self.timeline.end_gesture()

    @contextlib.contextmanager
    def gesture(self):
        """`with session.gesture(): ...`: the intents inside make one undo step."""
        self.begin_gesture()
        try:
            yield self
        finally:
            self.end_gesture()

    def undo(self) -> bool:
        """Go back one step: controls, parameters, weights and s exactly as before it, nothing trains. False if
        there is no step to undo."""
        return self.timeline.undo()

    def redo(self) -> bool:
        """Go forward again after an undo, exactly; False if there is nothing to redo."""
        return self.timeline.redo()

    # -- intents: controls -------------------------------------------------------------------------------------
    def _check_controls(self, controls: np.ndarray, symmetry: bool | None = None) -> None:
        if symmetry is None:
            symmetry = self.clay.params["symmetry"]
        k = controls.shape[0]
        if k < 1:
            raise ValueError("controls: at least one control is needed")
        if k * (2 if symmetry else 1) > MAX_CONTROLS:
            raise ValueError(f"controls: at most {MAX_CONTROLS} controls counting mirrored copies; "
                             f"{k} controls{' with symmetry' if symmetry else ''} is too many")

    def _edit_control(self, step: str, index, edit, control_id=None) -> None:
        """One control's values changed by `edit(i, values) -> values` (caller's checks inside), as one step."""
        clay = self.clay
        with self.timeline.step(step), clay.lock:
            i = (_check_index("control", index, clay.controls.shape[0]) if control_id is None
                 else self.index_of_control(control_id))
            controls = clay.controls.copy()
            controls[i] = edit(i, controls[i].copy())
            clay.controls = controls
            self._enqueue_controls(controls.copy())

    def move_control(self, index: int | None, position, *, control_id: int | None = None) -> None:
        """Move control `index` to `position`: 3 numbers (x, y, z; the other features stay) or all n features."""
        layout = self.clay.layout

        def edit(i, values):
            n = layout.n_dims
            if hasattr(position, "__len__") and not isinstance(position, str) and len(position) == n:
                return checks.finite_vector(f"control {i}", position, n, MAX_ABS_VALUE)
            values[list(layout.position)] = checks.finite_vector(f"control {i} position", position, 3, MAX_ABS_VALUE)
            return values

        self._edit_control("controls", index, edit, control_id)

    def move_control_id(self, control_id, position) -> None:
        """`move_control` for the control with this id (ValueError when it is gone), in one step with the lookup:
        a control removed meanwhile cannot make the move edit another one."""
        self.move_control(None, position, control_id=control_id)

    def set_control_feature(self, index: int, dim: int, value) -> None:
        """Set one feature dim of control `index`."""
        layout = self.clay.layout

        def edit(i, values):
            d = checks.integer_text("feature dimension", dim, 0, layout.n_dims - 1)
            values[d] = checks.real(f"control {i} {layout.names[d]}", value, -MAX_ABS_VALUE, MAX_ABS_VALUE)
            return values

        self._edit_control("controls", index, edit)

    def set_control_colour(self, index: int, colour) -> None:
        """Set control `index`'s colour dims from an RGB triple in [0, 1] or a '#rrggbb' string."""
        rgb = parse_hex_colour(colour) if isinstance(colour, str) else colour
        layout = self.clay.layout

        def edit(_i, values):
            values[list(layout.colour)] = rgb_to_colour_dims(rgb, layout)
            return values

        self._edit_control("colour", index, edit)

    def set_controls(self, controls) -> None:
        """Replace every control: (k, n) finite values, 1 <= k (counting mirrored copies <= 256)."""
        arr = checks.finite_array("controls", controls, 2, np.float64)
        if np.abs(arr).max(initial=0.0) > MAX_ABS_VALUE:
            raise ValueError(f"controls: values must lie within +-{MAX_ABS_VALUE:g}")
        arr = arr.astype(np.float32)
        clay = self.clay
        with self.timeline.step("controls"), clay.lock:
            n = clay.layout.n_dims
            if arr.shape[1] != n:
                raise ValueError(f"controls: expected shape (k, {n}), got {arr.shape}")
            self._check_controls(arr)
            clay.controls = arr.copy()
            if len(arr) != len(clay.control_ids):
                clay.control_ids = clay.fresh_ids(len(arr))
            self._enqueue_controls(arr)

    def add_control(self, values=None) -> int:
        """Append a control (all n features; default: next to the last one); returns its index."""
        clay = self.clay
        with self.timeline.step("add"), clay.lock:
            if values is None:
                v = clay.controls[-1].copy()
                pos = self.frame.positions
                span = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0))) or 1.0
                v[clay.layout.position[2]] += 0.15 * span
            else:
                v = checks.finite_vector("new control", values, clay.layout.n_dims, MAX_ABS_VALUE)
            controls = np.concatenate([clay.controls, v[None, :]]).astype(np.float32)
            self._check_controls(controls)
            clay.controls = controls
            clay.control_ids = (*clay.control_ids, *clay.fresh_ids(1))
            self._enqueue_controls(controls.copy())
            return controls.shape[0] - 1

    def remove_control(self, index: int) -> None:
        clay = self.clay
        with self.timeline.step("remove"), clay.lock:
            i = _check_index("control", index, clay.controls.shape[0])
            if clay.controls.shape[0] <= 1:
                raise ValueError("controls: cannot remove the last control")
            clay.controls = np.delete(clay.controls, i, axis=0)
            clay.control_ids = clay.control_ids[:i] + clay.control_ids[i + 1:]
            self._enqueue_controls(clay.controls.copy())

    # -- intents: parameters -----------------------------------------------------------------------------------
    def set_parameter(self, name: str, value) -> None:
        """Set one of PARAMETERS (iterations or S, l_start, l_end, smoothing, reach, symmetry) or metric_weights.
        A schedule parameter restarts the schedule locally from the latest weights."""
        name = "iterations" if name == "S" else name
        if name == "symmetry":
            return self.set_symmetry(value)
        if name == "metric_weights":
            return self.set_metric_weights(value)
        if name not in _PARAM:
            raise ValueError(f"unknown parameter {name!r}; known: {', '.join((*_PARAM, 'metric_weights'))}")
        x = _PARAM[name].parse(value)
        with self.timeline.step(f"parameter:{name}"), self.clay.lock:
            if name == "iterations" and x > self.max_iterations:
                d_max = int(self.clay.preset.topology.d_max)
                raise ValueError(f"S (iterations): {x} is more than this mesh allows: at most {self.max_iterations}, "
                                 f"since the learning table S x (d_max + 1) = {x} x {d_max + 1} may hold at most "
                                 f"{MAX_TABLE_ENTRIES} entries")
            self.clay.params[name] = x
            self.trainer.enqueue(SetParameter(name, x))

    def set_iterations(self, value) -> None:
        """S: cycles in a run."""
        self.set_parameter("iterations", value)

    def set_l_start(self, value) -> None:
        self.set_parameter("l_start", value)

    def set_l_end(self, value) -> None:
        self.set_parameter("l_end", value)

    def set_smoothing(self, value) -> None:
        """lambda of one Laplacian step per cycle, in [0, 1]; 0 is off."""
        self.set_parameter("smoothing", value)

    def set_reach(self, value) -> None:
        """How far a moved control's pull reaches when the clay follows it: the neighbourhood radius a restart
        begins with, as a share of the whole mesh's (0, 1]; small keeps the rest of the shape, 1 regrows it all."""
        self.set_parameter("reach", value)

    def set_learning_rates(self, l_start, l_end) -> None:
        """l_start and l_end together, as one step."""
        a, b = _PARAM["l_start"].parse(l_start), _PARAM["l_end"].parse(l_end)
        with self.timeline.step("parameter:rates"), self.clay.lock:
            self.clay.params["l_start"], self.clay.params["l_end"] = a, b
            self.trainer.enqueue(SetParameter("l_start", a))
            self.trainer.enqueue(SetParameter("l_end", b))

    @property
    def max_iterations(self) -> int:
        """The largest S this mesh allows: MAX_ITERATIONS, or fewer where the engine's learning table
        S x (d_max + 1) would pass MAX_TABLE_ENTRIES (a mesh with a long grid diameter)."""
        d_max = int(self.clay.preset.topology.d_max)  # the Som's own d_max: sessions keep the dense table
        return min(MAX_ITERATIONS, MAX_TABLE_ENTRIES // (d_max + 1))

    def set_symmetry(self, value) -> None:
        """Mirror every control across the xz-plane (the preset's mirror dims) or not."""
        on = SYMMETRY.parse(value)
        clay = self.clay
        with self.timeline.step("parameter:symmetry"), clay.lock:
            self._check_controls(clay.controls, symmetry=on)
            clay.params["symmetry"] = on
            self.trainer.enqueue(SetMirror(clay.mirror_dims if on else ()))

    def set_metric_weights(self, value) -> None:
        """One weight >= 0 per feature dim (at least one positive) for the winner search."""
        clay = self.clay
        with self.timeline.step("parameter:metric_weights"), clay.lock:
            m = checks.finite_vector("metric_weights", value, clay.layout.n_dims, MAX_ABS_VALUE)
            if (m < 0).any():
                raise ValueError(f"metric_weights: weights must be >= 0, got {m.tolist()}")
            if not (m > 0).any():
                raise ValueError("metric_weights: at least one weight must be positive")
            clay.params["metric_weights"] = [float(x) for x in m]
            self.trainer.enqueue(SetMetricWeights(m))

    def set_metric_weight(self, dim: int, value) -> None:
        clay = self.clay
        with clay.lock:
            d = checks.integer_text("feature dimension", dim, 0, clay.layout.n_dims - 1)
            m = list(clay.params["metric_weights"])
            m[d] = METRIC_WEIGHT.check(value, f"{METRIC_WEIGHT.label} of {clay.layout.names[d]}")
        self.set_metric_weights(m)

    # -- intents: run control ----------------------------------------------------------------------------------
    def train(self) -> None:
        """Resume training. A settled run (s = S) or a held state restarts locally from the latest weights (one
        undo step: the shape changes)."""
        clay = self.clay
        with clay.lock:
            restart = clay.som.iteration >= clay.som.iterations and not self.trainer.ops
        with contextlib.ExitStack() as stack:
            if restart:
                stack.enter_context(self.timeline.step("train"))
            with clay.lock:
                clay.paused = False
                clay.error = None
                if restart:
                    self.trainer.enqueue(Restart())
                else:
                    clay.hold = False
                    self.trainer.enqueue(Publish())

    def pause(self) -> None:
        with self.clay.lock:
            self.clay.paused = True
            self.trainer.enqueue(Publish())

    def reset(self) -> None:
        """Back to the start mesh and s = 0: the whole schedule runs again; the controls stay."""
        with self.timeline.step("reset"), self.clay.lock:
            self.trainer.enqueue(Reset())

    # -- intents: whole session --------------------------------------------------------------------------------
    def load_preset(self, preset: str | Preset) -> None:
        """Replace the mesh, layout, controls and parameters with a preset (a name or a Preset): one undo step. A
        preset that grows (the paper's case studies) runs its whole schedule; any other shape is shown as it is.
        Choosing the current preset again brings back its own controls and start.

        The new Som is built in the caller's thread (this can take a while for a big mesh); a failure leaves the
        session as it was.
        """
        if isinstance(preset, str) and preset not in _presets.PRESETS:
            raise ValueError(f"unknown preset {preset!r}; known presets: {', '.join(_presets.PRESETS)}")
        built = build(preset, self.device, self.max_vertices)
        with self.timeline.step("preset"):
            self._replace(built)

    def load_mesh(self, path) -> Preset:
        """Load a mesh file (io.load_mesh) as the new start mesh, shown as it is with controls on it; ValueError for
        a bad file, session unchanged."""
        from ...backend import io as sw_io

        preset = sw_io.load_mesh(path, max_vertices=self.max_vertices)
        preset.name = f"mesh:{preset.name}"  # never mistaken for a built-in preset of the same name
        self.load_preset(preset)
        return preset

    def snapshot(self) -> dict:
        """A consistent copy of the session's state (for export and save): taken between training steps."""
        clay = self.clay
        with clay.som_lock, clay.lock:
            return {"preset": clay.preset, "weights": np.asarray(clay.som.weights, np.float32),
                    "controls": clay.controls.copy(), "iteration": int(clay.som.iteration),
                    "parameters": clay.parameters()}

    def session_state(self) -> dict:
        """The state io.save_session writes: the start mesh, the current weights, controls and parameters."""
        return files.state_of(self.snapshot())

    def export_mesh(self, path) -> None:
        """Write the current mesh (OBJ, PLY, GLB by extension) with its vertex colours (io.export_mesh). A loaded
        mesh is written back in its file's original frame (io.load_mesh normalised it)."""
        files.export_mesh(path, self.snapshot())

    def save(self, path) -> None:
        """Save the session (io.save_session, a versioned .npz)."""
        files.write(path, self.session_state())

    def load(self, path) -> None:
        """Load a session saved by `save` exactly as it was saved, training nothing until the next intent; one undo
        step. ValueError for a bad file, session unchanged."""
        self.restore(files.read(path, self.max_vertices))

    def restore(self, state: dict) -> None:
        """Rebuild the session from a loaded session state: its start mesh, controls and settings, its weights
        and s exactly as saved, nothing training until the next intent. ValueError if the state does not describe
        a session."""
        preset, weights, iteration = files.preset_of(state)
        built = build(preset, self.device, self.max_vertices)
        built[1].restore(weights, iteration)
        with self.timeline.step("session"):
            self._replace(built, hold=True)

    def apply_variant(self, controls, parameters: dict, weights) -> None:
        """Make a design variant (somwidget.sweep) the current state: its controls, its schedule (iterations,
        l_start, l_end, smoothing, reach) and its trained weights, at the end of its schedule, nothing training
        until the next intent; one undo step. ValueError if it does not fit this session's mesh."""
        clay = self.clay
        w = checks.finite_array("weights", weights, 2)
        if w.shape != clay.preset.weights.shape:
            raise ValueError(f"weights: expected shape {clay.preset.weights.shape} (this session's mesh), got "
                             f"{w.shape}")
        c = checks.finite_array("controls", controls, 2)
        if c.shape[1] != self.n_dims or not len(c):
            raise ValueError(f"controls: expected (k, {self.n_dims}) with k >= 1, got {c.shape}")
        unknown = sorted(set(parameters) - set(SCHEDULE_KEYS))
        if unknown:
            raise ValueError(f"parameters: unknown {unknown}; a variant sets some of {list(SCHEDULE_KEYS)}")
        checked = {name: _PARAM[name].check(value) for name, value in parameters.items()}
        with self.timeline.step("variant"):
            with clay.som_lock:
                self.trainer.drain()
                with clay.lock:
                    params = dict(clay.capture().parameters, **checked)
                self.timeline.put_back(Step(preset=clay.preset, controls=c, parameters=params, weights=w,
                                            iteration=params["iterations"]))
            with clay.lock:
                self.trainer.enqueue(Publish(), intent=False)

    # -- autosave and recovery ---------------------------------------------------------------------------------
    @property
    def autosave_path(self) -> Path | None:
        """Where this session's latest state is kept while it lives (None without autosave)."""
        return None if self.autosave is None else self.autosave.path

    def flush_autosave(self, timeout: float = 10.0) -> bool:
        """Write the current state to the autosave now and wait until it is on disk; False at the timeout or
        without autosave."""
        return False if self.autosave is None else self.autosave.flush(timeout)

    @classmethod
    def recover(cls, **options) -> Session | None:
        """The session of the latest exit that did not close cleanly (a crash, a kill), restored exactly as its
        autosave left it (nothing trains until the next intent); None if there is none. `options` go to Session
        (device, start...). Its autosave is taken over: it is deleted once the new session has saved its own."""
        start = options.pop("start", True)
        max_vertices = options.get("max_vertices") or max_vertices_for(options.get("device"))
        for path in _autosave.crashed():
            try:
                state = files.read(path, max_vertices)
                preset, weights, iteration = files.preset_of(state)
                saved = path.stat().st_mtime
            except (ValueError, OSError) as exc:
                log.warning("autosave %s cannot be read (%s): discarded", path, exc)
                _autosave.discard(path)
                continue
            session = cls(preset, start=False, **options)
            clay = session.clay
            with clay.som_lock, clay.lock:  # weights and s into the Som of its preset, which holds the rest
                clay.som.restore(weights, iteration)
                clay.hold = True
                session._install_frame()
            session.recovered = {"path": str(path), "saved": saved, "preset": state["preset"]}
            session.flush_autosave()
            _autosave.discard(path)
            if start:
                session.start()
            return session
        return None


__all__ = ["Frame", "Session", "default_mirror", "max_vertices_for"]
