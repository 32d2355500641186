"""One modelling session: the single source of truth that every view (web app, notebook, WebXR) shares.

A `Session` owns the modelling state (state.py: the preset, its Som, the controls and settings, shared with its
training thread) and hands out its parts by role:

    session.history        undo, redo and gestures (timeline.py); read as a tuple: (undo steps, redo steps)
    session.settings       the settings, declared in backend/schedule.py (settings.py)
    session.control_edits  the controls: move, add, stroke, radius, remove, replace (controls.py)
    session.files          save, load, export, snapshots, design variants put in place (files.py)
    session.autosave       each completed step and the history on disk (autosave.py, store.py), or None
    session.frames         what the views draw (frames.py), published by the training thread (trainer.py)

Views send *intents* (move control i, set a setting, reset, train, pause, load a preset) and receive *frames*
through listeners:

    view --intent--> Session --Operation--> training thread (som.step(k)) --Frame--> every listener

The session itself keeps the intents a view or a script calls most (the README's, the views' wire) as short calls
of its parts. Intents are validated in the caller's thread before anything changes: a bad index, NaN, inf or a
wrong length raises ValueError with a message and leaves the session as it was. A valid intent changes the session's
own view at once (so `session.controls` reflects it immediately) and queues an operation (operations.py) for the
training thread. Listeners run on the training thread: they must return quickly.

Clay rules (backend/som.py, Restarts): a control move, an added or removed control and a setting change restart the
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

import numpy as np

from ...backend import checks
from ...backend import io as mesh_io
from ...backend import presets as _presets
from ...backend.presets import Preset
from . import revolving
from .autosave import SessionAutosave
from .controls import ControlEdits
from .files import SessionFiles
from .frames import Frame, FrameListener, FrameStream
from .hands import Hand, Hands, redo_own, undo_own
from .operations import Publish, Reset, Restart
from .recovery import recover as recover_session
from .refining import refined_preset
from .settings import SessionSettings
from .state import GPU_MAX_VERTICES, ModellingState, build, max_vertices_for
from .store import SessionStore, prune
from .summary import summary
from .timeline import SessionHistory, Timeline
from .trainer import Trainer

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



def _of_modelling(name: str, doc: str) -> property:
    """Session.<name>: the modelling state's value of that name (session.modelling), read only."""
    return property(lambda session: getattr(session.modelling, name), doc=doc)


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
        self.modelling = ModellingState(*self._build(preset), paused=paused)
        self.frames = FrameStream(self.modelling.wake)
        self.trainer = Trainer(self.modelling, self.frames, self._make_frame, self._after_turn, frame_rate,
                               step_fraction)
        store = _store if _store is not None or not autosave else _store_for(origin, self.notices)
        self.timeline = Timeline(self.modelling, self.trainer, self._rebuild, self._install_frame, shelf=store)
        self.hands = Hands(self.modelling, self.timeline)  # who is on the session and what each holds (hands.py)
        self.control_edits = ControlEdits(self.modelling, self.timeline, self.trainer, self.frames, self.hands)
        self.settings = SessionSettings(self.modelling, self.timeline, self.trainer)
        self.files = SessionFiles(self.modelling, self.timeline, self._build, self._install, self.max_vertices)
        self.frames.install(self._make_frame(0))
        self.autosave = None if store is None else SessionAutosave(self.modelling, store, self.timeline,
                                                                              self.trainer)
        _LIVE.add(self)
        if start:
            self.start()

    # -- what the parts call back ------------------------------------------------------------------------------
    def _make_frame(self, cycles: int, weights: np.ndarray | None = None, colours: np.ndarray | None = None) -> Frame:
        """A frame of the Som now (quiescent: under the Som's lock, or before the thread starts); `weights`: the Som's
        weights where a batch holds them (a studio's room), `colours` their nodes' colours if made already."""
        state = self.modelling

        def status() -> dict:  # read under the state lock with the frame's number
            if len(state.applied_ids) != len(state.som.controls):  # cannot happen: ids travel with their controls
                state.applied_ids = state.fresh_ids(len(state.som.controls))
            return {"paused": state.paused, "held": state.hold, "applied": self.trainer.applied,
                    "history": self.timeline.counts, "control_ids": state.applied_ids,
                    "group": state.symmetry.spec if state.symmetry is not None else "none"}

        return self.frames.make(state.som, state.preset, state.generation, cycles=cycles,
                                cycle_time=self.trainer.cycle_time, status=status, weights=weights,
                                colours=colours)

    def _install_frame(self) -> None:
        self.frames.install(self._make_frame(0))

    def _after_turn(self) -> None:
        self.hands.prune()  # grabs of controls that are gone end
        if self.autosave is not None and not self.trainer.closed:
            self.autosave.if_due()

    def _build(self, preset: str | Preset | None) -> tuple[Preset, object]:
        """(preset, its Som) on this session's device, within its vertex limit."""
        return build(preset, self.device, self.max_vertices)

    def _rebuild(self, preset: Preset) -> None:
        """Install `preset`'s Som (caller holds the Som's lock)."""
        built = self._build(preset)
        with self.modelling.lock:
            self.modelling.install(*built)
            self.trainer.reset_pace()

    def _install(self, built: tuple[Preset, object], hold: bool = False) -> None:
        """Make a built preset and Som the session's (one undo step is the caller's)."""
        state = self.modelling
        with state.som_lock, state.lock:
            if self.trainer.closed:
                raise RuntimeError("session is closed")
            self.trainer.discard_queued()  # they belonged to the old mesh
            state.install(*built)
            self.trainer.reset_pace()
            state.hold = hold
            state.paused = False  # a new clay starts by its own rule (a case study grows, a shape waits), never paused
            state.error = None
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

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self.trainer.closed

    # -- frames ------------------------------------------------------------------------------------------------
    def add_listener(self, callback: FrameListener, replay: bool = True) -> FrameListener:
        """Call `callback(frame)` for every new frame (on the training thread); replay the latest one now."""
        return self.frames.add_listener(callback, replay)

    def remove_listener(self, callback: FrameListener) -> None:
        self.frames.remove_listener(callback)

    @property
    def frame(self) -> Frame:
        """The latest frame."""
        return self.frames.latest  # __init__ installs the first

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
    preset = _of_modelling("preset", "The Preset the session started from (its mesh, controls and schedule).")
    layout = _of_modelling("layout", "The FeatureLayout: what each feature dim means (position, colour, ...).")
    generation = _of_modelling("generation", "Counts the clays: a new preset, mesh, refine or load makes the next.")
    paused = _of_modelling("paused", "Whether training is paused (`pause`, `train`).")
    topology = property(lambda self: self.modelling.preset.topology, doc="The mesh's Topology (its neurons' graph).")
    n_dims = property(lambda self: self.modelling.layout.n_dims, doc="n: the feature dims of every node and control.")

    @property
    def controls(self) -> np.ndarray:
        """(k, n) the controls as the session holds them now (intents already applied here)."""
        with self.modelling.lock:
            return self.modelling.controls.copy()

    @property
    def n_controls(self) -> int:
        """k, read without the lock: a server's event loop checks every intent with it and must never wait."""
        return int(self.modelling.controls.shape[0])

    @property
    def parameters(self) -> dict:
        """Every setting held by name (`settings.values()`)."""
        return self.settings.values()

    @property
    def error(self) -> str | None:
        """The latest failure (a refused intent, a failed step), or why the training thread stopped."""
        return self.trainer.thread_error or self.modelling.error

    @property
    def save_error(self) -> str | None:
        """Why the autosave cannot write now (what and where; it tries again every second), None while it works."""
        return None if self.autosave is None else self.autosave.error

    @property
    def training_device(self) -> str:
        """The Warp device the map trains on: "cpu" or "cuda:N" (what `device="auto"` chose)."""
        with self.modelling.som_lock:
            return str(self.modelling.som.device)

    @property
    def control_ids(self) -> tuple[int, ...]:
        """The stable id of each control, in index order (an id stays with its control; a new control gets a new
        one). Views hold controls by id (`index_of_control`), so a removal elsewhere cannot redirect a drag."""
        with self.modelling.lock:
            return tuple(self.modelling.control_ids)

    def index_of_control(self, control_id) -> int:
        """The index of the control with this id now; ValueError when it is gone (removed, or a preset, undo or
        load replaced the controls)."""
        return self.control_edits.index_of(control_id)

    def state(self, positions: bool = False) -> dict:
        """A JSON-friendly summary (for debug routes and tests); `positions` adds every node's x, y, z."""
        return summary(self, positions)

    # -- undo, redo and gestures (session.history) ---------------------------------------------------------------
    @property
    def history(self) -> SessionHistory:
        """Undo, redo and gestures; read as a tuple, (undo steps, redo steps) available now."""
        return SessionHistory(self.timeline)

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

    def submit(self, call, quick: bool = False):
        """Run `call()` on the training thread between two steps (a server's event loop never waits for the Som's
        lock); returns a concurrent.futures.Future of its result. `quick`: it takes no time (Trainer.post)."""
        return self.trainer.post(call, quick)

    # -- intents: controls (session.control_edits) ----------------------------------------------------------------
    def move_control(self, index: int | None, position, *, control_id: int | None = None) -> None:
        """Move control `index` to `position`: 3 numbers (x, y, z; the other features stay) or all n features."""
        self.control_edits.move(index, position, control_id)

    def move_control_id(self, control_id, position) -> None:
        """`move_control` for the control with this id (ValueError when it is gone), in one step with the lookup."""
        self.control_edits.move(None, position, control_id)

    def set_control_feature(self, index: int, dim: int, value) -> None:
        """Set one feature dim of control `index`."""
        self.control_edits.set_feature(index, dim, value)

    def set_control_colour(self, index: int, colour) -> None:
        """Set control `index`'s colour dims from an RGB triple in [0, 1] or a '#rrggbb' string."""
        self.control_edits.set_colour(index, colour)

    def set_control_radius(self, index: int | None, radius: float) -> None:
        """Control `index`'s radius of influence (model units; 0: the paper's point control), or every control's
        with `index` None."""
        self.control_edits.set_radius(index, radius)

    def add_control(self, values=None, radius: float | None = None) -> int:
        """Append a control (`control_edits.add`): where it is placed, moving nothing until it is dragged. Returns
        its index."""
        return self.control_edits.add(values, radius)

    def add_stroke(self, points, radius: float | None = None) -> int:
        """A polyline (m >= 2 points) as one control whose samples pull the clay along it (`control_edits
        .add_stroke`). Returns the index of its first sample."""
        return self.control_edits.add_stroke(points, radius)

    def revolve(self, profile_points, axis="z", n: int = 16, radius: float | None = None) -> int:
        """Lathe the clay: its nodes placed on the surface of revolution of the profile (m >= 2 points beside the axis
        "x", "y" or "z" through the origin; each node keeps its angle about the axis and its place along the clay's
        meridian), n-fold radial symmetry about the axis, and the profile's samples as a stroke control (radius:
        None for the preset's) with its copies in place of the controls. One undo step; nothing trains until the
        next intent. Returns the stroke's sample count (revolving.py)."""
        return revolving.revolve(self, profile_points, axis, n, radius)

    def remove_control(self, index: int) -> None:
        self.control_edits.remove(index)

    # -- intents: settings (session.settings) ------------------------------------------------------------------
    def set_parameter(self, name: str, value) -> None:
        """Set one setting by name (backend/schedule.py: S or iterations, the schedule's, symmetry) or
        metric_weights. A schedule setting restarts the schedule locally from the latest weights."""
        self.settings.set(name, value)

    def set_symmetry(self, group) -> str:
        """The symmetry group: a Symmetry, its spec ("mirror-y", "radial-8-z"), True (the last group, else the
        preset's), False or None (off). Off, every copy becomes a control of its own and nothing moves; on, no control
        is merged into another's copy unless all of them pair up (the copies a group left when turned off). One undo
        step; returns what happened to the controls, in words (`settings.set_symmetry`)."""
        return self.settings.set_symmetry(group)

    def set_iterations(self, value) -> None:
        """S: cycles in a run."""
        self.settings.set("iterations", value)

    def set_smoothing(self, value) -> None:
        """lambda of one Laplacian step per cycle, in [0, 1]; 0 is off."""
        self.settings.set("smoothing", value)

    # -- intents: run control ----------------------------------------------------------------------------------
    def train(self) -> None:
        """Resume training. A settled run (s = S) or a held state restarts locally from the latest weights (one
        undo step: the shape changes)."""
        state = self.modelling
        with state.lock:
            restart = state.som.iteration >= state.som.iterations and not self.trainer.ops
        with contextlib.ExitStack() as stack:
            if restart:
                stack.enter_context(self.timeline.step("train"))
            with state.lock:
                state.paused = False
                state.error = None
                if restart:
                    self.trainer.enqueue(Restart())
                else:
                    state.hold = False
                    self.trainer.enqueue(Publish())

    def pause(self) -> None:
        with self.modelling.lock:
            self.modelling.paused = True
            self.trainer.enqueue(Publish())

    def reset(self) -> None:
        """Back to the start mesh and s = 0: the whole schedule runs again; the controls stay. A preset that grows
        (the paper's case studies) grows again to where the controls are, whatever their radii."""
        with self.timeline.step("reset"), self.modelling.lock:
            self.trainer.enqueue(Reset(grow=self.preset.grow))

    # -- intents: whole session --------------------------------------------------------------------------------
    def load_preset(self, preset: str | Preset) -> None:
        """Replace the mesh, layout, controls and settings with a preset (a name or a Preset): one undo step. A
        preset that grows (the paper's case studies) runs its whole schedule; any other shape is shown as it is.
        Either way a Pause does not carry over. Choosing the current preset again brings back its own controls and
        start. The new Som is built in the caller's thread; a failure leaves the session as it was."""
        if isinstance(preset, str) and preset not in _presets.PRESETS:
            raise ValueError(f"unknown preset {preset!r}; known presets: {', '.join(_presets.PRESETS)}")
        built = self._build(preset)
        with self.timeline.step("preset"):
            self._install(built)

    def refine(self, stretched: float | None = None) -> int:
        """Subdivide the clay, its shape kept (backend/refine.py): every face split at its edges' midpoints, or with
        `stretched` (a factor, e.g. 2) only the edges longer than that times the median edge. The controls, their
        radii, the symmetry and the schedule stay; nothing trains until the next intent. One undo step; returns the
        new node count. ValueError for a clay without faces or one past this session's vertex limit."""
        refined = refined_preset(self.files.snapshot(), stretched, self.max_vertices)
        built = self._build(refined)
        with self.timeline.step("refine"):
            self._install(built, hold=True)
        return refined.n_vertices

    def load_mesh(self, path, decimate: bool = False) -> Preset:
        """Load a mesh file (io.load_mesh) as the new start mesh, shown as it is with controls on it; ValueError for
        a bad file (io.TooManyVertices for one past this session's limit: `decimate` loads it coarsened to the limit),
        session unchanged."""
        preset = mesh_io.load_mesh(path, max_vertices=self.max_vertices, decimate=decimate)
        preset.name = f"mesh:{preset.name}"  # never mistaken for a built-in preset of the same name
        self.load_preset(preset)
        return preset

    def export_mesh(self, path, units: str = "meters") -> None:
        """Write the current mesh (OBJ, PLY, STL, glTF, GLB, .3dm by extension) with its vertex colours and controls
        (`files.export_mesh`); `units`: a .3dm's unit system."""
        self.files.export_mesh(path, units=units)

    def save(self, path) -> None:
        """Save the session (`files.save`: a versioned .npz)."""
        self.files.save(path)

    def load(self, path) -> None:
        """Load a session saved by `save` exactly as it was saved (`files.load`); one undo step."""
        self.files.load(path)

    # -- recovery ----------------------------------------------------------------------------------------------
    @classmethod
    def recover(cls, origin: str | None = "python", **options) -> Session | None:
        """The session that stopped last (however it stopped: closed, interrupted, killed, crashed), of `origin`
        ("python": made from Python, a notebook's included; "serve": `somwidget serve`'s; None: any), brought back
        as its autosave left it: its last completed step (or a drag not released, as a step of its own) with its
        undo history; nothing trains until the next intent. None if there is none. `session.recovered["message"]`
        says which state came back. `options` go to Session (device, start...). Everything it reads is checked
        before anything is built (readback.py); read whole, it goes on saving in the same folder, which is not
        written until the next step. A folder not read whole is set aside whole (renamed, never changed) and what
        could be read comes back in a new folder, or the next one is tried; `session.notices` and the log say what
        was wrong, in which file, and what was kept where (recovery.py)."""
        session, notices = recover_session(cls, origin, **options)
        for notice in notices:
            log.warning("%s", notice)
        return session


def _store_for(origin: str, notices: list[str]) -> SessionStore:
    """A new session's folder (made with its first save), after the stopped sessions past the bounds are pruned."""
    store = SessionStore.new(origin)
    try:
        store.open(notices)
    except OSError as exc:  # the autosave says so, and tries again
        log.warning("autosave: cannot make %s (%s); trying again with each save", store.folder, exc.strerror or exc)
    prune()
    return store


__all__ = ["Frame", "Session"]
