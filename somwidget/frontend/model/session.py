"""One modelling session: the single source of truth that every view (web app, notebook, WebXR) shares.

A `Session` owns the clay (clay.py: the preset, its Som, the controls and parameters) and composes its parts: the
training thread (trainer.py), the frames it publishes (frames.py), the undo history (timeline.py), the autosave
(autosave.py: each completed step and the history in the session's folder, store.py) and the files (files.py).
Views send *intents* (move control i, set a parameter, reset, train, pause, load a preset) and receive *frames*
through listeners:

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
from ...backend.presets import FeatureLayout, Preset
from . import autosave as _autosave
from . import files
from . import store as _store
from .clay import GPU_MAX_VERTICES, Clay, build, max_vertices_for
from .frames import Frame, FrameListener, FrameStream
from .controls import ControlEdits
from .hands import Hand, Hands, redo_own, undo_own
from .operations import Publish, Reset, Restart
from .refining import refined_preset
from .settings import ParameterEdits
from .summary import summary
from .timeline import Timeline
from .trainer import Trainer
from .variants import check_variant

log = logging.getLogger(__name__)

_LIVE: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _close_live_sessions() -> None:
    """A process that ends normally closes its sessions: what changed since their last save is written."""
    for session in list(_LIVE):
        try:
            session.close(timeout=2.0)
        except Exception:  # pragma: no cover - nothing must stop the exit
            pass


class Session:
    """A live modelling session: one Som, its controls and a background training thread.

    preset:     a preset name (presets.PRESETS), a Preset, or None for "car"
    device:     Warp device for the Som: "auto"/None (best available), "cpu", "cuda", "cuda:N"
    frame_rate: frames per second the training thread aims at while training
    step_fraction: share of each frame interval spent in som.step (the rest is left to rendering)
    start:      start the training thread now (else call `start()`)
    paused:     begin paused (no training until `train()`)
    autosave:   keep each completed step and the undo history on disk (autosave.py), so that `Session.recover()`
                brings the session back however it stopped; False for a session nothing should outlive
    origin:     what made the session, kept with its autosave: `Session.recover(origin=...)` takes only those
                (`somwidget serve` makes and recovers "serve" sessions)
    """

    def __init__(self, preset: str | Preset | None = "car", device: str | None = "auto", frame_rate: float = 60.0,
                 step_fraction: float = 0.6, start: bool = True, paused: bool = False,
                 max_vertices: int | None = None, autosave: bool = True, origin: str = "python", *, _store=None):
        frame_rate = checks.real("frame_rate", frame_rate, 0.0, 1000.0, low_open=True)
        step_fraction = checks.real("step_fraction", step_fraction, 0.0, 1.0, low_open=True)
        self.device = "auto" if device is None else device
        if max_vertices is None:
            max_vertices = max_vertices_for(self.device)
        self.max_vertices = checks.integer_text("max_vertices", max_vertices, 1, GPU_MAX_VERTICES)
        self.recovered: dict | None = None  # set by `recover()`: where the state came from, when, and its "message"
        self.notices: list[str] = []  # what went wrong with the saved sessions (set aside, unreadable), to show
        self.clay = Clay(*build(preset, self.device, self.max_vertices), paused=paused)
        self.frames = FrameStream(self.clay.wake)
        self.trainer = Trainer(self.clay, self.frames, self._make_frame, self._after_turn, frame_rate, step_fraction)
        store = _store if _store is not None or not autosave else _store_for(origin, self.notices)
        self.timeline = Timeline(self.clay, self.trainer, self._rebuild, self._install_frame, shelf=store)
        self.hands = Hands(self.clay, self.timeline)  # who is on the session and what each holds (hands.py)
        self.edit_controls = ControlEdits(self.clay, self.timeline, self.trainer, self.frames, self.hands)
        self.edit_parameters = ParameterEdits(self.clay, self.timeline, self.trainer)
        self.frames.install(self._make_frame(0))
        self.autosave = None if store is None else _autosave.SessionAutosave(
            self.clay, store, self._saving, lambda: not self.trainer.ops, self._settled, self.trainer.drain,
            self._publish)
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
                    "history": self.timeline.counts, "control_ids": clay.applied_ids,
                    "group": clay.symmetry.spec if clay.symmetry is not None else "none"}

        return self.frames.make(clay.som, clay.preset, clay.generation, cycles=cycles,
                                cycle_time=self.trainer.cycle_time, status=status)

    def _install_frame(self) -> None:
        self.frames.install(self._make_frame(0))

    def _after_turn(self) -> None:
        self.hands.prune()  # grabs of controls that are gone end
        if self.autosave is not None and not self.trainer.closed:
            self.autosave.if_due()

    def _saving(self) -> _store.Saving:
        """What the autosave writes now (caller holds both locks, no intent queued)."""
        undo, redo = self.timeline.steps()
        return _store.Saving(self.clay.capture(), undo, redo, gesture=self.timeline.gesture_recorded)

    def _publish(self) -> None:
        """A frame for every view now (the autosave's status changed: the views show it)."""
        with self.clay.lock:
            if not self.trainer.closed:
                self.trainer.enqueue(Publish(), intent=False)

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
            clay.paused = False  # a new clay starts by its own rule (a case study grows, a shape waits), never paused
            clay.error = None
            self._install_frame()  # `frame` matches `preset` at once; listeners get the next one
            self.trainer.enqueue(Publish())

    # -- lifetime ----------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the training thread (idempotent)."""
        self.trainer.start()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the training thread; the session accepts no more intents. What changed since the last save is
        written (for up to `timeout` seconds), and the session's folder stays for `Session.recover()`."""
        if not self.trainer.close(timeout):
            return
        _LIVE.discard(self)
        if self.autosave is not None:
            self.autosave.close(timeout)
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
    def save_error(self) -> str | None:
        """Why the autosave cannot write now (what and where; it tries again every second), None while it works."""
        return None if self.autosave is None else self.autosave.error

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
        return self.edit_controls.index_of(control_id)

    def state(self, positions: bool = False) -> dict:
        """A JSON-friendly summary (for debug routes and tests); `positions` adds every node's x, y, z."""
        return summary(self, positions)

    # -- undo, redo and gestures -------------------------------------------------------------------------------
    def begin_gesture(self) -> None:
        """Python's gesture starts: its intents until `end_gesture()` make one undo step, whatever the views do
        meanwhile (each view's drag is a gesture of its own: hands.py), and the controls it changes are held by
        Python until it ends. A gesture left open ends at the next one."""
        self.hands.begin_script()

    def end_gesture(self) -> None:
        """Python's gesture ends: the step is complete and goes to the autosave."""
        self.hands.end_script()

    @contextlib.contextmanager
    def gesture(self):
        """`with session.gesture(): ...`: the intents inside make one undo step."""
        self.begin_gesture()
        try:
            yield self
        finally:
            self.end_gesture()

    def undo(self, hand: Hand | None = None) -> bool:
        """Go back one step: controls, parameters, weights and s exactly as before it, nothing trains. False if
        there is no step to undo. `hand` (a view's, hands.py): that person's own latest step first."""
        return self.timeline.undo() if hand is None else undo_own(self, hand)

    def redo(self, hand: Hand | None = None) -> bool:
        """Go forward again after an undo, exactly; False if there is nothing to redo. `hand`: after that person's
        undo of an older step, that undo is taken back."""
        return self.timeline.redo() if hand is None else redo_own(self, hand)

    def submit(self, call):
        """Run `call()` on the training thread between two steps (a server's event loop never waits for the Som's
        lock); returns a concurrent.futures.Future of its result."""
        return self.trainer.post(call)

    # -- intents: controls -------------------------------------------------------------------------------------
    def move_control(self, index: int | None, position, *, control_id: int | None = None) -> None:
        """Move control `index` to `position`: 3 numbers (x, y, z; the other features stay) or all n features."""
        self.edit_controls.move(index, position, control_id)

    def move_control_id(self, control_id, position) -> None:
        """`move_control` for the control with this id (ValueError when it is gone), in one step with the lookup:
        a control removed meanwhile cannot make the move edit another one."""
        self.edit_controls.move(None, position, control_id)

    def set_control_feature(self, index: int, dim: int, value) -> None:
        """Set one feature dim of control `index`."""
        self.edit_controls.set_feature(index, dim, value)

    def set_control_colour(self, index: int, colour) -> None:
        """Set control `index`'s colour dims from an RGB triple in [0, 1] or a '#rrggbb' string."""
        self.edit_controls.set_colour(index, colour)

    def set_controls(self, controls, radii=None) -> None:
        """Replace every control: (k, n) finite values, 1 <= k (counting symmetric copies <= 256), and their radii
        (None: kept where the count stays, else the preset's radius for all)."""
        self.edit_controls.replace(controls, radii)

    def add_control(self, values=None, radius: float | None = None) -> int:
        """Append a control where it is placed: all n features, or a position (x, y, z) whose other features are the
        nearest node's; None puts it on the clay's node farthest from the other controls. Its radius of influence in
        model units (None: the preset's, 0 for the case studies). It moves nothing until it is dragged: the clay keeps
        its weights and s. Returns its index."""
        return self.edit_controls.add(values, radius)

    def add_stroke(self, points, radius: float | None = None) -> int:
        """A polyline (m >= 2 points of x, y, z, or all n features) as one control: its samples, spaced evenly along
        it, pull the clay along its length and act as one (they move, are removed, undone and mirrored together);
        radius as for a control (None: the preset's). Returns the index of its first sample."""
        return self.edit_controls.add_stroke(points, radius)

    @property
    def strokes(self) -> tuple[int, ...]:
        """The lengths of the runs of controls that act as one (a stroke's samples), in index order."""
        with self.clay.lock:
            return tuple(self.clay.strokes)

    def set_control_radius(self, index: int | None, radius: float) -> None:
        """Control `index`'s radius of influence (model units; 0: the paper's point control), or every control's
        with `index` None: moving it then carries the clay around its winner with a smooth falloff of about that
        radius. Set again within a moment (a slider's drag), it joins the same undo step."""
        self.edit_controls.set_radius(index, radius)

    @property
    def radii(self) -> np.ndarray:
        """(k,) each control's radius of influence as the session holds it now."""
        with self.clay.lock:
            return self.clay.radii.copy()

    @property
    def symmetry(self):
        """The symmetry group in effect (a `Symmetry`), or None."""
        return self.clay.symmetry

    def remove_control(self, index: int) -> None:
        self.edit_controls.remove(index)

    # -- intents: parameters -----------------------------------------------------------------------------------
    def set_parameter(self, name: str, value) -> None:
        """Set one of the parameters (parameters.py: iterations or S, l_start, l_end, smoothing, reach, symmetry)
        or metric_weights. A schedule parameter restarts the schedule locally from the latest weights."""
        self.edit_parameters.set(name, value)

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
        self.edit_parameters.set_learning_rates(l_start, l_end)

    def set_symmetry(self, value) -> None:
        """A symmetry group for the controls: a `Symmetry` (Symmetry.mirror(axis), Symmetry.radial(n, axis,
        mirror=)), its spec ("radial-8-z"), None or False (off), True (on: the last group, else the preset's mirror).
        Every copy of a control acts together with it. Turned off, the copies become controls of their own and
        nothing moves; turned on, controls that are each other's images pair up again without moving."""
        self.edit_parameters.set_symmetry(value)

    def set_metric_weights(self, value) -> None:
        """One weight >= 0 per feature dim (at least one positive) for the winner search."""
        self.edit_parameters.set_metric_weights(value)

    def set_metric_weight(self, dim: int, value) -> None:
        self.edit_parameters.set_metric_weight(dim, value)

    @property
    def max_iterations(self) -> int:
        """The largest S this mesh allows: MAX_ITERATIONS, or fewer where the engine's learning table
        S x (d_max + 1) would pass MAX_TABLE_ENTRIES (a mesh with a long grid diameter)."""
        return self.edit_parameters.max_iterations

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
        Either way a Pause does not carry over. Choosing the current preset again brings back its own controls and
        start.

        The new Som is built in the caller's thread (this can take a while for a big mesh); a failure leaves the
        session as it was.
        """
        if isinstance(preset, str) and preset not in _presets.PRESETS:
            raise ValueError(f"unknown preset {preset!r}; known presets: {', '.join(_presets.PRESETS)}")
        built = build(preset, self.device, self.max_vertices)
        with self.timeline.step("preset"):
            self._replace(built)

    def refine(self, stretched: float | None = None) -> int:
        """Subdivide the clay, its shape kept (backend/refine.py): every face split at its edges' midpoints, or with
        `stretched` (a factor, e.g. 2) only the edges longer than that times the median edge. The controls, their
        radii, the symmetry and the schedule stay; the distances follow the new mesh; nothing trains until the next
        intent. One undo step; returns the new node count. ValueError for a clay without faces or one that would
        pass this session's vertex limit."""
        refined = refined_preset(self.snapshot(), stretched, self.max_vertices)
        built = build(refined, self.device, self.max_vertices)
        with self.timeline.step("refine"):
            self._replace(built, hold=True)
        return refined.n_vertices

    def load_mesh(self, path, decimate: bool = False) -> Preset:
        """Load a mesh file (io.load_mesh) as the new start mesh, shown as it is with controls on it; ValueError for
        a bad file (io.TooManyVertices for one past this session's limit: `decimate` loads it coarsened to the limit),
        session unchanged."""
        from ...backend import io as sw_io

        preset = sw_io.load_mesh(path, max_vertices=self.max_vertices, decimate=decimate)
        preset.name = f"mesh:{preset.name}"  # never mistaken for a built-in preset of the same name
        self.load_preset(preset)
        return preset

    def snapshot(self) -> dict:
        """A consistent copy of the session's state (for export and save): taken between training steps."""
        clay = self.clay
        with clay.som_lock, clay.lock:
            return {"preset": clay.preset, "weights": np.asarray(clay.som.weights, np.float32),
                    "controls": clay.controls.copy(), "radii": clay.radii.copy(), "symmetry": clay.symmetry,
                    "strokes": tuple(clay.strokes),
                    "smoothing_rule": clay.som.smoothing_rule, "iteration": int(clay.som.iteration),
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
        c, checked, w = check_variant(self.clay.preset, controls, parameters, weights)
        with self.timeline.step("variant"):
            self.timeline.jump(c, checked, w)

    # -- autosave and recovery ---------------------------------------------------------------------------------
    @property
    def autosave_path(self) -> Path | None:
        """The folder this session's steps and history are kept in (store.py; None without autosave)."""
        return None if self.autosave is None else self.autosave.path

    def flush_autosave(self, timeout: float = 10.0) -> bool:
        """Write the current state to the autosave now and wait until it is on disk; False at the timeout, while
        saves fail, or without autosave."""
        return False if self.autosave is None else self.autosave.flush(timeout)

    @classmethod
    def recover(cls, origin: str | None = "python", **options) -> Session | None:
        """The session that stopped last (however it stopped: closed, interrupted, killed, crashed), of `origin`
        ("python": made from Python, a notebook's included; "serve": `somwidget serve`'s; None: any), brought back
        as its autosave left it: its last completed step (or a drag not released, as a step of its own) with its
        undo history; nothing trains until the next intent. None if there is none. `session.recovered["message"]`
        says which state came back. `options` go to Session (device, start...). It goes on saving in the same
        folder. A saved session that cannot be read is set aside (renamed, never deleted; `session.notices` and the
        log say where) and the next one tried."""
        session, notices = _autosave.recover(cls, origin, **options)
        for notice in notices:
            log.warning("%s", notice)
        return session

    def _bring_back(self, saved) -> None:
        """Put a session read from its folder in place (its preset is the installed one): the current step exactly,
        held, and its undo and redo steps."""
        clay = self.clay
        with clay.som_lock:
            self.timeline.put_back(saved.current)
            with clay.lock:
                self.timeline.history.restore(saved.undo, saved.redo)
                clay.unsaved = True
                self._install_frame()


def _store_for(origin: str, notices: list[str]) -> _store.SessionStore:
    """A new session's folder (made with its first save), after the stopped sessions past the bounds are pruned."""
    store = _store.SessionStore.new(origin)
    try:
        store.open(notices)
    except OSError as exc:  # the autosave says so, and tries again
        log.warning("autosave: cannot make %s (%s); trying again with each save", store.folder, exc.strerror or exc)
    _store.prune()
    return store


__all__ = ["Frame", "Session"]
