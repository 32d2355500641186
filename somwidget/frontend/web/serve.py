"""`somwidget serve`: one session (the one the last serve left, however it stopped, unless --fresh), its web app,
served until interrupted (Ctrl+C, SIGTERM: what changed since the last save is written); beyond loopback over HTTPS
with an access token (lan.py).
"""

from __future__ import annotations

import logging
import sys

from ...backend import device as _device
from ..model import Session
from ..model import recovery as _recovery
from ..model.state import max_vertices_for
from . import lan as _lan
from .app import build_app

log = logging.getLogger(__name__)


def run_server(preset=None, mesh=None, host: str | None = None, port: int = 8080, device: str = "auto",
               open_browser: bool = False, lan: bool = False, fresh: bool = False) -> None:
    """Serve the app until interrupted: `somwidget serve`.

    preset: a preset name (default "car", case study 2); mesh: a mesh file to start from instead (io.load_mesh);
    host: interface to listen on (loopback by default; "0.0.0.0" every interface; "" is refused); port: 0 picks a
    free one (the printed URL has it); device: "auto", "cpu", "cuda" or "cuda:N" for the training. Unless `fresh`,
    the session the last `somwidget serve` left comes back as its autosave left it (its last completed step and its
    undo history, however that server stopped), and the panel says so with a "Start fresh" button that loads
    `preset` or `mesh` instead; a saved session that cannot be read is set aside and the panel says where. lan: serve on
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
    session, notices = (None, []) if fresh else _recovery.recover(Session, "serve", device=device, start=False)
    for notice in notices:
        print(f"somwidget: {notice}", flush=True)
    if session is not None:
        print(f"somwidget: {session.recovered['message']} (from {session.recovered['path']}; "
              "`somwidget serve --fresh` starts anew)", flush=True)
    else:
        session = Session(start, device=device, start=False, origin="serve")
        session.notices[:0] = notices
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
