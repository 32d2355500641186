"""Design variants for a person: `sweep` draws n variants of a preset or of a session's current design, trains them
batched on the GPU (or the CPU, or a Dask cluster: backend/variants.py), and returns `Variants`: their arrays and
figures, a gallery picture, and a way back into a session as one undo step.

    import somwidget
    v = somwidget.sweep("car", n=256, jitter=0.05, params={"reach": (0.05, 0.2)})
    v.metrics["gap"].argmin()              # the variant that reaches its controls best
    v.picture("gallery.png")               # thumbnails of the first 16 (or v.picture(indices=[...]))
    session = v.session(best)              # a live session showing variant `best` (undo goes back to the preset)
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Mapping, Sequence

import numpy as np

from ...backend import presets as _presets
from ...backend import schedule
from ...backend.presets import Preset
from ...backend.variants import FIGURES, VariantPlan, plan_variants, run_plan

#: Thumbnails a gallery shows when no indices are given.
GALLERY_COUNT = 16
#: The apps' gallery thumbnails in CSS pixels: two to a row in a panel, large enough to compare designs by eye; drawn
#: at twice that, so they stay sharp on a high-density screen.
THUMBNAIL = (170, 136)
#: The apps' Variants sections: how many variants a sweep there trains at most (each gets a thumbnail).
MAX_GALLERY_VARIANTS = 48
#: The settings a Variants section may vary (each over its declared `vary` range around its current value).
VARIED = tuple(setting.name for setting in schedule.SETTINGS if setting.vary)
VARIANTS_HELP = ("Design variants: each control moved at random by up to the jitter (a share of the model's size), "
                 "the chosen schedule settings varied around their values, all trained at once from the current "
                 "shape. Pick one to continue from it (Undo goes back).")


def vary_around(names, parameters: Mapping) -> dict:
    """sweep's params for the apps' Variants sections: each named setting over its declared range around its value
    in `parameters` (a session's)."""
    unknown = sorted(set(names) - set(VARIED))
    if unknown:
        raise ValueError(f"vary: unknown parameter(s) {unknown}; expected some of {list(VARIED)}")
    return {name: schedule.BY_NAME[name].range_around(parameters[name]) for name in names}


class Variants:
    """n trained variants of one design.

    controls (n, k, dims), weights (n, N, dims), params (a dict per variant: its schedule, schedule.KEYS),
    metrics (each of gap, spike, symmetry, size: an (n,) array; see backend.variants.figures), preset (the
    mesh they share), source (the Session they were swept from, or None)."""

    def __init__(self, plan: VariantPlan, weights: np.ndarray, figures: dict, preset: Preset, source=None) -> None:
        self.plan = plan
        self.controls = plan.controls
        self.weights = weights
        self.params = [plan.params(i) for i in range(plan.n_variants)]
        self.metrics = figures
        self.preset = preset
        self.source = source

    def __len__(self) -> int:
        return self.plan.n_variants

    def __repr__(self) -> str:
        return f"<Variants: {len(self)} of {self.preset.title!r}>"

    def _index(self, i) -> int:
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)) or not 0 <= int(i) < len(self):
            raise ValueError(f"variant: expected an index 0 .. {len(self) - 1}, got {i!r}")
        return int(i)

    def table(self) -> list[dict]:
        """A row per variant: its index, schedule and figures (for a DataFrame or a printed table)."""
        return [{"variant": i, **self.params[i], **{name: float(self.metrics[name][i]) for name in FIGURES}}
                for i in range(len(self))]

    def best(self, figure: str = "gap") -> int:
        """The variant with the least `figure` (gap, spike or symmetry)."""
        if figure not in FIGURES:
            raise ValueError(f"figure: expected one of {list(FIGURES)}, got {figure!r}")
        return int(np.argmin(self.metrics[figure]))

    def picture(self, path=None, indices: Sequence[int] | None = None, columns: int | None = None,
                size: tuple[int, int] = (240, 200)) -> np.ndarray:
        """A gallery of thumbnails (pyvista, off-screen), each captioned with its index: (H, W, 3) uint8, written
        to `path` if given. indices: which variants (default: the first 16)."""
        from .picture import save_image

        chosen = list(range(min(len(self), GALLERY_COUNT))) if indices is None else [self._index(i) for i in indices]
        if not chosen:
            raise ValueError("indices: expected at least one variant")
        columns = columns or min(len(chosen), max(1, math.ceil(math.sqrt(len(chosen) * 1.5))))
        rows = math.ceil(len(chosen) / columns)
        width, height = int(size[0]), int(size[1])
        sheet = np.full((rows * height, columns * width, 3), 255, np.uint8)
        for slot, i in enumerate(chosen):
            img = self._render(i, (width, height), title=f"#{i}", zoom=1.25)
            r, c = divmod(slot, columns)
            sheet[r * height:(r + 1) * height, c * width:(c + 1) * width] = img[:height, :width]
        if path is not None:
            save_image(path, sheet)
        return sheet

    def thumbnails(self, size: tuple[int, int] = (2 * THUMBNAIL[0], 2 * THUMBNAIL[1])) -> list[np.ndarray]:
        """One picture per variant, uncaptioned (the apps' galleries label them), framed closer than `picture`'s
        tiles: (H, W, 3) uint8 each."""
        return [self._render(i, size, zoom=1.1) for i in range(len(self))]

    def _render(self, i: int, size: tuple[int, int], **options) -> np.ndarray:
        """Variant i as picture.render draws a preset: its clay and its controls."""
        from .picture import render

        return render(dataclasses.replace(self.preset, controls=self.controls[i]), weights=self.weights[i],
                      size=size, **options)

    def apply(self, i: int, session=None) -> None:
        """Make variant i the current state of `session` (default: the session it was swept from): its controls,
        schedule and trained weights, nothing training until the next intent; one undo step."""
        i = self._index(i)
        session = session if session is not None else self.source
        if session is None:
            raise ValueError("session: these variants were swept from a preset; pass a session of that preset, or "
                             "use .session(i) for a new one")
        if session.preset.n_vertices != self.plan.n_vertices or session.n_dims != self.weights.shape[2]:
            raise ValueError(f"session: its mesh ({session.preset.n_vertices} vertices, {session.n_dims} dims) is "
                             f"not the variants' ({self.plan.n_vertices} vertices, {self.weights.shape[2]} dims)")
        session.files.apply_variant(self.controls[i], self.params[i], self.weights[i])

    def session(self, i: int, **options):
        """A new Session of the variants' preset showing variant i (undo goes back to the preset's start).
        `options` go to Session (device, frame_rate...)."""
        from .session import Session

        i = self._index(i)
        session = Session(self.preset, **options)
        self.apply(i, session)
        return session


