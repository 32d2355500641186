"""somwidget inside Jupyter: an ipywidgets panel beside the live 3-D clay view, both bound to one Session.

`show(...)` returns a `SomWidget` (an ipywidgets HBox): on the left the `Panel` (preset, S, l_start, l_end,
smoothing, reach, symmetry, the feature dimensions with their metric weights, Train / Pause / Reset, Undo / Redo,
progress, the controls and their gaps), on the right the `ClayWidget` (widget.py): the browser's own view of the
clay, fed frames over the kernel's comm. Both talk to the same `Session`:

    panel widget --set_iterations / set_l_start / ... --> Session --frames--> panel (iteration, gaps, parameters)
    view (drag a sphere) --grab / move / release--> Session --frames--> every view and panel

The panel works without a frontend: its widgets are plain Python objects, so tests (and scripts) can set
`panel.S.value = 300` and watch the session follow, or move a control and watch `panel.progress.value` restart.
"""

from __future__ import annotations

import html as _html
import logging
import math
import os
import threading
import time
from contextlib import contextmanager
from pathlib import Path

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")  # the saved notebook's picture

import ipywidgets as widgets  # noqa: E402

from ...backend import presets as _presets  # noqa: E402
from ...backend.presets import Preset  # noqa: E402
from ..model.parameters import BY_NAME as _PARAM  # noqa: E402
from ..model.parameters import GAP_HELP, METRIC_WEIGHT  # noqa: E402
from ...backend.presets import hex_colour  # noqa: E402
from ..model import Frame, Session  # noqa: E402
from ..model.parameters import REACH_HELP  # noqa: E402
from ..model.variants import MAX_GALLERY_VARIANTS, VARIANTS_HELP, VARIED, vary_around  # noqa: E402
from ..model.variants import sweep as sweep_variants  # noqa: E402
from .widget import ClayWidget  # noqa: E402

log = logging.getLogger(__name__)

#: The panel refreshes its numbers at most this often per second (frames arrive at up to 60 a second).
PANEL_HZ = 8
#: The S slider's range and step (the session accepts any S >= 1 through `session.set_iterations`; the slider's
#: range widens to show a larger one).
S_SLIDER = _PARAM["iterations"].slider
#: Text blocks: the notebook's default line height spreads small print apart.
_BLOCK = '<div style="line-height:1.35">{}</div>'

#: The dropdown's preset names: the web app's, shorter for the case studies (the panel is narrow).
_PRESET_LABELS = {**_presets.PRESET_LABELS, "space-grid": "Case study 1: space grid",
                  "car": "Case study 2: car (colours)", "lines": "Case study 3: lines (8-D)"}


