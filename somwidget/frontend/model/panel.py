"""The panel model: what every panel of a session shows and does, with no UI. The web app's trame panel
(web/panel.py) and the notebook's ipywidgets panel (notebook/panel.py) bind their widgets to one of these:

- the fields: the settings' declarations (backend/schedule.py, SETTINGS) and their values as the session holds
  them;
- the rows: one per feature dimension (name, role, metric weight) and one per control (colour, position, gap);
- the status line and the run button's label (Pause / Resume / Train: what a press does now), from a frame;
- the actions (ACTIONS: train or pause, undo, redo, reset, the preset again) and the edits (a parameter, a metric
  weight, a control's radius, the symmetry group), each returning the message a panel shows when the session
  refuses it (None when it took it);
- the variants: a sweep of the current design, its thumbnails and captions, and picking one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...backend import metrics, schedule
from ...backend import presets as _presets
from ...backend.presets import hex_colour
from ...backend.symmetry import Symmetry
from .controls import check_index
from .frames import Frame
from .session import Session
from .settings import PARAMETERS
from .variants import MAX_GALLERY_VARIANTS, THUMBNAIL, VARIED, Variants, vary_around
from .variants import sweep as sweep_variants


@dataclass(frozen=True)
class Action:
    """A button every panel has."""

    name: str
    label: str
    icon: str  # a Material Design icon name (mdi-...), for the web; the notebook maps it to Font Awesome
    help: str


ACTIONS: tuple[Action, ...] = (
    Action("toggle_training", "Train", "play", "Train or pause the map"),
    Action("undo", "Undo", "undo", "Undo the last step (a drag, a setting, a preset...); Ctrl+Z"),
    Action("redo", "Redo", "redo", "Redo the step undone last; Ctrl+Shift+Z"),
    Action("reset", "Reset", "restore", "Back to the start mesh and the whole schedule runs again; your controls "
                                        "stay where they are (the preset's own controls: Reload)"),
    Action("reload_preset", "Reload", "reload", "Reload this preset as it starts: its own controls and start mesh "
                                                "(one undo step); choosing it again in the menu does the same"),
    Action("refine", "Refine", "vector-triangle", "Subdivide the clay, its shape kept: every face split in four "
                                                  "(one undo step)"),
)
ACTION_NAMES = tuple(a.name for a in ACTIONS)
#: What each action's button says it does (the tooltip in every panel).
ACTION_HELP = {a.name: a.help for a in ACTIONS}
#: The run button's tooltip for each of its labels (PanelModel.train_label).
TRAIN_HELP = {"Pause": "Pause the training",
              "Resume": "Go on with the schedule from where it stopped",
              "Train": "Train again: a local restart from the current shape"}
#: The radial groups a panel offers (any n from 2 to 32 is one call of session.settings.set_symmetry away).
RADIAL_CHOICES = (2, 3, 4, 5, 6, 8, 12, 16)
RADIAL_MIRRORED_CHOICES = (3, 4, 6, 8)
#: What every panel shows under its reach slider.
REACH_HELP = schedule.BY_NAME["reach"].help
#: What a panel shows beside each control's radius.
RADIUS_HELP = schedule.BY_NAME["radius"].help
#: A panel's export menu: (extension, label) of each format io.export_mesh writes, the first chosen at the start.
EXPORT_CHOICES: tuple[tuple[str, str], ...] = (
    ("obj", "OBJ (mesh, colours)"), ("stl", "STL (3-D printing)"), ("3dm", "Rhino .3dm (mesh, controls)"),
    ("glb", "GLB (mesh, controls)"), ("gltf", "glTF (mesh, controls)"), ("ply", "PLY (mesh, colours)"))
#: What a panel shows beside the gaps of the controls table.
GAP_HELP = ("The distance from each control (and its mirrored copy) to its nearest node: small when the clay has "
            "reached the control.")


#: A control farther than this share of the clay's size (`clay_size`) from its nearest node is off the clay: the
#: controls table marks its gap and the view draws a thin line from it to that node (transport/display.py sends the
#: distance as the topology's `off_clay_gap`).
OFF_CLAY = 0.03
#: The gap cell of a control off the clay, in every panel: a quiet amber mark, and what it means.
OFF_CLAY_STYLE = "background: #fff1c2; color: #7a4a00; font-weight: 600; border-radius: 3px"
OFF_CLAY_HELP = (f"Off the clay: farther than {OFF_CLAY:.0%} of the size of the clay from its nearest node (the view "
                 "draws a thin line to that node). It pulls that node while the map trains: press Train, or drag "
                 "the control onto the clay.")  # no quotes: it goes into a Vue binding
#: A coordinate within this share of the clay's size of zero is shown as 0 (float noise such as 3.69e-17).
ZERO_SHARE = 1e-6


def clay_size(preset) -> float:
    """The clay's size: its start mesh's bounding diagonal (what a radius and a gap are measured against)."""
    return metrics.bounding_diagonal(preset.weights[:, list(preset.layout.position)]) or 1.0


def coordinate_text(x: float, size: float) -> str:
    """A coordinate as the controls table shows it: 3 significant digits, 0 within ZERO_SHARE x `size` of zero."""
    return "0" if abs(x) < ZERO_SHARE * size else f"{x:.3g}"


def fmt(x: float | None, digits: int = 3) -> str:
    """A number as a panel shows it ("-" for none)."""
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def field_text(setting: schedule.Setting, value) -> str | float | bool:
    """A setting's value as its widget holds it: a flag for a switch, a number for a slider, text for a field (an
    integer whole, a real number to 6 digits)."""
    if setting.kind == "bool":
        return bool(value)
    if setting.widget == "slider":
        return float(value)
    return str(value) if setting.kind == "int" else fmt(value, 6)


def slider_digits(setting: schedule.Setting) -> int:
    """The digits after the point a slider shows: as many as its step has."""
    step = setting.slider[2] if setting.slider else 1
    return max(0, -math.floor(math.log10(step))) if step < 1 else 0


def other_dims(layout) -> tuple[int, ...]:
    """A layout's feature dims that are neither position nor colour (a direction, a length, any other feature)."""
    return tuple(d for d in range(layout.n_dims) if d not in layout.position and d not in layout.colour)


