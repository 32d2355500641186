"""The web app: a trame (vue3 + vuetify3) page with the session's panel beside the clay view.

`somwidget serve` calls `run_server` (serve.py). One server holds one `Session`; every tab on it shares the session,
so any tab can drag a control and all of them see the clay follow. The 3-D view is the browser's own (the client's
module, served at /xr/somview.js and mounted into the page's #clay-view): it draws the frames the hub (hub.py)
streams over the websocket /view/ws and sends the drags back as intents, so each tab keeps its own camera and nothing is
rendered on the server. The panel (layout.py) is bound to the session's panel model (model/panel.py) through
trame's state and triggers.

Threads: the session trains on its own thread and hands frames to `SomApp._on_frame`, which only stores the latest
one. A task on the server's event loop (`_pump`) refreshes the panel's numbers a few times a second and the panel's
fields when the preset or the history changes.

A read-only JSON route, GET /api/state, reports the session, the panel and the connected clients (for tests,
benchmarks and scripts); add ?positions=1 for every node's position.

Every bind gets `lan.request_guard`: websockets (trame's /ws, the view's /view/ws) from pages of other sites are
refused, and a loopback-bound server answers only loopback Host names (no DNS rebinding). Beyond loopback,
`run_server` adds HTTPS and the access token (lan.py).
"""

from __future__ import annotations

import asyncio
import logging
import tempfile
from pathlib import Path

from aiohttp import web
from trame.app import get_server
from wslink.websocket import LinkProtocol

from ...backend import presets as _presets
from ...backend.io import TooManyVertices
from ...backend.presets import Preset
from ..model import Session
from ..model.panel import EXPORT_CHOICES, REACH_HELP
from ..transport.limits import bound_messages
from . import lan as _lan
from . import uploads
from .hub import ViewHub
from .hub import attach as attach_hub
from .layout import build_page
from .panel_state import PanelState
from .state_guard import guard_state_updates

log = logging.getLogger(__name__)

#: The page's triggers: each calls the method of the same name of the panel's state (panel_state.py) or the app.
TRIGGERS = ("set_param", "set_metric", "set_colour", "set_radius", "set_position", "set_features", "add_control",
            "remove_control", "toggle_training", "reset", "undo", "redo", "start_fresh", "reload_preset", "refine",
            "decimate_upload", "export_mesh", "save_session", "sweep_variants", "pick_variant", "notice_shown")


class _ClientWatch(LinkProtocol):
    """Counts the page's websocket clients (for /api/state)."""

    def __init__(self, app: SomApp) -> None:
        super().__init__()
        self._app = app

    def onConnect(self, request, client_id) -> None:  # noqa: N802 (wslink's name)
        self._app.clients.add(str(client_id))

    def onClose(self, client_id) -> None:  # noqa: N802
        self._app.clients.discard(str(client_id))

