"""The web app's page, laid out with trame's vuetify widgets: the toolbar, the panel (the settings' fields, sliders
and switches generated from their declaration, backend/schedule.py; tables bound to the state app.py keeps), and the
element the clay view mounts into. The page's own scripts: the keyboard shortcuts, the view's mount and the
reconnect.
"""

from __future__ import annotations

from trame.ui.vuetify3 import SinglePageWithDrawerLayout
from trame.widgets import client, html
from trame.widgets import vuetify3 as v3

from ...backend.schedule import BY_NAME, SECTIONS, Setting
from ..model.panel import ACTION_HELP, GAP_HELP, OFF_CLAY_HELP, OFF_CLAY_STYLE, RADIUS_HELP, PanelModel, slider_digits
from ..model.variants import VARIANTS_HELP
from .state_guard import state_key

#: What a download's name gets after the session's (`export_stem`): "-<day>-<hhmm>" by the browser's clock, as
#: model/files.py's export_name writes it ("sphere-2026-11-27-1042.obj"): two exports of a day do not collide.
STAMP = ("'-' + new Date(Date.now() - new Date().getTimezoneOffset() * 60000).toISOString().slice(0, 16)"
         ".replace('T', '-').replace(':', '')")

#: The page's keyboard shortcuts: Ctrl+Z undoes, Ctrl+Shift+Z or Ctrl+Y redoes (Cmd on a Mac), except while a text
#: field has the focus (its own undo).
SHORTCUTS_JS = """
if (!window.somwidgetShortcuts) {
  window.somwidgetShortcuts = true;
  window.addEventListener('keydown', (e) => {
    if (!(e.ctrlKey || e.metaKey) || e.altKey || !window.trame) return;
    const t = e.target;
    if (t && (t.tagName === 'INPUT' || t.tagName === 'TEXTAREA' || t.isContentEditable)) return;
    const key = e.key.toLowerCase();
    const name = key === 'z' ? (e.shiftKey ? 'redo' : 'undo') : key === 'y' ? 'redo' : null;
    if (!name) return;
    e.preventDefault();
    window.trame.trigger(name);
  });
}
"""


#: When trame's websocket closes (the server stopped or restarted), a banner says "reconnecting" and the page asks the
#: server every half second; once it answers, the page reloads. A restarted server is a new process with a new
#: trame state and page, so a fresh load is the sure way back to the session as it is (trame's own reconnect only
#: re-attaches to the state of the same process). The clay view's link reconnects by itself (link.js).
RECONNECT_JS = """
if (!window.somwidgetReconnect && window.trame) {
  window.somwidgetReconnect = true;
  const reconnect = () => {
    if (document.getElementById('reconnecting')) return;
    const note = document.createElement('div');
    note.id = 'reconnecting';
    note.setAttribute('role', 'status');
    note.textContent = 'The server is gone: reconnecting\u2026';
    note.style.cssText = 'position: fixed; top: 0; left: 0; right: 0; z-index: 10000; padding: 10px; '
      + 'text-align: center; background: #8a1010; color: white; font: 600 15px system-ui, sans-serif';
    document.body.appendChild(note);
    const ask = () => fetch(window.location.href, { cache: 'no-store' })
      .then((r) => (r.ok ? window.location.reload() : setTimeout(ask, 500)), () => setTimeout(ask, 500));
    setTimeout(ask, 500);
  };
  window.trame.addConnectListener(() => window.trame.client.onConnectionClose(reconnect));
}
"""


#: Mounts the clay view (the module the XR hub serves) into the page's #clay-view, and again should the page
#: replace that element.
MOUNT_VIEW_JS = """
if (!window.somwidgetMount) {
  window.somwidgetMount = () => {
    const el = document.getElementById('clay-view');
    if (!el || el.somview || el.dataset.mounting) return;
    el.dataset.mounting = '1';
    import(new URL('xr/somview.js', document.baseURI).href)
      .then((m) => { window.somview = m.mountWebView(el); })
      .catch((err) => { el.textContent = `The clay view did not load: ${err}`; })
      .finally(() => { delete el.dataset.mounting; });
  };
  setInterval(window.somwidgetMount, 300);
  window.somwidgetMount();
  // a click on a control's number in the panel's table selects it in the view: its handle moves it
  document.addEventListener('click', (ev) => {
    const cell = ev.target.closest?.('[data-control]');
    const view = document.getElementById('clay-view')?.somview;
    if (cell && view) view.selectControl(Number(cell.dataset.control));
  });
}
"""