# --------------------------------------------------------------------------------------------------------------
# The panel: ipywidgets <-> Session
# --------------------------------------------------------------------------------------------------------------
class Panel(widgets.VBox):
    """ipywidgets bound both ways to a Session.

    A widget change sends an intent to the session (a refused value shows its message in `error` and the widget
    goes back to the session's value at the next refresh). Frames from the session refresh the widgets at most
    `refresh_hz` times a second, on a thread of the panel's own (`auto_refresh=False`: only when `refresh()` is
    called). Parameters changed elsewhere (the web app in a browser tab, a script) show up here too.
    """

    def __init__(self, session: Session, refresh_hz: float = PANEL_HZ, auto_refresh: bool = True):
        self.session = session
        self.refresh_hz = float(refresh_hz)
        self._lock = threading.RLock()
        self._local = threading.local()
        self._latest: Frame | None = None
        self._wake = threading.Event()
        self._closed = False
        self._generation = None
        self._preset_name = None
        self.refreshes = 0  # refreshes applied (for tests)
        self.last_frame_seq = -1

        style = {"description_width": "70px"}
        wide = widgets.Layout(width="330px")
        self.title = widgets.HTML()
        self.preset = widgets.Dropdown(description="preset", style=style, layout=widgets.Layout(width="290px"))
        self.reload_button = widgets.Button(icon="rotate-left", layout=widgets.Layout(width="36px"),
                                            tooltip="This preset again as it starts: its own controls and start mesh")
        self.train_button = widgets.Button(description="Pause", icon="pause", layout=widgets.Layout(width="100px"),
                                           tooltip="Train / pause the map")
        self.reset_button = widgets.Button(description="Reset", icon="refresh", layout=widgets.Layout(width="100px"),
                                           tooltip="Back to the start mesh, the whole schedule again (the controls "
                                                   "stay)")
        self.undo_button = widgets.Button(description="Undo", icon="undo", layout=widgets.Layout(width="80px"),
                                          tooltip="Undo the last step (a drag, a setting, a preset...)")
        self.redo_button = widgets.Button(description="Redo", icon="repeat", layout=widgets.Layout(width="80px"),
                                          tooltip="Redo the step undone last")
        self.progress = widgets.IntProgress(min=0, max=1, value=0, description="progress", style=style,
                                            layout=wide)
        self.status = widgets.HTML()
        # the sliders and their tooltips come from the parameters' declaration (parameters.py)
        def slider(name: str, kind, digits: str | None = None, description: str | None = None):
            p = _PARAM[name]
            lo, hi, step = p.slider
            extra = {"readout_format": digits} if digits else {}
            return kind(description=description or p.label, min=lo, max=hi, step=step, continuous_update=False,
                        style=style, layout=wide, tooltip=p.help, **extra)

        self.S = slider("iterations", widgets.IntSlider, description="S")
        self.l_start = slider("l_start", widgets.FloatSlider, ".3f")
        self.l_end = slider("l_end", widgets.FloatSlider, ".3f")
        self.smoothing = slider("smoothing", widgets.FloatSlider, ".2f")
        self.reach = slider("reach", widgets.FloatSlider, ".2f")
        self.symmetry = widgets.Checkbox(description=_PARAM["symmetry"].label, indent=False,
                                         tooltip=_PARAM["symmetry"].help)
        self.features_box = widgets.VBox()
        self.metric: list[widgets.BoundedFloatText] = []
        self.controls_html = widgets.HTML()
        self.error = widgets.HTML()
        self.variants = VariantsSection(session, self._intent)

        super().__init__([
            self.title, widgets.HBox([self.preset, self.reload_button]),
            widgets.HBox([self.train_button, self.undo_button, self.redo_button, self.reset_button]),
            self.progress, self.status,
            widgets.HTML(_BLOCK.format("<b>Schedule</b> <small>(alpha(s) from l_start to l_end over S cycles)"
                                       "</small>")),
            self.S, self.l_start, self.l_end, self.smoothing, self.reach,
            widgets.HTML(_BLOCK.format(f"<small>{_html.escape(REACH_HELP)}</small>")),
            self.symmetry,
            widgets.HTML(_BLOCK.format("<b>Feature dimensions</b> <small>(metric weights m<sub>j</sub> of the "
                                       "winner search)</small>")),
            self.features_box,
            widgets.HTML(_BLOCK.format(f'<b title="{_html.escape(GAP_HELP)}">Controls</b> <small>(gap: distance to '
                                       'the nearest node, original / mirror)</small>')),
            self.controls_html, self.variants, self.error,
        ], layout=widgets.Layout(width="360px", min_width="360px", padding="4px"))

        for w, setter in ((self.S, session.set_iterations), (self.l_start, session.set_l_start),
                          (self.l_end, session.set_l_end), (self.smoothing, session.set_smoothing),
                          (self.reach, session.set_reach), (self.symmetry, session.set_symmetry)):
            w.observe(lambda change, setter=setter: self._intent(setter, change["new"]), names="value")
        self.preset.observe(self._preset_chosen, names="value")
        self.train_button.on_click(lambda _b: self._intent(self._toggle_training))
        self.reset_button.on_click(lambda _b: self._intent(session.reset))
        self.undo_button.on_click(lambda _b: self._intent(session.undo))
        self.reload_button.on_click(lambda _b: self._reload_preset())
        self.redo_button.on_click(lambda _b: self._intent(session.redo))

        self.refresh()
        session.add_listener(self._on_frame, replay=False)
        self._thread = None
        if auto_refresh:
            self._thread = threading.Thread(target=self._refresh_loop, name="somwidget-panel", daemon=True)
            self._thread.start()

    # -- widget -> session ------------------------------------------------------------------------------------
    @contextmanager
    def _syncing(self):
        """While the panel itself writes widget values (in this thread), their observers send no intent."""
        before = getattr(self._local, "syncing", False)
        self._local.syncing = True
        try:
            yield
        finally:
            self._local.syncing = before

    def _intent(self, fn, *args) -> bool:
        if getattr(self._local, "syncing", False) or self._closed:
            return False
        with self._lock:
            try:
                fn(*args)
            except (ValueError, RuntimeError) as exc:
                self.error.value = f'<span style="color:#b00020">{_html.escape(str(exc))}</span>'
                self._wake.set()  # the next refresh puts the widget back to the session's value
                return False
            self.error.value = ""
        self._wake.set()
        return True

    def _toggle_training(self) -> None:
        frame = self.session.frame
        if frame.running:
            self.session.pause()
        else:
            self.session.train()

    def _preset_chosen(self, change) -> None:
        name = change["new"]
        if getattr(self._local, "syncing", False) or not name or name == self.session.preset.name:
            return
        self.status.value = f"<i>loading {_html.escape(str(name))}...</i>"
        if self._intent(self.session.load_preset, name):
            self.refresh()

    def _reload_preset(self) -> None:
        """The current preset again, as it starts (one undo step)."""
        preset = self.session.preset
        if self._intent(self.session.load_preset, preset.name if preset.name in _presets.PRESETS else preset):
            self.refresh()

    def set_metric_weight(self, dim: int, value) -> None:
        self._intent(self.session.set_metric_weight, dim, value)

    # -- session -> widgets -----------------------------------------------------------------------------------
    def _on_frame(self, frame: Frame) -> None:
        """Training thread: keep the latest frame, wake the refresher (no widget work here)."""
        self._latest = frame
        self._wake.set()

    def _refresh_loop(self) -> None:
        last = 0.0
        while not self._closed:
            self._wake.wait(1.0)  # also refresh now and then without frames
            if self._closed:
                break
            rest = 1.0 / self.refresh_hz - (time.monotonic() - last)
            if rest > 0:
                time.sleep(rest)
            self._wake.clear()
            last = time.monotonic()
            try:
                self.refresh()
            except Exception:  # a failed refresh must not end the loop
                log.exception("panel refresh failed")

    def refresh(self, frame: Frame | None = None) -> None:
        """Bring every widget in line with the session and its latest frame."""
        session = self.session
        frame = frame or self._latest or session.frame
        if frame.generation != session.generation:
            frame = session.frame  # a frame of the previous preset: wait for the new one
        with self._lock, self._syncing():
            if frame.generation != self._generation or session.preset.name != self._preset_name:
                self._rebuild()
            p = session.parameters
            self.S.max = max(S_SLIDER[1], int(p["iterations"]))
            self.S.min = min(S_SLIDER[0], int(p["iterations"]))
            _set(self.S, int(p["iterations"]))
            _set(self.l_start, float(p["l_start"]))
            _set(self.l_end, float(p["l_end"]))
            _set(self.smoothing, float(p["smoothing"]))
            _set(self.reach, float(p["reach"]))
            _set(self.symmetry, bool(p["symmetry"]))
            for w, m in zip(self.metric, p["metric_weights"]):
                _set(w, float(m))
            self.progress.max = max(1, frame.iterations)
            _set(self.progress, min(frame.iteration, frame.iterations))
            self.progress.bar_style = "info" if frame.running else ("warning" if frame.paused else "success")
            state = "training" if frame.running else ("paused" if frame.paused else "converged")
            cycle = f"{frame.cycle_time * 1e3:.3g} ms" if frame.cycle_time > 0 else "-"
            k, k_eff = frame.n_controls, len(frame.effective_controls)
            self.status.value = _BLOCK.format(
                f'<span class="somwidget-iteration">iteration {frame.iteration} / {frame.iterations} ({state})'
                f"</span><br><small>cycle {cycle}, {session.frames_per_second:.3g} frames/s; "
                f"{frame.positions.shape[0]} nodes, {k} controls ({k_eff} with mirrors)</small>")
            running = frame.running
            self.train_button.description = "Pause" if running else "Train"
            self.train_button.icon = "pause" if running else "play"
            self.undo_button.disabled = frame.history[0] == 0
            self.redo_button.disabled = frame.history[1] == 0
            self.controls_html.value = _controls_table(frame, session.layout.colour_space != "none")
            if session.error and not self.error.value:
                self.error.value = f'<span style="color:#b00020">{_html.escape(session.error)}</span>'
            self.last_frame_seq = frame.seq
            self.refreshes += 1

    def _rebuild(self) -> None:
        """New preset: the dropdown, the title and one metric-weight row per feature dimension."""
        session = self.session
        preset = session.preset
        options = [(_PRESET_LABELS.get(name, name), name) for name in _presets.PRESETS]
        if preset.name not in _presets.PRESETS:
            options.append((f"{preset.title} (loaded)", preset.name))
        if list(self.preset.options) != options:
            self.preset.options = options
        self.preset.value = preset.name
        self.title.value = _BLOCK.format(f"<b>{_html.escape(preset.title)}</b><br><small>"
                                         f"{_html.escape(preset.description)}</small>")
        layout = session.layout
        roles = {d: "position" for d in layout.position}
        roles.update({d: f"colour ({layout.colour_space})" for d in layout.colour})
        roles.update({d: "direction" for d in layout.direction})
        if layout.length is not None:
            roles[layout.length] = "length"
        weights = session.parameters["metric_weights"]
        metric, rows = [], []
        for d, name in enumerate(layout.names):
            w = widgets.BoundedFloatText(value=float(weights[d]), min=METRIC_WEIGHT.low, max=METRIC_WEIGHT.high,
                                         step=0.1, description=name, tooltip=METRIC_WEIGHT.help,
                                         style={"description_width": "70px"}, layout=widgets.Layout(width="170px"))
            w.observe(lambda change, d=d: self.set_metric_weight(d, change["new"]), names="value")
            metric.append(w)
            rows.append(widgets.HBox([w, widgets.HTML(f"<small>dim {d}: {roles.get(d, 'feature')}</small>")]))
        old_rows = self.features_box.children
        self.features_box.children = rows
        self.metric = metric
        for row in old_rows:
            for w in row.children:
                w.close()
            row.close()
        self._generation = session.generation
        self._preset_name = preset.name

    # -- lifetime ---------------------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop following the session and close the widgets (the session itself keeps running)."""
        self._closed = True
        self._wake.set()
        self.session.remove_listener(self._on_frame)
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        self.variants.close()
        for w in [*self.children, *self.metric, *self.features_box.children]:
            w.close()
        super().close()


