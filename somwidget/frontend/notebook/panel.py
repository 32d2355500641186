"""The notebook's panel: ipywidgets bound to a Session through its panel model (model/panel.py), the same model the
web app's panel binds to: preset, the settings (a slider or a checkbox each, from their declaration in
backend/schedule.py), the feature dimensions with their metric weights, Train / Pause / Reset, Undo / Redo,
progress, the controls and their gaps, the variants. `show()` (show.py) puts it beside the clay view (widget.py).
Both talk to the same `Session`:

    panel widget --set_parameter(name, value)--> Session --frames--> panel (iteration, gaps, settings)
    view (drag a sphere) --grab / move / release--> Session --frames--> every view and panel

The panel works without a frontend: its widgets are plain Python objects (`panel.fields[name]`, also an attribute
of its short name: `panel.S`), so tests (and scripts) can set `panel.S.value = 300` and watch the session follow,
or move a control and watch `panel.progress.value` restart.
"""

from __future__ import annotations

import base64
import html as _html
import logging
import math
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import ipywidgets as widgets

from ...backend import presets as _presets
from ...backend.schedule import BY_NAME, SECTIONS, Setting
from ..model import Frame, Session
from ..model.panel import (
    ACTION_HELP,
    EXPORT_CHOICES,
    GAP_HELP,
    OFF_CLAY_HELP,
    OFF_CLAY_STYLE,
    RADIUS_HELP,
    PanelModel,
    slider_digits,
)
from .variants import VariantsSection

log = logging.getLogger(__name__)

#: The panel refreshes its numbers at most this often per second (frames arrive at up to 60 a second).
PANEL_HZ = 8
#: Text blocks: the notebook's default line height spreads small print apart; long words wrap.
_BLOCK = '<div style="line-height:1.35; white-space:normal; overflow-wrap:anywhere">{}</div>'
#: The width of the labels that line up (the sliders', the metric weights'): the longest, "smoothing", fits.
LABEL_WIDTH = "76px"
#: An export's download link carries the file in the page: up to this size (larger: the file next to the notebook).
MAX_LINK_BYTES = 20_000_000
EXPORT_MIME = "application/octet-stream"

