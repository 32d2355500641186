"""The WebXR client (JavaScript under src/, built with vite into dist/) and its server route.

`attach(wslink_server_or_aiohttp_app, session, token=None)` serves the page at /xr/ and the websocket /xr/ws
(server.py); the websocket protocol is documented in protocol.py. Build the client with `npm ci && npm run build`
in this folder (scripts/setup.sh does it).
"""

from .server import DIST, XRHub, attach

__all__ = ["attach", "XRHub", "DIST"]
