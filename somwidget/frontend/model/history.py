"""Undo and redo: the states a session passed through, one per completed gesture.

A `Step` is everything a session needs to be put back exactly: the preset (mesh, layout), the controls, the
parameters, the weights and s. `History` keeps two stacks of them. Their weights are the bulk: the newest steps keep
theirs in memory up to `memory_bytes`; older ones are written to `spill_dir` (one .npy each) up to `disk_bytes`
and read back when reached; the oldest beyond both bounds are forgotten. So a 65,536-vertex session (768 KiB of
weights a step at 3 dims) keeps MAX_STEPS steps with about 100 MiB in memory, never MAX_STEPS copies.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

#: The most steps kept for undo (and as many for redo).
MAX_STEPS = 200
#: Weights of the newest steps kept in memory, in bytes; older steps' weights go to disk.
MEMORY_BYTES = 128 << 20
#: Weights written to disk for older steps, in bytes; past this the oldest steps are forgotten.
DISK_BYTES = 2 << 30


@dataclass(frozen=True)
class Step:
    """One state of a session. `weights` is an (N, n) float32 array, or a Path to one saved with np.save."""

    preset: object
    controls: np.ndarray
    parameters: dict
    weights: np.ndarray | Path
    iteration: int
    radii: np.ndarray | None = None  # each control's radius (None: all 0)
    symmetry: object = None  # the Symmetry group in effect, or None
    strokes: tuple | None = None  # the lengths of the runs of controls that act as one (None: each alone)

    @property
    def nbytes(self) -> int:
        return int(self.weights.nbytes) if isinstance(self.weights, np.ndarray) else 0

    def loaded(self) -> Step:
        """This step with its weights in memory."""
        if isinstance(self.weights, np.ndarray):
            return self
        return replace(self, weights=np.load(self.weights, allow_pickle=False))


class History:
    """Undo and redo stacks of Steps with bounded memory and disk (see the module's docstring)."""

    def __init__(self, max_steps: int = MAX_STEPS, memory_bytes: int = MEMORY_BYTES, disk_bytes: int = DISK_BYTES,
                 spill_dir: str | os.PathLike | None = None):
        self.max_steps = max_steps
        self.memory_bytes = memory_bytes
        self.disk_bytes = disk_bytes
        self._spill_root = spill_dir
        self._spill: Path | None = None
        self._undo: list[Step] = []
        self._redo: list[Step] = []
        self._files = 0

    @property
    def undo_count(self) -> int:
        return len(self._undo)

    @property
    def redo_count(self) -> int:
        return len(self._redo)

    def push(self, before: Step) -> None:
        """A gesture completes: `before` is the state it started from. Redo steps are dropped."""
        self._discard(self._redo)
        self._redo = []
        self._undo.append(before)
        self._bound()

    def drop_last(self, step: Step) -> None:
        """Take back `step` if it is the newest (the gesture it began was refused)."""
        if self._undo and self._undo[-1] is step:
            self._discard([self._undo.pop()])

    def undo(self, current: Step) -> Step | None:
        """The state before the latest step (None if there is none); `current` becomes the next redo."""
        return self._travel(self._undo, self._redo, current)

    def redo(self, current: Step) -> Step | None:
        """The state an undo left (None if there is none); `current` becomes the next undo."""
        return self._travel(self._redo, self._undo, current)

    def _travel(self, source: list[Step], dest: list[Step], current: Step) -> Step | None:
        """Take the top of `source` (in memory), leave `current` on `dest`."""
        if not source:
            return None
        step = source.pop()
        dest.append(current)
        self._bound()
        return self._load(step)

    def clear(self) -> None:
        self._discard(self._undo + self._redo)
        self._undo, self._redo = [], []

    def close(self) -> None:
        self.clear()
        if self._spill is not None:
            shutil.rmtree(self._spill, ignore_errors=True)
            self._spill = None

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
                    self._spill_step(step)
        self._forget_past_disk()

    def _spill_step(self, step: Step) -> None:
        if self._spill is None:
            root = self._spill_root
            if root is not None:
                Path(root).mkdir(parents=True, exist_ok=True)
            self._spill = Path(tempfile.mkdtemp(prefix="history-", dir=root))
        self._files += 1
        path = self._spill / f"step-{self._files}.npy"
        np.save(path, step.weights, allow_pickle=False)
        for stack in (self._undo, self._redo):
            for i, s in enumerate(stack):
                if s is step:
                    stack[i] = replace(step, weights=path)

    def _forget_past_disk(self) -> None:
        """Oldest undo steps go first once the files pass disk_bytes."""
        def size(s: Step) -> int:
            return s.weights.stat().st_size if isinstance(s.weights, Path) and s.weights.exists() else 0

        total = sum(size(s) for s in self._undo + self._redo)
        while total > self.disk_bytes and self._undo:
            old = self._undo.pop(0)
            total -= size(old)
            self._discard([old])

    def _load(self, step: Step) -> Step:
        out = step.loaded()
        self._discard([step])
        return out

    @staticmethod
    def _discard(steps: list[Step]) -> None:
        for s in steps:
            if isinstance(s.weights, Path):
                try:
                    s.weights.unlink()
                except OSError:
                    pass
