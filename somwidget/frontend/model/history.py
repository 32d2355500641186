"""Undo and redo: the states a session passed through, one per completed step.

A `Step` is everything a session needs to be put back exactly: the preset (mesh, layout), the controls, the
parameters, the weights and s. `History` keeps two stacks of them. Their weights are the bulk: the newest steps keep
theirs in memory up to `memory_bytes`; older ones are handed to a shelf (a folder of files: a temporary one, or the
session's autosave store, which keeps every step on disk) and read back when reached; past `disk_bytes` of steps in
all, or MAX_STEPS a stack, the oldest are forgotten. So a 65,536-vertex session (768 KiB of weights a step at 3 dims)
keeps MAX_STEPS steps with about 100 MiB in memory, never MAX_STEPS copies.
"""

from __future__ import annotations

import itertools
import logging
import os
import shutil
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from ...backend import checks

log = logging.getLogger(__name__)

#: The most steps kept for undo (and as many for redo).
MAX_STEPS = 200
#: Weights of the newest steps kept in memory, in bytes; older steps' weights are read back from disk when reached.
MEMORY_BYTES = 128 << 20
#: Weights of all the steps kept, in bytes (in memory and on disk); past this the oldest steps are forgotten.
DISK_BYTES = 2 << 30

_KEYS = itertools.count(1)


@dataclass(frozen=True)
class Step:
    """One state of a session. `weights` is an (N, n) float32 array, or the Path of a step file (`load_weights`).
    `key` names the step while the process lives (a copy with its weights elsewhere keeps it)."""

    preset: object
    controls: np.ndarray
    parameters: dict
    weights: np.ndarray | Path
    iteration: int
    radii: np.ndarray | None = None  # each control's radius (None: all 0)
    symmetry: object = None  # the Symmetry group in effect, or None
    strokes: tuple | None = None  # the lengths of the runs of controls that act as one (None: each alone)
    control_ids: tuple | None = None  # the controls' stable ids (None: new ones when put back)
    key: int = field(default_factory=lambda: next(_KEYS), compare=False)

    @property
    def nbytes(self) -> int:
        """Bytes of weights this step holds in memory."""
        return int(self.weights.nbytes) if isinstance(self.weights, np.ndarray) else 0

    @property
    def size(self) -> int:
        """Bytes of weights this step keeps, in memory or on disk."""
        if isinstance(self.weights, np.ndarray):
            return int(self.weights.nbytes)
        try:
            return self.weights.stat().st_size
        except OSError:
            return 0

    def loaded(self) -> Step:
        """This step with its weights in memory (OSError or ValueError when its file cannot be read)."""
        if isinstance(self.weights, np.ndarray):
            return self
        return replace(self, weights=load_weights(self.weights))


def load_weights(path: Path) -> np.ndarray:
    """The weights of a step file (an .npz with a "weights" member): finite float32 values within the engine's
    bounds (checks.MAX_MAGNITUDE). ValueError in plain words when the file is not one, OSError when it cannot be
    read."""
    try:
        with np.load(path, allow_pickle=False) as z:
            weights = z["weights"]
    except OSError:
        raise
    except Exception:  # zipfile's, zlib's and numpy's own words for a damaged file: ours are given instead
        raise ValueError(f"{path}: not a step file (cut short or damaged)") from None
    if weights.dtype != np.float32 or weights.ndim != 2 or not np.isfinite(weights).all() \
            or np.abs(weights).max(initial=0.0) > checks.MAX_MAGNITUDE:
        raise ValueError(f"{path}: not the weights of a step (finite float32 values up to {checks.MAX_MAGNITUDE:g})")
    return weights


class Shelf(Protocol):
    """Where a History's steps go on disk: `put(step)` writes the step (once) and returns its file; `drop(step)`:
    the history forgot it; `close()`: the history is closed."""

    def put(self, step: Step) -> Path: ...

    def drop(self, step: Step) -> None: ...

    def close(self) -> None: ...


class TemporaryShelf:
    """Steps' weights in a temporary folder of their own (made when first needed), deleted with it."""

    def __init__(self, parent: str | os.PathLike | None = None):
        self.parent = parent
        self.folder: Path | None = None
        self._files: dict[int, Path] = {}

    def put(self, step: Step) -> Path:
        if step.key in self._files:
            return self._files[step.key]
        if self.folder is None:
            if self.parent is not None:
                Path(self.parent).mkdir(parents=True, exist_ok=True)
            self.folder = Path(tempfile.mkdtemp(prefix="history-", dir=self.parent))
        path = self.folder / f"step-{step.key}.npz"
        with open(path, "wb") as f:
            np.savez(f, weights=np.asarray(step.weights, np.float32))
        self._files[step.key] = path
        return path

    def drop(self, step: Step) -> None:
        path = self._files.pop(step.key, None)
        if path is not None:
            try:
                path.unlink()
            except OSError:
                pass

    def close(self) -> None:
        self._files.clear()
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None