#: Milliseconds a pointer rests on a button before its tooltip shows (a native `title` takes a second or more over a
#: Vuetify button, and a person who waited two seconds saw none).
TOOLTIP_DELAY = 250


def _button(help_text, *args, **props) -> None:
    """A VBtn with a Vuetify tooltip (shown on hover after TOOLTIP_DELAY ms) saying what it does: `help_text` a
    string or a state binding ("expr",). The tooltip hangs on a span around the button, so that a disabled button
    (which takes no pointer events) says what it would do too."""
    with v3.VTooltip(text=help_text, location="bottom", open_delay=TOOLTIP_DELAY, max_width=320):
        with html.Template(v_slot_activator="{ props }"), html.Span(v_bind="props", classes="d-inline-block"):
            v3.VBtn(*args, **props)


def build_page(server, panel: PanelModel):
    """The page: a toolbar (iteration, Train / Pause, Undo, Redo, Reset, Export), the panel in a drawer, and the
    element the clay view mounts into (#clay-view). Returns trame's layout."""
    with SinglePageWithDrawerLayout(server, full_height=True) as layout:
        layout.title.set_text("somwidget: computational clay")
        with layout.toolbar:
            v3.VSpacer()
            html.Div("{{ stats.iteration }} / {{ stats.S }}", classes="mr-3 text-body-2", id="iteration-label")
            # says what a press does: Pause (training), Resume (stopped part way), Train (settled)
            _button(("stats.train_help",), "{{ stats.train_label }}", id="train-button",
                    click="trigger('toggle_training')",
                    prepend_icon=("stats.running ? 'mdi-pause' : 'mdi-play'",), variant="tonal", classes="mr-2")
            _button(ACTION_HELP["undo"], icon="mdi-undo", id="undo-button", click="trigger('undo')",
                    disabled=("!stats.can_undo",), variant="text")
            _button(ACTION_HELP["redo"], icon="mdi-redo", id="redo-button", click="trigger('redo')",
                    disabled=("!stats.can_redo",), variant="text", classes="mr-2")
            _button(ACTION_HELP["reset"], "Reset", id="reset-button", click="trigger('reset')",
                    prepend_icon="mdi-restore", variant="tonal", classes="mr-2")
            # Export in the bar, in sight at any panel scroll (at the panel's foot it lay below the fold at 1400 x 900)
            _button(("'Download the clay as ' + export_format.toUpperCase() + ' (the format menu under Export and "
                     "sessions in the panel), named after the session and the time'",), "Export",
                    variant="tonal", prepend_icon="mdi-download", id="export-mesh", classes="mr-2",
                    click=f"utils.download(export_stem + {STAMP} + '.' + export_format, trigger('export_mesh', "
                          "[export_format]), export_mimes[export_format])")
        with layout.drawer as drawer:
            drawer.width = 390
            _panel(panel)
        client.Style(TABLE_FIELDS_CSS)
        client.Script(SHORTCUTS_JS)
        client.Script(MOUNT_VIEW_JS)
        client.Script(RECONNECT_JS)
        # what trame draws in the page's place while its websocket is closed (instead of "Connection closed")
        server.state.trame__template_error = '<trame-loading message="The page reloads when the server is back" />'
        with layout.content, html.Div(style="position: relative"):
            _alerts()  # errors over the view's top left corner: they never move the panel nor cover its fields
            _notices()  # notices over the view's foot, as a snackbar: they never resize the view
            # the clay view mounts here (MOUNT_VIEW_JS); Vue leaves the element's children alone
            html.Div(id="clay-view", style="position: relative; width: 100%; height: calc(100vh - 88px)")
    return layout


def _revision_key(name: str, row: str = "''") -> str:
    """The Vue key of a field (or a table row) that is drawn anew when the panel state bumps `field_revs[name]`: the
    value in effect replaces a refused one a person typed."""
    return f"{row} + ':' + (field_revs['{name}'] || 0)"


#: The controls table's typed cells (position, features, radius) look like fields: a faint outline, a text cursor, a
#: focus ring in the theme's colour. Outlines take no room: the table keeps its width in the drawer.
TABLE_FIELDS_CSS = """
#controls-table .v-field { outline: 1px solid rgba(0, 0, 0, 0.22); outline-offset: -2px; border-radius: 3px;
  cursor: text; }
#controls-table .v-field:hover { outline-color: rgba(0, 0, 0, 0.5); }
#controls-table .v-field.v-field--focused { outline: 2px solid rgb(var(--v-theme-primary)); }
#controls-table .v-field input { cursor: text; padding-left: 4px; padding-right: 4px; }
"""