class VariantsSection(widgets.VBox):
    """The panel's Variants section: how many, how much jitter, which schedule parameters to vary; Sweep trains them
    from the session's current shape (somwidget.sweep) and shows a gallery; a thumbnail's Use button makes that
    variant the session's state (one undo step, through `intent`)."""

    def __init__(self, session: Session, intent):
        self.session = session
        self._intent = intent
        self.result = None  # the latest Variants
        style = {"description_width": "70px"}
        self.count = widgets.BoundedIntText(value=12, min=1, max=MAX_GALLERY_VARIANTS, description="how many",
                                            style=style, layout=widgets.Layout(width="170px"))
        self.jitter = widgets.BoundedFloatText(value=0.05, min=0.0, max=1.0, step=0.01, description="jitter",
                                               style=style, layout=widgets.Layout(width="170px"),
                                               tooltip="each control moves by up to this share of the model's size")
        self.vary = widgets.SelectMultiple(options=list(VARIED), value=(), description="vary", rows=len(VARIED),
                                           style=style, layout=widgets.Layout(width="250px"))
        self.sweep_button = widgets.Button(description="Sweep", icon="th", tooltip=VARIANTS_HELP,
                                           layout=widgets.Layout(width="100px"))
        self.progress = widgets.IntProgress(min=0, max=1, value=0, layout=widgets.Layout(width="220px"))
        self.gallery = widgets.GridBox(layout=widgets.Layout(grid_template_columns="repeat(3, 108px)",
                                                             grid_gap="2px"))
        self.sweep_button.on_click(lambda _b: self.sweep())
        super().__init__([
            widgets.HTML(_BLOCK.format(f'<b title="{_html.escape(VARIANTS_HELP)}">Variants</b> <small>(many '
                                       'designs at once; pick one to go on from it)</small>')),
            widgets.HBox([self.count, self.jitter]), self.vary, widgets.HBox([self.sweep_button, self.progress]),
            self.gallery,
        ])

    def sweep(self) -> bool:
        """Train the variants (in this thread) and show them; False (the message in the panel) if refused."""
        def run():
            params = vary_around(list(self.vary.value), self.session.parameters)
            self.progress.max, self.progress.value = int(self.count.value), 0
            self.result = sweep_variants(self.session, n=int(self.count.value), jitter=float(self.jitter.value),
                                         params=params, device=self.session.training_device,
                                         progress=lambda done, total: setattr(self.progress, "value", done))
            self._show(self.result)

        self.sweep_button.disabled = True
        try:
            return self._intent(run)
        finally:
            self.sweep_button.disabled = False

    def _show(self, variants) -> None:
        from ..model.picture import png_bytes

        cells = []
        for i, image in enumerate(variants.thumbnails(size=(104, 84))):
            picture = widgets.Image(value=png_bytes(image), format="png", layout=widgets.Layout(width="104px"))
            use = widgets.Button(description=f"use #{i}", layout=widgets.Layout(width="104px", height="24px"),
                                 tooltip=f"gap {variants.metrics['gap'][i]:.3f}, spike "
                                         f"{variants.metrics['spike'][i]:.2f}")
            use.on_click(lambda _b, i=i: self.pick(i))
            cells.append(widgets.VBox([picture, use]))
        for old in self.gallery.children:
            old.close()
        self.gallery.children = cells

    def pick(self, i: int) -> bool:
        """Make variant i of the latest sweep the session's state (one undo step)."""
        def apply():
            if self.result is None:
                raise ValueError("no variants yet: press Sweep first")
            self.result.apply(i, self.session)

        return self._intent(apply)

    def close(self) -> None:
        for w in [*self.gallery.children, *self.children]:
            w.close()
        super().close()


