"""The web app: a trame (vue3 + vuetify3) page with the session's panel beside the clay view.

`somwidget serve` calls `run_server(...)`. One server holds one `Session`; every tab on it shares the session, so
any tab can drag a control and all of them see the clay follow. The 3-D view is the browser's own (the module
/xr/somview.js, built from xr/src/view.js, mounted into the page): it draws the frames the XR hub streams over the
websocket /xr/ws and sends the drags back as intents, so each tab keeps its own camera and nothing is rendered on
the server. The panel is trame's: its state and triggers.

Threads: the session trains on its own thread and hands frames to `SomApp._on_frame`, which only stores the
latest one. A task on the server's event loop (`_pump`) refreshes the panel's numbers a few times a second and the
panel's fields when the preset or the history changes.

A read-only JSON route, GET /api/state, reports the session, the panel and the connected clients (for tests,
benchmarks and scripts); add ?positions=1 for every node's position.

Every bind gets `lan.request_guard`: websockets (trame's /ws, /xr/ws) from pages of other sites are refused, and a
loopback-bound server answers only loopback Host names (no DNS rebinding). Beyond loopback, `run_server` adds HTTPS
and the access token (lan.py).
"""

from __future__ import annotations

import asyncio
import logging
import math
import os
import sys
import tempfile
import threading
import time
import unicodedata
from pathlib import Path

from aiohttp import web
from trame.app import get_server
from trame.ui.vuetify3 import SinglePageWithDrawerLayout
from trame.widgets import client, html
from trame.widgets import vuetify3 as v3
from wslink.websocket import LinkProtocol

from ...backend import checks
from ...backend import device as _device
from ...backend import presets as _presets
from . import lan as _lan
from ..model.parameters import BY_NAME as _PARAM
from ..model.parameters import GAP_HELP, METRIC_WEIGHT
from ..transport.display import control_colours
from ...backend.presets import hex_colour
from ..model import Frame, Session
from ..model.clay import max_vertices_for
from ..model.parameters import REACH_HELP
from ..model.variants import MAX_GALLERY_VARIANTS, VARIANTS_HELP, VARIED, vary_around
from ..model.variants import sweep as sweep_variants
from .state_guard import guard_state_updates
from ..transport.limits import bound_messages
from .hub import attach as attach_xr

log = logging.getLogger(__name__)

#: Largest file the upload fields accept (a mesh or a session).
MAX_UPLOAD_BYTES = 50_000_000  # "50 MB", as the README and the messages say
#: Panel numbers (iteration, gaps, cycle time) refresh at most this often per second.
PANEL_HZ = 8
def _png_data_url(img) -> str:
    """An (H, W, 3) uint8 image as a PNG data URL (a thumbnail the page shows as it is)."""
    import base64

    from ..model.picture import png_bytes

    return "data:image/png;base64," + base64.b64encode(png_bytes(img)).decode("ascii")


