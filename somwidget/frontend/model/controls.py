"""A session's controls (`session.control_edits`): move one (by index or by its stable id), set one feature, its
colour or its radius, replace them all, add one or a stroke, remove one. Each intent is checked in the caller's
thread, changes the session's view of the controls at once, and queues the new controls for the Som as one undo step
(inside a drag: the drag's step).
"""

from __future__ import annotations

import numpy as np

from ...backend import checks, schedule
from ...backend import presets as _presets
from ...backend.metrics import median_edge
from ...backend.presets import parse_hex_colour, rgb_to_colour_dims
from ...backend.som_controls import check_radii
from .frames import FrameStream
from .hands import Hands
from .operations import SetControls
from .state import ModellingState
from .timeline import Timeline
from .trainer import Trainer

#: The engine's limit on effective controls (originals plus mirrored copies).
MAX_CONTROLS = _presets.MAX_CONTROLS
#: Largest |value| accepted for a control coordinate or feature.
MAX_ABS_VALUE = 1e6
#: Edges sampled (evenly) for the clay's median edge length when a move's restart is sized: a drag frame stays cheap.
MEDIAN_EDGES = 4096


def check_index(name: str, value, count: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer index, got {value!r}")
    i = int(value)
    if not 0 <= i < count:
        raise ValueError(f"{name}: index {i} is out of range (there are {count} controls: 0..{count - 1})")
    return i


def check_count(controls: np.ndarray, group) -> None:
    """At least one control, and at most MAX_CONTROLS counting the copies of a symmetry `group` (or None)."""
    k = controls.shape[0]
    if k < 1:
        raise ValueError("controls: at least one control is needed")
    order = group.order if group is not None else 1
    if k * order > MAX_CONTROLS:
        with_group = f" with {group.describe()} ({order} copies each)" if group is not None else ""
        raise ValueError(f"controls: at most {MAX_CONTROLS} controls counting symmetric copies; {k} controls"
                         f"{with_group} is too many")


def check_radius(name: str, value) -> float:
    """A radius of influence: a finite number in model units within its declared bounds (0: a point control)."""
    return schedule.BY_NAME["radius"].check(value, name)


class ControlEdits:
    """The controls of one session and their intents (see the module's docstring)."""

    def __init__(self, state: ModellingState, timeline: Timeline, trainer: Trainer, frames: FrameStream, hands: Hands):
        self.state = state
        self.timeline = timeline
        self.trainer = trainer
        self.frames = frames
        self.hands = hands  # a control another hand holds is refused (hands.py)

    def _queue(self, controls: np.ndarray, keep: bool = False,
               rest: tuple[np.ndarray, np.ndarray] | None = None, reach: float | None = None) -> None:
        """The new controls (and the radii and strokes the clay holds) to the Som (caller holds state.lock); inside a
        drag they restart from where it began; with `keep` nothing restarts (a control placed); with `rest` (weights
        and controls before a move) the move is made again from that shape; `reach`: the restart's own."""
        state = self.state
        self.trainer.enqueue(SetControls(controls, state.radii.copy(), state.strokes, self.timeline.drag_anchor(),
                                         state.control_ids, keep=keep, group=state.symmetry, rest=rest, reach=reach))

    def _move_reach(self, run: range, values: np.ndarray) -> float | None:
        """The reach of the restart that moves the point controls `run` to `values` (caller holds state.lock): wide
        enough for the distance they moved from where the restart's shape had them (a drag's start, else where they
        are), over the clay's median edge (schedule.reach_for_move); None for a handle (its patch goes with it)."""
        state = self.state
        if state.radii[list(run)].any():
            return None
        pos = list(state.layout.position)
        before = state.controls[list(run)]
        boundary = self.timeline.gestures.boundary if self.timeline.drag_anchor() is not None else None
        if boundary is not None:
            ids = self.timeline.gestures.boundary_ids
            known = [ids.index(state.control_ids[i]) for i in run if state.control_ids[i] in ids]
            if len(known) == len(run):
                before = np.asarray(boundary.controls)[known]
        moved = float(np.linalg.norm(values[:, pos] - before[:, pos], axis=1).max(initial=0.0))
        edges = state.preset.topology.edges
        edge = median_edge(self.frames.latest.positions, edges[::max(1, len(edges) // MEDIAN_EDGES)])
        if not moved or not edge:
            return None
        return schedule.reach_for_move(float(state.params["reach"]), moved / edge, int(state.preset.topology.d_max))

    @property
    def radii(self) -> np.ndarray:
        """(k,) each control's radius of influence as the session holds it now."""
        with self.state.lock:
            return self.state.radii.copy()

    @property
    def strokes(self) -> tuple[int, ...]:
        """The lengths of the runs of controls that act as one (a stroke's samples), in index order."""
        with self.state.lock:
            return tuple(self.state.strokes)

    def index_of(self, control_id) -> int:
        if isinstance(control_id, bool) or not isinstance(control_id, (int, np.integer)):
            raise ValueError(f"control id: expected an integer, got {control_id!r}")
        with self.state.lock:
            try:
                return self.state.control_ids.index(int(control_id))
            except ValueError:
                raise ValueError(f"control {int(control_id)} no longer exists (it was removed, or the controls "
                                 "were replaced)") from None

    def _edit(self, step: str, index, edit, control_id=None) -> None:
        """One control's values changed by `edit(i, values) -> values` (its checks inside), as one step; the other
        samples of its stroke change by as much."""
        state = self.state
        self.hands.claim(index, control_id)
        with self.timeline.step(step), state.lock:
            i = (check_index("control", index, state.controls.shape[0]) if control_id is None
                 else self.index_of(control_id))
            controls = state.controls.copy()
            values = edit(i, controls[i].copy())
            run = state.run_of(i)
            controls[list(run)] += values - controls[i]
            controls[i] = values  # exactly as given
            reach = self._move_reach(run, controls[list(run)])
            state.controls = controls
            self._queue(controls.copy(), reach=reach)

    def move(self, index, position, control_id=None) -> None:
        layout = self.state.layout

        def edit(i, values):
            n = layout.n_dims
            if hasattr(position, "__len__") and not isinstance(position, str) and len(position) == n:
                return checks.finite_vector(f"control {i}", position, n, MAX_ABS_VALUE)
            values[list(layout.position)] = checks.finite_vector(f"control {i} position", position, 3, MAX_ABS_VALUE)
            return values

        self._edit("controls", index, edit, control_id)

    def set_feature(self, index, dim, value) -> None:
        layout = self.state.layout

        def edit(i, values):
            d = checks.integer_text("feature dimension", dim, 0, layout.n_dims - 1)
            values[d] = checks.real(f"control {i} {layout.names[d]}", value, -MAX_ABS_VALUE, MAX_ABS_VALUE)
            return values

        self._edit("controls", index, edit)

    def set_colour(self, index, colour) -> None:
        rgb = parse_hex_colour(colour) if isinstance(colour, str) else colour
        layout = self.state.layout

        def edit(_i, values):
            values[list(layout.colour)] = rgb_to_colour_dims(rgb, layout)
            return values

        self._edit("colour", index, edit)

    def set_radius(self, index, radius) -> None:
        """Control `index`'s radius (its stroke's), or every control's with `index` None; it acts at once: where the
        control was moved last (the latest steps moved it and set nothing else but radii), the move is done again
        from the shape before it with the new radius, so the clay shows the radius; otherwise a local restart.
        The radius the control has already changes nothing: no undo step, no restart (a panel's field sends its
        value again when it loses focus, and that must not be a step a person has to undo)."""
        state = self.state
        r = check_radius("every control's radius" if index is None else f"control {index} radius", radius)
        with state.lock:
            k = len(state.radii)
            run = range(k) if index is None else state.run_of(check_index("control", index, k))
            if k and np.all(state.radii[list(run)] == np.float32(r)):
                return
        if index is not None:
            self.hands.claim(index)
        with self.timeline.step(f"parameter:radius:{'all' if index is None else index}"), state.lock:
            radii = state.radii.copy()
            if index is None:
                run = range(len(radii))
            else:
                run = state.run_of(check_index("control", index, state.controls.shape[0]))
            radii[list(run)] = r
            state.radii = radii
            before = None if self.timeline.drag_anchor() is not None else self._before_move(run)
            self._queue(state.controls.copy(), rest=before)

    def _before_move(self, run: range) -> tuple[np.ndarray, np.ndarray] | None:
        """The weights and the controls before the latest move of the controls `run`, when every step since changed
        only their positions and radii (caller holds state.lock); else None."""
        state = self.state
        k = len(state.controls)
        others = np.ones(k, bool)
        others[list(run)] = False
        strokes = tuple(state.strokes)
        for step in reversed(self.timeline.history.steps()[0]):
            radii = np.zeros(k, np.float32) if step.radii is None else np.asarray(step.radii)
            if (step.preset is not state.preset or step.symmetry != state.symmetry or step.controls.shape != (k,) +
                    state.controls.shape[1:] or tuple(step.strokes or (1,) * k) != strokes
                    or step.parameters != state.params or radii.shape != (k,)
                    or not np.array_equal(step.controls[others], state.controls[others])
                    or not np.array_equal(radii[others], state.radii[others])):
                return None
            if not np.array_equal(step.controls[list(run)], state.controls[list(run)]):
                try:
                    return np.asarray(step.loaded().weights, np.float32), np.array(step.controls, np.float32)
                except (OSError, ValueError):
                    return None
        return None

    def replace(self, controls, radii=None) -> None:
        arr = checks.finite_array("controls", controls, 2, np.float64)
        if np.abs(arr).max(initial=0.0) > MAX_ABS_VALUE:
            raise ValueError(f"controls: values must lie within +-{MAX_ABS_VALUE:g}")
        arr = arr.astype(np.float32)
        state = self.state
        with self.timeline.step("controls"), state.lock:
            n = state.layout.n_dims
            if arr.shape[1] != n:
                raise ValueError(f"controls: expected shape (k, {n}), got {arr.shape}")
            check_count(arr, state.symmetry)
            if radii is not None:
                state.radii = check_radii(radii, len(arr))
            elif len(arr) != len(state.radii):
                state.radii = np.full(len(arr), state.preset.radius, np.float32)
            if len(arr) != len(state.controls):
                state.strokes = (1,) * len(arr)
            state.controls = arr.copy()
            if len(arr) != len(state.control_ids):
                state.control_ids = state.fresh_ids(len(arr))
            self._queue(arr)

    def add(self, values=None, radius=None) -> int:
        """A new control where it is placed, moving nothing until it is dragged (the Som keeps its weights and s):
        `values` all n features, or a position (x, y, z) whose other features are the nearest node's; None puts it on
        the node farthest from the other controls. Returns its index."""
        state = self.state
        layout = state.layout
        r = None if radius is None else check_radius("new control radius", radius)
        with self.timeline.step("add"), state.lock:
            weights = self.frames.latest.weights
            nodes = weights[:, list(layout.position)]
            if values is None:
                far = np.full(len(nodes), np.inf, np.float32)
                for c in state.controls[:, list(layout.position)]:
                    far = np.minimum(far, np.linalg.norm(nodes - c, axis=1))
                v = weights[int(np.argmax(far))].copy()
            elif np.ndim(values) == 1 and len(values) == 3 and layout.n_dims != 3:
                position = checks.finite_vector("new control position", values, 3, MAX_ABS_VALUE)
                v = weights[int(np.argmin(np.linalg.norm(nodes - position, axis=1)))].copy()
                v[list(layout.position)] = position
            else:
                v = checks.finite_vector("new control", values, layout.n_dims, MAX_ABS_VALUE)
            controls = np.concatenate([state.controls, v[None, :]]).astype(np.float32)
            check_count(controls, state.symmetry)
            state.radii = np.append(state.radii, state.preset.radius if r is None else r).astype(np.float32)
            state.strokes = (*state.strokes, 1)
            state.controls = controls
            state.control_ids = (*state.control_ids, *state.fresh_ids(1))
            self._queue(controls.copy(), keep=True)
            return controls.shape[0] - 1

    def add_stroke(self, points, radius=None) -> int:
        """A polyline (m >= 2 points: x, y, z or all n features) as one stroke: samples spaced evenly along it,
        which act as one control (moved, removed, undone and mirrored together); returns its first sample's
        index. The features a point leaves out are the last control's."""
        state = self.state
        layout = state.layout
        pts = checks.finite_array("stroke points", points, 2, np.float64)
        if len(pts) < 2 or pts.shape[1] not in (3, layout.n_dims):
            raise ValueError(f"stroke points: expected at least 2 points of 3 (x, y, z) or {layout.n_dims} values, got "
                             f"shape {pts.shape}")
        if np.abs(pts).max() > MAX_ABS_VALUE:
            raise ValueError(f"stroke points: values must lie within +-{MAX_ABS_VALUE:g}")
        r = check_radius("stroke radius", state.preset.radius if radius is None else radius)
        with self.timeline.step("stroke"), state.lock:
            full = np.repeat(state.controls[-1:].astype(np.float64), len(pts), axis=0)
            if pts.shape[1] == 3:
                full[:, list(layout.position)] = pts
            else:
                full = pts
            samples = resample(full, layout.position, self._spacing(r)).astype(np.float32)
            controls = np.concatenate([state.controls, samples]).astype(np.float32)
            check_count(controls, state.symmetry)
            first = len(state.controls)
            state.radii = np.concatenate([state.radii, np.full(len(samples), r, np.float32)])
            state.strokes = (*state.strokes, len(samples))
            state.controls = controls
            state.control_ids = (*state.control_ids, *state.run_ids((len(samples),)))
            self._queue(controls.copy())
            return first

    def _spacing(self, radius: float) -> float:
        """How far apart a stroke's samples are: SPACING_SHARE of its radius, at least the clay's median edge."""
        edge = median_edge(self.frames.latest.positions, self.state.preset.topology.edges)
        return max(edge, SPACING_SHARE * radius, 1e-6)

    def remove(self, index) -> None:
        state = self.state
        self.hands.claim(index)
        with self.timeline.step("remove"), state.lock:
            i = check_index("control", index, state.controls.shape[0])
            run = state.run_of(i)  # a stroke goes whole
            if len(run) >= state.controls.shape[0]:
                raise ValueError("controls: cannot remove the last control")
            state.controls = np.delete(state.controls, list(run), axis=0)
            state.radii = np.delete(state.radii, list(run))
            state.strokes = tuple(n for n, first in zip(state.strokes, np.cumsum((0, *state.strokes[:-1])))
                                 if first != run.start)
            state.control_ids = state.control_ids[:run.start] + state.control_ids[run.stop:]
            self._queue(state.controls.copy())


#: The most samples a stroke has (each a control: MAX_CONTROLS bounds them with their copies).
MAX_STROKE_SAMPLES = 24
#: A stroke's samples lie this share of its radius apart (at least the clay's median edge): at a quarter of the radius
#: the clay between them dipped into creases of 42 degrees along a ridge lifted by a fifth of the size; at a tenth,
#: 23 degrees (tests/test_shaping.py, the stroke over the grid).
SPACING_SHARE = 0.1


def resample(points: np.ndarray, position, spacing: float, most: int = MAX_STROKE_SAMPLES) -> np.ndarray:
    """Samples of a polyline (all features interpolated) evenly spaced about `spacing` apart along its positions,
    its ends included; 2 to `most` of them."""
    pos = points[:, list(position)]
    seg = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    along = np.concatenate([[0.0], np.cumsum(seg)])
    count = int(np.clip(np.ceil(along[-1] / spacing) + 1, 2, max(2, most)))
    at = np.linspace(0.0, along[-1], count)
    return np.stack([np.interp(at, along, points[:, d]) for d in range(points.shape[1])], axis=1)
