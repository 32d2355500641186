"""The XR page and websocket on a small aiohttp server of their own, in a background thread: for a session that has
no trame server (a notebook, a script), and for tests and benchmarks.

    with XRServer(session, port=0) as srv:     # port 0: a free one
        print(srv.url)                          # http://127.0.0.1:PORT/xr/
"""

from __future__ import annotations

import asyncio
import threading

from aiohttp import web

from .hub import ViewHub, attach


class XRServer:
    """Serve `session`'s XR page on host:port from a daemon thread. `token`: require it (lan.token_middleware);
    `ssl_context`: serve HTTPS.

    A host beyond loopback (a LAN address, 0.0.0.0) needs a token (ValueError without one), and a headset needs
    `ssl_context` too (WebXR wants a secure context): `lan.prepare_lan(host)` makes both. Every request passes
    `lan.request_guard`: websockets from pages of other sites are refused, and on loopback only loopback Host
    names are answered."""

    def __init__(self, session, host: str = "127.0.0.1", port: int = 0, token: str | None = None, ssl_context=None,
                 dist=None) -> None:
        from . import lan

        host = lan.normalise_host(host) or "127.0.0.1"
        if not lan.is_loopback(host) and not token:
            raise ValueError(f"XRServer: host {host!r} is reachable from other machines; give a token (and an "
                             "ssl_context for a headset): cfg = lan.prepare_lan(host); XRServer(session, host, "
                             "token=cfg.token, ssl_context=cfg.ssl_context())")
        self.session = session
        self.host = host
        self.port = port
        self.token = token
        self.ssl_context = ssl_context
        self.dist = dist
        self.hub: ViewHub | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._runner: web.AppRunner | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    @property
    def base(self) -> str:
        scheme = "https" if self.ssl_context is not None else "http"
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{scheme}://{host}:{self.port}"

    @property
    def url(self) -> str:
        return f"{self.base}/xr/" + (f"?token={self.token}" if self.token else "")

    def start(self, timeout: float = 20.0) -> XRServer:
        self._thread = threading.Thread(target=self._run, name="somwidget-xr-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise RuntimeError("XR server did not start")
        if self._error is not None:
            raise RuntimeError(f"XR server failed to start: {self._error}") from self._error
        return self

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._start())
        except BaseException as exc:  # report to start()
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            if self._runner is not None:  # _start made it before the loop ran
                loop.run_until_complete(self._runner.cleanup())
            loop.close()

    async def _start(self) -> None:
        from . import lan

        middlewares = [lan.request_guard(check_host=lan.is_loopback(self.host))]
        if self.token:
            middlewares.append(lan.token_middleware(self.token))
        app = web.Application(middlewares=middlewares)
        self.hub = attach(app, self.session, token=self.token, dist=self.dist)
        self._runner = runner = web.AppRunner(app, handle_signals=False)
        await runner.setup()
        site = web.TCPSite(runner, self.host, self.port, ssl_context=self.ssl_context)
        await site.start()
        self.port = runner.addresses[0][1]

    def stop(self, timeout: float = 10.0) -> None:
        loop = self._loop
        if loop is None or self._thread is None:
            return
        hub = self.hub
        if loop.is_running():
            async def shutdown() -> None:
                if hub is not None:  # _start made it before the loop ran
                    await hub.close()
                loop.stop()
            asyncio.run_coroutine_threadsafe(shutdown(), loop)
        self._thread.join(timeout)
        if self.hub is not None:
            self.hub.detach()
        self._thread = None

    def __enter__(self) -> XRServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


__all__ = ["XRServer"]