#: The controls table's cells: little padding, so that position, gap and radius fit the drawer's width.
_TIGHT = "padding: 0 3px"


def _on_enter_or_change(handler: str) -> list[str]:
    return [f'@change="{handler}"', f'@keydown.enter="{handler}"']


#: The panel's errors lie over the clay view's top left corner, below the view's own bar line, so that showing or
#: closing one never moves the panel's fields (at the top of the panel they took 50-66 px, and every field moved
#: down by as much) and never covers them (over the foot of the drawer they hid the export buttons). They stay until
#: closed.
_ALERTS = ("position: absolute; left: 8px; top: 40px; width: min(440px, 55%); z-index: 20; display: flex; "
           "flex-direction: column; gap: 6px")

#: The notices (news, a recovered session, saved sessions set aside) lie side by side over the clay view's foot, above
#: its status line, as a snackbar does: the view keeps its size (a notice that shrank it moved every control on the
#: screen, at a Refine too), the clay in the middle stays clear, and they go away by themselves (panel_state.py,
#: NOTICE_SECONDS) or when closed.
_NOTICES = ("position: absolute; left: 8px; right: 8px; bottom: 34px; z-index: 20; display: flex; flex-wrap: wrap; "
            "gap: 6px; pointer-events: none")
_NOTICE = "flex: 0 1 480px; pointer-events: auto"


def _alerts() -> None:
    """The errors (a refusal, a failing autosave) over the clay view's corner (_ALERTS): they come and go without
    moving the panel."""
    with html.Div(id="panel-alerts", style=_ALERTS):
        v3.VAlert(v_if="error_message", text=("error_message",), type="error", density="compact",
                  closable=True, id="error-alert", click_close="error_message = ''", elevation=4)
        v3.VAlert(v_if="save_error", text=("save_error",), type="error", density="compact", id="save-alert",
                  icon="mdi-content-save-alert", elevation=4)  # until a save is on disk again: not closable


def _shown(name: str) -> list[str]:
    """A notice's time runs from when the page shows it: the alert, made again for each new text, tells the server
    when it is on the screen (panel_state.py, `notice_shown`), not when the server set it (under load the page showed
    it seconds later, and it went after less than NOTICE_SECONDS)."""
    return [f':key="{name}"', f'@vue:mounted="trigger(\'notice_shown\', [\'{name}\', {name}])"']


def _notices() -> None:
    """The notices (news, a recovered session, saved sessions set aside) over the clay view's foot (_NOTICES)."""
    with html.Div(id="panel-notices", style=_NOTICES,
                  v_show="(info_message && !error_message) || recovered_message || notice_message"):
        v3.VAlert(v_if="info_message && !error_message", text=("info_message",), type="info", id="info-alert",
                  density="compact", closable=True, click_close="info_message = ''", style=_NOTICE, elevation=4,
                  raw_attrs=_shown("info_message"))
        with v3.VAlert(v_if="recovered_message", type="success", density="compact", style=_NOTICE, elevation=4,
                       id="recovered-alert", closable=True, click_close="recovered_message = ''",
                       raw_attrs=_shown("recovered_message")):
            html.Div("{{ recovered_message }}")
            v3.VBtn("Start fresh", size="small", variant="tonal", classes="mt-1", id="start-fresh",
                    click="trigger('start_fresh')", title="Load the preset the server was started with (Undo "
                                                       "brings the recovered session back)")
        v3.VAlert(v_if="notice_message", text=("notice_message",), type="warning", density="compact",
                  id="notice-alert", closable=True, click_close="notice_message = ''", style=_NOTICE, elevation=4,
                  raw_attrs=_shown("notice_message"))