def _set(widget, value) -> None:
    """Assign only when the value differs (float sliders compare with a tolerance)."""
    old = widget.value
    if isinstance(value, float) and isinstance(old, float):
        if math.isclose(old, value, rel_tol=1e-9, abs_tol=1e-12):
            return
    elif old == value:
        return
    widget.value = value


def _controls_table(frame: Frame, has_colour: bool) -> str:
    k = frame.n_controls
    own = frame.control_colours if has_colour else _presets.palette_colours(k, k)[0]  # the web view's colours
    gaps = frame.gaps
    rows = []
    for i in range(k):
        rgb = own[i]
        g = [float(gaps[i])] if i < len(gaps) else []
        if len(gaps) >= 2 * k:
            g.append(float(gaps[k + i]))
        pos = ", ".join(f"{x:.2f}" for x in frame.control_positions[i])
        rows.append(f'<tr><td>{i}</td><td><span style="display:inline-block;width:12px;height:12px;'
                    f'background:{hex_colour(rgb)};border:1px solid #888"></span></td><td>{pos}</td>'
                    f'<td class="somwidget-gap">{" / ".join(f"{x:.3f}" for x in g)}</td></tr>')
    return ('<table style="font-size:11px;line-height:1.2"><tr><th>#</th><th></th><th>x, y, z</th><th>gap</th></tr>'
            + "".join(rows) + "</table>")


