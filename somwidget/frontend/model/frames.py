"""Frames: what a view needs to draw one moment of a session, made from the clay between two training steps and
published to every listener (on the training thread: a listener copies what it needs and returns at once).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ...backend import presets as _presets
from ...backend.metrics import nearest_distances
from ...backend.presets import FeatureLayout, Preset

log = logging.getLogger(__name__)


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
    gaps:               (k_eff,) distance in position space from each effective control to its nearest node, worked
                        out when first read (a panel reads it a few times a second; a frame need not)
    preset:             the Preset (topology, layout, display) this frame belongs to: draw with these, not with
                        the session's current ones, which may already be the next generation's
    time:               time.monotonic() when the frame was made
    applied:            how many intents the training thread had handled (applied, or refused with an error)
                        when the frame was made; intents are numbered from 1 as they are queued
    held:               nothing trains until the next intent (after an undo, a redo, a loaded or recovered session)
    history:            (undo steps, redo steps) available
    control_ids:        a stable id for each control (k,): an id stays with its control while others come and go
    radii:              (k,) each control's radius of influence (model units; 0: a point control)
    strokes:            the lengths of the runs of controls that act as one (a stroke's samples), in index order
    group:              the symmetry group in effect (its spec: "mirror-y", "radial-8-z"), "none" when off
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
    preset: Preset
    time: float = field(default_factory=time.monotonic)
    applied: int = 0
    held: bool = False
    history: tuple[int, int] = (0, 0)
    control_ids: tuple[int, ...] = ()
    radii: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    strokes: tuple[int, ...] = ()
    group: str = "none"

    @functools.cached_property
    def gaps(self) -> np.ndarray:
        return _readonly(nearest_gaps(self.positions, self.effective_positions))

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
    def control_display_colours(self) -> np.ndarray:
        """(k_eff, 3) the colours the views draw the effective controls in: their colour dims' where the layout has
        them, else the palette's by the control's stable id (a mirrored copy in its control's colour; a stroke's samples
        in its first sample's)."""
        if self.preset.layout.colour_space != "none":
            return np.asarray(self.effective_colours, np.float32)
        ids = self.control_ids if len(self.control_ids) == self.n_controls else None
        if ids is not None and sum(self.strokes) == self.n_controls:
            first = np.repeat(np.cumsum((0, *self.strokes[:-1])), self.strokes)
            ids = tuple(ids[i] for i in first)
        return _presets.palette_colours(self.n_controls, len(self.effective_controls), ids)[1]

    @property
    def progress(self) -> float:
        return self.iteration / self.iterations if self.iterations else 1.0


FrameListener = Callable[[Frame], None]


@functools.lru_cache(maxsize=4)
def _grey(n: int) -> np.ndarray:
    """(n, 3) the colour of nodes without colour dims, one read-only array shared by every frame of n nodes."""
    return _readonly(np.tile(np.asarray(_presets.NEUTRAL_GREY, np.float32), (n, 1)))


def _node_colours(weights: np.ndarray, layout: FeatureLayout) -> np.ndarray:
    """(N, 3) the nodes' colours (presets.colours_of); the shared grey where the layout has no colour dims."""
    return _grey(len(weights)) if layout.colour_space == "none" else _presets.colours_of(weights, layout)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def nearest_gaps(nodes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The distance from each point (a control) to its nearest node, in float32 one coordinate at a time: a million
    nodes and 18 controls take a few tens of ms, not the float64 blocks' half second."""
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


class FrameStream:
    """Numbers, keeps and publishes a session's frames: `make` one from the Som (quiescent: under the Som's lock, or
    before training starts), `publish` it to every listener, `latest`, and the rate frames go out at."""

    def __init__(self, lock: threading.Condition) -> None:
        self._lock = lock  # the session's condition: waiters wake when a frame is published
        self._listeners: list[FrameListener] = []
        self._latest: Frame | None = None
        self._seq = 0
        self._times: list[float] = []
        self._control_colours: tuple = ((), None)  # (key, (control colours, effective colours)): `_colours_of`
        self._node_colours: tuple = (None, None, None)  # (layout, the weights' colour dims, colours): `_nodes_of`

    def make(self, som, preset: Preset, generation: int, *, cycles: int, cycle_time: float,
             status: Callable[[], dict], weights: np.ndarray | None = None,
             colours: np.ndarray | None = None) -> Frame:
        """A frame of `som` now. `status()` gives what the session knows besides the Som (paused, held, applied,
        history, control_ids); it is read under the session's lock, together with the frame's number. `weights`: the
        Som's weights where they are held elsewhere (a batch: a studio's room), else read from it; `colours`: their
        nodes' colours (read-only, presets.colours_of) where made already (a batch's rooms' at once)."""
        layout = preset.layout
        w = np.asarray(som.weights if weights is None else weights, dtype=np.float32)
        controls = np.asarray(som.controls, dtype=np.float32)
        eff = np.asarray(som.effective_controls, dtype=np.float32)
        pos = w if layout.position == (0, 1, 2) and w.shape[1] == 3 else _presets.positions_of(w, layout)
        cpos = _presets.positions_of(controls, layout)
        control_colours, effective_colours = self._colours_of(controls, eff, layout)
        epos = _presets.positions_of(eff, layout)
        with self._lock:
            self._seq += 1
            seq = self._seq
            st = status()
        paused, held = st["paused"], st["held"]
        s, S = int(som.iteration), int(som.iterations)
        return Frame(
            seq=seq, generation=generation, iteration=s, iterations=S, running=(not paused and not held and s < S),
            paused=paused, weights=_readonly(w), positions=_readonly(pos),
            colours=self._nodes_of(w, layout) if colours is None else colours, controls=_readonly(controls),
            control_colours=control_colours, effective_controls=_readonly(eff),
            effective_colours=effective_colours, control_positions=_readonly(cpos),
            effective_positions=_readonly(epos), cycle_time=float(cycle_time), step_cycles=int(cycles),
            preset=preset, applied=st["applied"], held=held, history=st["history"],
            control_ids=tuple(st["control_ids"]), radii=_readonly(np.asarray(som.radii, np.float32)),
            strokes=tuple(int(n) for n in som.strokes),
            group=st.get("group", "none"))

    def _colours_of(self, controls: np.ndarray, eff: np.ndarray, layout) -> tuple[np.ndarray, np.ndarray]:
        """The controls' and their copies' colours (read-only), made again only when their colour dims changed (a
        drag's frames move positions only). Caller: `make`, under the Som's lock."""
        dims = list(layout.colour)
        key = (layout, controls.shape, eff.shape, controls[:, dims].tobytes(), eff[:, dims].tobytes())
        kept_key, kept = self._control_colours
        if kept is None or kept_key != key:
            kept = (_readonly(_presets.colours_of(controls, layout)), _readonly(_presets.colours_of(eff, layout)))
            self._control_colours = (key, kept)
        return kept

    def _nodes_of(self, w: np.ndarray, layout) -> np.ndarray:
        """The nodes' colours (read-only), made again only when the weights' colour dims changed: a drag's frames,
        restarted from its anchor, mostly move positions only (a car room's colours took a quarter of its frame).
        Caller: `make`, under the Som's lock."""
        if layout.colour_space == "none":
            return _node_colours(w, layout)
        dims = w[:, list(layout.colour)]
        kept_layout, kept_dims, kept = self._node_colours
        if kept is None or kept_layout != layout or not np.array_equal(kept_dims, dims):
            kept = _readonly(_node_colours(w, layout))
            self._node_colours = (layout, dims, kept)
        return kept

    def again(self, frame: Frame, **changes) -> Frame:
        """`frame` once more under a new number, with `changes` (after a failure that could make no new one)."""
        with self._lock:
            self._seq += 1
            return dataclasses.replace(frame, seq=self._seq, time=time.monotonic(), **changes)

    def install(self, frame: Frame) -> None:
        """Make `frame` the latest without publishing it (a preset installed, a step put back): `latest` shows it at
        once, listeners get the next published one."""
        with self._lock:
            self._latest = frame

    def publish(self, frame: Frame) -> None:
        with self._lock:
            if self._latest is not None and frame.seq < self._latest.seq:
                return  # made before a newer frame was installed: stale
            self._latest = frame
            self._times.append(frame.time)
            if len(self._times) > 60:
                del self._times[:-60]
            listeners = list(self._listeners)
            self._lock.notify_all()
        for cb in listeners:
            try:
                cb(frame)
            except Exception:  # a broken view must not stop the others
                log.exception("frame listener %r failed", cb)

    def add_listener(self, callback: FrameListener, replay: bool = True) -> FrameListener:
        if not callable(callback):
            raise ValueError("listener: expected a callable")
        with self._lock:
            self._listeners.append(callback)
            frame = self._latest
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
    def listeners(self) -> tuple[FrameListener, ...]:
        with self._lock:
            return tuple(self._listeners)

    @property
    def latest(self) -> Frame:
        """The latest frame installed or published; RuntimeError before the first (a session installs its first
        frame as it is made, so its views never see none)."""
        with self._lock:
            frame = self._latest
        if frame is None:
            raise RuntimeError("no frame yet: the session installs its first frame when it is made")
        return frame

    @property
    def per_second(self) -> float:
        """Frames published per second over the last few frames (0 when idle)."""
        with self._lock:
            times = list(self._times)
        if len(times) < 2 or time.monotonic() - times[-1] > 1.0:
            return 0.0
        return (len(times) - 1) / max(times[-1] - times[0], 1e-9)
