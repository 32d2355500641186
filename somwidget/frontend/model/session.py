"""One modelling session: the single source of truth that every view (web app, notebook, WebXR) shares.

A `Session` owns the `Som`, the controls and the training thread. Views send *intents* (move control i, set a
parameter, reset, train, pause, load a preset) and receive *frames* through listeners. Data flows one way:

    view --intent--> Session --(training thread: som.step(k))--> Frame --> every listener

Intents are validated in the caller's thread before anything changes: a bad index, NaN, inf or a wrong length
raises ValueError with a message and leaves the session as it was. Valid intents update the session's own copy
of the controls and parameters at once (so `session.controls` reflects them immediately) and are queued for the
training thread, which applies them to the Som in order between two steps; several control moves that arrive
within one frame collapse into one `set_controls`. The caller therefore never waits for a training step.

The training thread runs `som.step(k)` with k sized so that a step takes about `step_fraction / frame_rate`
seconds, publishes a Frame after each step (and after each batch of intents), and sleeps once s reaches S until
the next intent. Listeners run on the training thread: they must return quickly (copy what they need, hand the
frame to their own loop).

Clay rules (backend/som.py, Restarts): a control move, an added or removed control and a parameter change restart the
schedule locally (the Som's `reach`); `reset()` runs the whole schedule from the start mesh; a preset that grows (the
paper's case studies) runs its whole schedule when chosen, any other shape (a general shape, an uploaded mesh) is
shown as it is until the person acts; undo, redo, a loaded session and a recovered one put everything back exactly
and train nothing until the next intent.

Drags: each frame of a drag (`begin_gesture()` .. `end_gesture()`) is the local restart from the shape the drag began
with, to the hand's latest position; so a drag ends exactly as one move there would, however many frames it took
(restarting from the latest weights at every frame would pull the neighbourhoods of the other controls in again and
again, wearing the rest of the shape down).

History: every completed gesture is one undo step (history.py): a drag from `begin_gesture()` to `end_gesture()`,
and each other intent call (a control added, removed or recoloured, a parameter set, a reset, a preset, a mesh, a
loaded session); the same parameter set again within PARAMETER_STEP_SECONDS joins its step. Autosave: the latest
state goes to disk after each step and whenever training settles (storage.py); `Session.recover()` brings back a
session that did not close cleanly.

This module must not import trame, pyvista or any other UI package.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import logging
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...backend import checks
from ...backend import presets as _presets
from ...backend import device as _device
from ...backend.metrics import nearest_distances
from ...backend.presets import FeatureLayout, Preset
# The colour helpers live with the layouts; importable from here for the views that already do.
from ...backend.presets import hex_colour, parse_hex_colour, rgb_to_colour_dims  # noqa: F401
from ...backend.som import _MAX_TABLE_ENTRIES
from . import storage
from .history import History, Step
from .parameters import BY_NAME as _PARAM
from .parameters import MAX_ITERATIONS, METRIC_WEIGHT

log = logging.getLogger(__name__)

#: The engine's cap on its learning table, S x (d_max + 1) float32 entries (2 GiB): backend/som.py, _build_table.
#: A mesh with a long grid diameter allows fewer than MAX_ITERATIONS cycles (`Session.max_iterations`).
MAX_TABLE_ENTRIES = _MAX_TABLE_ENTRIES
#: The engine's limit on effective controls (originals plus mirrored copies).
MAX_CONTROLS = _presets.MAX_CONTROLS
#: Largest mesh a session on the CPU accepts by default: the dense distance table is N^2 uint16 (16384 -> 512 MiB),
#: built and searched on the CPU's cores.
DEFAULT_MAX_VERTICES = 16384
#: Largest mesh a session on a GPU accepts by default: past 65,536 neurons the engine computes distance rows for the
#: current winners on demand instead of a table, and the views stream a decimated display mesh past 32,768.
GPU_MAX_VERTICES = 4_194_304
#: Largest |value| accepted for a control coordinate or feature.
MAX_ABS_VALUE = 1e6

PARAMETERS = (*_PARAM, "metric_weights")  # declared in parameters.py
#: The line every panel shows under its reach slider.
REACH_HELP = _PARAM["reach"].help
#: Setting the same parameter again within this many seconds joins the previous undo step (a slider's drag).
PARAMETER_STEP_SECONDS = 1.5
#: While training, the autosave writes at most this often (it always writes when training settles).
AUTOSAVE_SECONDS = 2.0

_LIVE: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _close_live_sessions() -> None:
    """A process that ends normally closes its sessions cleanly (their autosaves go); a crash leaves them."""
    for session in list(_LIVE):
        try:
            session.close(timeout=2.0)
        except Exception:  # pragma: no cover - nothing must stop the exit
            pass


@dataclass(frozen=True)
class Frame:
    """What a view needs to draw one moment of the session. Arrays are read-only copies.

    seq:                frame number, increasing by one per published frame
    generation:         increases when the preset (topology, layout) changes: views rebuild their scene
    iteration, iterations: s and S of the schedule
    running:            True while the training thread is stepping (not paused and s < S)
    paused:             the user's Train / Pause choice
    weights:            (N, n) float32
    positions:          (N, 3) float32 node positions (layout.position dims)
    colours:            (N, 3) float32 RGB in [0, 1] (presets.colours_of)
    controls:           (k, n) the controls as given; control_colours (k, 3)
    effective_controls: (k_eff, n) originals then mirrored copies; effective_colours (k_eff, 3)
    control_positions / effective_positions: (k, 3) / (k_eff, 3) their position dims
    cycle_time:         seconds per training cycle (moving average over the recent steps; 0 before any step)
    step_cycles:        cycles run by the step that produced this frame (0 for a frame after an intent only)
    gaps:               (k_eff,) distance in position space from each effective control to its nearest node
    preset:             the Preset (topology, layout, display) this frame belongs to: draw with these, not with
                        the session's current ones, which may already be the next generation's
    time:               time.monotonic() when the frame was made
    applied:            how many intents the training thread had handled (applied, or refused with an error)
                        when the frame was made; intents are numbered from 1 as they are queued
    held:               nothing trains until the next intent (after an undo, a redo, a loaded or recovered session)
    history:            (undo steps, redo steps) available
    control_ids:        a stable id for each control (k,): an id stays with its control while others come and go
    """

    seq: int
    generation: int
    iteration: int
    iterations: int
    running: bool
    paused: bool
    weights: np.ndarray
    positions: np.ndarray
    colours: np.ndarray
    controls: np.ndarray
    control_colours: np.ndarray
    effective_controls: np.ndarray
    effective_colours: np.ndarray
    control_positions: np.ndarray
    effective_positions: np.ndarray
    cycle_time: float
    step_cycles: int
    gaps: np.ndarray
    preset: Preset | None = None
    time: float = field(default_factory=time.monotonic)
    applied: int = 0
    held: bool = False
    history: tuple[int, int] = (0, 0)
    control_ids: tuple[int, ...] = ()

    @property
    def layout(self) -> FeatureLayout:
        return self.preset.layout

    @property
    def topology(self):
        return self.preset.topology

    @property
    def display(self) -> str:
        return self.preset.display

    @property
    def n_controls(self) -> int:
        return int(self.controls.shape[0])

    @property
    def progress(self) -> float:
        return self.iteration / self.iterations if self.iterations else 1.0


FrameListener = Callable[[Frame], None]


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _finite_vector(name: str, value, length: int) -> np.ndarray:
    """A float32 vector of `length` finite values within +-MAX_ABS_VALUE, or ValueError."""
    return checks.finite_vector(name, value, length, MAX_ABS_VALUE)


def _check_bool(name: str, value) -> bool:
    """A checkbox's value: a bool, 0 / 1, or its text ("true", "off"...)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)) and int(value) in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.strip().lower() in ("true", "false", "on", "off", "1", "0"):
        return value.strip().lower() in ("true", "on", "1")
    raise ValueError(f"{name}: expected true or false, got {value!r}")