# --------------------------------------------------------------------------------------------------------------
# The widget show() returns
# --------------------------------------------------------------------------------------------------------------
class SomWidget(widgets.HBox):
    """The panel and the live view side by side: `session`, `panel`, `view` (a ClayWidget; None without one).

    A saved notebook reads without a kernel: the output keeps a picture of the clay (image/png next to the widget)
    as the view last showed it, or as it was when shown; the widget state, where the notebook saves it, keeps the
    view's latest picture (ClayWidget.picture), which the view shows until frames come again."""

    def __init__(self, session: Session, panel: Panel, view: ClayWidget | None = None, owns_session: bool = False):
        self.session = session
        self.panel = panel
        self.view = view
        self.owns_session = owns_session
        children = [panel] if view is None else [panel, view]
        if view is not None:
            view.layout = widgets.Layout(flex="1 1 auto", min_width="360px")
        super().__init__(children, layout=widgets.Layout(width="100%", align_items="flex-start"))

    def _repr_mimebundle_(self, **kwargs):
        bundle = super()._repr_mimebundle_(**kwargs)
        if self.view is not None and isinstance(bundle, dict):
            try:
                bundle["image/png"] = self.view.picture_png() or picture_png(self.session)
            except Exception:  # no off-screen rendering here: the live view is all there is
                log.debug("no picture for the saved notebook", exc_info=True)
        return bundle

    def close(self) -> None:
        """Close the widgets, and the session when show() made it."""
        self.panel.close()
        if self.view is not None:
            self.view.close()
        if self.owns_session:
            self.session.close()
        super().close()