class History:
    """Undo and redo stacks of Steps with bounded memory and disk (see the module's docstring). `shelf`: where
    steps go on disk (default: a TemporaryShelf under `spill_dir`)."""

    def __init__(self, max_steps: int = MAX_STEPS, memory_bytes: int = MEMORY_BYTES, disk_bytes: int = DISK_BYTES,
                 spill_dir: str | os.PathLike | None = None, shelf: Shelf | None = None):
        self.max_steps = max_steps
        self.memory_bytes = memory_bytes
        self.disk_bytes = disk_bytes
        self.shelf: Shelf = shelf if shelf is not None else TemporaryShelf(spill_dir)
        self._undo: list[Step] = []
        self._redo: list[Step] = []

    @property
    def undo_count(self) -> int:
        return len(self._undo)

    @property
    def redo_count(self) -> int:
        return len(self._redo)

    def steps(self) -> tuple[list[Step], list[Step]]:
        """(undo steps, redo steps), oldest first: copies of the stacks (what the autosave writes)."""
        return list(self._undo), list(self._redo)

    def restore(self, undo: list[Step], redo: list[Step]) -> None:
        """Take over the stacks of a recovered session (its steps on the shelf already), then keep the bounds."""
        self.clear()
        self._undo, self._redo = list(undo), list(redo)
        self._bound()

    def push(self, before: Step) -> None:
        """A step begins: `before` is the state it started from. Redo steps are dropped."""
        self._discard(self._redo)
        self._redo = []
        self._undo.append(before)
        self._bound()

    def drop_last(self, step: Step) -> None:
        """Take back `step` if it is the newest (the gesture it began was refused)."""
        if self._undo and self._undo[-1] is step:
            self._discard([self._undo.pop()])

    def drop_redo(self) -> None:
        """Forget the newest redo step (a view's redo of its own undo took that undo back: nothing is left to redo)."""
        if self._redo:
            self._discard([self._redo.pop()])

    def undo(self, current: Step) -> Step | None:
        """The state before the latest step (None if there is none); `current` becomes the next redo."""
        return self._travel(self._undo, self._redo, current)

    def redo(self, current: Step) -> Step | None:
        """The state an undo left (None if there is none); `current` becomes the next undo."""
        return self._travel(self._redo, self._undo, current)

    def _travel(self, source: list[Step], dest: list[Step], current: Step) -> Step | None:
        """Take the top of `source` (in memory), leave `current` on `dest`. A step whose file cannot be read is
        forgotten, with a ValueError that says so."""
        if not source:
            return None
        step = source.pop()
        try:
            out = step.loaded()
        except (OSError, ValueError) as exc:
            self._discard([step])
            raise ValueError(f"this step cannot be read back from {step.weights} ({exc}); it is forgotten") from None
        dest.append(current)
        self._discard([step])
        self._bound()
        return out

    def clear(self) -> None:
        self._discard(self._undo + self._redo)
        self._undo, self._redo = [], []

    def close(self) -> None:
        self._undo, self._redo = [], []
        self.shelf.close()

    @property
    def memory_used(self) -> int:
        return sum(s.nbytes for s in self._undo + self._redo)

    # -- bounds -----------------------------------------------------------------------------------------------
    def _bound(self) -> None:
        for stack in (self._undo, self._redo):
            while len(stack) > self.max_steps:
                self._discard([stack.pop(0)])
        in_memory = 0  # the tops of both stacks (the steps reached next) keep their weights in memory
        for step in list(reversed(self._undo)) + list(reversed(self._redo)):
            if isinstance(step.weights, np.ndarray):
                if in_memory + step.nbytes <= self.memory_bytes:
                    in_memory += step.nbytes
                else:
                    self._spill(step)
        self._forget_past_disk()

    def _spill(self, step: Step) -> None:
        """Keep `step`'s weights on the shelf only (a disk that refuses keeps them in memory for now)."""
        try:
            path = self.shelf.put(step)
        except OSError as exc:
            log.warning("history: could not write a step to disk (%s); it stays in memory", exc)
            return
        for stack in (self._undo, self._redo):
            for i, s in enumerate(stack):
                if s is step:
                    stack[i] = replace(step, weights=path)

    def _forget_past_disk(self) -> None:
        """Oldest undo steps go first once all the steps' weights pass disk_bytes."""
        total = sum(s.size for s in self._undo + self._redo)
        while total > self.disk_bytes and self._undo:
            old = self._undo.pop(0)
            total -= old.size
            self._discard([old])

    def _discard(self, steps: list[Step]) -> None:
        for s in steps:
            self.shelf.drop(s)
