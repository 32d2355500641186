"""The modelling state: what every part of a session shares. The installed preset and its Som, the controls and
settings as the views see them (an intent changes them at once; the Som follows on the training thread), and the run
flags.

Two locks: `lock` guards this state (`wake` is its condition: waiters wake on every change that matters), `som_lock`
guards the Som, which the training thread holds while it steps. Whoever needs both takes `som_lock` first. In a
studio a batch may hold the Som's state between rounds (studio/batched.py): `lent` is then the room's Som lock, through
which a save reads the state without taking the Som back (`lent.for_save()`, `lent.state_to_save()`).
"""

from __future__ import annotations

import threading

import numpy as np

from ...backend import device as _device
from ...backend import presets as _presets
from ...backend import schedule
from ...backend.presets import Preset
from ...backend.symmetry import Symmetry, mirror_dims_of, mirror_of_dims
from .history import Step

#: Largest mesh a session on the CPU accepts by default: past 16,384 neurons the engine reads distance rows searched
#: as deep as a restart reaches (256 MiB of them at most) and moves only the blocks of neurons within reach of a
#: winner (backend/local_path.py), so a drag costs what it touches; at 262,144 a drag frame (10 cycles) stays in a
#: frame's time on two cores.
DEFAULT_MAX_VERTICES = 262_144
#: Largest mesh a session on a GPU accepts by default: past 65,536 neurons the engine computes distance rows for the
#: current winners on demand instead of a table, and the views stream a decimated display mesh past 32,768.
GPU_MAX_VERTICES = 4_194_304


#: Ids of a stroke's samples after its first start here (`run_ids`): no view shows them, so the numbers shown count
#: strokes as one. Below fields.py's u31 limit with room for 2^30 samples.
SAMPLE_IDS = 1 << 30

def max_vertices_for(device: str | None) -> int:
    """The largest mesh a session on `device` takes by default: GPU_MAX_VERTICES on a GPU, DEFAULT_MAX_VERTICES on
    the CPU."""
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


def default_group(preset: Preset) -> Symmetry | None:
    """The group "symmetry on" brings for a preset: its own (a radial group, or its mirror dims as a mirror), else the
    mirror across the xz-plane (y negated), acting on the layout's position and direction dims."""
    layout = preset.layout
    if preset.symmetry is not None:
        return preset.symmetry
    return mirror_of_dims(default_mirror(preset), layout.position, layout.direction)


def engine_symmetry(group: Symmetry | None) -> tuple[Symmetry | None, tuple[int, ...]]:
    """(Som's symmetry, Som's mirror dims) for a group: a mirror runs as the engine's mirrored pairs."""
    dims = mirror_dims_of(group)
    return (None, dims) if dims is not None else (group, ())


def som_group(som, layout) -> Symmetry | None:
    """The group a Som runs, as the session keeps it (acting on the layout's dims)."""
    if som.symmetry is not None and som.symmetry.kind == "radial":
        return som.symmetry
    return mirror_of_dims(som.mirror, layout.position, layout.direction) if som.mirror else None


def held_settings() -> tuple[schedule.Setting, ...]:
    """The settings a session holds by name (`ModellingState.params`): those of one value and those of one value per
    feature dimension (a control's radius is held with the controls, the symmetry group as a Symmetry)."""
    return tuple(s for s in schedule.SETTINGS if s.by_name or s.per == "dim")


def settings_of(som) -> dict:
    """The held settings of a Som: the engine's as it keeps them (a list of floats for one per dimension), the
    session's own at their defaults."""
    values = {}
    for s in held_settings():
        if s.scope != "engine":
            values[s.name] = s.default
        elif s.per:
            values[s.name] = [float(x) for x in getattr(som, s.name)]
        else:
            values[s.name] = s.check(getattr(som, s.name))
    return values


def with_defaults(values: dict) -> dict:
    """`values` with each held setting it lacks at its default (a step recorded before that setting was declared)."""
    return {**{s.name: s.default for s in held_settings() if s.name not in values}, **values}