#: The dropdown's preset names: the web app's, shorter for the case studies (the panel is narrow).
PRESET_LABELS = {**_presets.PRESET_LABELS, "space-grid": "Case study 1: space grid",
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

    def __init__(self, session: Session, refresh_hz: float = PANEL_HZ, auto_refresh: bool = True) -> None:
        self.session = session
        self.model = PanelModel(session)
        self.refresh_hz = float(refresh_hz)
        self._lock = threading.RLock()
        self._local = threading.local()
        self._latest: Frame | None = None
        self._wake = threading.Event()
        self._closed = False
        self._generation = None
        self._preset_name = None
        self.refreshes = 0  # refreshes applied (for tests)
        self._notices_seen = session.settings.notices
        self.last_frame_seq = -1

        style = {"description_width": LABEL_WIDTH}
        own = {"description_width": "initial"}  # a label as wide as its words
        wide = _fluid()
        self.title = widgets.HTML(layout=_fluid())
        self.preset = widgets.Dropdown(description="preset", style=style, layout=_fluid("1 1 190px"))
        self.reload_button = widgets.Button(icon="rotate-left", layout=widgets.Layout(width="36px", min_width="36px"),
                                            tooltip=ACTION_HELP["reload_preset"])
        self.train_button = widgets.Button(description="Pause", icon="pause", layout=_button())
        self.reset_button = widgets.Button(description="Reset", icon="refresh", layout=_button(),
                                           tooltip=ACTION_HELP["reset"])
        self.undo_button = widgets.Button(description="Undo", icon="undo", layout=_button(),
                                          tooltip=ACTION_HELP["undo"])
        self.redo_button = widgets.Button(description="Redo", icon="repeat", layout=_button(),
                                          tooltip=ACTION_HELP["redo"])
        self.refine_button = widgets.Button(description="Refine", icon="th", layout=_button(),
                                            tooltip=ACTION_HELP["refine"])
        self.progress = widgets.IntProgress(min=0, max=1, value=0, description="progress", style=style,
                                            layout=wide)
        self.status = widgets.HTML(layout=_fluid())
        # a widget per setting a panel sets by name, from its declaration (backend/schedule.py); each is also an
        # attribute of its short name (panel.S, panel.reach, panel.symmetry)
        self.fields: dict[str, widgets.ValueWidget] = {p.name: _field(p, style, wide) for p in self.model.fields}
        for name, w in self.fields.items():
            setattr(self, BY_NAME[name].short or name, w)
        self.features_box = widgets.VBox()
        self.metric: list[widgets.BoundedFloatText] = []
        group = BY_NAME["group"]
        self.group = widgets.Dropdown(options=self.model.group_choices(), description=group.label, style=own,
                                      layout=_fluid("1 1 190px"), tooltip=group.help)
        self.radius_of = widgets.Dropdown(description="control", style=own, layout=_fluid("0 1 125px"),
                                          tooltip="The control whose position, features and radius the fields show")
        self.position = widgets.Text(placeholder="x, y, z", continuous_update=False, layout=_fluid("1 1 110px"),
                                     tooltip="x, y, z: type a position and press Enter to move the control there")
        self.features = widgets.Text(description="features", style=own, continuous_update=False,
                                     layout=_fluid("1 1 190px"))
        self.radius = widgets.BoundedFloatText(min=0.0, max=1e6, step=0.05, description="radius", style=own,
                                               tooltip=RADIUS_HELP, layout=_fluid("0 1 130px"))
        self.all_radii = widgets.Text(placeholder="all radii", continuous_update=False, layout=_fluid("0 1 90px"),
                                      tooltip="Every control's radius of influence at once: type it and press Enter")
        self.controls_html = widgets.HTML(layout=_fluid())
        self.error = widgets.HTML(layout=_fluid())
        self.export_format = widgets.Dropdown(options=[(label, ext) for ext, label in EXPORT_CHOICES],
                                              description="format", style=own, layout=_fluid("1 1 200px"),
                                              tooltip="What the next tool reads: STL for 3-D printing, .3dm for "
                                                      "Rhino, glTF / GLB for Blender and game engines")
        self.export_button = widgets.Button(description="Export", icon="download", layout=_button(),
                                            tooltip="Write the clay in the chosen format next to the notebook, "
                                                    "named after the session and the day, and offer it as a "
                                                    "download")
        self.export_link = widgets.HTML(layout=_fluid())
        self.recovered = _banner(self.model.recovered_message())
        self.notices = _banner(self.model.notice_message(), "#e0a030")  # saved sessions not read whole
        self.saving = widgets.HTML()  # the autosave's failure, until a save is on disk again
        self.variants = VariantsSection(self.model, self._intent)

        super().__init__([
            self.recovered, self.notices, self.saving, self.title,
            _row([self.preset, self.reload_button, self.refine_button]),
            _row([self.train_button, self.undo_button, self.redo_button, self.reset_button]),
            self.progress, self.status, self.error,
            _heading("schedule"), *self._section("schedule"),
            _row([*self._section("symmetry"), self.group]),
            _heading("features"),
            self.features_box,
            widgets.HTML(_BLOCK.format(f'<b title="{_html.escape(GAP_HELP)}">Controls</b> <small>(gap: distance to '
                                       'the nearest node, original / mirror)</small>'), layout=_fluid()),
            self.controls_html, _row([self.radius_of, self.position, self.radius]),
            _row([self.features, self.all_radii]),
            widgets.HTML(_BLOCK.format("<b>Export</b> <small>(the file is named after the session and the day)"
                                       "</small>"), layout=_fluid()),
            _row([self.export_format, self.export_button]), self.export_link,
            self.variants,
        ], layout=widgets.Layout(flex="1 1 320px", width="auto", min_width="0", max_width="440px", padding="4px"))
        self.add_class("somwidget-panel")

        for name, w in self.fields.items():
            w.observe(lambda change, name=name: self._intent(session.set_parameter, name, change["new"]),
                      names="value")
        self.group.observe(lambda change: self._intent(session.settings.set_symmetry, change["new"]), names="value")
        self.radius_of.observe(lambda _change: self.refresh(), names="value")
        self.position.observe(lambda change: self._intent(self._typed, self.model.set_position, change["new"]),
                              names="value")
        self.features.observe(lambda change: self._intent(self._typed, self.model.set_features, change["new"]),
                              names="value")
        self.radius.observe(lambda change: self._intent(session.set_control_radius, self.radius_of.value,
                                                        change["new"]), names="value")
        self.all_radii.observe(lambda change: change["new"] and self._intent(session.set_control_radius, None,
                                                                             change["new"]), names="value")
        self.preset.observe(self._preset_chosen, names="value")
        self.train_button.on_click(lambda _b: self._intent(self.model.toggle_training))
        self.reset_button.on_click(lambda _b: self._intent(session.reset))
        self.undo_button.on_click(lambda _b: self._intent(session.undo))
        self.reload_button.on_click(lambda _b: self._reload_preset())
        self.refine_button.on_click(lambda _b: self._refine())
        self.redo_button.on_click(lambda _b: self._intent(session.redo))
        self.export_button.on_click(lambda _b: self.export())

        self.refresh()
        session.add_listener(self._on_frame, replay=False)
        self._thread = None
        if auto_refresh:
            self._thread = threading.Thread(target=self._refresh_loop, name="somwidget-panel", daemon=True)
            self._thread.start()

    def _section(self, section: str) -> list:
        """The widgets of a section's settings, each slider followed by its help."""
        out = []
        for p in self.model.fields:
            if p.section == section:
                out.append(self.fields[p.name])
                if p.widget == "slider":
                    out.append(widgets.HTML(_BLOCK.format(f"<small>{_html.escape(p.help)}</small>"),
                                            layout=_fluid()))
        return out

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

    def _refine(self) -> None:
        if self._intent(self.model.refine):
            self.refresh()

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

    def _typed(self, setter, text) -> None:
        """A position or feature values typed for the chosen control (PanelModel.set_position / set_features)."""
        error = setter(self.radius_of.value, text)
        if error is not None:
            raise ValueError(error)

    def _preset_chosen(self, change) -> None:
        name = change["new"]
        if getattr(self._local, "syncing", False) or not name or name == self.session.preset.name:
            return
        self.status.value = f"<i>loading {_html.escape(str(name))}...</i>"
        if self._intent(self.session.load_preset, name):
            self.refresh()

    def _reload_preset(self) -> None:
        """The current preset again, as it starts (one undo step)."""
        if self._intent(self.model.reload_preset):
            self.refresh()

    def export(self, folder: str | Path = ".") -> Path | None:
        """Write the clay in the chosen format (`export_format`) into `folder` (the notebook's, by default) under the
        session's name and the day, and show a link that downloads it; None (the message in the panel) if refused."""
        ext = self.export_format.value
        written: list[Path] = []

        def write() -> None:
            data = self.model.export_bytes(ext)
            path = Path(folder) / self.model.export_name(ext)
            path.write_bytes(data)
            written.append(path)
            link = (f'<a download="{_html.escape(path.name)}" href="data:{EXPORT_MIME};base64,'
                    f'{base64.b64encode(data).decode("ascii")}">download {_html.escape(path.name)}</a>'
                    if len(data) <= MAX_LINK_BYTES else f"<b>{_html.escape(path.name)}</b>")
            self.export_link.value = _BLOCK.format(f"{link} <small>({len(data) / 1024:,.0f} KB, also written to "
                                                   f"{_html.escape(str(path.resolve().parent))})</small>")

        return written[0] if self._intent(write) else None

    def set_metric_weight(self, dim: int, value) -> None:
        self._intent(self.session.settings.set_metric_weight, dim, value)

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
            for name, w in self.fields.items():
                _show(w, BY_NAME[name], p[name])
            choices = self.model.group_choices()
            if list(self.group.options) != choices:
                self.group.options = choices
            _set(self.group, p["group"])
            rows = self.model.control_rows(frame)  # by the controls' ids, as the view numbers them; a stroke one row
            options = [(f'{r["id"]}{" (stroke)" if r["samples"] > 1 else ""}', r["i"]) for r in rows]
            if list(self.radius_of.options) != options:
                self.radius_of.options = options
            starts = [r["i"] for r in rows]
            i = self.radius_of.value if self.radius_of.value in starts else starts[0] if starts else 0
            _set(self.radius_of, i)
            self.radius.max = max(2.0 * self.model.size, float(frame.radii.max(initial=0.0)))  # a few sizes at most
            if i < len(frame.radii):
                _set(self.radius, round(float(frame.radii[i]), 4))
            row = next((r for r in rows if r["i"] == i), None)
            if row is not None:
                _set(self.position, row["position"])
                _set(self.features, row["features"])
            _set(self.all_radii, self.model.common_radius(frame))
            names = self.model.feature_names()
            self.features.layout.display = "" if names else "none"
            self.features.placeholder = names
            for w, m in zip(self.metric, p["metric_weights"]):
                _set(w, float(m))
            self.progress.max = max(1, frame.iterations)
            _set(self.progress, min(frame.iteration, frame.iterations))
            st = self.model.status(frame)
            self.progress.bar_style = {"training": "info", "paused": "warning"}.get(st["state"], "success")
            self.status.value = _BLOCK.format(
                f'<span class="somwidget-iteration">iteration {st["iteration"]} / {st["S"]} ({st["state"]})'
                f"</span><br><small>cycle {st['cycle_ms']} ms, {st['fps']} frames/s; "
                f"{st['n_vertices']} nodes, {st['controls_text']}</small>")
            self.train_button.description = st["train_label"]
            self.train_button.tooltip = st["train_help"]
            self.train_button.icon = "pause" if frame.running else "play"
            self.undo_button.disabled = not st["can_undo"]
            self.redo_button.disabled = not st["can_redo"]
            self.controls_html.value = _controls_table(rows)
            if session.error and not self.error.value:
                self.error.value = f'<span style="color:#b00020">{_html.escape(session.error)}</span>'
            if session.settings.notices != self._notices_seen:  # what a symmetry change or revolve did
                self._notices_seen = session.settings.notices
                self.error.value = f'<span style="color:#1d428a">{_html.escape(session.settings.notice)}</span>'
            failed = session.save_error
            _set(self.saving, _BLOCK.format(f'<b style="color:#b00020">{_html.escape(failed)}</b>') if failed else "")
            self.last_frame_seq = frame.seq
            self.refreshes += 1

    def _rebuild(self) -> None:
        """New preset: the dropdown, the title and one metric-weight row per feature dimension."""
        session = self.session
        preset = session.preset
        options = self.model.preset_options(PRESET_LABELS)
        if list(self.preset.options) != options:
            self.preset.options = options
        self.preset.value = preset.name
        self.title.value = _BLOCK.format(f"<b>{_html.escape(preset.title)}</b><br><small>"
                                         f"{_html.escape(preset.description)}</small>")
        metric, rows = [], []
        m = self.model.metric
        for row in self.model.feature_rows():
            d = row["d"]
            w = widgets.BoundedFloatText(value=row["weight"], min=m.low, max=m.high, step=0.1, description=row["name"],
                                         tooltip=m.help, style={"description_width": LABEL_WIDTH},
                                         layout=_fluid("0 1 170px"))
            w.observe(lambda change, d=d: self.set_metric_weight(d, change["new"]), names="value")
            metric.append(w)
            rows.append(_row([w, widgets.HTML(f"<small>dim {d}: {row['role']}</small>", layout=_fluid("1 1 100px"))]))
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
        for w in self.children:  # every widget of the panel, rows and all: a widget left open stays registered
            close_tree(w)  # with its comm, and its handlers would keep this panel and its session alive
        super().close()


def close_tree(widget) -> None:
    """Close a widget and every widget inside it."""
    for child in getattr(widget, "children", ()):
        close_tree(child)
    widget.close()


def _fluid(flex: str = "1 1 100%") -> widgets.Layout:
    """A field's layout in a row that wraps: it grows and shrinks from `flex`'s basis, never wider than the panel."""
    return widgets.Layout(flex=flex, width="auto", min_width="0", max_width="100%")


def _button() -> widgets.Layout:
    """A button as wide as its icon and words."""
    return widgets.Layout(width="auto", min_width="fit-content", flex="0 0 auto")


def _row(children) -> widgets.HBox:
    """Fields side by side while they fit the panel's width, the next line where they do not."""
    return widgets.HBox(children, layout=widgets.Layout(flex_flow="row wrap", align_items="center", width="100%"))


def _heading(section: str) -> widgets.HTML:
    """A section's title and what it is about (backend/schedule.py, SECTIONS)."""
    title, about = SECTIONS[section]
    return widgets.HTML(_BLOCK.format(f"<b>{_html.escape(title)}</b> <small>({_html.escape(about)})</small>"),
                        layout=_fluid())


def _field(p: Setting, style: dict, layout) -> widgets.ValueWidget:
    """A setting's widget: a checkbox for a flag, else a slider over its declared range (its value may lie past it:
    `_show` widens the range)."""
    if p.kind == "bool":
        return widgets.Checkbox(description=p.short or p.label, indent=False, tooltip=p.help,
                                layout=widgets.Layout(width="auto", flex="0 0 auto"))
    low, high, step = p.slider_range()
    kind, extra = (widgets.IntSlider, {}) if p.kind == "int" else (
        widgets.FloatSlider, {"readout_format": f".{slider_digits(p)}f"})
    return kind(description=p.short or p.label, min=low, max=high, step=step, continuous_update=False, style=style,
                layout=layout, tooltip=p.help, **extra)


def _show(widget, p: Setting, value) -> None:
    """A setting's value in its widget (a slider's range widened to hold a value past it)."""
    if p.kind == "bool":
        return _set(widget, bool(value))
    value = int(value) if p.kind == "int" else float(value)
    low, high, _ = p.slider_range()
    widget.max = max(high, value)
    widget.min = min(low, value)
    _set(widget, value)


def _banner(message: str, colour: str = "#9c9") -> widgets.HBox:
    """A banner (the recovered session's; the notices about saved sessions) hidden when there is nothing to say, with
    a button that dismisses it."""
    dismiss = widgets.Button(icon="times", tooltip="Dismiss", layout=widgets.Layout(width="32px", min_width="32px"))
    banner = widgets.HBox([widgets.HTML(_BLOCK.format(f"<small>{_html.escape(message)}</small>"),
                                        layout=widgets.Layout(flex="1 1 auto")), dismiss],
                          layout=widgets.Layout(display="flex" if message else "none", border=f"1px solid {colour}",
                                                padding="2px 4px", margin="0 0 4px 0", align_items="center"))
    banner.add_class("somwidget-recovered")

    def close(_button) -> None:
        banner.layout.display = "none"

    dismiss.on_click(close)
    return banner


def _set(widget, value) -> None:
    """Assign only when the value differs (float sliders compare with a tolerance)."""
    old = widget.value
    if isinstance(value, float) and isinstance(old, float):
        if math.isclose(old, value, rel_tol=1e-9, abs_tol=1e-12):
            return
    elif old == value:
        return
    widget.value = value


#: The gap cell of a control off the clay: the web page's amber mark and its words.
_OFF_MARK = f' style="{OFF_CLAY_STYLE}" title="{_html.escape(OFF_CLAY_HELP)}"'


def _controls_table(rows: list[dict]) -> str:
    """The panel model's control rows as a small HTML table."""
    cells = [f'<tr><td title="{"a stroke: its samples act as one" if r["samples"] > 1 else ""}">{r["id"]}'
             f'{"~" if r["samples"] > 1 else ""}</td><td><span style="display:inline-block;width:12px;height:12px;'
             f'background:{r["colour"]};border:1px solid #888"></span></td><td>{r["position"]}</td>'
             f'<td class="somwidget-gap"{_OFF_MARK if r["off"] else ""}>{r["gap"]}</td>'
             f'<td class="somwidget-radius">{r["radius"]:.3g}</td></tr>'
             for r in rows]
    return ('<table style="font-size:11px;line-height:1.2"><tr><th>#</th><th></th><th>x, y, z</th><th>gap</th>'
            '<th title="radius of influence">radius</th></tr>' + "".join(cells) + "</table>")