def _panel(panel: PanelModel) -> None:
    with v3.VContainer(classes="pa-2 text-body-2", id="panel", style="position: relative"):
        # busy: a bar over the top of the panel (it takes no room)
        v3.VProgressLinear(v_if="busy", indeterminate=True, style="position: absolute; left: 0; top: 0; z-index: 5")

        # preset and files
        with html.Div(classes="d-flex align-center mb-1"):
            # the preset in use chosen again: it reloads (the menu reports no change of its value, its item's click
            # does)
            v3.VSelect(v_model=("preset_name",), items=("preset_items",), label="Preset", density="compact",
                       hide_details=True, id="preset-select", disabled=("busy",),
                       # every preset in sight at once (a 900 px high window shows them all, none below a fold)
                       menu_props=("{ maxHeight: 'calc(100vh - 100px)' }",), list_props=("{ density: 'compact' }",),
                       item_props=("(item) => ({ onClick: () => item.value === preset_name && !busy "
                                   "&& trigger('reload_preset') })",))
            _button(ACTION_HELP["reload_preset"], icon="mdi-reload", variant="text", size="small", id="reload-preset",
                    click="trigger('reload_preset')", disabled=("busy",))
            _button(ACTION_HELP["refine"], "Refine", variant="tonal", size="small", id="refine",
                    click="trigger('refine')", disabled=("busy",), prepend_icon="mdi-vector-triangle", classes="ml-1")
        html.Div("{{ preset_description }}", classes="text-caption mb-2")
        v3.VBtn("Decimate and load", v_if="decimate_offer", size="small", variant="tonal", color="primary",
                id="decimate-upload", prepend_icon="mdi-vector-polyline-minus", classes="mb-2",
                click="trigger('decimate_upload')", disabled=("busy",),
                title="Load the refused mesh coarsened to this device's limit (vertex clustering)")
        v3.VFileInput(v_model=("mesh_upload",), label="Upload a mesh (OBJ, PLY, STL, OFF, GLB)",
                      density="compact", hide_details=True, prepend_icon="mdi-upload", id="mesh-upload",
                      accept=".obj,.ply,.stl,.off,.glb,.gltf", classes="mb-2", disabled=("busy",))

        # progress
        with v3.VCard(variant="outlined", classes="pa-2 mb-2"):
            html.Div("iteration {{ stats.iteration }} / {{ stats.S }}"
                     " {{ stats.running ? '(training)' : (stats.paused ? '(paused)' : '(converged)') }}",
                     id="iteration-text")
            v3.VProgressLinear(model_value=("stats.progress",), height=6, color="primary", classes="my-1",
                               id="progress-bar")
            # two lines that never wrap: figures changing every frame must not move the fields below them
            with html.Div(classes="text-caption", id="speed-text",
                          style="white-space: nowrap; overflow: hidden; text-overflow: ellipsis"):
                html.Div("cycle {{ stats.cycle_ms }} ms, {{ stats.fps }} frames/s")
                html.Div("{{ stats.n_vertices }} nodes, {{ stats.controls_text }}", id="status-counts")

        # settings: each comes from its declaration (backend/schedule.py) and shows the value in effect (bound one
        # way: what a person types goes to the session as an intent, never into the state); a refused value shows
        # its message and the field is drawn anew with the value in effect (field_revs, panel_state.py).
        _schedule_section(panel)
        _symmetry_section()

        # features
        title, about = SECTIONS["features"]
        html.Div(title, classes="text-subtitle-2 mt-2", title=about)
        with v3.VTable(density="compact", id="features-table"):
            with html.Tbody():
                with html.Tr(v_for="f in features_ui", key=_revision_key("metric_weights", "f.d")):
                    html.Td("{{ f.d }}")
                    html.Td("{{ f.name }}")
                    html.Td("{{ f.role }}", classes="text-caption")
                    with html.Td(style="width: 96px"):
                        v3.VTextField(model_value=("f.weight",), density="compact", type="number",
                                      hide_details="auto", variant="plain", title=BY_NAME["metric_weights"].help,
                                      error_messages=("param_errors['metric_weights_' + f.d] || []",),
                                      raw_attrs=_on_enter_or_change(
                                          "trigger('set_metric', [f.d, $event.target.value])"))

        # controls
        with html.Div(classes="d-flex align-center mt-2"):
            html.Div("Controls (position; gap to the nearest node: original / copy; radius)",
                     classes="text-subtitle-2", title=GAP_HELP)
            v3.VSpacer()
            v3.VTextField(key=_revision_key("radius", "'all'"), model_value=("all_radii",), label="all radii",
                          density="compact", type="number", variant="underlined", hide_details=True, min=0, step=0.05,
                          id="all-radii",
                          style="max-width: 80px", title="Every control's radius of influence at once: type it and "
                                                         "press Enter (model units; 0: the paper's point controls)",
                          raw_attrs=_on_enter_or_change("trigger('set_radius', [null, $event.target.value])"))
            _button("Add a control on the clay, where it is farthest from the others (it moves nothing until "
                    "dragged); or double-click the clay in the view", icon="mdi-plus", size="small", variant="text",
                    click="trigger('add_control')", id="add-control")
        with v3.VTable(density="compact", id="controls-table"):
            with html.Tbody():
                with html.Tr(v_for="c in controls_ui", key=_revision_key("radius", "c.id")):
                    # numbered by the control's stable id, as the view numbers it; a stroke is one row
                    with html.Td(style=f"{_TIGHT}; cursor: pointer", classes="control-index",
                                 raw_attrs=[':data-control="c.i"'],
                                 title=("c.samples > 1 ? 'A stroke of ' + c.samples + ' samples that act as one: "
                                        "select it in the view' : 'Select this control in the view: its handle "
                                        "moves it, also from behind the clay'",)):
                        html.Span("{{ c.id }}")
                        v3.VIcon("mdi-gesture", v_if="c.samples > 1", size="x-small", classes="stroke-mark ml-1")
                    with html.Td(style=_TIGHT):
                        html.Input(type="color", value=("c.colour",), disabled=("!has_colour",),
                                   style="width: 32px; height: 22px; border: none; padding: 0",
                                   change="trigger('set_colour', [c.i, $event.target.value])",
                                   title="control colour")
                    with html.Td(style=f"{_TIGHT}; min-width: 160px"):  # typed: the control moves there (Enter)
                        v3.VTextField(model_value=("c.position",), density="compact", variant="plain",
                                      hide_details=True, classes="position-cell text-caption",
                                      title="x, y, z: type a position and press Enter to move the control there",
                                      raw_attrs=_on_enter_or_change(
                                          "trigger('set_position', [c.i, $event.target.value])"))
                        v3.VTextField(v_if="feature_names", model_value=("c.features",), density="compact",
                                      variant="plain", hide_details=True, classes="features-cell text-caption",
                                      title=("'the other features (' + feature_names + '): type values and press "
                                             "Enter'",),
                                      raw_attrs=_on_enter_or_change(
                                          "trigger('set_features', [c.i, $event.target.value])"))
                    # a gap over OFF_CLAY of the clay's size: marked, as the view's line from the control to the clay
                    html.Td("{{ c.gap }}", classes=("'text-caption gap-cell' + (c.off ? ' gap-off' : '')",),
                            style=(f"'{_TIGHT}' + (c.off ? '; {OFF_CLAY_STYLE}' : '')",),
                            title=(f"c.off ? '{OFF_CLAY_HELP}' : ''",))
                    with html.Td(style=f"{_TIGHT}; width: 60px"):
                        v3.VTextField(model_value=("c.radius",), density="compact", type="number", variant="plain",
                                      hide_details=True, classes="radius-cell", min=0, step=0.05,
                                      title=RADIUS_HELP,
                                      raw_attrs=_on_enter_or_change(
                                          "trigger('set_radius', [c.i, $event.target.value])"))
                    with html.Td(style=_TIGHT):
                        _button("Remove this control (the others keep their numbers; Undo brings it back)",
                                icon="mdi-close", size="x-small", variant="text", classes="remove-control",
                                click="trigger('remove_control', [c.i])")

        # design variants
        html.Div("Variants", classes="text-subtitle-2 mt-2", title=VARIANTS_HELP)
        with v3.VRow(dense=True):
            with v3.VCol(cols=6):
                v3.VTextField(v_model=("variants_n",), label="how many", density="compact", type="number",
                              hide_details=True, id="variants-n", title="Variants to train at once (at most "
                              f"{panel.max_variants} here; somwidget.sweep takes thousands)")
            with v3.VCol(cols=6):
                v3.VTextField(v_model=("variants_jitter",), label="jitter", density="compact", type="number",
                              hide_details=True, id="variants-jitter",
                              title="Each control moves by up to this share of the model's size")
        with v3.VChipGroup(v_model=("variants_vary",), multiple=True, column=True, id="variants-vary"):
            for name in panel.varied:
                v3.VChip(name, value=name, size="small", filter=True, variant="outlined",
                         title=f"vary {name} around its value")
        with html.Div(classes="d-flex align-center ga-2 mb-1"):
            _button("Train this many variants of the design at once, the controls jittered and the chosen settings "
                    "varied; click a thumbnail to take it", "Sweep", size="small", variant="tonal",
                    prepend_icon="mdi-view-grid-plus", id="sweep", click="trigger('sweep_variants')",
                    disabled=("busy",))
            v3.VProgressLinear(model_value=("variants_progress",), height=4, color="primary",
                               v_if="variants_gallery.length || busy", id="variants-progress")
        with html.Div(classes="d-flex flex-wrap ga-1 mb-2", id="variants-gallery"):
            with html.Div(v_for="v in variants_gallery", key="v.i", style="position: relative"):
                html.Img(src=("v.src",), title=("v.title",), classes="variant-thumb",
                         style=f"width: {panel.thumbnail[0]}px; height: {panel.thumbnail[1]}px; cursor: pointer; "
                               "border: 1px solid #ccd; border-radius: 4px; display: block",
                         click="trigger('pick_variant', [v.i])")
                html.Span("#{{ v.i }}", classes="text-caption",
                          style="position: absolute; left: 4px; top: 1px; pointer-events: none")

        # files out
        html.Div("Export and sessions", classes="text-subtitle-2 mt-2")
        with html.Div(classes="d-flex flex-wrap align-center ga-1 mb-2"):
            # the format menu (model/panel.py, EXPORT_CHOICES) of the bar's Export; the file is named after the
            # session and the day
            v3.VSelect(v_model=("export_format",), items=("export_items",), label="Format", density="compact",
                       hide_details=True, id="export-format", style="min-width: 190px; max-width: 240px",
                       title="What the next tool reads: STL for 3-D printing, .3dm for Rhino, glTF / GLB for "
                             "Blender and game engines (the controls as named nodes)")
            _button("Download the whole session (clay, controls, settings) as a .npz to load again later",
                    "Save session", size="small", variant="tonal", prepend_icon="mdi-content-save", id="save-session",
                    click=f"utils.download(export_stem + {STAMP} + '.npz', trigger('save_session'), "
                          "'application/octet-stream')")
        v3.VFileInput(v_model=("session_upload",), label="Load a session (.npz)", density="compact",
                      hide_details=True, prepend_icon="mdi-folder-open", accept=".npz", id="session-upload",
                      disabled=("busy",))


