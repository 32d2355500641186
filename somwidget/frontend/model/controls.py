"""Intents on a session's controls: move one (by index or by its stable id), set one feature or its colour, replace
them all, add one, remove one. Each is checked in the caller's thread, changes the session's view of the controls
at once, and queues the new controls for the Som as one undo step (inside a drag: the drag's step).
"""

from __future__ import annotations

import numpy as np

from ...backend import checks
from ...backend import presets as _presets
from ...backend.presets import parse_hex_colour, rgb_to_colour_dims
from .clay import Clay
from .frames import FrameStream
from .operations import SetControls
from .timeline import Timeline
from .trainer import Trainer

#: The engine's limit on effective controls (originals plus mirrored copies).
MAX_CONTROLS = _presets.MAX_CONTROLS
#: Largest |value| accepted for a control coordinate or feature.
MAX_ABS_VALUE = 1e6
#: Largest radius of influence (model units).
MAX_RADIUS = 1e6


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
    """A radius of influence: a finite number in [0, MAX_RADIUS] model units (0: a point control)."""
    return checks.real(name, value, 0.0, MAX_RADIUS)


class ControlEdits:
    """The control intents of one session (see the module's docstring)."""

    def __init__(self, clay: Clay, timeline: Timeline, trainer: Trainer, frames: FrameStream):
        self.clay = clay
        self.timeline = timeline
        self.trainer = trainer
        self.frames = frames

    def _queue(self, controls: np.ndarray) -> None:
        """The new controls (and the radii the clay holds) to the Som (caller holds clay.lock); inside a drag they
        restart from where it began."""
        clay = self.clay
        self.trainer.enqueue(SetControls(controls, clay.radii.copy(), self.timeline.drag_anchor(), clay.control_ids))

    def index_of(self, control_id) -> int:
        if isinstance(control_id, bool) or not isinstance(control_id, (int, np.integer)):
            raise ValueError(f"control id: expected an integer, got {control_id!r}")
        with self.clay.lock:
            try:
                return self.clay.control_ids.index(int(control_id))
            except ValueError:
                raise ValueError(f"control {int(control_id)} no longer exists (it was removed, or the controls "
                                 "were replaced)") from None

    def _edit(self, step: str, index, edit, control_id=None) -> None:
        """One control's values changed by `edit(i, values) -> values` (its checks inside), as one step."""
        clay = self.clay
        with self.timeline.step(step), clay.lock:
            i = (check_index("control", index, clay.controls.shape[0]) if control_id is None
                 else self.index_of(control_id))
            controls = clay.controls.copy()
            controls[i] = edit(i, controls[i].copy())
            clay.controls = controls
            self._queue(controls.copy())

    def move(self, index, position, control_id=None) -> None:
        layout = self.clay.layout

        def edit(i, values):
            n = layout.n_dims
            if hasattr(position, "__len__") and not isinstance(position, str) and len(position) == n:
                return checks.finite_vector(f"control {i}", position, n, MAX_ABS_VALUE)
            values[list(layout.position)] = checks.finite_vector(f"control {i} position", position, 3, MAX_ABS_VALUE)
            return values

        self._edit("controls", index, edit, control_id)

    def set_feature(self, index, dim, value) -> None:
        layout = self.clay.layout

        def edit(i, values):
            d = checks.integer_text("feature dimension", dim, 0, layout.n_dims - 1)
            values[d] = checks.real(f"control {i} {layout.names[d]}", value, -MAX_ABS_VALUE, MAX_ABS_VALUE)
            return values

        self._edit("controls", index, edit)

    def set_colour(self, index, colour) -> None:
        rgb = parse_hex_colour(colour) if isinstance(colour, str) else colour
        layout = self.clay.layout

        def edit(_i, values):
            values[list(layout.colour)] = rgb_to_colour_dims(rgb, layout)
            return values

        self._edit("colour", index, edit)

    def set_radius(self, index, radius) -> None:
        clay = self.clay
        r = check_radius(f"control {index} radius", radius)
        with self.timeline.step(f"parameter:radius:{index}"), clay.lock:
            i = check_index("control", index, clay.controls.shape[0])
            radii = clay.radii.copy()
            radii[i] = r
            clay.radii = radii
            self._queue(clay.controls.copy())

    def replace(self, controls, radii=None) -> None:
        arr = checks.finite_array("controls", controls, 2, np.float64)
        if np.abs(arr).max(initial=0.0) > MAX_ABS_VALUE:
            raise ValueError(f"controls: values must lie within +-{MAX_ABS_VALUE:g}")
        arr = arr.astype(np.float32)
        clay = self.clay
        with self.timeline.step("controls"), clay.lock:
            n = clay.layout.n_dims
            if arr.shape[1] != n:
                raise ValueError(f"controls: expected shape (k, {n}), got {arr.shape}")
            check_count(arr, clay.symmetry)
            if radii is not None:
                r = checks.finite_array("radii", radii, 1)
                if r.shape != (len(arr),) or (r < 0).any() or (r > MAX_RADIUS).any():
                    raise ValueError(f"radii: expected {len(arr)} values in [0, {MAX_RADIUS:g}] (one per control), "
                                     f"got {r.tolist()}")
                clay.radii = r
            elif len(arr) != len(clay.radii):
                clay.radii = np.full(len(arr), clay.preset.radius, np.float32)
            clay.controls = arr.copy()
            if len(arr) != len(clay.control_ids):
                clay.control_ids = clay.fresh_ids(len(arr))
            self._queue(arr)

    def add(self, values=None, radius=None) -> int:
        clay = self.clay
        r = None if radius is None else check_radius("new control radius", radius)
        with self.timeline.step("add"), clay.lock:
            if values is None:  # next to the last one
                v = clay.controls[-1].copy()
                pos = self.frames.latest.positions
                span = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0))) or 1.0
                v[clay.layout.position[2]] += 0.15 * span
            else:
                v = checks.finite_vector("new control", values, clay.layout.n_dims, MAX_ABS_VALUE)
            controls = np.concatenate([clay.controls, v[None, :]]).astype(np.float32)
            check_count(controls, clay.symmetry)
            clay.radii = np.append(clay.radii, clay.preset.radius if r is None else r).astype(np.float32)
            clay.controls = controls
            clay.control_ids = (*clay.control_ids, *clay.fresh_ids(1))
            self._queue(controls.copy())
            return controls.shape[0] - 1

    def remove(self, index) -> None:
        clay = self.clay
        with self.timeline.step("remove"), clay.lock:
            i = check_index("control", index, clay.controls.shape[0])
            if clay.controls.shape[0] <= 1:
                raise ValueError("controls: cannot remove the last control")
            clay.controls = np.delete(clay.controls, i, axis=0)
            clay.radii = np.delete(clay.radii, i)
            clay.control_ids = clay.control_ids[:i] + clay.control_ids[i + 1:]
            self._queue(clay.controls.copy())
