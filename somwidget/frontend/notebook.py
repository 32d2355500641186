"""somwidget inside Jupyter: an ipywidgets panel beside the web app's live 3-D view, both bound to one Session.

`show(...)` returns a `SomWidget` (an ipywidgets HBox): on the left the `Panel` (preset, S, l_start, l_end,
smoothing, symmetry, the feature dimensions with their metric weights, Train / Pause / Reset, progress, the
controls and their gaps), on the right an iframe with the draggable view. Both talk to the same `Session`:

    panel widget --set_iterations / set_l_start / ... --> Session --frames--> panel (iteration, gaps, parameters)
    view (drag a sphere) --move_control--> Session --frames--> view and panel

The view is the web app of app.py (`build_app`), served by its own trame server on a free loopback port and run
on a thread of its own with its own event loop (`NotebookServer`): it keeps drawing while a cell runs, and every
route the app registers (the /api/state debug route, the later WebXR page) is on that server too. trame's Jupyter
extension is not used (its backend has no aiohttp app for extra routes): the iframe points at the server itself,
which works when the browser runs on the kernel's machine. Elsewhere (a remote Jupyter server, JupyterHub), install
jupyter-server-proxy and set SOMWIDGET_JUPYTER_URL (see `view_url`).

The panel works without a frontend: its widgets are plain Python objects, so tests (and scripts) can set
`panel.S.value = 300` and watch the session follow, or move a control and watch `panel.progress.value` restart.
"""

from __future__ import annotations

import asyncio
import html as _html
import itertools
import logging
import math
import os
import threading
import time
from contextlib import contextmanager
from pathlib import Path

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import ipywidgets as widgets  # noqa: E402

from ..backend import presets as _presets  # noqa: E402
from ..backend.presets import Preset  # noqa: E402
from .session import REACH_HELP, Frame, Session, hex_colour  # noqa: E402

log = logging.getLogger(__name__)