MIME = {"obj": "text/plain", "ply": "application/octet-stream", "glb": "model/gltf-binary"}
#: Mesh files the upload field takes (by the suffix of the browser's file name).
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
#: Longest file name shown back in messages and preset titles.
MAX_SHOWN_NAME = 80
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
}
"""


#: Uploads are written to tempfile's folder as somwidget-upload-<pid>-*: a server killed mid-upload leaves its
#: folder behind, and the next server start (and every exit) removes the folders of processes that are gone.
UPLOAD_PREFIX = "somwidget-upload-"


def _upload_prefix() -> str:
    return f"{UPLOAD_PREFIX}{os.getpid()}-"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def sweep_uploads(own: bool = False) -> list[str]:
    """Remove upload folders left by servers that are gone (and this process's own with `own`); returns them."""
    import shutil

    removed = []
    root = Path(tempfile.gettempdir())
    for folder in root.glob(f"{UPLOAD_PREFIX}*"):
        pid = folder.name[len(UPLOAD_PREFIX):].split("-", 1)[0]
        mine = pid == str(os.getpid())
        if folder.is_dir() and ((own and mine) or (not mine and (not pid.isdigit() or not _pid_alive(int(pid))))):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(str(folder))
    return removed


def _state_key(name: str) -> str:
    """The trame state key of a parameter's field."""
    return "param_S" if name == "iterations" else f"param_{name}"


def _fmt(x: float, digits: int = 3) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


class _ClientWatch(LinkProtocol):
    """Counts the page's websocket clients (for /api/state)."""

    def __init__(self, app: SomApp):
        super().__init__()
        self._app = app

    def onConnect(self, request, client_id):  # noqa: N802 (wslink's name)
        self._app.clients.add(str(client_id))

    def onClose(self, client_id):  # noqa: N802
        self._app.clients.discard(str(client_id))


class SomApp:
    """The trame app around one Session: layout, panel callbacks, the clay view's hub and the panel pump."""

    def __init__(self, session: Session, server=None, title: str = "somwidget", fresh=None):
        self.session = session
        self.fresh = fresh if fresh is not None else session.preset  # what "Start fresh" loads after a recovery
        self.xr_token: str | None = None  # the LAN access token, when served beyond loopback
        # on a loopback bind, answer only loopback Host names (False behind a proxy that forwards the browser's Host)
        self.check_host = True
        self.xr = None  # the clay view's hub (/xr/ws, /xr/somview.js), once the server is bound
        self.server = server if server is not None else get_server("somwidget", client_type="vue3")
        self.server.client_type = "vue3"
        self.state, self.ctrl = self.server.state, self.server.controller
        self.title = title
        self.clients: set[str] = set()
        self._latest: Frame | None = None
        self._latest_lock = threading.Lock()
        self._generation_seen = session.frame.generation
        self._history_seen = session.frame.history
        self._params_seen = session.parameters
        self._params_synced: dict = {}
        self._last_panel = 0.0
        self._panel_seq = -1
        self._pump_task = None
        self._extra_presets: list[dict] = []
        self._uploaded: dict[str, object] = {}  # name -> Preset of the meshes loaded in this server's life
        if session.preset.name not in _presets.PRESETS:  # started from `somwidget serve --mesh FILE`
            self._remember_upload(session.preset)
        sweep_uploads()  # what servers killed mid-upload left behind
        self._init_state()
        self._build_ui()
        self._register()
        session.add_listener(self._on_frame)

    def close(self) -> None:
        """Detach from the session (the app and its hub; call on the server's thread, after it stopped)."""
        sweep_uploads(own=True)
        self.session.remove_listener(self._on_frame)
        if self.xr is not None:
            self.xr.detach()
        if self._pump_task is not None:
            self._pump_task.cancel()
            self._pump_task = None

    # -- session -> panel -------------------------------------------------------------------------------------
    def _on_frame(self, frame: Frame) -> None:
        """Training thread: keep only the latest frame; the pump shows its numbers."""
        with self._latest_lock:
            self._latest = frame

    async def _pump(self) -> None:
        while True:
            try:
                self._pump_once()
            except Exception:
                log.exception("panel pump failed")
            await asyncio.sleep(1.0 / (2 * PANEL_HZ))

    def _pump_once(self) -> None:
        with self._latest_lock:
            frame = self._latest
        if frame is None:
            return
        params = self.session.parameters
        if frame.generation != self._generation_seen:  # a new preset (from any view): every field
            self._generation_seen, self._history_seen, self._params_seen = frame.generation, frame.history, params
            with self.state:
                self._sync_session_state(force=True)
        elif frame.history != self._history_seen or params != self._params_seen:
            # an undo, a redo, a new step or a parameter set elsewhere (a repeat within PARAMETER_STEP_SECONDS joins
            # its step, so the history alone does not tell): the fields whose values changed follow
            self._history_seen, self._params_seen = frame.history, params
            with self.state:
                self._sync_session_state()
        now = time.monotonic()
        if now - self._last_panel > 1 / PANEL_HZ and (frame.seq != self._panel_seq or now - self._last_panel > 1.0):
            self._update_panel(frame)
            self._panel_seq = frame.seq
            self._last_panel = now

    # -- state -------------------------------------------------------------------------------------------------------
    def _preset_items(self) -> list[dict]:
        items = [{"title": _presets.PRESET_LABELS.get(name, name), "value": name} for name in _presets.PRESETS]
        return items + self._extra_presets

    def _init_state(self) -> None:
        s = self.state
        s.trame__title = self.title
        s.preset_items = self._preset_items()
        s.preset_name = self.session.preset.name
        s.error_message = ""
        s.info_message = ""
        s.busy = False
        s.mesh_upload = None
        s.session_upload = None
        s.stats = {}
        s.controls_ui = []
        s.features_ui = []
        s.param_errors = {}
        s.reach_help = REACH_HELP
        s.recovered_message = self._recovered_message()
        s.variants_n = 12
        s.variants_jitter = 0.05
        s.variants_vary = []
        s.variants_gallery = []
        s.variants_progress = 0
        self._variants = None
        self._sync_session_state()
        self._update_panel(self.session.frame)

    def _sync_session_state(self, force: bool = False) -> None:
        """Panel fields that change with the preset or a parameter intent (not every frame). A parameter's field
        is written only when its value changed since the last sync (or with `force`): a field someone is typing in
        is not reset by another view's step."""
        s, sess = self.state, self.session
        p = sess.parameters
        last = {} if force else self._params_synced
        s.preset_name = sess.preset.name
        s.preset_title = sess.preset.title
        s.preset_description = sess.preset.description
        for name in ("iterations", "l_start", "l_end", "smoothing", "reach", "symmetry"):
            if force or p[name] != last.get(name):
                value = p[name]
                s[_state_key(name)] = (str(value) if name == "iterations" else float(value) if name == "reach"
                                       else bool(value) if name == "symmetry" else _fmt(value, 6))
        self._params_synced = p
        s.paused = sess.paused
        layout = sess.layout
        roles = {}
        for d in layout.position:
            roles[d] = "position"
        for d in layout.colour:
            roles[d] = f"colour ({layout.colour_space})"
        for d in layout.direction:
            roles[d] = "direction"
        if layout.length is not None:
            roles[layout.length] = "length"
        s.features_ui = [{"d": d, "name": layout.names[d], "role": roles.get(d, "feature"),
                          "colour": d in layout.colour, "weight": _fmt(p["metric_weights"][d], 6)}
                         for d in range(layout.n_dims)]
        s.has_colour = layout.colour_space != "none"
        s.param_errors = {}

    def _update_panel(self, frame: Frame) -> None:
        sess = self.session
        k = frame.n_controls
        gaps = frame.gaps
        own = control_colours(frame, frame.layout.colour_space != "none")[:k]
        controls = []
        for i in range(k):
            g = [float(gaps[i])]
            if len(gaps) >= 2 * k:  # mirrored copy i sits at k + i
                g.append(float(gaps[k + i]))
            controls.append({"i": i, "colour": hex_colour(own[i]),
                             "position": ", ".join(f"{x:.2f}" for x in frame.control_positions[i]),
                             "gap": " / ".join(f"{x:.3f}" for x in g)})
        with self.state as s:
            s.controls_ui = controls
            s.stats = {
                "iteration": frame.iteration, "S": frame.iterations,
                "progress": round(100.0 * frame.progress, 1),
                "running": frame.running, "paused": frame.paused,
                "cycle_ms": _fmt(frame.cycle_time * 1e3, 3),
                "fps": _fmt(sess.frames_per_second, 3),
                "n_vertices": int(frame.positions.shape[0]), "k": k, "k_eff": int(len(gaps)),
                "max_gap": _fmt(float(gaps.max()) if len(gaps) else 0.0, 3),
                "can_undo": frame.history[0] > 0, "can_redo": frame.history[1] > 0, "held": frame.held,
            }
            s.paused = frame.paused
            if sess.error and not s.error_message:
                s.error_message = sess.error

    def _error(self, message: str) -> None:
        log.info("refused: %s", message)
        self.state.error_message = message
        self.state.flush()

    # -- intents from the panel ---------------------------------------------------------------------------------
    def set_param(self, name, value) -> None:
        errors = dict(self.state.param_errors or {})
        try:
            self.session.set_parameter(name, value)
            errors.pop(name, None)
            self.state.error_message = ""
        except ValueError as exc:
            errors[name] = str(exc)
            self.state.error_message = str(exc)
        with self.state:
            self.state.param_errors = errors
            if name not in errors:
                self._sync_session_state()

    def set_metric(self, dim, value) -> None:
        key = f"metric_weights_{dim}" if isinstance(dim, int) and not isinstance(dim, bool) else "metric_weights"
        try:
            self.session.set_metric_weight(dim, value)  # the session checks dim: no truncation here
            self.state.error_message = ""
            failed = None
        except (ValueError, TypeError) as exc:
            failed = str(exc)
            self._error(failed)
        with self.state:
            self._sync_session_state()
            if failed is not None:  # at the field that caused it (the sync above cleared the others)
                self.state.param_errors = {**(self.state.param_errors or {}), key: failed}

    def set_colour(self, index, colour) -> None:
        try:
            self.session.set_control_colour(index, colour)
        except (ValueError, TypeError) as exc:
            self._error(str(exc))

    def add_control(self) -> None:
        try:
            self.session.add_control()
        except ValueError as exc:
            self._error(str(exc))

    def remove_control(self, index) -> None:
        try:
            self.session.remove_control(index)  # "0" or 1.9 are refused there, not truncated
        except (ValueError, TypeError) as exc:
            self._error(str(exc))

    def toggle_training(self) -> None:
        """Pause a running map; otherwise train (a settled run restarts locally), as the button says."""
        if self.session.frame.running:
            self.session.pause()
        else:
            self.session.train()
        self.state.paused = self.session.paused

    def reset(self) -> None:
        self.session.reset()

    def undo(self) -> None:
        self._travel(self.session.undo)

    def redo(self) -> None:
        self._travel(self.session.redo)

    def _travel(self, move) -> None:
        try:
            move()
        except (ValueError, RuntimeError) as exc:
            self._error(str(exc))
        with self.state:
            self._sync_session_state()
            self._update_panel(self.session.frame)

    def _recovered_message(self) -> str:
        found = self.session.recovered
        if not found:
            return ""
        saved = time.strftime("%Y-%m-%d %H:%M", time.localtime(found["saved"]))
        return (f"Recovered your session of {saved} ({found['preset'] or 'a session'}), which did not close cleanly: "
                "everything is as its last completed step left it.")

    async def reload_preset(self) -> None:
        """The current preset again, as it starts: its own controls and start mesh (one undo step)."""
        preset = self.session.preset
        name = preset.name if preset.name in _presets.PRESETS else None
        fresh = self._uploaded.get(preset.name) if name is None else name
        if fresh is None:  # a loaded session: its start mesh with the controls it was saved with
            fresh = preset
        await self._replace(lambda: self.session.load_preset(fresh))

    async def start_fresh(self) -> None:
        """After a recovery: load what the server was started with (one undo step: Undo brings the recovered
        session back)."""
        fresh = self.fresh
        with self.state:
            self.state.recovered_message = ""
        await self._replace(lambda: self.session.load_preset(fresh))

    def _remember_upload(self, preset) -> None:
        self._uploaded = {preset.name: preset}  # keep the latest upload only
        self._extra_presets = [{"title": f"Uploaded: {preset.title} ({preset.n_vertices} nodes)",
                                "value": preset.name}]

    async def choose_preset(self, name) -> None:
        """Load a preset chosen in the menu (the current one again: `reload_preset`)."""
        if not isinstance(name, str):
            self._error(f"unknown preset: expected a preset's name, got {type(name).__name__}")
            with self.state:
                self.state.preset_name = self.session.preset.name
            return
        if not name or name == self.session.preset.name:
            return
        if name in self._uploaded:
            preset = self._uploaded[name]
            await self._replace(lambda: self.session.load_preset(preset))
            return
        if name not in _presets.PRESETS:
            self._error(f"unknown preset {name!r}")
            with self.state:
                self.state.preset_name = self.session.preset.name
            return
        await self._replace(lambda: self.session.load_preset(name))

    async def _replace(self, fn, scrub: dict[str, str] | None = None) -> bool:
        """Run a slow session replacement off the event loop; errors go to the panel (with each key of `scrub`, a
        temporary path, replaced by its value, the name the person knows)."""
        def shown(message: str) -> str:
            for old, new in (scrub or {}).items():
                message = message.replace(old, new)
            return message

        with self.state:
            self.state.busy = True
        try:
            await asyncio.get_running_loop().run_in_executor(None, fn)
            ok = True
            self.state.error_message = ""
        except (ValueError, OSError) as exc:
            ok = False
            self.state.error_message = shown(str(exc))
        except Exception as exc:  # keep the server up whatever a file does to a reader
            log.exception("loading failed")
            ok = False
            self.state.error_message = shown(f"could not load: {type(exc).__name__}: {exc}")
        with self.state:
            self.state.busy = False
            self.state.preset_name = self.session.preset.name
        return ok

    @staticmethod
    def _shown_name(raw) -> str:
        """The browser's file name made safe to show: its last path part, without control characters, at most
        MAX_SHOWN_NAME characters (keeping the suffix). Never used as a path."""
        name = str(raw or "").replace("\\", "/").rsplit("/", 1)[-1]
        name = "".join(ch for ch in name if unicodedata.category(ch)[0] != "C").strip()
        if len(name) > MAX_SHOWN_NAME:
            stem, dot, suffix = name.rpartition(".")
            if dot and stem and len(suffix) <= 8:
                name = name[:MAX_SHOWN_NAME - len(suffix) - 4] + "..." + dot + suffix
            else:
                name = name[:MAX_SHOWN_NAME - 3] + "..."
        return name or "upload"

    @staticmethod
    def _suffix(name: str) -> str:
        stem, dot, suffix = name.rpartition(".")
        return "." + suffix.lower() if dot and stem else ""

    @classmethod
    def _file_of(cls, value):
        """trame's file dict (or the first of a list) -> (name to show, bytes), None for no file, or ValueError."""
        if isinstance(value, list):
            value = value[0] if value else None
        if not value:
            return None
        if not isinstance(value, dict):
            raise ValueError("upload: unexpected data from the browser")
        name = cls._shown_name(value.get("name"))
        try:
            size = int(value.get("size") or 0)
        except (TypeError, ValueError):
            raise ValueError("upload: unexpected data from the browser") from None
        if size > MAX_UPLOAD_BYTES:
            raise ValueError(f"upload: {name!r} is {size / 1e6:.1f} MB; the limit is "
                             f"{MAX_UPLOAD_BYTES / 1e6:.0f} MB")
        content = value.get("content")
        if isinstance(content, list):
            content = b"".join(content)
        if isinstance(content, str):
            content = content.encode("latin-1")
        if not content:
            raise ValueError(f"upload: {name!r} is empty")
        if not isinstance(content, (bytes, bytearray, memoryview)):
            raise ValueError("upload: unexpected data from the browser")
        if len(content) > MAX_UPLOAD_BYTES:
            raise ValueError(f"upload: file is larger than {MAX_UPLOAD_BYTES / 1e6:.0f} MB")
        return name, bytes(content)

    def _load_mesh(self, path: Path, name: str) -> None:
        """Session.load_mesh for an uploaded file saved as `path`, named after the browser's file `name`."""
        from ...backend import io as sw_io

        preset = sw_io.load_mesh(path, max_vertices=self.session.max_vertices)
        stem = name[: -len(self._suffix(name))] if self._suffix(name) else name
        preset.name = f"mesh:{stem or 'upload'}"  # never mistaken for a built-in preset of the same name
        preset.title = name
        preset.description = preset.description.replace(path.name, name)
        self.session.load_preset(preset)

    async def upload_mesh(self, value) -> None:
        """A mesh file from the upload field becomes the clay. The bytes are written as "upload<suffix>" in a fresh
        temporary folder (the browser's file name only picks the suffix and labels messages), which is removed
        afterwards; the field (and the bytes in trame's state) is cleared whatever happens."""
        try:
            got = self._file_of(value)
            if got is None:
                return
            name, content = got
            suffix = self._suffix(name)
            if suffix not in MESH_SUFFIXES:
                self._error(f"upload: {name!r} is not a mesh file this app reads; use "
                            f"{', '.join(x[1:].upper() for x in MESH_SUFFIXES)}")
                return
            with tempfile.TemporaryDirectory(prefix=_upload_prefix()) as folder:
                path = Path(folder) / f"upload{suffix}"
                path.write_bytes(content)
                ok = await self._replace(lambda: self._load_mesh(path, name), scrub={str(path): name})
            if ok:
                preset = self.session.preset
                self._remember_upload(preset)
                with self.state:
                    self.state.preset_items = self._preset_items()
                    self.state.preset_name = preset.name
                    self.state.info_message = f"loaded {name}: {preset.n_vertices} vertices"
        except (ValueError, OSError) as exc:
            self._error(str(exc))
        finally:
            with self.state:
                self.state.mesh_upload = None

    async def upload_session(self, value) -> None:
        """A saved session (.npz) from the upload field replaces the session; the same care as upload_mesh."""
        try:
            got = self._file_of(value)
            if got is None:
                return
            name, content = got
            with tempfile.TemporaryDirectory(prefix=_upload_prefix()) as folder:
                path = Path(folder) / "upload.npz"
                path.write_bytes(content)
                ok = await self._replace(lambda: self.session.load(path), scrub={str(path): name})
            if ok:
                with self.state:
                    self.state.info_message = f"session {name} loaded"
        except (ValueError, OSError) as exc:
            self._error(str(exc))
        finally:
            with self.state:
                self.state.session_upload = None

    def export_mesh(self, fmt) -> bytes | None:
        fmt = str(fmt).lower()
        if fmt not in MIME:
            self._error(f"export: unknown format {fmt!r}; use obj, ply or glb")
            return None
        return self._written_bytes(self.session.export_mesh, "." + fmt)

    def save_session(self) -> bytes | None:
        return self._written_bytes(self.session.save, ".npz")

    def _written_bytes(self, write, suffix: str) -> bytes | None:
        """What `write(path)` puts in a temporary file with `suffix`, for a download; errors go to the panel."""
        fd, tmp = tempfile.mkstemp(prefix="somwidget-", suffix=suffix)
        os.close(fd)
        try:
            write(tmp)
            return Path(tmp).read_bytes()
        except (ValueError, OSError) as exc:
            self._error(str(exc))
            return None
        finally:
            os.remove(tmp)

    # -- wiring ----------------------------------------------------------------------------------------------------
    async def sweep_variants(self) -> None:
        """Train the Variants section's design variants of the current design (a local restart each, batched on the
        session's device) and show them as a gallery of thumbnails."""
        s = self.state
        try:
            n = checks.integer_text("variants: how many", s.variants_n, 1, MAX_GALLERY_VARIANTS)
            jitter = checks.real("variants: jitter", float(s.variants_jitter), 0.0, 1.0)
        except (TypeError, ValueError) as exc:
            self._error(str(exc))
            return
        vary = [name for name in (s.variants_vary or []) if name in VARIED]
        params = vary_around(vary, self.session.parameters)

        def run():
            variants = sweep_variants(self.session, n=n, jitter=jitter, params=params, progress=progress,
                                      device=self.session.training_device)
            thumbs = [_png_data_url(image) for image in variants.thumbnails()]
            return variants, thumbs

        loop = asyncio.get_running_loop()

        def progress(done, total):
            loop.call_soon_threadsafe(self._set_variants_progress, 100.0 * done / max(1, total))

        with self.state:
            s.busy = True
            s.variants_progress = 0
        try:
            variants, thumbs = await loop.run_in_executor(None, run)
        except (ValueError, RuntimeError) as exc:
            self._error(f"variants: {exc}")
            return
        finally:
            with self.state:
                s.busy = False
        self._variants = variants
        with self.state:
            s.variants_gallery = [
                {"i": i, "src": thumbs[i], "title": f"#{i}: gap {variants.metrics['gap'][i]:.3f}, spike "
                 f"{variants.metrics['spike'][i]:.2f}" + "".join(f", {k} {_fmt(v)}" for k, v in
                                                              variants.params[i].items() if k in vary)}
                for i in range(len(variants))]
            s.variants_progress = 100

    def _set_variants_progress(self, value: float) -> None:
        with self.state:
            self.state.variants_progress = value

    def pick_variant(self, i) -> None:
        """Make gallery variant i the session's current state (one undo step)."""
        variants = self._variants
        try:
            if variants is None:
                raise ValueError("no variants yet: press Sweep first")
            variants.apply(i, self.session)
        except ValueError as exc:
            self._error(f"variants: {exc}")

    def _register(self) -> None:
        server, state, ctrl = self.server, self.state, self.ctrl
        server.trigger("set_param")(self.set_param)
        server.trigger("set_metric")(self.set_metric)
        server.trigger("set_colour")(self.set_colour)
        server.trigger("add_control")(self.add_control)
        server.trigger("remove_control")(self.remove_control)
        server.trigger("toggle_training")(self.toggle_training)
        server.trigger("reset")(self.reset)
        server.trigger("undo")(self.undo)
        server.trigger("redo")(self.redo)
        server.trigger("start_fresh")(self.start_fresh)
        server.trigger("reload_preset")(self.reload_preset)
        server.trigger("export_mesh")(self.export_mesh)
        server.trigger("save_session")(self.save_session)
        server.trigger("sweep_variants")(self.sweep_variants)
        server.trigger("pick_variant")(self.pick_variant)

        @state.change("preset_name")
        async def _preset_changed(preset_name, **_):
            await self.choose_preset(preset_name)

        @state.change("mesh_upload")
        async def _mesh_uploaded(mesh_upload, **_):
            if mesh_upload:
                await self.upload_mesh(mesh_upload)

        @state.change("session_upload")
        async def _session_uploaded(session_upload, **_):
            if session_upload:
                await self.upload_session(session_upload)

        @state.change("param_symmetry")
        def _symmetry(param_symmetry, **_):
            if bool(param_symmetry) != self.session.parameters["symmetry"]:
                self.set_param("symmetry", bool(param_symmetry))

        ctrl.on_server_bind.add(self._bind_routes)
        ctrl.on_server_ready.add(self._on_ready)
        server.add_protocol_to_configure(lambda protocol: protocol.registerLinkProtocol(_ClientWatch(self)))

    def _on_ready(self, **_):
        if self._pump_task is None:
            self._pump_task = asyncio.get_event_loop().create_task(self._pump())

    def _bind_routes(self, wslink_server) -> None:
        bound = getattr(wslink_server, "config", {}).get("host")
        try:
            loopback = _lan.is_loopback(bound)
        except ValueError:  # an empty host: every interface
            loopback = False
        wslink_server.app.middlewares.append(_lan.request_guard(check_host=self.check_host and loopback))
        if not bound_messages(wslink_server):
            log.warning("could not bound the page's websocket messages (wslink's handlers not found)")
        if not guard_state_updates(wslink_server):
            log.warning("could not guard the page's state updates (trame's state.update not found)")
        wslink_server.app.router.add_get("/api/state", self._api_state)
        self.xr = attach_xr(wslink_server, self.session, token=self.xr_token)

    async def _api_state(self, request: web.Request) -> web.Response:
        positions = request.query.get("positions", "0") not in ("0", "", "false")
        hub = self.xr
        body = {"session": self.session.state(positions=positions), "clients": len(self.clients),
                "views": {"clients": len(hub.clients) if hub else 0,
                          "frames_sent": sum(c.frames_sent for c in hub.clients.values()) if hub else 0,
                          "grabs": {str(i): cid for i, cid in hub.grabs.items()} if hub else {}},
                "panel": {"error_message": self.state.error_message, "param_S": self.state.param_S,
                          "recovered_message": self.state.recovered_message,
                          "preset_name": self.state.preset_name}}
        return web.json_response(body, headers={"Cache-Control": "no-store"})

    # -- layout --------------------------------------------------------------------------------------------------
    def _build_ui(self) -> None:
        with SinglePageWithDrawerLayout(self.server, full_height=True) as layout:
            layout.title.set_text("somwidget: computational clay")
            with layout.toolbar:
                v3.VSpacer()
                html.Div("{{ stats.iteration }} / {{ stats.S }}", classes="mr-3 text-body-2", id="iteration-label")
                v3.VBtn("{{ stats.running ? 'Pause' : 'Train' }}", id="train-button",
                        click="trigger('toggle_training')",
                        prepend_icon=("stats.running ? 'mdi-pause' : 'mdi-play'",), variant="tonal", classes="mr-2")
                v3.VBtn(icon="mdi-undo", id="undo-button", click="trigger('undo')", disabled=("!stats.can_undo",),
                        title="Undo (Ctrl+Z)", variant="text")
                v3.VBtn(icon="mdi-redo", id="redo-button", click="trigger('redo')", disabled=("!stats.can_redo",),
                        title="Redo (Ctrl+Shift+Z)", variant="text", classes="mr-2")
                v3.VBtn("Reset", id="reset-button", click="trigger('reset')", prepend_icon="mdi-restore",
                        variant="tonal", classes="mr-2", title="Back to the start mesh; the whole schedule runs again")
            with layout.drawer as drawer:
                drawer.width = 390
                self._panel()
            client.Script(SHORTCUTS_JS)
            client.Script(MOUNT_VIEW_JS)
            with layout.content:
                # the clay view mounts here (MOUNT_VIEW_JS); Vue leaves the element's children alone
                html.Div(id="clay-view", style="position: relative; width: 100%; height: calc(100vh - 88px)")
        self.layout = layout

    @staticmethod
    def _on_enter_or_change(handler: str) -> list[str]:
        return [f'@change="{handler}"', f'@keydown.enter="{handler}"']

    def _panel(self) -> None:
        with v3.VContainer(classes="pa-2 text-body-2", id="panel"):
            v3.VAlert(v_if="error_message", text=("error_message",), type="error", density="compact",
                      closable=True, id="error-alert", classes="mb-2",
                      click_close="error_message = ''")
            v3.VAlert(v_if="info_message && !error_message", text=("info_message",), type="info",
                      density="compact", closable=True, classes="mb-2", click_close="info_message = ''")
            with v3.VAlert(v_if="recovered_message", type="success", density="compact", classes="mb-2",
                           id="recovered-alert", closable=True, click_close="recovered_message = ''"):
                html.Div("{{ recovered_message }}")
                v3.VBtn("Start fresh", size="small", variant="tonal", classes="mt-1", id="start-fresh",
                        click="trigger('start_fresh')", title="Load the preset the server was started with (Undo "
                                                           "brings the recovered session back)")
            v3.VProgressLinear(v_if="busy", indeterminate=True, classes="mb-2")

            # preset and files
            with html.Div(classes="d-flex align-center mb-1"):
                v3.VSelect(v_model=("preset_name",), items=("preset_items",), label="Preset", density="compact",
                           hide_details=True, id="preset-select", disabled=("busy",))
                v3.VBtn(icon="mdi-reload", variant="text", size="small", id="reload-preset",
                        click="trigger('reload_preset')", disabled=("busy",),
                        title="This preset again as it starts: its own controls and start mesh")
            html.Div("{{ preset_description }}", classes="text-caption mb-2")
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
                html.Div("cycle {{ stats.cycle_ms }} ms, {{ stats.fps }} frames/s; {{ stats.n_vertices }} nodes, "
                         "{{ stats.k }} controls ({{ stats.k_eff }} with mirrors)", classes="text-caption",
                         id="speed-text")

            # schedule: the fields come from the parameters' declaration (parameters.py)
            html.Div("Schedule", classes="text-subtitle-2 mt-2")
            with v3.VRow(dense=True):
                for name in ("iterations", "smoothing", "l_start", "l_end"):
                    p = _PARAM[name]
                    with v3.VCol(cols=6), html.Div(id=f"param-{name}", title=p.help):
                        v3.VTextField(v_model=(_state_key(name),), label=p.label, density="compact", type="number",
                                      error_messages=(f"param_errors['{name}'] || []",), hide_details="auto",
                                      id=f"field-{name}",
                                      raw_attrs=self._on_enter_or_change(
                                          f"trigger('set_param', ['{name}', $event.target.value])"))
            reach = _PARAM["reach"]
            with html.Div(id="param-reach", title=reach.help):
                v3.VSlider(v_model=("param_reach",), label=("'reach ' + Number(param_reach).toFixed(2)",),
                           min=reach.slider[0], max=reach.slider[1], step=reach.slider[2], density="compact",
                           hide_details="auto", thumb_label=True, id="reach-slider", classes="mt-1",
                           error_messages=("param_errors['reach'] || []",),
                           end="trigger('set_param', ['reach', $event])")
            html.Div("{{ reach_help }}", classes="text-caption", id="reach-help")
            with html.Div(id="param-symmetry", title=_PARAM["symmetry"].help):
                v3.VSwitch(v_model=("param_symmetry",), label=_PARAM["symmetry"].label, density="compact",
                           hide_details=True, color="primary", id="symmetry-switch")

            # features
            html.Div("Feature dimensions (metric weights)", classes="text-subtitle-2 mt-2")
            with v3.VTable(density="compact", id="features-table"):
                with html.Tbody():
                    with html.Tr(v_for="f in features_ui", key="f.d"):
                        html.Td("{{ f.d }}")
                        html.Td("{{ f.name }}")
                        html.Td("{{ f.role }}", classes="text-caption")
                        with html.Td(style="width: 96px"):
                            v3.VTextField(model_value=("f.weight",), density="compact", type="number",
                                          hide_details="auto", variant="plain", title=METRIC_WEIGHT.help,
                                          error_messages=("param_errors['metric_weights_' + f.d] || []",),
                                          raw_attrs=self._on_enter_or_change(
                                              "trigger('set_metric', [f.d, $event.target.value])"))

            # controls
            with html.Div(classes="d-flex align-center mt-2"):
                html.Div("Controls (gap to the nearest node: original / mirror)", classes="text-subtitle-2",
                         title=GAP_HELP)
                v3.VSpacer()
                v3.VBtn(icon="mdi-plus", size="small", variant="text", click="trigger('add_control')",
                        id="add-control", title="Add a control")
            with v3.VTable(density="compact", id="controls-table"):
                with html.Tbody():
                    with html.Tr(v_for="c in controls_ui", key="c.i"):
                        html.Td("{{ c.i }}")
                        with html.Td():
                            html.Input(type="color", value=("c.colour",), disabled=("!has_colour",),
                                       style="width: 32px; height: 22px; border: none; padding: 0",
                                       change="trigger('set_colour', [c.i, $event.target.value])",
                                       title="control colour")
                        html.Td("{{ c.position }}", classes="text-caption")
                        html.Td("{{ c.gap }}", classes="text-caption gap-cell")
                        with html.Td():
                            v3.VBtn(icon="mdi-close", size="x-small", variant="text",
                                    click="trigger('remove_control', [c.i])", title="Remove")

            # design variants
            html.Div("Variants", classes="text-subtitle-2 mt-2", title=VARIANTS_HELP)
            with v3.VRow(dense=True):
                with v3.VCol(cols=6):
                    v3.VTextField(v_model=("variants_n",), label="how many", density="compact", type="number",
                                  hide_details=True, id="variants-n", title="Variants to train at once (at most "
                                  f"{MAX_GALLERY_VARIANTS} here; somwidget.sweep takes thousands)")
                with v3.VCol(cols=6):
                    v3.VTextField(v_model=("variants_jitter",), label="jitter", density="compact", type="number",
                                  hide_details=True, id="variants-jitter",
                                  title="Each control moves by up to this share of the model's size")
            with v3.VChipGroup(v_model=("variants_vary",), multiple=True, column=True, id="variants-vary"):
                for name in VARIED:
                    v3.VChip(name, value=name, size="small", filter=True, variant="outlined",
                             title=f"vary {name} around its value")
            with html.Div(classes="d-flex align-center ga-2 mb-1"):
                v3.VBtn("Sweep", size="small", variant="tonal", prepend_icon="mdi-view-grid-plus", id="sweep",
                        click="trigger('sweep_variants')", disabled=("busy",))
                v3.VProgressLinear(model_value=("variants_progress",), height=4, color="primary",
                                   v_if="variants_gallery.length || busy", id="variants-progress")
            with html.Div(classes="d-flex flex-wrap ga-1 mb-2", id="variants-gallery"):
                with html.Div(v_for="v in variants_gallery", key="v.i", style="position: relative"):
                    html.Img(src=("v.src",), title=("v.title",), classes="variant-thumb",
                             style="width: 96px; height: 77px; cursor: pointer; border: 1px solid #ccd; "
                                   "border-radius: 4px; display: block",
                             click="trigger('pick_variant', [v.i])")
                    html.Span("#{{ v.i }}", classes="text-caption",
                              style="position: absolute; left: 4px; top: 1px; pointer-events: none")

            # files out
            html.Div("Export and sessions", classes="text-subtitle-2 mt-2")
            with html.Div(classes="d-flex flex-wrap ga-1 mb-2"):
                for fmt in ("obj", "ply", "glb"):
                    v3.VBtn(fmt.upper(), size="small", variant="tonal", prepend_icon="mdi-download",
                            id=f"export-{fmt}",
                            click=f"utils.download('somwidget-mesh.{fmt}', trigger('export_mesh', ['{fmt}']), "
                                  f"'{MIME[fmt]}')")
                v3.VBtn("Save session", size="small", variant="tonal", prepend_icon="mdi-content-save",
                        id="save-session",
                        click="utils.download('somwidget-session.npz', trigger('save_session'), "
                              "'application/octet-stream')")
            v3.VFileInput(v_model=("session_upload",), label="Load a session (.npz)", density="compact",
                          hide_details=True, prepend_icon="mdi-folder-open", accept=".npz", id="session-upload",
                          disabled=("busy",))


def build_app(session: Session, server=None, title: str = "somwidget", fresh=None) -> SomApp:
    """The trame app for `session` on `server` (a fresh vue3 trame server by default); `fresh`: the preset (a name
    or a Preset) that "Start fresh" loads after a recovered session (default: the session's own)."""
    return SomApp(session, server=server, title=title, fresh=fresh)


def run_server(preset=None, mesh=None, host: str | None = None, port: int = 8080, device: str = "auto",
               open_browser: bool = False, lan: bool = False, fresh: bool = False) -> None:
    """Serve the app until interrupted: `somwidget serve`.

    preset: a preset name (default "car", case study 2); mesh: a mesh file to start from instead (io.load_mesh);
    host: interface to listen on (loopback by default; "0.0.0.0" every interface; "" is refused); port: 0 picks a
    free one (the printed URL has it); device: "auto", "cpu", "cuda" or "cuda:N" for the training. Unless `fresh`,
    a session that did not close cleanly (a crash, a kill) comes back as its autosave left it, and the panel says so
    with a "Start fresh" button that loads `preset` or `mesh` instead. lan: serve on
    this machine's LAN address. Any address beyond loopback is served over HTTPS (a self-signed certificate, made
    once and reused) with an access token on every route, and the URL, certificate fingerprint and a QR code for a
    headset are printed.
    """
    if preset is not None and mesh is not None:
        raise ValueError("give either a preset or a mesh, not both")
    host = _lan.normalise_host(host)  # ValueError for "": say 0.0.0.0 for every interface
    lan_cfg = None
    if lan or not _lan.is_loopback(host):  # beyond loopback: HTTPS and a token, always
        lan_cfg = _lan.prepare_lan(host)  # host None: this machine's LAN address (ValueError when it has none)
        host = lan_cfg.bind
    host = host or "127.0.0.1"
    start = preset or "car"
    if mesh is not None:
        from ...backend import io as sw_io

        start = sw_io.load_mesh(mesh, max_vertices=max_vertices_for(device))
        start.name = f"mesh:{start.name}"
    session = None if fresh else Session.recover(device=device, start=False)
    if session is not None:
        print(f"somwidget: recovered the session that did not close cleanly ({session.recovered['path']}); "
              "`somwidget serve --fresh` starts anew", flush=True)
    else:
        session = Session(start, device=device, start=False)
    app = build_app(session, fresh=start)
    if lan_cfg is not None:
        app.xr_token = lan_cfg.token
        app.ctrl.on_server_bind.add(lambda wslink_server: _lan.apply_lan(wslink_server, lan_cfg))
    session.start()

    def announce(**_):
        bound = app.server.port
        if lan_cfg is not None:
            print(_lan.announcement(lan_cfg, bound), flush=True)
            print(f"somwidget: training on {_device.describe(session.training_device)}", flush=True)
            return
        shown = f"[{host}]" if ":" in host else host
        print(f"somwidget serving {session.preset.name!r} at http://{shown}:{bound}/ "
              f"(WebXR page: http://{shown}:{bound}/xr/); training on "
              f"{_device.describe(session.training_device)}", flush=True)

    app.ctrl.on_server_ready.add(announce)
    argv = sys.argv
    sys.argv = argv[:1]  # trame parses sys.argv for its own options: keep `somwidget serve ...` away from it
    try:
        app.server.start(host=host, port=port, open_browser=open_browser, show_connection_info=False,
                         timeout=0, disable_logging=True)
    except OSError as exc:  # port taken, address not available...
        raise ValueError(f"cannot serve on {host}:{port}: {exc.strerror or exc}") from None
    finally:
        sys.argv = argv
        try:
            app.close()
        except Exception:  # pragma: no cover - closing must not hide the real error
            log.exception("closing the app failed")
        session.close()