class SomApp:
    """The trame app around one Session: the page, the panel's state and triggers, the clay view's hub and the
    panel pump."""

    def __init__(self, session: Session, server=None, title: str = "somwidget", fresh=None) -> None:
        self.session = session
        self.fresh = fresh if fresh is not None else session.preset  # what "Start fresh" loads after a recovery
        self.xr_token: str | None = None  # the LAN access token, when served beyond loopback
        # on a loopback bind, answer only loopback Host names (False behind a proxy that forwards the browser's Host)
        self.check_host = True
        # the clay view's routes and clients (/view/ws, /xr/...), once the server is bound
        self.view_hub: ViewHub | None = None
        self.server = server if server is not None else get_server("somwidget", client_type="vue3")
        self.server.client_type = "vue3"
        self.state, self.ctrl = self.server.state, self.server.controller
        self.title = title
        self.clients: set[str] = set()
        self._pump_task: asyncio.Task[None] | None = None
        self._uploaded: dict[str, Preset] = {}  # the latest mesh uploaded in this server's life, by name
        self._refused_upload = None  # the latest upload refused as too big (its file value), for the Decimate offer
        if session.preset.name not in _presets.PRESETS:  # started from `somwidget serve --mesh FILE`
            self._uploaded = {session.preset.name: session.preset}
        uploads.sweep_uploads()  # what servers killed mid-upload left behind
        self.panel_state = PanelState(session, self.state)
        self.panel = self.panel_state.panel
        self._init_state()
        self.layout = build_page(self.server, self.panel)
        self._register()

    def close(self) -> None:
        """Detach from the session (the app and its hub; call on the server's thread, after it stopped)."""
        uploads.sweep_uploads(own=True)
        self.panel_state.close()
        if self.view_hub is not None:
            self.view_hub.detach()
        if self._pump_task is not None:
            self._pump_task.cancel()
            self._pump_task = None

    def _preset_items(self) -> list[dict]:
        items = [{"title": label, "value": name} for label, name in self.panel.preset_options()
                 if name in _presets.PRESETS]
        return items + [{"title": f"Uploaded: {p.title} ({p.n_vertices} nodes)", "value": name}
                        for name, p in self._uploaded.items()]

    def _init_state(self) -> None:
        s = self.state
        s.trame__title = self.title
        s.preset_items = self._preset_items()
        s.preset_name = self.session.preset.name
        s.error_message = ""
        s.info_message = ""
        s.busy = False
        s.mesh_upload = None
        s.decimate_offer = False
        s.session_upload = None
        s.stats = {}
        s.controls_ui = []
        s.all_radii = ""
        s.features_ui = []
        s.param_errors = {}
        s.field_revs = {}  # bumped when a field's value is refused: the page draws it anew (panel_state.py)
        s.reach_help = REACH_HELP
        s.recovered_message = self.panel.recovered_message()
        s.notice_message = " ".join(self.session.notices)  # saved sessions set aside: what and where
        s.save_error = ""  # the autosave's failure while saves fail (panel_state.py)
        s.export_format = EXPORT_CHOICES[0][0]
        s.export_items = [{"title": label, "value": ext} for ext, label in EXPORT_CHOICES]
        s.export_mimes = dict(uploads.MIME)
        s.variants_n = 12
        s.variants_jitter = 0.05
        s.variants_vary = []
        s.variants_gallery = []
        s.variants_progress = 0
        self.panel_state.sync_fields()
        self.panel_state.show_frame(self.session.frame)

    async def reload_preset(self) -> None:
        """The current preset again, as it starts: its own controls and start mesh (one undo step)."""
        await self._replace(self.panel.reload_preset)

    async def refine(self) -> None:
        """Subdivide the clay, its shape kept (one undo step), off the event loop."""
        if await self._replace(self.panel.refine):
            with self.state:
                self.state.info_message = f"refined: {self.session.preset.n_vertices:,} nodes"

    async def start_fresh(self) -> None:
        """After a recovery: load what the server was started with (one undo step: Undo brings the recovered
        session back)."""
        fresh = self.fresh
        with self.state:
            self.state.recovered_message = ""
        await self._replace(lambda: self.session.load_preset(fresh))

    async def choose_preset(self, name) -> None:
        """Load a preset chosen in the menu (the current one again: `reload_preset`)."""
        if isinstance(name, str) and (not name or name == self.session.preset.name):
            return
        if not isinstance(name, str) or (name not in self._uploaded and name not in _presets.PRESETS):
            self.panel_state.error(f"unknown preset {name!r}" if isinstance(name, str) else
                        f"unknown preset: expected a preset's name, got {type(name).__name__}")
            with self.state:
                self.state.preset_name = self.session.preset.name
            return
        preset = self._uploaded.get(name, name)
        await self._replace(lambda: self.session.load_preset(preset))

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

    async def _upload(self, value, field: str, file_name, load) -> str | None:
        """An uploaded file (uploads.py: checked, then written as `file_name(name)` in a fresh temporary folder that
        is removed afterwards) handed to `load(path, name)` off the event loop; the browser's file name when it
        loaded, else None (the message in the panel). The field (and the bytes in trame's state) is cleared
        whatever happens."""
        try:
            got = uploads.file_of(value)
            if got is None:
                return None
            name, content = got
            with tempfile.TemporaryDirectory(prefix=uploads.upload_prefix()) as folder:
                path = Path(folder) / file_name(name)
                path.write_bytes(content)
                ok = await self._replace(lambda: load(path, name), scrub={str(path): name})
            return name if ok else None
        except (ValueError, OSError) as exc:
            self.panel_state.error(str(exc))
            return None
        finally:
            with self.state:
                self.state[field] = None

    async def upload_mesh(self, value, decimate: bool = False) -> None:
        """A mesh file from the upload field becomes the clay, shown as it is with controls on it. One with more
        vertices than this device takes is refused with an offer: the Decimate button loads it coarsened (the file is
        kept in memory until then, or until the next upload)."""
        def load(path, name):
            try:
                self.session.load_preset(uploads.read_mesh(path, name, self.session.max_vertices, decimate))
            except TooManyVertices:
                self._refused_upload = value
                raise

        self._refused_upload = None
        name = await self._upload(value, "mesh_upload", lambda n: f"upload{uploads.check_mesh_name(n)}", load)
        with self.state:
            self.state.decimate_offer = self._refused_upload is not None
        if name is not None:
            preset = self.session.preset
            self._uploaded = {preset.name: preset}  # the latest upload only
            with self.state:
                self.state.preset_items = self._preset_items()
                self.state.preset_name = preset.name
                self.state.info_message = f"loaded {name}: {preset.n_vertices} vertices"

    async def decimate_upload(self) -> None:
        """The mesh refused as too big, loaded decimated to this device's limit (one undo step)."""
        value, self._refused_upload = self._refused_upload, None
        with self.state:
            self.state.decimate_offer = False
        if value is None:
            self.panel_state.error("decimate: no refused upload to load (upload the mesh again)")
            return
        await self.upload_mesh(value, decimate=True)

    async def upload_session(self, value) -> None:
        """A saved session (.npz) from the upload field replaces the session, exactly as it was saved."""
        name = await self._upload(value, "session_upload", lambda _n: "upload.npz",
                                  lambda path, _n: self.session.load(path))
        if name is not None:
            with self.state:
                self.state.info_message = f"session {name} loaded"

    def export_mesh(self, fmt) -> bytes | None:
        fmt = str(fmt).lower()
        if fmt not in uploads.MIME:
            self.panel_state.error(f"export: unknown format {fmt!r}; use one of {', '.join(uploads.MIME)}")
            return None
        return self._download(self.session.export_mesh, "." + fmt)

    def save_session(self) -> bytes | None:
        return self._download(self.session.save, ".npz")

    def _download(self, write, suffix: str) -> bytes | None:
        try:
            return uploads.written_bytes(write, suffix)
        except (ValueError, OSError) as exc:
            self.panel_state.error(str(exc))
            return None

    def _register(self) -> None:
        server, state, ctrl = self.server, self.state, self.ctrl
        for name in TRIGGERS:
            server.trigger(name)(getattr(self.panel_state if hasattr(self.panel_state, name) else self, name))

        @state.change("preset_name")
        async def _preset_changed(preset_name, **_) -> None:
            await self.choose_preset(preset_name)

        @state.change("mesh_upload")
        async def _mesh_uploaded(mesh_upload, **_) -> None:
            if mesh_upload:
                await self.upload_mesh(mesh_upload)

        @state.change("session_upload")
        async def _session_uploaded(session_upload, **_) -> None:
            if session_upload:
                await self.upload_session(session_upload)

        @state.change("param_symmetry")
        def _symmetry(param_symmetry, **_) -> None:
            if bool(param_symmetry) != self.session.parameters["symmetry"]:
                self.panel_state.set_param("symmetry", bool(param_symmetry))

        @state.change("param_group")
        def _group(param_group, **_) -> None:
            if isinstance(param_group, str) and param_group != self.session.parameters["group"]:
                self.panel_state.set_group(param_group)

        ctrl.on_server_bind.add(self._bind_routes)
        ctrl.on_server_ready.add(self._on_ready)
        server.add_protocol_to_configure(lambda protocol: protocol.registerLinkProtocol(_ClientWatch(self)))

    def _on_ready(self, **_) -> None:
        if self._pump_task is None:
            self._pump_task = asyncio.get_event_loop().create_task(self.panel_state.pump())

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
        wslink_server.app.router.add_post("/paraview/", self._launcher)
        self.view_hub = attach_hub(wslink_server, self.session, token=self.xr_token)

    async def _launcher(self, request: web.Request) -> web.Response:
        """trame's page first asks a launcher where its websocket is (POST <base>/paraview/) and, refused (405), falls
        back to the page's own /ws; answering with that same /ws (the page puts in its host and ws or wss) spares
        every page load the refused request in its console."""
        prefix = request.path[: -len("paraview/")]
        return web.json_response({"sessionURL": f"ws://USE_HOST{prefix}ws"}, headers={"Cache-Control": "no-store"})

    async def _api_state(self, request: web.Request) -> web.Response:
        positions = request.query.get("positions", "0") not in ("0", "", "false")
        hub = self.view_hub
        body = {"session": self.session.state(positions=positions), "clients": len(self.clients),
                "views": {"clients": len(hub.clients) if hub else 0,
                          "frames_sent": sum(c.frames_sent for c in hub.clients.values()) if hub else 0,
                          "grabs": {str(i): cid for i, cid in hub.grabs.items()} if hub else {}},
                "panel": {"error_message": self.state.error_message, "param_S": self.state.param_S,
                          "recovered_message": self.state.recovered_message,
                          "notice_message": self.state.notice_message, "save_error": self.state.save_error,
                          "preset_name": self.state.preset_name}}
        return web.json_response(body, headers={"Cache-Control": "no-store"})


def build_app(session: Session, server=None, title: str = "somwidget", fresh=None) -> SomApp:
    """The trame app for `session` on `server` (a fresh vue3 trame server by default); `fresh`: the preset (a name
    or a Preset) that "Start fresh" loads after a recovered session (default: the session's own)."""
    return SomApp(session, server=server, title=title, fresh=fresh)