#: The panel refreshes its numbers at most this often per second (frames arrive at up to 30 a second).
PANEL_HZ = 8
#: The trame template (`?ui=...`) that holds the view alone, without the web app's own panel.
VIEW_TEMPLATE = "notebook_view"
#: The S slider's range and step (the session accepts any S >= 1 through `session.set_iterations`; the slider's
#: range widens to show a larger one).
S_SLIDER = (10, 5000, 10)
#: Text blocks: the notebook's default line height spreads small print apart.
_BLOCK = '<div style="line-height:1.35">{}</div>'
#: Seconds to wait for a notebook server to come up.
START_TIMEOUT = 60.0

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
        self.S = widgets.IntSlider(description="S", min=S_SLIDER[0], max=S_SLIDER[1], step=S_SLIDER[2],
                                   continuous_update=False,
                                   style=style, layout=wide, tooltip="cycles in a run (iterations)")
        self.l_start = widgets.FloatSlider(description="l_start", min=0.001, max=1.0, step=0.001,
                                           readout_format=".3f", continuous_update=False, style=style,
                                           layout=wide)
        self.l_end = widgets.FloatSlider(description="l_end", min=0.001, max=1.0, step=0.001, readout_format=".3f",
                                         continuous_update=False, style=style, layout=wide)
        self.smoothing = widgets.FloatSlider(description="smoothing", min=0.0, max=1.0, step=0.01,
                                             readout_format=".2f", continuous_update=False, style=style,
                                             layout=wide)
        self.reach = widgets.FloatSlider(description="reach", min=0.01, max=1.0, step=0.01, readout_format=".2f",
                                         continuous_update=False, style=style, layout=wide)
        self.symmetry = widgets.Checkbox(description="symmetry (mirror across the xz-plane)", indent=False)
        self.features_box = widgets.VBox()
        self.metric: list[widgets.BoundedFloatText] = []
        self.controls_html = widgets.HTML()
        self.error = widgets.HTML()

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
            widgets.HTML(_BLOCK.format("<b>Controls</b> <small>(gap: distance to the nearest node, original / "
                                       "mirror)</small>")),
            self.controls_html, self.error,
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
            w = widgets.BoundedFloatText(value=float(weights[d]), min=0.0, max=1e6, step=0.1, description=name,
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
        for w in [*self.children, *self.metric, *self.features_box.children]:
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
# The view: the web app's trame server on a thread of its own
# --------------------------------------------------------------------------------------------------------------
_START_LOCK = threading.Lock()  # trame binds its protocol to the server being started: one start at a time
_SERVERS: dict[int, NotebookServer] = {}
_NAMES = itertools.count(1)


class NotebookServer:
    """The web app (app.build_app) for `session`, served on `host`:`port` (0: a free port) from its own thread.

    Everything trame and VTK do happens on that thread's event loop; the kernel's thread only starts and stops it.
    Besides the app's page (`app_url`), a template with the view alone (`view_url`, `?ui=notebook_view`) is what
    the notebook's iframe shows.

    `host` must be a loopback address (ValueError otherwise): the notebook's server has no access token and no TLS.
    For a headset or another machine, serve the session with `somwidget serve --lan`; for a remote Jupyter server,
    go through jupyter-server-proxy (see `base_url`). Like `somwidget serve`, it answers only loopback Host names,
    except behind such a proxy (SOMWIDGET_JUPYTER_URL or JupyterHub), which forwards the browser's Host; websockets
    from pages of other sites are refused either way (lan.request_guard).
    """

    def __init__(self, session: Session, host: str = "127.0.0.1", port: int = 0, timeout: float = START_TIMEOUT):
        from . import lan

        host = lan.normalise_host(host) or "127.0.0.1"
        if not lan.is_loopback(host):
            raise ValueError(f"the notebook's view serves on loopback only (got host {host!r}): it has no access "
                             "token and no HTTPS. To reach the session from another machine or a headset, run "
                             "`somwidget serve --lan` (HTTPS, a token and a QR code); for a remote Jupyter server "
                             "use jupyter-server-proxy (SOMWIDGET_JUPYTER_URL)")
        self.session = session
        self.host = host
        self.name = f"somwidget-notebook-{next(_NAMES)}"
        self.app = None
        self.server = None
        self.port: int | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stopped = False
        with _START_LOCK:
            self._thread = threading.Thread(target=self._run, args=(port,), name=self.name, daemon=True)
            self._thread.start()
            if not self._ready.wait(timeout):
                raise RuntimeError(f"the notebook view's server did not start within {timeout:g} s")
        if self._error is not None:
            raise RuntimeError(f"the notebook view's server failed to start: {self._error}") from self._error

    def _run(self, port: int) -> None:
        try:
            from trame.app import get_server
            from trame.ui.vuetify3 import VAppLayout
            from trame_pyvista import PyVistaRemoteView

            from .app import build_app

            loop = asyncio.new_event_loop()
            asyncio.set_event_loop(loop)
            self._loop = loop
            server = get_server(self.name, client_type="vue3")
            app = build_app(self.session, server=server, title="somwidget")
            app.check_host = not behind_proxy()  # a proxy forwards the browser's Host (the Jupyter server's)
            with VAppLayout(server, template_name=VIEW_TEMPLATE, fill_height=True) as layout:
                layout.root.style = "height: 100vh; overflow: hidden"
                PyVistaRemoteView(app.scene.plotter, interactive_ratio=1, still_ratio=1, interactive_quality=80,
                                  still_quality=95, style="width: 100%; height: 100vh")
            self.server, self.app = server, app
            server.controller.on_server_ready.add(self._on_ready)
            coro = server.start(exec_mode="coroutine", port=port, host=self.host, thread=True, open_browser=False,
                                show_connection_info=False, disable_logging=True, timeout=0)
        except BaseException as exc:  # report to the starting thread
            self._error = exc
            self._ready.set()
            return
        try:
            loop.run_until_complete(coro)
        except BaseException as exc:
            if not self._ready.is_set():
                self._error = exc
            else:
                log.exception("notebook view server stopped")
        finally:
            self._ready.set()
            try:
                app.close()  # off the session (app and XR hub), the frame pump cancelled, the render window freed
            except Exception:
                log.exception("closing the notebook view failed")
            try:
                pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
                for task in pending:
                    task.cancel()
                if pending:
                    loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            except Exception:
                log.exception("cancelling the notebook view's tasks failed")
            loop.close()

    def _on_ready(self, **_) -> None:
        self.port = int(self.server.port)
        self._ready.set()

    @property
    def running(self) -> bool:
        return self._thread.is_alive() and not self._stopped

    @property
    def base_url(self) -> str:
        return base_url(self.port, self.host)

    @property
    def app_url(self) -> str:
        """The whole web app (its own panel included) of this session."""
        return self.base_url

    @property
    def view_url(self) -> str:
        """The view alone: what the notebook's iframe shows."""
        return f"{self.base_url}?ui={VIEW_TEMPLATE}"

    def stop(self, timeout: float = 10.0) -> None:
        """Stop the server and its thread (the session keeps running)."""
        if self._stopped:
            return
        self._stopped = True
        _SERVERS.pop(id(self.session), None)
        loop, server = self._loop, self.server
        if loop is not None and server is not None and not loop.is_closed() and self._thread.is_alive():
            try:
                asyncio.run_coroutine_threadsafe(server.stop(), loop).result(timeout)
            except Exception:
                log.exception("stopping the notebook view server failed")
        self._thread.join(timeout)


def behind_proxy() -> bool:
    """True when the notebook's views go through a proxy (SOMWIDGET_JUPYTER_URL or JupyterHub's), not straight to
    the loopback port."""
    return bool(os.environ.get("SOMWIDGET_JUPYTER_URL") or os.environ.get("JUPYTERHUB_SERVICE_PREFIX"))


def base_url(port: int, host: str = "127.0.0.1") -> str:
    """Where the browser finds a notebook server on `port`.

    SOMWIDGET_JUPYTER_URL, when set, is a template with {port} (and optionally {host}): e.g. "/proxy/{port}/"
    behind jupyter-server-proxy on a remote Jupyter server. On JupyterHub (JUPYTERHUB_SERVICE_PREFIX set) the
    default is the hub's server proxy, "<prefix>proxy/{port}/". Otherwise http://127.0.0.1:{port}/ (the browser
    runs on the kernel's machine).
    """
    template = os.environ.get("SOMWIDGET_JUPYTER_URL")
    if template:
        return template.format(port=port, host=host)
    prefix = os.environ.get("JUPYTERHUB_SERVICE_PREFIX")
    if prefix:
        return f"{prefix.rstrip('/')}/proxy/{port}/"
    shown = "127.0.0.1" if host in ("0.0.0.0", "", "::", None) else host
    shown = f"[{shown}]" if ":" in shown else shown
    return f"http://{shown}:{port}/"


def server_for(session: Session, host: str = "127.0.0.1", port: int = 0) -> NotebookServer:
    """The running notebook server of `session`, started on first use (one per session, shared by its views)."""
    srv = _SERVERS.get(id(session))
    if srv is not None and srv.session is session and srv.running:
        return srv
    srv = NotebookServer(session, host=host, port=port)
    _SERVERS[id(session)] = srv
    return srv


# --------------------------------------------------------------------------------------------------------------
# The widget show() returns
# --------------------------------------------------------------------------------------------------------------
class SomWidget(widgets.HBox):
    """The panel and the live view side by side. `session`, `panel`, `server` (None without a view), `url`."""

    def __init__(self, session: Session, panel: Panel, server: NotebookServer | None = None, height: int = 560,
                 full_app: bool = False, owns_session: bool = False):
        self.session = session
        self.panel = panel
        self.server = server
        self.owns_session = owns_session
        self.url = None
        children = [panel]
        if server is not None:
            self.url = server.app_url if full_app else server.view_url
            frame = (f'<iframe src="{_html.escape(self.url, quote=True)}" style="width:100%;height:{int(height)}px;'
                     'border:1px solid #ddd;border-radius:4px" allow="xr-spatial-tracking; fullscreen"></iframe>')
            self.view = widgets.HTML(frame, layout=widgets.Layout(flex="1 1 auto", min_width="360px"))
            children.append(self.view)
        else:
            self.view = None
        super().__init__(children, layout=widgets.Layout(width="100%", align_items="flex-start"))

    @property
    def app_url(self) -> str | None:
        """The whole web app of this session (open it in a tab; a later WebXR page lives on the same server)."""
        return None if self.server is None else self.server.app_url

    def close(self, stop_server: bool = True) -> None:
        """Close the widgets; stop the view's server (unless `stop_server=False`) and a session show() made."""
        self.panel.close()
        if self.view is not None:
            self.view.close()
        if stop_server and self.server is not None:
            self.server.stop()
        if self.owns_session:
            self.session.close()
        super().close()


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


def show(what="car", *, device: str | None = "auto", paused: bool = False, view: bool = True, full_app: bool = False,
         host: str = "127.0.0.1", port: int = 0, height: int = 560) -> SomWidget:
    """An interactive SOM in a notebook cell: the panel beside the live, draggable 3-D view of one Session.

    what:     a preset name ("car", "space-grid", "lines", ...), a Preset, a mesh file path (OBJ, PLY, STL, OFF,
              GLB), an existing Session (its other views, e.g. the web app, stay in step), or a SomWidget
    device:   where a new session trains: "auto" (the GPU when there is one), "cpu", "cuda:N"
    paused:   a new session starts paused (press Train)
    view:     False: the panel alone (no server, no iframe)
    full_app: show the whole web app (its own panel too) instead of the view alone
    host, port: where the view's server listens (loopback and a free port by default; a host beyond loopback is
              refused with ValueError: use `somwidget serve --lan` to reach a session from another machine)
    height:   of the view in pixels

    Returns the widget (an ipywidgets HBox: put it last in the cell, or `display()` it); `.session` is the
    Session to script (`move_control`, `set_iterations`, `wait_idle`, `export_mesh`...), `.app_url` the whole
    web app of the same session, `.close()` stops it all.
    """
    session, owned = _session_of(what, device, paused)
    try:
        server = server_for(session, host=host, port=port) if view else None
        panel = Panel(session)
    except Exception:
        if owned:
            session.close()
        raise
    return SomWidget(session, panel, server, height=height, full_app=full_app, owns_session=owned)


def close_all() -> None:
    """Stop every notebook server this kernel started (their sessions keep running)."""
    for srv in list(_SERVERS.values()):
        srv.stop()


__all__ = ["Panel", "NotebookServer", "SomWidget", "show", "server_for", "base_url", "close_all", "VIEW_TEMPLATE"]