def numbers(text, count: int, what: str) -> list[float]:
    """`count` numbers typed in a field, between commas or spaces; ValueError naming `what` otherwise."""
    parts = [t for t in str(text).replace(",", " ").split() if t]
    try:
        values = [float(t) for t in parts]
    except ValueError:
        values = []
    if len(values) != count:
        raise ValueError(f"{what}: expected {count} numbers (as in \"0.5, -1, 2\"), got {str(text)[:40]!r}")
    return values


class PanelModel:
    """One panel's view of a Session (see the module's docstring)."""

    fields = PARAMETERS
    metric = schedule.BY_NAME["metric_weights"]
    max_variants = MAX_GALLERY_VARIANTS
    thumbnail = THUMBNAIL  # a gallery thumbnail's size on screen (CSS pixels)
    varied = tuple(VARIED)

    def __init__(self, session: Session) -> None:
        self.session = session
        self.variants: Variants | None = None  # the latest sweep's

    # -- edits and actions: None when the session took it, else the message to show -------------------------------
    @staticmethod
    def attempt(fn: Callable, *args) -> str | None:
        try:
            fn(*args)
        except (ValueError, RuntimeError, TypeError) as exc:
            return str(exc)
        return None

    def set(self, name: str, value) -> str | None:
        return self.attempt(self.session.set_parameter, name, value)

    def set_metric(self, dim, value) -> str | None:
        return self.attempt(self.session.settings.set_metric_weight, dim, value)

    def run(self, action: str) -> str | None:
        if action not in ACTION_NAMES:
            return f"unknown action {action!r}"
        return self.attempt(getattr(self, action))

    def toggle_training(self) -> None:
        """Pause a running map; otherwise train (a settled run restarts locally), as the button says."""
        if self.session.frame.running:
            self.session.pause()
        else:
            self.session.train()

    def undo(self) -> None:
        self.session.undo()

    def redo(self) -> None:
        self.session.redo()

    def reset(self) -> None:
        self.session.reset()

    def refine(self) -> None:
        self.session.refine()

    def reload_preset(self) -> None:
        """The current preset again, as it starts (one undo step); a loaded mesh or session: its own start."""
        preset = self.session.preset
        self.session.load_preset(preset.name if preset.name in _presets.PRESETS else preset)

    # -- what the panel shows ----------------------------------------------------------------------------------
    def values(self) -> dict:
        """Each field's value as the session holds it (`field_text`), and the metric weights."""
        p = self.session.parameters
        out: dict[str, str | float | bool | list[float]] = {f.name: field_text(f, p[f.name]) for f in self.fields}
        out["metric_weights"] = [float(x) for x in p["metric_weights"]]
        out["group"] = p["group"]
        return out

    def recovered_message(self) -> str:
        """What the panel's banner says about a session brought back (which state came back), "" for any other."""
        return (self.session.recovered or {}).get("message", "")

    def notice_message(self) -> str:
        """What the panel's notice says about the saved sessions that could not be read whole (what was wrong, in
        which file, what came back and where the folder is kept), "" when there is none."""
        return " ".join(self.session.notices)

    @staticmethod
    def train_label(frame: Frame) -> str:
        """What the run button does now: Pause a running map, Resume one stopped part way through its schedule
        (paused, or held after an undo), Train a settled one (a local restart)."""
        if frame.running:
            return "Pause"
        return "Resume" if frame.iteration < frame.iterations else "Train"

    @staticmethod
    def control_count(frame: Frame) -> tuple[int, int]:
        """(controls, with their copies) as the person counts them: a stroke is one control (one row of the controls
        table), and each has as many copies as the symmetry group makes."""
        samples = max(1, frame.n_controls)
        rows = len(frame.strokes) if sum(frame.strokes) == frame.n_controls else frame.n_controls
        return rows, rows * max(1, len(frame.gaps) // samples)

    @classmethod
    def controls_text(cls, frame: Frame) -> str:
        """"9 controls (18 with their copies)", "1 control (16 with its copies)", "3 controls" without a group."""
        k, k_eff = cls.control_count(frame)
        said = f"{k} control{'s' * (k != 1)}"
        return said if k_eff == k else f"{said} ({k_eff} with {'its' if k == 1 else 'their'} copies)"

    def status(self, frame: Frame) -> dict:
        k, k_eff = self.control_count(frame)
        gaps = frame.gaps
        return {
            "iteration": frame.iteration, "S": frame.iterations, "progress": round(100.0 * frame.progress, 1),
            "running": frame.running, "paused": frame.paused,
            "state": "training" if frame.running else ("paused" if frame.paused else "converged"),
            "cycle_ms": fmt(frame.cycle_time * 1e3, 3) if frame.cycle_time > 0 else "-",
            "fps": fmt(self.session.frames_per_second, 3), "n_vertices": int(frame.positions.shape[0]), "k": k,
            "k_eff": k_eff, "controls_text": self.controls_text(frame),
            "max_gap": fmt(float(gaps.max()) if len(gaps) else 0.0, 3),
            "can_undo": frame.history[0] > 0, "can_redo": frame.history[1] > 0, "held": frame.held,
            "train_label": self.train_label(frame), "train_help": TRAIN_HELP[self.train_label(frame)],
        }

    @staticmethod
    def control_rows(frame: Frame) -> list[dict]:
        """One row per control, a stroke's samples in one row: its index (a stroke's first sample's), its stable id
        (the number the views show), colour ('#rrggbb'), position ("x, y, z"; a stroke's first sample's: typed, the
        whole stroke moves by as much), its other features' values (the dims that are neither position nor colour,
        `other_dims`; "" when there are none), gap text (original / mirror; a stroke's largest), `off` (a gap over
        OFF_CLAY of the clay's size), radius and `samples` (1, or a stroke's count). Position and features are written
        as a panel's field takes them back (a coordinate within ZERO_SHARE of the size of zero as 0)."""
        k, gaps = frame.n_controls, frame.gaps
        colours = frame.control_display_colours[:k]
        others = other_dims(frame.preset.layout)
        size = clay_size(frame.preset)
        ids = frame.control_ids if len(frame.control_ids) == k else tuple(range(k))
        runs = frame.strokes if sum(frame.strokes) == k else (1,) * k
        rows, i = [], 0
        for n in runs:
            run = range(i, i + n)
            g = [max(float(gaps[j]) for j in run)] if i < len(gaps) else []
            if len(gaps) >= 2 * k:  # mirrored copy j sits at k + j
                g.append(max(float(gaps[k + j]) for j in run))
            radius = float(frame.radii[i]) if i < len(frame.radii) else 0.0
            rows.append({"i": i, "id": int(ids[i]), "samples": n, "colour": hex_colour(colours[i]),
                         "position": ", ".join(coordinate_text(float(x), size) for x in frame.control_positions[i]),
                         "features": ", ".join(f"{float(frame.controls[i, d]):.3g}" for d in others),
                         "gap": " / ".join(f"{x:.3f}" for x in g), "off": bool(g) and max(g) > OFF_CLAY * size,
                         "radius": round(radius, 4)})
            i += n
        return rows

    @staticmethod
    def common_radius(frame: Frame) -> str:
        """Every control's radius when they all have one ("" when they differ): what the "all radii" field shows."""
        radii = np.asarray(frame.radii, np.float64)
        if not len(radii) or np.ptp(radii) > 1e-9 * max(1.0, float(radii.max())):
            return ""
        return f"{float(radii[0]):.4g}"

    def set_position(self, index, text) -> str | None:
        """Control `index` moved to a typed position: "x, y, z" (commas or spaces between the numbers); where it is
        already (Enter, then the field's change event), nothing happens."""
        def edit() -> None:
            controls = self.session.controls
            i = check_index("control", index, len(controls))
            position = numbers(text, 3, f"control {index} position")
            if not np.allclose(controls[i, list(self.session.layout.position)], position, rtol=1e-6, atol=1e-7):
                self.session.move_control(i, position)

        return self.attempt(edit)

    def set_features(self, index, text) -> str | None:
        """Control `index`'s other features (`other_dims`, in order) set from typed values, as one step."""
        def edit() -> None:
            controls = self.session.controls
            i = check_index("control", index, len(controls))
            layout = self.session.layout
            dims = other_dims(layout)
            values = controls[i].copy()
            typed = values.copy()
            typed[list(dims)] = numbers(text, len(dims), f"control {index} " + ", ".join(layout.names[d]
                                                                                         for d in dims))
            if not np.allclose(typed, values, rtol=1e-6, atol=1e-7):
                self.session.move_control(i, typed)

        return self.attempt(edit)

    def export_name(self, ext: str) -> str:
        """What an export (or a saved session) of this session is called: "sphere-2026-11-27-1042.obj"."""
        return self.session.files.export_name(ext)

    def export_bytes(self, ext: str) -> bytes:
        """The current mesh in format `ext` (EXPORT_CHOICES) as the file's bytes; ValueError naming the format."""
        import tempfile
        from pathlib import Path

        ext = str(ext).lower().lstrip(".")
        if ext not in dict(EXPORT_CHOICES):
            raise ValueError(f"export: unknown format {ext!r}; use one of {', '.join(dict(EXPORT_CHOICES))}")
        with tempfile.TemporaryDirectory(prefix="somwidget-export-") as folder:
            path = Path(folder) / self.export_name(ext)
            self.session.export_mesh(path)
            return path.read_bytes()

    def feature_names(self) -> str:
        """The names of the other features a control row lists ("" when there are none)."""
        layout = self.session.layout
        return ", ".join(layout.names[d] for d in other_dims(layout))

    @property
    def size(self) -> float:
        """The clay's size: its start mesh's bounding diagonal (what a radius is measured against)."""
        return clay_size(self.session.preset)

    def group_choices(self) -> list[tuple[str, str]]:
        """(label, spec) of the symmetry groups a panel offers, the one in effect among them."""
        choices = [("off", "none")] + [(f"mirror across {a}", f"mirror-{a}") for a in "xyz"]
        choices += [(f"{n}-fold about z", f"radial-{n}-z") for n in RADIAL_CHOICES]
        choices += [(f"{n}-fold about z, mirrored", f"radial-{n}-z-mirror") for n in RADIAL_MIRRORED_CHOICES]
        group = self.session.parameters["group"]
        if group not in [spec for _, spec in choices]:
            symmetry = Symmetry.parse(group)
            choices.append((symmetry.describe() if symmetry is not None else "off", group))
        return choices

    def set_group(self, spec) -> str | None:
        """A symmetry group by its spec ("none" for off)."""
        return self.attempt(self.session.settings.set_symmetry, spec if isinstance(spec, str) else "")

    def set_radius(self, index, value) -> str | None:
        return self.attempt(self.session.set_control_radius, index, value)

    def feature_rows(self) -> list[dict]:
        """One row per feature dimension: its index, name, role and metric weight."""
        layout = self.session.layout
        roles = {d: "position" for d in layout.position}
        roles.update({d: f"colour ({layout.colour_space})" for d in layout.colour})
        roles.update({d: "direction" for d in layout.direction})
        if layout.length is not None:
            roles[layout.length] = "length"
        weights = self.session.parameters["metric_weights"]
        return [{"d": d, "name": layout.names[d], "role": roles.get(d, "feature"), "colour": d in layout.colour,
                 "weight": float(weights[d])} for d in range(layout.n_dims)]

    def preset_options(self, labels: dict[str, str] | None = None) -> list[tuple[str, str]]:
        """(label, name) of every preset, and of the session's own when it is a loaded mesh or session."""
        labels = _presets.PRESET_LABELS if labels is None else labels
        options = [(labels.get(name, name), name) for name in _presets.PRESETS]
        preset = self.session.preset
        if preset.name not in _presets.PRESETS:
            options.append((f"{preset.title} (loaded, {preset.n_vertices} nodes)", preset.name))
        return options

    # -- variants ----------------------------------------------------------------------------------------------
    def sweep(self, n, jitter, vary, progress: Callable[[int, int], None] | None = None):
        """Train n variants of the current design (a local restart each, with the controls jittered and the chosen
        parameters varied around their values) on the session's device; returns (Variants, thumbnails)."""
        from ...backend import checks

        n = checks.integer_text("variants: how many", n, 1, MAX_GALLERY_VARIANTS)
        jitter = checks.real("variants: jitter", jitter, 0.0, 1.0)
        params = vary_around([name for name in vary if name in VARIED], self.session.parameters)
        variants = sweep_variants(self.session, n=n, jitter=jitter, params=params, progress=progress,
                                  device=self.session.training_device)
        thumbs = variants.thumbnails()
        self.variants = variants
        return variants, thumbs

    def caption(self, i: int, vary=()) -> str:
        """Variant i's figures (and the varied parameters' values) in a line."""
        v = self.variants
        if v is None:
            raise ValueError(f"variants: no variant #{i}: no sweep yet")
        return (f"#{i}: gap {v.metrics['gap'][i]:.3f}, spike {v.metrics['spike'][i]:.2f}"
                + "".join(f", {k} {fmt(x)}" for k, x in v.params[i].items() if k in vary))

    def pick(self, i) -> str | None:
        """Make variant i of the latest sweep the session's state (one undo step)."""
        if self.variants is None:
            return "variants: no variants yet: press Sweep first"
        error = self.attempt(self.variants.apply, i, self.session)
        return None if error is None else f"variants: {error}"


__all__ = ["PanelModel", "ACTIONS", "ACTION_HELP", "Action", "EXPORT_CHOICES", "GAP_HELP", "OFF_CLAY", "OFF_CLAY_HELP",
           "OFF_CLAY_STYLE", "RADIUS_HELP", "REACH_HELP", "clay_size", "fmt"]