def _text_progress(done: int, total: int) -> None:
    """A one-line progress bar on stderr."""
    width = 30
    filled = int(width * done / max(1, total))
    sys.stderr.write(f"\rvariants [{'#' * filled}{'.' * (width - filled)}] {done}/{total}")
    if done >= total:
        sys.stderr.write("\n")
    sys.stderr.flush()


def sweep(preset_or_session="car", n: int = 64, jitter: float = 0.05, params: Mapping | None = None, seed: int = 0,
          device: str | None = None, client=None, progress=True, batch_size: int | None = None) -> Variants:
    """Train n variants of a design in batches and return them as `Variants`.

    preset_or_session: a preset name or Preset (each variant a whole run from its start mesh, as reset() then
        train()), or a Session (each a local restart from the session's current weights, as a move of its
        controls would be);
    jitter: each control moves by up to this share of the model's size (its bounding diagonal);
    params: per schedule setting (schedule.KEYS) a (low, high) range, a list of values or one value; the others
        keep the design's;
    seed: the same seed gives the same variants; device: where to train here (None: the GPU when there is one);
    client: a dask.distributed.Client to spread the batches over its workers (the results are the same);
    progress: True for a progress bar on stderr, False for none, or a callable progress(done, total).
    """
    source = None
    if hasattr(preset_or_session, "session") and not isinstance(preset_or_session, (str, Preset)):
        preset_or_session = preset_or_session.session  # the widget of show()
    if isinstance(preset_or_session, str):
        preset = _presets.get_preset(preset_or_session)
    elif isinstance(preset_or_session, Preset):
        preset = preset_or_session
    elif hasattr(preset_or_session, "files") and hasattr(preset_or_session.files, "apply_variant"):
        source = preset_or_session
    else:
        raise ValueError("sweep: expected a preset name, a Preset or a Session, got "
                         f"{type(preset_or_session).__name__}")
    metric: np.ndarray | None  # None: the Som's default
    if source is not None:
        snap = source.files.snapshot()
        preset = snap["preset"]
        p = snap["parameters"]
        start, controls = snap["weights"], snap["controls"]
        base = {key: p[key] for key in schedule.KEYS}
        mirror, metric = tuple(p["mirror"]), np.asarray(p["metric_weights"], np.float32)
        radii, group, rule, strokes = snap["radii"], snap["symmetry"], snap["smoothing_rule"], snap["strokes"]
    else:
        start, controls = preset.weights, preset.controls
        base = {key: getattr(preset, key) for key in schedule.KEYS}
        mirror, metric = preset.mirror, preset.metric_weights
        radii, group, rule, strokes = preset.control_radii(), preset.symmetry, preset.smoothing_rule, preset.strokes
    radial = group if group is not None and group.kind == "radial" else None
    if not len(controls):
        raise ValueError("sweep: the design has no controls to vary; add one first")
    plan = plan_variants(preset.topology, start, controls, base, n, jitter=jitter, params=params, seed=seed,
                         restart=source is not None, mirror=mirror, smooth_dims=preset.smooth_dims,
                         metric_weights=metric, position_dims=preset.layout.position, radii=radii, symmetry=radial,
                         smoothing_rule=rule, origin=preset.weights if source is not None else None, strokes=strokes)
    report = _text_progress if progress is True else (progress or None)
    weights, figures = run_plan(plan, device=device, client=client, batch_size=batch_size, progress=report)
    return Variants(plan, weights, figures, preset, source)


__all__ = ["Variants", "sweep", "vary_around", "GALLERY_COUNT", "MAX_GALLERY_VARIANTS", "VARIED"]