def build(preset: str | Preset | None, device: str | None, max_vertices: int) -> tuple[Preset, object]:
    """(preset, its Som) for a preset name or a Preset on `device`; ValueError for an unknown preset or a mesh over
    `max_vertices`. A shape that does not grow (a general shape, an uploaded mesh) is shown as it is: its Som holds
    the start weights at s = S, so nothing trains until the person acts."""
    if preset is None:
        preset = "car"
    if isinstance(preset, str):
        preset = _presets.get_preset(preset)
    if not isinstance(preset, Preset):
        raise ValueError(f"preset: expected a preset name or a Preset, got {type(preset).__name__}")
    if preset.n_vertices > max_vertices:
        raise ValueError(f"mesh has {preset.n_vertices:,} vertices; this session accepts at most {max_vertices:,} on "
                         f"its device ({device}; a session takes up to {DEFAULT_MAX_VERTICES:,} on the CPU, "
                         f"{GPU_MAX_VERTICES:,} on a GPU)")
    if preset.controls.shape[0] < 1:
        raise ValueError(f"preset {preset.name!r} has no controls; at least one is needed")
    som = preset.make_som(device=None if device in (None, "auto") else device)
    if not preset.grow:
        som.restore(preset.weights, som.iterations)
    return preset, som


class ModellingState:
    """The shared state of one session (see the module's docstring)."""

    controls: np.ndarray  # (k, n) the controls as the session holds them (set by `install`)

    def __init__(self, preset: Preset, som, paused: bool = False) -> None:
        self.lock = threading.RLock()
        self.wake = threading.Condition(self.lock)
        self.som_lock = threading.RLock()
        self.lent = None  # a studio room's Som lock (studio/batched.py RoomLock); None in a session of its own
        self.generation = 0
        self.paused = bool(paused)  # the person's Train / Pause choice
        self.hold = False  # nothing trains until the next intent (after an undo, a redo, a loaded session)
        self.error: str | None = None  # the latest refused intent or failed step, for the views
        self.gesture = False  # a gesture (a drag) is open: its intents make one undo step
        self.unsaved = True  # a change the autosave has not written yet (a new session: its first state)
        self.completed = 0  # steps completed (and undos, redos) so far: the autosave writes each at once
        self._next_id = 0
        self._next_sample_id = SAMPLE_IDS
        self.install(preset, som)

    def install(self, preset: Preset, som) -> None:
        """A new preset and its Som (caller holds both locks, or nothing runs yet): new ids from 0 (the views number
        and colour controls by them; the same controls, as after Refine, keep theirs), settings from the Som, the
        next generation."""
        self.preset, self.som, self.layout = preset, som, preset.layout
        controls = np.array(som.controls, dtype=np.float32)
        same = getattr(self, "controls", None) is not None and np.array_equal(controls, self.controls)
        self.controls = controls
        self.radii = np.array(som.radii, dtype=np.float32)
        self.strokes = tuple(som.strokes)
        if not same:  # another clay's controls: numbered from 0 again (the same controls, Refine: their ids stay)
            self._next_id, self._next_sample_id = 0, SAMPLE_IDS
            self.control_ids = self.run_ids(self.strokes if sum(self.strokes) == len(self.controls)
                                            else (1,) * len(self.controls))
        self.applied_ids = self.control_ids
        self.symmetry = som_group(som, preset.layout)
        self.params = settings_of(som)
        self.set_symmetry(self.symmetry)
        self.default_group = self.symmetry or default_group(preset)  # what "symmetry on" brings
        self.generation += 1

    def fresh_ids(self, k: int) -> tuple[int, ...]:
        """k new control ids, never used before on this clay (since its preset was installed): the numbers the views
        and the controls table show, each the next after the highest given."""
        first = self._next_id
        self._next_id += k
        return tuple(range(first, first + k))

    def run_ids(self, strokes) -> tuple[int, ...]:
        """New ids for controls in runs of these lengths (a stroke's samples act as one): a run's first sample takes
        the next shown number (`fresh_ids`), the others ids from SAMPLE_IDS on, which no view shows, so a stroke
        counts as one number and the next control added takes the number after it."""
        ids = []
        for n in strokes:
            ids += [*self.fresh_ids(1), *range(self._next_sample_id, self._next_sample_id + n - 1)]
            self._next_sample_id += n - 1
        return tuple(ids)

    def _renumber_after(self, ids) -> None:
        """The next ids follow `ids` (ids put back by an undo or a loaded session)."""
        self._next_id = max(self._next_id, max((i for i in ids if i < SAMPLE_IDS), default=-1) + 1)
        self._next_sample_id = max(self._next_sample_id, max((i for i in ids if i >= SAMPLE_IDS), default=-1) + 1)

    def run_of(self, i: int) -> range:
        """The indices of the controls that act as one with control i (a stroke's samples; i alone otherwise)."""
        first = 0
        for length in self.strokes:
            if i < first + length:
                return range(first, first + length)
            first += length
        return range(i, i + 1)

    def set_symmetry(self, group: Symmetry | None) -> None:
        """The group in effect (caller holds lock); the one "symmetry on" brings follows a chosen group."""
        self.symmetry = group
        self.params["symmetry"] = group is not None
        if group is not None:
            self.default_group = group

    def parameters(self) -> dict:
        """A copy of the held settings, with "mirror" (the dims a mirror group negates) and "group" (the group's
        spec, "none" when off) (caller holds lock)."""
        p = {name: list(v) if isinstance(v, list) else v for name, v in self.params.items()}
        p["mirror"] = list(mirror_dims_of(self.symmetry) or ())
        p["group"] = self.symmetry.spec if self.symmetry is not None else "none"
        return p

    def capture(self) -> Step:
        """The state now as an undo step (caller holds both locks, with no operation queued). A studio room's Som
        held by a batch gives the weights and cycle a give-back would leave in it (`lent.state_to_save()`), read
        together; its own otherwise."""
        params = {name: list(v) if isinstance(v, list) else v for name, v in self.params.items()}
        held = None if self.lent is None else self.lent.state_to_save()
        weights, iteration = held if held is not None else (self.som.weights, int(self.som.iteration))
        return Step(preset=self.preset, controls=self.controls.copy(), parameters=params, weights=weights,
                    iteration=iteration, radii=self.radii.copy(), symmetry=self.symmetry,
                    strokes=self.strokes, control_ids=tuple(self.control_ids))

    def put_back(self, step: Step) -> None:
        """Put a recorded state into the Som exactly, and the session's view with it; nothing trains until the next
        intent (caller holds both locks; the step's preset is the installed one)."""
        som, p = self.som, with_defaults(step.parameters)
        for s in held_settings():
            if s.scope != "engine":
                continue
            if s.per and list(getattr(som, s.name)) != list(p[s.name]):
                setattr(som, s.name, np.asarray(p[s.name], np.float32))
            elif not s.per and getattr(som, s.name) != p[s.name]:
                setattr(som, s.name, p[s.name])
        radii = np.zeros(len(step.controls), np.float32) if step.radii is None else step.radii
        som.regroup(step.controls, radii, *engine_symmetry(step.symmetry), strokes=step.strokes)
        som.restore(step.weights, step.iteration)
        self.controls = np.array(step.controls, np.float32)
        self.radii = np.array(radii, np.float32)
        self.strokes = tuple(som.strokes)
        if step.control_ids is not None and len(step.control_ids) == len(self.controls):  # the ids it had: each
            self.control_ids = tuple(step.control_ids)  # control's number and colour come back with it
            self._renumber_after(self.control_ids)
        elif len(self.controls) != len(self.control_ids):  # a control added or removed: new ids (a grab on an id
            self.control_ids = self.run_ids(self.strokes if sum(self.strokes) == len(self.controls)  # that is gone
                                            else (1,) * len(self.controls))  # ends)
        self.applied_ids = self.control_ids
        self.params = {name: list(v) if isinstance(v, list) else v for name, v in p.items()}
        self.set_symmetry(step.symmetry)
        self.hold = True
        self.error = None