def _schedule_section(panel: PanelModel) -> None:
    """The schedule's settings: number fields two to a row, then each slider with its help under it."""
    title, about = SECTIONS["schedule"]
    html.Div(title, classes="text-subtitle-2 mt-2", title=about)
    with v3.VRow(dense=True):
        for p in panel.fields:
            if p.section == "schedule" and p.widget == "field":
                with v3.VCol(cols=6), html.Div(id=f"param-{p.name}", title=p.help):
                    v3.VTextField(model_value=(state_key(p.name),), key=_revision_key(p.name), label=p.label,
                                  density="compact", type="number",
                                  error_messages=(f"param_errors['{p.name}'] || []",), hide_details="auto",
                                  id=f"field-{p.name}",
                                  raw_attrs=_on_enter_or_change(
                                      f"trigger('set_param', ['{p.name}', $event.target.value])"))
    for p in panel.fields:
        if p.section == "schedule" and p.widget == "slider":
            _slider(p)


def _slider(p: Setting) -> None:
    """A setting's slider (its value shown in its label) and its help under it."""
    key, (low, high, step) = state_key(p.name), p.slider_range()
    with html.Div(id=f"param-{p.name}", title=p.help):
        v3.VSlider(v_model=(key,), label=(f"'{p.short or p.label} ' + Number({key}).toFixed({slider_digits(p)})",),
                   min=low, max=high, step=step, density="compact", hide_details="auto", thumb_label=True,
                   id=f"{p.name}-slider", classes="mt-1", error_messages=(f"param_errors['{p.name}'] || []",),
                   end=f"trigger('set_param', ['{p.name}', $event])")
    html.Div(p.help, classes="text-caption", id=f"{p.name}-help")


def _symmetry_section() -> None:
    """The symmetry switch and the group beside it."""
    switch, group = BY_NAME["symmetry"], BY_NAME["group"]
    with html.Div(id=f"param-{switch.name}", title=switch.help, classes="d-flex align-center ga-2"):
        v3.VSwitch(v_model=(state_key(switch.name),), label=switch.short or switch.label, density="compact",
                   hide_details=True, color="primary", id="symmetry-switch")
        v3.VSelect(v_model=(state_key(group.name),), items=("group_items",), label=group.label, density="compact",
                   hide_details=True, id="symmetry-group", style="max-width: 210px", title=group.help)