def picture_png(session: Session, size=(640, 420)) -> bytes:
    """The session's latest frame as a PNG (pyvista, off screen)."""
    from ..model.picture import png_bytes, render

    return png_bytes(render(session, size=size))


def _session_of(what, device, paused: bool) -> tuple[Session, bool]:
    """(session, made_here) from a Session, a SomWidget, a Preset, a preset name or a mesh path."""
    if isinstance(what, Session):
        return what, False
    if isinstance(what, SomWidget):
        return what.session, False
    if what is None:
        what = "car"
    if isinstance(what, (str, Path)) and str(what) not in _presets.PRESETS:
        p = Path(what)
        if not p.is_file():
            raise ValueError(f"{what!r} is neither a preset ({', '.join(_presets.PRESETS)}) nor a mesh file")
        session = Session("car", device=device, start=False, paused=paused)
        try:
            session.load_mesh(p)
        except Exception:
            session.close()
            raise
        session.start()
        return session, True
    if isinstance(what, (str, Preset)):
        return Session(str(what) if isinstance(what, Path) else what, device=device, paused=paused), True
    raise ValueError(f"show: expected a preset name, a Preset, a mesh path or a Session, got {type(what).__name__}")


_DEVICES_SAID: set[str] = set()


def _say_device(session: Session) -> None:
    """Say once per kernel and device, in plain words, where the map trains."""
    from ...backend import device as _device

    where = session.training_device
    if where not in _DEVICES_SAID:
        _DEVICES_SAID.add(where)
        print(f"somwidget: training on {_device.describe(where)}")


def show(what="car", *, device: str | None = "auto", paused: bool = False, view: bool = True,
         height: int = 520) -> SomWidget:
    """An interactive SOM in a notebook cell: the panel beside the live, draggable 3-D view of one Session.

    what:     a preset name ("car", "space-grid", "lines", ...), a Preset, a mesh file path (OBJ, PLY, STL, OFF,
              GLB), an existing Session (its other views, e.g. the web app, stay in step), or a SomWidget
    device:   where a new session trains: "auto" (the GPU when there is one), "cpu", "cuda:N"
    paused:   a new session starts paused (press Train)
    view:     False: the panel alone
    height:   of the view in pixels

    Returns the widget (an ipywidgets HBox: put it last in the cell, or `display()` it); `.session` is the
    Session to script (`move_control`, `set_iterations`, `wait_idle`, `export_mesh`...), `.close()` closes it.
    The view draws in the browser from frames the kernel sends over the widget's comm: no server, no port.
    """
    session, owned = _session_of(what, device, paused)
    _say_device(session)
    try:
        panel = Panel(session)
        clay = ClayWidget(session, height=height) if view else None
    except Exception:
        if owned:
            session.close()
        raise
    return SomWidget(session, panel, clay, owns_session=owned)


__all__ = ["Panel", "SomWidget", "ClayWidget", "show", "picture_png"]