def _check_index(name: str, value, count: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer index, got {value!r}")
    i = int(value)
    if not 0 <= i < count:
        raise ValueError(f"{name}: index {i} is out of range (there are {count} controls: 0..{count - 1})")
    return i


def max_vertices_for(device: str | None) -> int:
    """The largest mesh a session on `device` takes by default: the engine's on a GPU, the dense table's on the
    CPU."""
    on_gpu = _device.resolve(None if device in (None, "auto") else device).startswith("cuda")
    return GPU_MAX_VERTICES if on_gpu else DEFAULT_MAX_VERTICES


def default_mirror(preset: Preset) -> tuple[int, ...]:
    """Dims negated by symmetry: the preset's own, else position y (and direction y where there is one)."""
    if preset.mirror:
        return tuple(preset.mirror)
    layout = preset.layout
    dims = [layout.position[1]]
    if layout.direction:
        dims.append(layout.direction[1])
    return tuple(sorted(dims))


class Session:
    """A live modelling session: one Som, its controls and a background training thread.

    preset:     a preset name (presets.PRESETS), a Preset, or None for "car"
    device:     Warp device for the Som: "auto"/None (best available), "cpu", "cuda", "cuda:N"
    frame_rate: frames per second the training thread aims at while training
    step_fraction: share of each frame interval spent in som.step (the rest is left to rendering)
    start:      start the training thread now (else call `start()`)
    paused:     begin paused (no training until `train()`)
    autosave:   keep the latest state on disk (storage.py) so that `Session.recover()` can bring it back after a
                crash; False for a session nothing should outlive
    """

    def __init__(self, preset: str | Preset | None = "car", device: str | None = "auto", frame_rate: float = 60.0,
                 step_fraction: float = 0.6, start: bool = True, paused: bool = False,
                 max_vertices: int | None = None, autosave: bool = True):
        self.frame_rate = checks.real("frame_rate", frame_rate, 0.0, 1000.0, low_open=True)
        self.step_fraction = checks.real("step_fraction", step_fraction, 0.0, 1.0, low_open=True)
        self.device = "auto" if device is None else device
        if max_vertices is None:
            max_vertices = max_vertices_for(self.device)
        self.max_vertices = checks.integer_text("max_vertices", max_vertices, 1, GPU_MAX_VERTICES)
        self.recovered: dict | None = None  # set by `recover()`: where the state came from and when it was saved
        self._lock = threading.RLock()  # the session's own state: controls, parameters, op queue
        self._wake = threading.Condition(self._lock)
        self._som_lock = threading.RLock()  # the Som: held by the training thread while it steps
        self._listeners: list[FrameListener] = []
        self._ops: list[tuple[str, object, int]] = []  # (kind, payload, number of the intent)
        self._enqueued = 0  # intents queued so far; each op carries its number
        self._applied = 0  # intents the training thread has handled (Frame.applied)
        self._thread: threading.Thread | None = None
        self._thread_error: str | None = None  # set if the training thread ever stops on an error
        self._closed = False
        self._paused = bool(paused)
        self._seq = 0
        self._generation = 0
        self._frame: Frame | None = None
        self._cycle_time = 0.0
        self._cycles_per_step = 1
        self._frames_published = 0
        self._frame_times: list[float] = []
        self._busy = False  # training thread is applying ops / stepping
        self._error: str | None = None
        self._hold = False  # nothing trains until the next intent (undo, redo, a loaded or recovered session)
        self._history = History()
        self._gesture = False  # a gesture (a drag) is open: its intents belong to one step
        self._gesture_step: Step | None = None  # the step the open gesture recorded, once it changed something
        self._gesture_base = None  # the Som that anchored its weights (Som.anchor): where each frame restarts
        self._last_step: tuple[str, float] = ("", 0.0)  # kind and time of the latest recorded step
        self._unsaved = True  # a change the autosave has not written yet (a new session: its first state)
        self._saved_at = 0.0
        self._next_control_id = 0
        self._install(self._build(preset))
        self._frame = self._make_frame(0)
        self._autosave = storage.Autosave() if autosave else None
        _LIVE.add(self)
        if start:
            self.start()

    # -- construction ------------------------------------------------------------------------------------------
    def _build(self, preset: str | Preset | None) -> tuple[Preset, object]:
        if preset is None:
            preset = "car"
        if isinstance(preset, str):
            preset = _presets.get_preset(preset)
        if not isinstance(preset, Preset):
            raise ValueError(f"preset: expected a preset name or a Preset, got {type(preset).__name__}")
        if preset.n_vertices > self.max_vertices:
            raise ValueError(f"mesh has {preset.n_vertices} vertices; this session accepts at most "
                             f"{self.max_vertices} on its device ({self.device}; on the CPU the distance table "
                             f"grows as N^2, a GPU session takes up to {GPU_MAX_VERTICES:,})")
        if preset.controls.shape[0] < 1:
            raise ValueError(f"preset {preset.name!r} has no controls; at least one is needed")
        device = None if self.device in (None, "auto") else self.device
        som = preset.make_som(device=device)
        if not preset.grow:  # the person's own shape: shown as it is, nothing trains until they act
            som.restore(preset.weights, som.iterations)
        return preset, som

    def _fresh_ids(self, k: int) -> tuple[int, ...]:
        """k new control ids, never used before in this session."""
        first = self._next_control_id
        self._next_control_id += k
        return tuple(range(first, first + k))

    def _install(self, built: tuple[Preset, object]) -> None:
        preset, som = built
        self._preset = preset
        self._som = som
        self._layout = preset.layout
        self._controls = np.array(som.controls, dtype=np.float32)
        self._control_ids = self._applied_ids = self._fresh_ids(len(self._controls))
        self._mirror_dims = default_mirror(preset)
        self._params = {
            "iterations": int(som.iterations), "l_start": float(som.l_start), "l_end": float(som.l_end),
            "smoothing": float(som.smoothing), "reach": float(som.reach), "symmetry": bool(som.mirror),
            "metric_weights": [float(x) for x in som.metric_weights],
        }
        self._cycle_time = 0.0
        self._cycles_per_step = 1
        self._generation += 1

    # -- thread --------------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the training thread (idempotent)."""
        with self._lock:
            if self._closed:
                raise RuntimeError("session is closed")
            if self._thread is not None:
                return
            self._thread = threading.Thread(target=self._run, name="somwidget-session", daemon=True)
            self._thread.start()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the training thread; the session accepts no more intents. A clean close: its autosave goes."""
        with self._wake:
            already = self._closed
            self._closed = True
            self._wake.notify_all()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout)
        if already:
            return
        _LIVE.discard(self)
        if self._autosave is not None:
            self._autosave.close(clean=True)
        self._history.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # a bug in the session itself: never die silently
            log.exception("the session's training thread stopped")
            with self._wake:
                self._thread_error = f"training thread stopped: {type(exc).__name__}: {exc}"
                self._paused = True
                self._busy = False
                self._wake.notify_all()

    def _loop(self) -> None:
        while True:
            with self._wake:
                while not self._closed and not self._ops and not self._should_step():
                    self._busy = False
                    self._wake.notify_all()
                    self._wake.wait()
                if self._closed:
                    self._busy = False
                    self._wake.notify_all()
                    return
                self._busy = True
            t0 = time.monotonic()
            self._cycle()
            self._autosave_if_due()
            # pace: a frame every 1 / frame_rate seconds while training; wake early for a new intent
            with self._wake:
                if self._should_step() and not self._ops and not self._closed:
                    rest = 1.0 / self.frame_rate - (time.monotonic() - t0)
                    if rest > 0:
                        self._wake.wait(rest)

    def _should_step(self) -> bool:
        # caller holds self._lock; _som is only swapped under both locks
        return not self._paused and not self._hold and self._som.iteration < self._som.iterations

    def _stopped(self) -> bool:
        """The training thread will handle no more intents: closed, never started, or stopped on an error."""
        t = self._thread
        return self._closed or t is None or self._thread_error is not None or not t.is_alive()

    def _cycle(self) -> None:
        """One turn of the training thread: apply the queued intents, step, publish a frame. Never raises."""
        try:
            frame = self._apply_and_step()
        except Exception as exc:  # keep the thread alive; views show the error
            log.exception("training step failed")
            frame = self._error_frame(f"training failed: {exc}")
        if frame is not None:
            self._publish(frame)

    def _drain(self) -> bool:
        """Apply every queued intent to the Som, in order (caller holds _som_lock); True if there were any."""
        with self._lock:  # taken under the Som lock: a load_preset in between cannot strand these ops
            ops, self._ops = self._ops, []
            if ops:  # handled from here on, whatever happens: every later frame is made after them
                self._applied = max(self._applied, ops[-1][2])
                self._unsaved = True
        som = self._som
        for i, op in enumerate(ops):
            self._apply_op(som, op, ops[i + 1:])
        return bool(ops)

    def _apply_and_step(self) -> Frame:
        with self._som_lock:
            ops = self._drain()
            som = self._som
            cycles = 0
            with self._lock:
                stepping = self._should_step()
            if stepping:
                k = self._cycles_per_step
                with self._lock:
                    dragging = self._gesture
                if ops and not dragging:  # a fresh intent: a short first step gets the change out sooner
                    k = max(1, k // 4)
                k = max(1, min(k, som.iterations - som.iteration))
                t = time.perf_counter()
                cycles = som.step(k)
                if hasattr(som, "synchronize"):
                    som.synchronize()
                dt = time.perf_counter() - t
                if cycles > 0:
                    self._tune(dt / cycles)
                    self._unsaved = True
            return self._make_frame(cycles)

    def _error_frame(self, message: str) -> Frame | None:
        """After a failed step: pause, show `message`, and return a frame to publish. Never raises."""
        try:
            with self._lock:
                self._error = message
                self._paused = True
            try:
                with self._som_lock:
                    return self._make_frame(0)
            except Exception:
                log.exception("could not make a frame after the error")
            with self._lock:  # the last frame again, marked paused, with the intents handled since
                self._seq += 1
                return dataclasses.replace(self._frame, seq=self._seq, applied=self._applied, running=False,
                                           paused=True, step_cycles=0, time=time.monotonic())
        except Exception:  # pragma: no cover - nothing above should fail
            log.exception("could not publish the error")
            return None

    def _apply_op(self, som, op: tuple[str, object, int], later) -> None:
        """Apply one intent to the Som. If the engine refuses it, put the session's own view of that parameter
        (or of the controls) back to what the Som holds, unless a later intent sets it again; record the error
        and carry on with the other intents."""
        kind, payload, _number = op
        try:
            if kind != "publish":
                with self._lock:
                    self._hold = False  # the person acted: training goes on
            self._apply(som, kind, payload)
            if kind == "controls":
                with self._lock:
                    self._applied_ids = payload[2]  # the ids of the controls the Som now holds
        except Exception as exc:
            log.warning("intent %s refused by the engine: %s", kind, exc)
            with self._lock:
                pending = {k for k, _, _ in later} | {k for k, _, _ in self._ops}
                try:
                    if kind not in pending:
                        self._roll_back(som, kind)
                except Exception:  # pragma: no cover - the Som's getters do not fail
                    log.exception("could not roll back %s", kind)
                self._error = f"the engine refused {kind}: {exc}"

    def _roll_back(self, som, kind: str) -> None:
        # caller holds self._lock
        if kind == "controls":
            self._controls = np.array(som.controls, dtype=np.float32)
            self._control_ids = self._applied_ids
        elif kind in ("iterations", "l_start", "l_end", "smoothing", "reach"):
            self._params[kind] = type(self._params[kind])(getattr(som, kind))
        elif kind == "mirror":
            self._params["symmetry"] = bool(som.mirror)
        elif kind == "metric_weights":
            self._params["metric_weights"] = [float(x) for x in som.metric_weights]

    def _tune(self, per_cycle: float) -> None:
        per_cycle = max(per_cycle, 1e-7)
        self._cycle_time = per_cycle if self._cycle_time == 0.0 else 0.7 * self._cycle_time + 0.3 * per_cycle
        budget = self.step_fraction / self.frame_rate
        target = int(budget / self._cycle_time)
        # grow at most x2 a frame so one slow first call does not overshoot
        self._cycles_per_step = max(1, min(target, 2 * self._cycles_per_step, MAX_ITERATIONS))

    @staticmethod
    def _apply(som, kind: str, payload) -> None:
        if kind == "controls":
            controls, base, _ids = payload  # base: in a drag, the Som that anchored the shape it began with
            som.set_controls(controls, from_anchor=base is som)  # each frame of the drag restarts from that shape
        elif kind == "iterations":
            som.iterations = payload
        elif kind == "l_start":
            som.l_start = payload
        elif kind == "l_end":
            som.l_end = payload
        elif kind == "smoothing":
            som.smoothing = payload
        elif kind == "reach":
            som.reach = payload
        elif kind == "mirror":
            som.mirror = payload
        elif kind == "metric_weights":
            som.metric_weights = payload
        elif kind == "reset":
            som.reset()
        elif kind == "weights":
            som.set_weights(payload)
        elif kind == "restart":
            som.restart()
        elif kind == "publish":
            pass
        else:  # pragma: no cover - programming error
            raise RuntimeError(f"unknown op {kind!r}")

    def _enqueue_controls(self, controls: np.ndarray) -> None:
        """Queue new controls (caller holds self._lock). Inside a gesture they carry the weights the gesture began
        from: each frame of a drag is the local restart from that shape, so a long drag does not wear down the rest
        of the shape restart after restart (it ends as one move would)."""
        self._enqueue("controls", (controls, self._gesture_base if self._gesture else None, self._control_ids))

    def _enqueue(self, kind: str, payload=None, intent: bool = True) -> None:
        """Queue an op for the training thread (caller holds self._lock). An intent gets the next number; the
        session's own ops (intent False: a frame to publish) share the latest one."""
        if self._closed:
            raise RuntimeError("session is closed")
        self._enqueued += int(intent)
        op = (kind, payload, self._enqueued)
        if kind == "controls" and self._ops and self._ops[-1][0] == "controls":
            self._ops[-1] = op  # several moves within one frame: only the latest counts
        else:
            self._ops.append(op)
        self._busy = True
        self._wake.notify_all()

    # -- frames ----------------------------------------------------------------------------------------------------
    def _make_frame(self, cycles: int) -> Frame:
        """Called with the Som quiescent (under _som_lock, or before the thread starts)."""
        som, layout = self._som, self._layout
        w = np.asarray(som.weights, dtype=np.float32)
        controls = np.asarray(som.controls, dtype=np.float32)
        eff = np.asarray(som.effective_controls, dtype=np.float32)
        pos = _presets.positions_of(w, layout)
        cpos = _presets.positions_of(controls, layout)
        epos = _presets.positions_of(eff, layout)
        gaps = self._gaps(pos, epos)
        with self._lock:
            self._seq += 1
            seq = self._seq
            paused = self._paused
            held = self._hold
            applied = self._applied
            history = (self._history.undo_count, self._history.redo_count)
            ids = self._applied_ids
            if len(ids) != len(controls):  # cannot happen: the ids travel with the controls they name
                ids = self._applied_ids = self._fresh_ids(len(controls))
        s, S = int(som.iteration), int(som.iterations)
        return Frame(
            seq=seq, generation=self._generation, iteration=s, iterations=S,
            running=(not paused and not held and s < S),
            paused=paused, weights=_readonly(w), positions=_readonly(pos),
            colours=_readonly(_presets.colours_of(w, layout)), controls=_readonly(controls),
            control_colours=_readonly(_presets.colours_of(controls, layout)), effective_controls=_readonly(eff),
            effective_colours=_readonly(_presets.colours_of(eff, layout)), control_positions=_readonly(cpos),
            effective_positions=_readonly(epos), cycle_time=float(self._cycle_time), step_cycles=int(cycles),
            gaps=_readonly(gaps), preset=self._preset, applied=applied, held=held, history=history,
            control_ids=tuple(ids))

    @staticmethod
    def _gaps(nodes: np.ndarray, points: np.ndarray) -> np.ndarray:
        """The distance from each point (a control) to its nearest node, in float32 one coordinate at a time: a
        million nodes and 18 controls take a few tens of ms, not the float64 blocks' half second."""
        if len(nodes) <= 4096:
            return nearest_distances(points, nodes).astype(np.float32)
        cols = [np.ascontiguousarray(nodes[:, a], np.float32) for a in range(nodes.shape[1])]
        out = np.empty(len(points), np.float32)
        for i, p in enumerate(np.asarray(points, np.float32)):
            d = np.square(cols[0] - p[0])
            for a in range(1, len(cols)):
                d += np.square(cols[a] - p[a])
            out[i] = np.sqrt(d.min())
        return out

    def _publish(self, frame: Frame) -> None:
        with self._wake:
            if self._frame is not None and frame.seq < self._frame.seq:
                return  # made before a load_preset / restore installed a newer frame: stale
            self._frame = frame
            self._frames_published += 1
            self._frame_times.append(frame.time)
            if len(self._frame_times) > 60:
                del self._frame_times[:-60]
            listeners = list(self._listeners)
            self._wake.notify_all()
        for cb in listeners:
            try:
                cb(frame)
            except Exception:  # a broken view must not stop the others
                log.exception("frame listener %r failed", cb)

    def add_listener(self, callback: FrameListener, replay: bool = True) -> FrameListener:
        """Call `callback(frame)` for every new frame (on the training thread); replay the latest one now."""
        if not callable(callback):
            raise ValueError("listener: expected a callable")
        with self._lock:
            self._listeners.append(callback)
            frame = self._frame
        if replay and frame is not None:
            try:
                callback(frame)
            except Exception:
                log.exception("frame listener %r failed", callback)
        return callback

    def remove_listener(self, callback: FrameListener) -> None:
        with self._lock:
            if callback in self._listeners:
                self._listeners.remove(callback)

    @property
    def frame(self) -> Frame:
        """The latest published frame."""
        with self._lock:
            return self._frame

    @property
    def frames_per_second(self) -> float:
        """Frames published per second over the last few frames (0 when idle)."""
        with self._lock:
            times = list(self._frame_times)
        if len(times) < 2 or time.monotonic() - times[-1] > 1.0:
            return 0.0
        return (len(times) - 1) / max(times[-1] - times[0], 1e-9)

    def wait_idle(self, timeout: float = 10.0) -> bool:
        """Block until every queued intent is applied and training has stopped (s = S or paused).

        False at the timeout, and at once if the training thread has stopped on an error (see `error`)."""
        deadline = time.monotonic() + timeout
        with self._wake:
            while True:
                t = self._thread
                if self._thread_error is not None or (t is not None and not self._closed and not t.is_alive()):
                    return False
                if not (self._ops or self._busy or (t is not None and self._should_step())):
                    return True
                if t is None or self._closed:
                    return not self._ops
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._wake.wait(min(left, 0.05))

    def wait_applied(self, timeout: float = 10.0) -> bool:
        """Block until every intent queued so far has reached the Som and a published frame shows it (`frame` then
        has it). An intent the engine refused counts as handled: `error` says why. False at the timeout, and at
        once if the training thread is not running (never started, closed, or stopped on an error)."""
        deadline = time.monotonic() + timeout
        with self._wake:
            target = self._enqueued
            while self._frame.applied < target:
                if self._stopped():
                    return False
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._wake.wait(min(left, 0.05))
        return True

    # -- read-only state ------------------------------------------------------------------------------------------
    @property
    def preset(self) -> Preset:
        return self._preset

    @property
    def layout(self) -> FeatureLayout:
        return self._layout

    @property
    def topology(self):
        return self._preset.topology

    @property
    def display(self) -> str:
        return self._preset.display

    @property
    def generation(self) -> int:
        return self._generation

    @property
    def controls(self) -> np.ndarray:
        """(k, n) the controls as the session holds them now (intents already applied here)."""
        with self._lock:
            return self._controls.copy()

    @property
    def n_controls(self) -> int:
        with self._lock:
            return int(self._controls.shape[0])

    @property
    def n_dims(self) -> int:
        return self._layout.n_dims

    @property
    def parameters(self) -> dict:
        with self._lock:
            p = dict(self._params)
            p["metric_weights"] = list(p["metric_weights"])
            p["mirror"] = list(self._mirror_dims) if p["symmetry"] else []
            return p

    @property
    def paused(self) -> bool:
        return self._paused

    @property
    def error(self) -> str | None:
        """The latest failure (a refused intent, a failed step), or why the training thread stopped."""
        return self._thread_error or self._error

    @property
    def training_device(self) -> str:
        """The Warp device the map trains on: "cpu" or "cuda:N" (what `device="auto"` chose)."""
        with self._som_lock:
            return str(self._som.device)

    def state(self, positions: bool = False) -> dict:
        """A JSON-friendly summary (for debug routes and tests); `positions` adds every node's x, y, z."""
        frame = self.frame
        with self._lock:
            controls = self._controls.copy()
            params = self.parameters
            pending = len(self._ops)
        layout = self._layout
        out = {
            "preset": self._preset.name, "title": self._preset.title, "display": self._preset.display,
            "generation": frame.generation, "n_vertices": int(self._preset.n_vertices), "n_dims": layout.n_dims,
            "feature_names": list(layout.names), "position_dims": list(layout.position),
            "colour_dims": list(layout.colour), "colour_space": layout.colour_space,
            "controls": controls.tolist(), "parameters": params, "paused": self._paused, "pending_intents": pending,
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

    # -- history: gestures, undo, redo ----------------------------------------------------------------------------
    def begin_gesture(self) -> None:
        """A gesture starts (a drag's press): the intents until `end_gesture()` make one undo step, recorded with
        the state before the first of them. A gesture left open (a tab closed mid-drag) ends at the next one."""
        with self._lock:
            self._gesture = True
            self._gesture_step = None
            self._gesture_base = None

    def end_gesture(self) -> None:
        """The gesture ends (a drag's release): the step is complete and goes to the autosave."""
        with self._wake:
            if not self._gesture:
                return
            self._gesture = False
            self._gesture_base = None
            self._unsaved = True
            self._wake.notify_all()

    @contextlib.contextmanager
    def gesture(self):
        """`with session.gesture(): ...`: the intents inside make one undo step."""
        self.begin_gesture()
        try:
            yield self
        finally:
            self.end_gesture()

    @contextlib.contextmanager
    def _step(self, kind: str):
        """Around one intent: record the state before it as an undo step (unless it belongs to an open gesture that
        has one, or repeats the same parameter within PARAMETER_STEP_SECONDS); a refused intent takes it back."""
        with self._lock:
            last_kind, last_time = self._last_step
            joins = (self._gesture and self._gesture_step is not None) or (
                kind.startswith("parameter:") and kind == last_kind
                and time.monotonic() - last_time < PARAMETER_STEP_SECONDS)
        step, base = (None, None) if joins else self._record_step()
        try:
            yield
        except BaseException:
            if step is not None:
                with self._lock:
                    self._history.drop_last(step)
                    if self._gesture and self._gesture_step is step:
                        self._gesture_step = self._gesture_base = None
            raise
        with self._lock:
            if step is not None and self._gesture:
                self._gesture_step, self._gesture_base = step, base
            self._last_step = (kind, time.monotonic())
            self._unsaved = True

    def _record_step(self) -> tuple[Step, object]:
        """Push the current state (every queued intent applied first) as an undo step. Returns it, and inside a
        gesture the Som that kept its weights (`Som.anchor`: the drag's frames restart from them), else None."""
        with self._som_lock:
            drained = self._drain()
            with self._lock:
                step = self._capture()
                self._history.push(step)
                base = None
                if self._gesture:
                    base = self._som
                    base.anchor()
                if drained:
                    self._enqueue("publish", intent=False)  # a frame that shows the drained intents
        return step, base

    def _capture(self) -> Step:
        # caller holds _som_lock and _lock, with no intent queued
        som = self._som
        params = dict(self._params)
        params["metric_weights"] = list(params["metric_weights"])
        return Step(preset=self._preset, controls=self._controls.copy(), parameters=params, weights=som.weights,
                    iteration=int(som.iteration))

    def undo(self) -> bool:
        """Go back one step: controls, parameters, weights and s exactly as before it, nothing trains. False if
        there is no step to undo."""
        return self._travel(self._history.undo)

    def redo(self) -> bool:
        """Go forward again after an undo, exactly; False if there is nothing to redo."""
        return self._travel(self._history.redo)

    def _travel(self, move) -> bool:
        with self._lock:
            self._gesture = False
        with self._som_lock:
            self._drain()
            with self._lock:
                target = move(self._capture())
            if target is None:
                return False
            self._apply_step(target)
        with self._lock:
            self._last_step = ("", 0.0)
            self._unsaved = True
            self._enqueue("publish", intent=False)
        return True

    def _apply_step(self, step: Step) -> None:
        """Put a recorded state back exactly and hold (caller holds _som_lock, no intent queued)."""
        if step.preset is not self._preset:
            built = self._build(step.preset)
            with self._lock:
                self._install(built)
        som = self._som
        p = step.parameters
        for name in ("iterations", "l_start", "l_end", "smoothing"):
            if getattr(som, name) != p[name]:
                setattr(som, name, p[name])
        if list(som.metric_weights) != list(p["metric_weights"]):
            som.metric_weights = np.asarray(p["metric_weights"], np.float32)
        mirror = tuple(self._mirror_dims) if p["symmetry"] else ()
        if som.mirror and tuple(som.mirror) != mirror:
            som.mirror = ()
        som.set_controls(step.controls)
        if tuple(som.mirror) != mirror:
            som.mirror = mirror
        som.reach = p["reach"]
        som.restore(step.weights, step.iteration)
        with self._lock:
            self._controls = np.array(step.controls, np.float32)
            if len(self._controls) != len(self._control_ids):  # a control added or removed: new ids (a grab on
                self._control_ids = self._fresh_ids(len(self._controls))  # an id that is gone ends)
            self._applied_ids = self._control_ids
            self._params = dict(p, metric_weights=list(p["metric_weights"]))
            self._hold = True
            self._error = None
            self._frame = self._make_frame(0)

    @property
    def history(self) -> tuple[int, int]:
        """(undo steps, redo steps) available now."""
        with self._lock:
            return self._history.undo_count, self._history.redo_count

    # -- autosave and recovery ---------------------------------------------------------------------------------
    def _autosave_if_due(self) -> None:
        """Training thread: write the state if something changed since the last save and training has settled (or
        AUTOSAVE_SECONDS have passed)."""
        if self._autosave is None:
            return
        with self._lock:
            if not self._unsaved or self._closed:
                return
            settled = not self._should_step() and not self._ops
            if not settled and time.monotonic() - self._saved_at < AUTOSAVE_SECONDS:
                return
            self._unsaved = False
            self._saved_at = time.monotonic()
        self._submit_autosave()

    def _submit_autosave(self) -> None:
        from ...backend import io as sw_io

        try:
            state = self.session_state()
        except Exception:  # pragma: no cover - a state that cannot be read now is saved at the next change
            log.exception("autosave: could not read the session's state")
            return
        self._autosave.submit(lambda path: sw_io.save_session(path, state))

    @property
    def autosave_path(self) -> Path | None:
        """Where this session's latest state is kept while it lives (None without autosave)."""
        return None if self._autosave is None else self._autosave.path

    def flush_autosave(self, timeout: float = 10.0) -> bool:
        """Write the current state to the autosave now and wait until it is on disk; False at the timeout or
        without autosave."""
        if self._autosave is None:
            return False
        with self._lock:
            self._unsaved = False
            self._saved_at = time.monotonic()
        self._submit_autosave()
        return self._autosave.flush(timeout)

    @classmethod
    def recover(cls, **options) -> Session | None:
        """The session of the latest exit that did not close cleanly (a crash, a kill), restored exactly as its
        autosave left it (nothing trains until the next intent); None if there is none. `options` go to Session
        (device, start...). Its autosave is taken over: it is deleted once the new session has saved its own."""
        from ...backend import io as sw_io

        start = options.pop("start", True)
        max_vertices = options.get("max_vertices") or max_vertices_for(options.get("device"))
        for path in storage.crashed():
            try:
                state = sw_io.load_session(path, max_vertices=max_vertices, max_iterations=MAX_ITERATIONS)
                saved = path.stat().st_mtime
            except (ValueError, OSError) as exc:
                log.warning("autosave %s cannot be read (%s): discarded", path, exc)
                storage.discard(path)
                continue
            session = cls(sw_io.preset_from_session(state), start=False, **options)
            session._restore_into(state)
            session.recovered = {"path": str(path), "saved": saved, "preset": state["preset"]}
            if session._autosave is not None:
                session.flush_autosave()
            storage.discard(path)
            if start:
                session.start()
            return session
        return None

    def _restore_into(self, state: dict) -> None:
        """Weights and s of a loaded state into the freshly built Som of its preset (which holds the rest), held."""
        with self._som_lock, self._lock:
            self._som.restore(np.asarray(state["weights"], np.float32), int(state["iteration"]))
            self._hold = True
            self._frame = self._make_frame(0)

    # -- intents: controls ----------------------------------------------------------------------------------------
    def _check_controls(self, controls: np.ndarray, symmetry: bool | None = None) -> None:
        if symmetry is None:
            symmetry = self._params["symmetry"]
        k = controls.shape[0]
        if k < 1:
            raise ValueError("controls: at least one control is needed")
        if k * (2 if symmetry else 1) > MAX_CONTROLS:
            raise ValueError(f"controls: at most {MAX_CONTROLS} controls counting mirrored copies; "
                             f"{k} controls{' with symmetry' if symmetry else ''} is too many")

    def move_control(self, index: int | None, position, *, control_id: int | None = None) -> None:
        """Move control `index` to `position`: 3 numbers (x, y, z; the other features stay) or all n features."""
        n = self._layout.n_dims
        with self._step("controls"), self._lock:
            i = (_check_index("control", index, self._controls.shape[0]) if control_id is None
                 else self.index_of_control(control_id))
            length = len(position) if hasattr(position, "__len__") and not isinstance(position, str) else -1
            if length == n:
                values = _finite_vector(f"control {i}", position, n)
            else:
                p = _finite_vector(f"control {i} position", position, 3)
                values = self._controls[i].copy()
                values[list(self._layout.position)] = p
            controls = self._controls.copy()
            controls[i] = values
            self._controls = controls
            self._enqueue_controls(controls.copy())

    @property
    def control_ids(self) -> tuple[int, ...]:
        """The stable id of each control, in index order (an id stays with its control; a new control gets a new
        one). Views hold controls by id (`index_of_control`), so a removal elsewhere cannot redirect a drag."""
        with self._lock:
            return tuple(self._control_ids)

    def index_of_control(self, control_id) -> int:
        """The index of the control with this id now; ValueError when it is gone (removed, or a preset, undo or
        load replaced the controls)."""
        if isinstance(control_id, bool) or not isinstance(control_id, (int, np.integer)):
            raise ValueError(f"control id: expected an integer, got {control_id!r}")
        with self._lock:
            try:
                return self._control_ids.index(int(control_id))
            except ValueError:
                raise ValueError(f"control {int(control_id)} no longer exists (it was removed, or the controls "
                                 "were replaced)") from None

    def move_control_id(self, control_id, position) -> None:
        """`move_control` for the control with this id (ValueError when it is gone), in one step with the lookup:
        a control removed meanwhile cannot make the move edit another one."""
        self.move_control(None, position, control_id=control_id)

    def set_control_feature(self, index: int, dim: int, value) -> None:
        """Set one feature dim of control `index`."""
        with self._step("controls"), self._lock:
            i = _check_index("control", index, self._controls.shape[0])
            d = checks.integer_text("feature dimension", dim, 0, self._layout.n_dims - 1)
            x = checks.real(f"control {i} {self._layout.names[d]}", value, -MAX_ABS_VALUE, MAX_ABS_VALUE)
            controls = self._controls.copy()
            controls[i, d] = x
            self._controls = controls
            self._enqueue_controls(controls.copy())

    def set_controls(self, controls) -> None:
        """Replace every control: (k, n) finite values, 1 <= k (counting mirrored copies <= 256)."""
        arr = checks.finite_array("controls", controls, 2, np.float64)
        if np.abs(arr).max(initial=0.0) > MAX_ABS_VALUE:
            raise ValueError(f"controls: values must lie within +-{MAX_ABS_VALUE:g}")
        arr = arr.astype(np.float32)
        with self._step("controls"), self._lock:
            n = self._layout.n_dims
            if arr.shape[1] != n:
                raise ValueError(f"controls: expected shape (k, {n}), got {arr.shape}")
            self._check_controls(arr)
            self._controls = arr.copy()
            if len(arr) != len(self._control_ids):
                self._control_ids = self._fresh_ids(len(arr))
            self._enqueue_controls(arr)

    def set_control_colour(self, index: int, colour) -> None:
        """Set control `index`'s colour dims from an RGB triple in [0, 1] or a '#rrggbb' string."""
        rgb = parse_hex_colour(colour) if isinstance(colour, str) else colour
        with self._step("colour"), self._lock:
            i = _check_index("control", index, self._controls.shape[0])
            dims = rgb_to_colour_dims(rgb, self._layout)
            controls = self._controls.copy()
            controls[i, list(self._layout.colour)] = dims
            self._controls = controls
            self._enqueue_controls(controls.copy())

    def add_control(self, values=None) -> int:
        """Append a control (all n features; default: next to the last one); returns its index."""
        n = self._layout.n_dims
        with self._step("add"), self._lock:
            if values is None:
                base = self._controls[-1].copy()
                pos = self._frame.positions if self._frame is not None else np.zeros((1, 3), np.float32)
                span = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0))) or 1.0
                p = list(self._layout.position)
                base[p[2]] += 0.15 * span
                v = base
            else:
                v = _finite_vector("new control", values, n)
            controls = np.concatenate([self._controls, v[None, :]]).astype(np.float32)
            self._check_controls(controls)
            self._controls = controls
            self._control_ids = (*self._control_ids, *self._fresh_ids(1))
            self._enqueue_controls(controls.copy())
            return controls.shape[0] - 1

    def remove_control(self, index: int) -> None:
        with self._step("remove"), self._lock:
            i = _check_index("control", index, self._controls.shape[0])
            if self._controls.shape[0] <= 1:
                raise ValueError("controls: cannot remove the last control")
            controls = np.delete(self._controls, i, axis=0)
            self._controls = controls
            self._control_ids = self._control_ids[:i] + self._control_ids[i + 1:]
            self._enqueue_controls(controls.copy())

    # -- intents: parameters -----------------------------------------------------------------------------------
    def set_parameter(self, name: str, value) -> None:
        """Set one of PARAMETERS: iterations (S), l_start, l_end, smoothing, reach, symmetry, metric_weights."""
        setters = {
            "iterations": self.set_iterations, "S": self.set_iterations, "l_start": self.set_l_start,
            "l_end": self.set_l_end, "smoothing": self.set_smoothing, "reach": self.set_reach,
            "symmetry": self.set_symmetry, "metric_weights": self.set_metric_weights,
        }
        if name not in setters:
            raise ValueError(f"unknown parameter {name!r}; known: {', '.join(PARAMETERS)}")
        setters[name](value)

    @property
    def max_iterations(self) -> int:
        """The largest S this mesh allows: MAX_ITERATIONS, or fewer where the engine's learning table
        S x (d_max + 1) would pass MAX_TABLE_ENTRIES (a mesh with a long grid diameter)."""
        with self._lock:
            d_max = int(self._preset.topology.d_max)  # the Som's own d_max: sessions keep the dense table
        return min(MAX_ITERATIONS, MAX_TABLE_ENTRIES // (d_max + 1))

    def set_iterations(self, value) -> None:
        """S: cycles in a run. Restarts the schedule locally from the latest weights."""
        s = _PARAM["iterations"].check(value)
        with self._step("parameter:iterations"), self._lock:
            limit = self.max_iterations
            if s > limit:
                d_max = int(self._preset.topology.d_max)
                raise ValueError(f"S (iterations): {s} is more than this mesh allows: at most {limit}, since the "
                                 f"learning table S x (d_max + 1) = {s} x {d_max + 1} may hold at most "
                                 f"{MAX_TABLE_ENTRIES} entries")
            self._params["iterations"] = s
            self._enqueue("iterations", s)

    def set_l_start(self, value) -> None:
        x = _PARAM["l_start"].check(value)
        with self._step("parameter:l_start"), self._lock:
            self._params["l_start"] = x
            self._enqueue("l_start", x)

    def set_l_end(self, value) -> None:
        x = _PARAM["l_end"].check(value)
        with self._step("parameter:l_end"), self._lock:
            self._params["l_end"] = x
            self._enqueue("l_end", x)

    def set_learning_rates(self, l_start, l_end) -> None:
        a, b = _PARAM["l_start"].check(l_start), _PARAM["l_end"].check(l_end)
        with self._step("parameter:rates"), self._lock:
            self._params["l_start"], self._params["l_end"] = a, b
            self._enqueue("l_start", a)
            self._enqueue("l_end", b)

    def set_smoothing(self, value) -> None:
        """lambda of one Laplacian step per cycle, in [0, 1]; 0 is off."""
        x = _PARAM["smoothing"].check(value)
        with self._step("parameter:smoothing"), self._lock:
            self._params["smoothing"] = x
            self._enqueue("smoothing", x)

    def set_reach(self, value) -> None:
        """How far a moved control's pull reaches when the clay follows it: the neighbourhood radius a restart
        begins with, as a share of the whole mesh's (0, 1]; small keeps the rest of the shape, 1 regrows it all."""
        x = _PARAM["reach"].check(value)
        with self._step("parameter:reach"), self._lock:
            self._params["reach"] = x
            self._enqueue("reach", x)

    def set_symmetry(self, value) -> None:
        """Mirror every control across the xz-plane (the preset's mirror dims) or not."""
        on = _check_bool("symmetry", value)
        with self._step("parameter:symmetry"), self._lock:
            self._check_controls(self._controls, symmetry=on)
            self._params["symmetry"] = on
            self._enqueue("mirror", self._mirror_dims if on else ())

    def set_metric_weights(self, value) -> None:
        """One weight >= 0 per feature dim (at least one positive) for the winner search."""
        with self._step("parameter:metric_weights"), self._lock:
            m = _finite_vector("metric_weights", value, self._layout.n_dims)
            if (m < 0).any():
                raise ValueError(f"metric_weights: weights must be >= 0, got {m.tolist()}")
            if not (m > 0).any():
                raise ValueError("metric_weights: at least one weight must be positive")
            self._params["metric_weights"] = [float(x) for x in m]
            self._enqueue("metric_weights", m)

    def set_metric_weight(self, dim: int, value) -> None:
        with self._lock:
            d = checks.integer_text("feature dimension", dim, 0, self._layout.n_dims - 1)
            m = list(self._params["metric_weights"])
            m[d] = checks.real(f"{METRIC_WEIGHT.label} of {self._layout.names[d]}", value, METRIC_WEIGHT.low,
                               METRIC_WEIGHT.high)
        self.set_metric_weights(m)

    # -- intents: run control ------------------------------------------------------------------------------
    def train(self) -> None:
        """Resume training. A settled run (s = S) or a held state restarts locally from the latest weights (one
        undo step: the shape changes)."""
        with self._lock:
            restart = self._som.iteration >= self._som.iterations and not self._ops
        with contextlib.ExitStack() as stack:
            if restart:
                stack.enter_context(self._step("train"))
            with self._lock:
                self._paused = False
                self._error = None
                if restart:
                    self._enqueue("restart")
                else:
                    self._hold = False
                    self._enqueue("publish")

    def pause(self) -> None:
        with self._lock:
            self._paused = True
            self._enqueue("publish")

    def reset(self) -> None:
        """Back to the start mesh and s = 0: the whole schedule runs again; the controls stay."""
        with self._step("reset"), self._lock:
            self._enqueue("reset")

    # -- intents: whole session -----------------------------------------------------------------------------
    def load_preset(self, preset: str | Preset) -> None:
        """Replace the mesh, layout, controls and parameters with a preset (a name or a Preset): one undo step. A
        preset that grows (the paper's case studies) runs its whole schedule; any other shape is shown as it is.
        Choosing the current preset again brings back its own controls and start.

        The new Som is built in the caller's thread (this can take a while for a big mesh); a failure leaves the
        session as it was.
        """
        if isinstance(preset, str) and preset not in _presets.PRESETS:
            raise ValueError(f"unknown preset {preset!r}; known presets: {', '.join(_presets.PRESETS)}")
        built = self._build(preset)
        with self._step("preset"):
            self._replace(built)

    def _replace(self, built, hold: bool = False) -> None:
        with self._som_lock, self._lock:
            if self._closed:
                raise RuntimeError("session is closed")
            self._ops.clear()
            self._applied = self._enqueued  # the cleared intents belonged to the old mesh: handled
            self._install(built)
            self._hold = hold
            self._error = None
            self._frame = self._make_frame(0)  # `frame` matches `preset` at once; listeners get the next one
            self._enqueue("publish")

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
        with self._som_lock, self._lock:
            som = self._som
            return {
                "preset": self._preset, "weights": np.asarray(som.weights, np.float32),
                "controls": self._controls.copy(), "iteration": int(som.iteration),
                "parameters": self.parameters,
            }

    def export_mesh(self, path) -> None:
        """Write the current mesh (OBJ, PLY, GLB by extension) with its vertex colours (io.export_mesh).

        A loaded mesh is written back in its file's original frame (io.load_mesh normalised it)."""
        from ...backend import io as sw_io

        snap = self.snapshot()
        preset = snap["preset"]
        sw_io.export_mesh(path, snap["weights"], preset.topology, preset.layout, display=preset.display,
                          transform=preset.meta.get("transform"))

    def session_state(self) -> dict:
        """The state io.save_session writes: the start mesh, the current weights, controls and parameters."""
        snap = self.snapshot()
        preset: Preset = snap["preset"]
        params = snap["parameters"]
        return {
            "preset": preset.name, "display": preset.display, "topology": preset.topology, "layout": preset.layout,
            "start_weights": np.asarray(preset.weights, np.float32), "weights": snap["weights"],
            "controls": snap["controls"], "iterations": params["iterations"], "iteration": snap["iteration"],
            "l_start": params["l_start"], "l_end": params["l_end"], "smoothing": params["smoothing"],
            "reach": params["reach"], "smooth_dims": preset.smooth_dims,
            "metric_weights": np.asarray(params["metric_weights"], np.float32), "mirror": tuple(params["mirror"]),
        }

    def save(self, path) -> None:
        """Save the session (io.save_session, a versioned .npz)."""
        from ...backend import io as sw_io

        sw_io.save_session(path, self.session_state())

    def load(self, path) -> None:
        """Load a session saved by `save` (io.load_session) exactly as it was saved, training nothing until the
        next intent; one undo step. ValueError for a bad file, session unchanged."""
        from ...backend import io as sw_io

        self.restore(sw_io.load_session(path, max_vertices=self.max_vertices, max_iterations=MAX_ITERATIONS))

    def restore(self, state: dict) -> None:
        """Rebuild the session from a loaded session state: its start mesh, controls and settings, its weights
        and s exactly as saved, nothing training until the next intent. ValueError if the state does not describe
        a session."""
        from ...backend import io as sw_io

        try:
            preset = sw_io.preset_from_session(state)
            weights = np.asarray(state["weights"], np.float32)
            iteration = int(state.get("iteration", 0))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"session: missing or malformed entry ({exc})") from None
        if weights.shape != preset.weights.shape or not np.isfinite(weights).all():
            raise ValueError(f"session: weights have shape {weights.shape}, expected {preset.weights.shape}")
        built = self._build(preset)
        built[1].restore(weights, min(iteration, preset.iterations))
        with self._step("session"):
            self._replace(built, hold=True)

    def apply_variant(self, controls, parameters: dict, weights) -> None:
        """Make a design variant (somwidget.sweep) the current state: its controls, its schedule (iterations,
        l_start, l_end, smoothing, reach) and its trained weights, at the end of its schedule, nothing training
        until the next intent; one undo step. ValueError if it does not fit this session's mesh."""
        w = checks.finite_array("weights", weights, 2)
        if w.shape != self._preset.weights.shape:
            raise ValueError(f"weights: expected shape {self._preset.weights.shape} (this session's mesh), got "
                             f"{w.shape}")
        c = checks.finite_array("controls", controls, 2)
        if c.shape[1] != self.n_dims or not len(c):
            raise ValueError(f"controls: expected (k, {self.n_dims}) with k >= 1, got {c.shape}")
        schedule = ("iterations", "l_start", "l_end", "smoothing", "reach")
        unknown = sorted(set(parameters) - set(schedule))
        if unknown:
            raise ValueError(f"parameters: unknown {unknown}; a variant sets some of {list(schedule)}")
        checked = {name: _PARAM[name].check(value) for name, value in parameters.items()}
        iterations = checked.get("iterations", self.parameters["iterations"])
        with self._step("variant"):
            with self._som_lock:
                self._drain()
                with self._lock:
                    current = self._capture()
                params = dict(current.parameters, **checked)
                self._apply_step(Step(preset=self._preset, controls=c, parameters=params, weights=w,
                                      iteration=iterations))
            with self._lock:
                self._enqueue("publish", intent=False)


__all__ = ["Frame", "Session", "PARAMETERS", "default_mirror", "rgb_to_colour_dims", "parse_hex_colour",
           "hex_colour"]
