"""Serving on the LAN for a headset: HTTPS with a self-signed certificate, an access token, a QR code to open it.

WebXR needs a secure context: https, or http on localhost. A headset on the same network therefore reaches the
server over TLS. `somwidget serve --lan` uses the functions here:

    cfg = prepare_lan(host=None, port=8080)     # LAN address, certificate (made once, reused), fresh token
    ... ctrl.on_server_bind: apply_lan(wslink_server, cfg)   # TLS on the listening socket + the token check
    print(announcement(cfg, port))              # the URL (with ?token=...) and a QR code for the headset

The certificate and its key live in `storage.data_dir()` ($SOMWIDGET_DATA_DIR, else the platform's data directory,
~/.local/share/somwidget on Linux) and are reused while they are valid and name the address being served, so a
headset that accepted the certificate once keeps accepting it.

The token travels in the URL (?token=...). A request that shows it (query, cookie or `Authorization: Bearer`)
gets a cookie (named per port, `somwidget_token_<port>`, since browsers share cookies between the ports of a host),
so the page's own scripts, images and websockets need not repeat it; any other request is refused with 403. The
token is compared in constant time.

Every server, loopback or not, also gets `request_guard`: a websocket (or any request that is not GET / HEAD /
OPTIONS) whose Origin names another site is refused, and a loopback-bound server answers only requests whose Host
names a loopback host (localhost, 127.x.x.x, [::1]), which stops DNS rebinding. `is_loopback(host)` decides which
binds are loopback: anything else is served the LAN way (HTTPS and a token).
"""

from __future__ import annotations

import datetime
import hmac
import io
import ipaddress
import logging
import os
import re
import secrets
import socket
import ssl
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

from ..model.storage import data_dir

log = logging.getLogger(__name__)

#: Prefix of the token cookie's name; the full name adds the port (`cookie_name`).
COOKIE = "somwidget_token"
CERT_FILE = "somwidget-cert.pem"
KEY_FILE = "somwidget-key.pem"
#: Certificate lifetime: Apple platforms refuse TLS server certificates valid for longer than 825 days.
CERT_DAYS = 820
#: Remake the certificate when it expires within this many days.
RENEW_DAYS = 7
REFUSED = ("somwidget: this server needs its access token. Open the URL that `somwidget serve --lan` printed "
           "(it ends in ?token=...), or scan its QR code.\n")
REFUSED_HOST = ("somwidget: this server listens on this machine only and answers only to the host names localhost, "
                "127.0.0.1 and [::1]; open it as http://127.0.0.1:<port>/.\n")
REFUSED_ORIGIN = "somwidget: refused a websocket or a request from a page of another site (its Origin).\n"
_HOST_RE = re.compile(r"^(?:\[([0-9a-f:.]+)\]|([a-z0-9._-]+))(?::(\d{1,5}))?$")


# --------------------------------------------------------------------------------------------------------------
# Which hosts are loopback; the Host / Origin guard
# --------------------------------------------------------------------------------------------------------------
def normalise_host(host: str | None) -> str | None:
    """`host` without surrounding blanks or IPv6 brackets; None stays None (the loopback default). An empty host
    is refused: it would mean "every interface" to a socket but reads like "nothing"; say 0.0.0.0 for that."""
    if host is None:
        return None
    h = str(host).strip()
    if h.startswith("[") and h.endswith("]"):
        h = h[1:-1].strip()
    if not h:
        raise ValueError("empty host: give 127.0.0.1 (this machine only, the default), 0.0.0.0 (every interface, "
                         "served over HTTPS with an access token) or one address of this machine")
    return h


def is_loopback(host: str | None) -> bool:
    """True when a server bound to `host` is reachable from this machine only: None (the default, 127.0.0.1),
    "localhost" and the loopback addresses (127.0.0.0/8, ::1). False for anything else, wildcards (0.0.0.0, ::)
    included. ValueError for an empty host (normalise_host)."""
    h = normalise_host(host)
    if h is None or h.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:  # a host name: it may resolve to anything
        return False


def _split_host(value: str) -> tuple[str, int | None] | None:
    """("host", port or None when not given) from a Host header value, or None when it is not a plain
    host[:port]."""
    m = _HOST_RE.match(value.strip().lower())
    if m is None:
        return None
    return (m.group(1) or m.group(2)), (int(m.group(3)) if m.group(3) else None)


def _host_is_loopback_name(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _default_port(scheme: str) -> int:
    return 443 if scheme in ("https", "wss") else 80


def host_allowed(request) -> bool:
    """The request's Host names a loopback host (localhost, 127.x.x.x, [::1]; any port). A request without a Host
    header (not a browser: HTTP/1.0 tools) passes."""
    value = request.headers.get("Host")
    if value is None:
        return True
    parsed = _split_host(value)
    return parsed is not None and _host_is_loopback_name(parsed[0])


def origin_allowed(request) -> bool:
    """No Origin header (not sent by a browser page of another site), or an Origin whose host:port is the request's
    Host: the page that opens the websocket was served by this server. A Host without a port (a browser on a
    default port, possibly through a TLS-terminating proxy such as JupyterHub's) matches an Origin on that host at
    its scheme's default port."""
    origin = request.headers.get("Origin")
    if origin is None:
        return True
    from yarl import URL

    try:
        o = URL(origin.strip())
    except ValueError:
        return False
    if o.scheme not in ("http", "https") or not o.host:
        return False  # "null" (sandboxed frames, file: pages) and other schemes
    value = request.headers.get("Host")
    here = _split_host(value) if value is not None else None
    if here is None:
        return False
    origin_host = o.host.lower().strip("[]")
    origin_port = o.port if o.port is not None else _default_port(o.scheme)
    if here[1] is None:
        return here[0] == origin_host and origin_port == _default_port(o.scheme)
    return here == (origin_host, origin_port)


def _needs_origin_check(request) -> bool:
    return (request.headers.get("Upgrade", "").lower() == "websocket"
            or request.method not in ("GET", "HEAD", "OPTIONS"))


def request_guard(check_host: bool = True):
    """An aiohttp middleware for every somwidget server. Websocket upgrades and state-changing requests (not GET /
    HEAD / OPTIONS) must come without an Origin or from this server's own origin (Origin host:port == Host): a page
    of another site cannot open the session's websockets. With `check_host` (for a loopback-bound server) every
    request's Host must name a loopback host, so a DNS-rebound name cannot reach the server either. Refusals are
    403. A server behind a reverse proxy that forwards the browser's Host (jupyter-server-proxy) passes
    check_host=False and keeps the Origin check."""
    from aiohttp import web

    @web.middleware
    async def guard(request, handler):
        if check_host and not host_allowed(request):
            log.info("refused %s %s: Host %r is not a loopback host", request.method, request.path,
                     request.headers.get("Host"))
            return web.Response(status=403, text=REFUSED_HOST, headers={"Cache-Control": "no-store"})
        if _needs_origin_check(request) and not origin_allowed(request):
            log.info("refused %s %s: Origin %r is not this server (Host %r)", request.method, request.path,
                     request.headers.get("Origin"), request.headers.get("Host"))
            return web.Response(status=403, text=REFUSED_ORIGIN, headers={"Cache-Control": "no-store"})
        return await handler(request)

    return guard


def lan_address() -> str:
    """This machine's address on the LAN: the source address of the default route (no packet is sent), falling
    back to the host name's address and then 127.0.0.1 (so a loopback address means: no LAN address found)."""
    for target in ("192.0.2.1", "10.255.255.255"):  # TEST-NET-1: never routed, only used to pick the interface
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.connect((target, 9))
                addr = s.getsockname()[0]
            if addr and not addr.startswith("0."):
                return addr
        except OSError:
            continue
    try:
        return socket.gethostbyname(socket.gethostname())
    except OSError:
        return "127.0.0.1"


def _names_for(hosts) -> tuple[list[str], list[str]]:
    """Split hosts into DNS names and IP addresses, adding localhost, 127.0.0.1 and this machine's name."""
    dns, ips = ["localhost"], ["127.0.0.1"]
    try:
        name = socket.gethostname()
        if name and name not in dns:
            dns.append(name)
    except OSError:  # pragma: no cover
        pass
    for h in hosts or ():
        h = str(h).strip().strip("[]")
        if not h or h in ("0.0.0.0", "::"):
            continue
        try:
            ip = str(ipaddress.ip_address(h))
            if ip not in ips:
                ips.append(ip)
        except ValueError:
            if h not in dns:
                dns.append(h)
    return dns, ips


def _certificate_covers(cert_path: Path, dns: list[str], ips: list[str]) -> bool:
    from cryptography import x509

    try:
        cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except (OSError, ValueError, x509.ExtensionNotFound):
        return False
    now = datetime.datetime.now(datetime.timezone.utc)
    if cert.not_valid_after_utc - now < datetime.timedelta(days=RENEW_DAYS) or cert.not_valid_before_utc > now:
        return False
    have_ips = {str(ip) for ip in san.get_values_for_type(x509.IPAddress)}
    have_dns = set(san.get_values_for_type(x509.DNSName))
    return set(ips) <= have_ips and set(dns) <= have_dns


def make_certificate(directory=None, hosts=()) -> tuple[Path, Path]:
    """A self-signed TLS certificate for `hosts` (IP addresses or names; localhost is always included) and its
    private key, as PEM files in `directory` (default: data_dir()). An existing pair is reused while it is valid
    for RENEW_DAYS more days and names every host; otherwise a new one (ECDSA P-256, CERT_DAYS days) replaces it.
    Returns (certificate path, key path); the key file is readable by its owner only."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    directory = Path(directory) if directory is not None else data_dir()
    cert_path, key_path = directory / CERT_FILE, directory / KEY_FILE
    dns, ips = _names_for(hosts)
    if cert_path.is_file() and key_path.is_file() and _certificate_covers(cert_path, dns, ips):
        try:
            ssl_context(cert_path, key_path)
            return cert_path, key_path
        except (ssl.SSLError, OSError, ValueError):
            log.warning("the stored certificate in %s does not load; making a new one", directory)
    directory.mkdir(parents=True, exist_ok=True)
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"somwidget {ips[-1] if len(ips) > 1 else dns[0]}"),
                      x509.NameAttribute(NameOID.ORGANIZATION_NAME, "somwidget (self-signed)")])
    now = datetime.datetime.now(datetime.timezone.utc)
    san = [x509.DNSName(d) for d in dns] + [x509.IPAddress(ipaddress.ip_address(i)) for i in ips]
    cert = (
        x509.CertificateBuilder()
        .subject_name(name).issuer_name(name).public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=CERT_DAYS))
        .add_extension(x509.SubjectAlternativeName(san), critical=False)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.KeyUsage(digital_signature=True, key_encipherment=False, content_commitment=False,
                                     data_encipherment=False, key_agreement=False, key_cert_sign=False,
                                     crl_sign=False, encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
        .sign(key, hashes.SHA256())
    )
    key_bytes = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                  serialization.NoEncryption())
    tmp_key = key_path.with_suffix(".tmp")
    fd = os.open(tmp_key, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(key_bytes)
    os.replace(tmp_key, key_path)
    tmp_cert = cert_path.with_suffix(".tmp")
    tmp_cert.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    os.replace(tmp_cert, cert_path)
    log.info("made a self-signed certificate for %s in %s", ", ".join(dns + ips), directory)
    return cert_path, key_path


def certificate_fingerprint(cert_path) -> str:
    """SHA-256 fingerprint of a PEM certificate, as colon-separated hex (what browsers show)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    cert = x509.load_pem_x509_certificate(Path(cert_path).read_bytes())
    return ":".join(f"{b:02X}" for b in cert.fingerprint(hashes.SHA256()))


def ssl_context(cert, key) -> ssl.SSLContext:
    """A server-side TLS context (TLS 1.2+) for the certificate and key files."""
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    ctx.load_cert_chain(str(cert), str(key))
    return ctx


def make_token(nbytes: int = 18) -> str:
    """A fresh URL-safe random access token (`nbytes` random bytes: 24 characters by default)."""
    return secrets.token_urlsafe(nbytes)


def cookie_name(port) -> str:
    """The token cookie's name for a server on `port` (browsers share cookies between the ports of one host, so
    two servers on one machine need two names)."""
    return f"{COOKIE}_{int(port)}" if port else COOKIE


def _request_port(request) -> int | None:
    try:
        return request.url.port
    except ValueError:  # a Host header yarl cannot read
        return None


def presented_token(request) -> tuple[str | None, str]:
    """(the token a request carries, where: "query" | "header" | "cookie" | "")."""
    q = request.query.get("token")
    if q:
        return q, "query"
    auth = request.headers.get("Authorization", "")
    if auth.lower().startswith("bearer "):
        return auth[7:].strip(), "header"
    c = request.cookies.get(cookie_name(_request_port(request)))
    if c:
        return c, "cookie"
    return None, ""


def set_token_cookie(request, response, token: str | None):
    """Give `response` the token cookie when the request brought the token in its URL or a header (so the page's
    own requests and websockets need not repeat it). Returns the response."""
    from aiohttp import web

    if (token and presented_token(request)[1] in ("query", "header") and isinstance(response, web.StreamResponse)
            and not response.prepared):
        response.set_cookie(cookie_name(_request_port(request)), token, httponly=True, samesite="Strict",
                            secure=request.secure, path="/")
    return response


def token_ok(request, token: str | None) -> bool:
    """True when `token` is None (no check) or the request carries it."""
    if token is None:
        return True
    given, _ = presented_token(request)
    return given is not None and hmac.compare_digest(given.encode("utf-8", "replace"), token.encode("utf-8"))


def forbidden():
    from aiohttp import web

    return web.Response(status=403, text=REFUSED, headers={"Cache-Control": "no-store"})


def token_middleware(token: str):
    """An aiohttp middleware that answers 403 to every request without `token` and sets the token cookie on
    responses to requests that brought it in the URL or a header."""
    from aiohttp import web

    if not token:
        raise ValueError("token_middleware: empty token")

    @web.middleware
    async def check_token(request, handler):
        if not token_ok(request, token):
            log.info("refused %s %s from %s: no valid token", request.method, request.path, request.remote)
            return forbidden()
        response = await handler(request)
        return set_token_cookie(request, response, token)

    return check_token


def lan_url(host: str, port: int, token: str | None = None, path: str = "/", scheme: str = "https") -> str:
    shown = f"[{host}]" if ":" in host else host
    url = f"{scheme}://{shown}:{port}{path}"
    return f"{url}?token={quote(token)}" if token else url


def qr_text(url: str, border: int = 2) -> str:
    """A QR code of `url` drawn with Unicode half blocks for a terminal (dark modules on a light background)."""
    import segno

    out = io.StringIO()
    segno.make(url, error="m").terminal(out=out, border=border, compact=True)
    return out.getvalue()


@dataclass(frozen=True)
class LanConfig:
    """Everything `--lan` needs: the address shown in URLs (`host`) and the one to bind (`bind`: the same, or a
    wildcard such as 0.0.0.0), the certificate pair and the access token."""

    host: str
    cert: Path
    key: Path
    token: str
    bind: str = ""

    def __post_init__(self) -> None:
        if not self.bind:
            object.__setattr__(self, "bind", self.host)

    def url(self, port: int, path: str = "/") -> str:
        return lan_url(self.host, port, self.token, path)

    def ssl_context(self) -> ssl.SSLContext:
        return ssl_context(self.cert, self.key)


def prepare_lan(host: str | None = None, directory=None, token: str | None = None) -> LanConfig:
    """The LAN address (or `host`), a certificate for it (made on first use, then reused) and a fresh token.
    A wildcard host (0.0.0.0, ::) is bound as given while URLs and the certificate name the LAN address. When
    `host` is None or a wildcard and this machine has no LAN address (only loopback), ValueError: a headset could
    not open the URL."""
    host = normalise_host(host)
    bind = host or ""
    shown = lan_address() if not host or host in ("0.0.0.0", "::") else host
    if shown != host and is_loopback(shown):
        raise ValueError(f"no LAN address found (this machine's only address is {shown}, loopback), so a headset "
                         "could not reach the server: connect to the network the headset is on, or give --host "
                         "with an address of this machine that the headset can reach")
    cert, key = make_certificate(directory, hosts=[shown])
    return LanConfig(host=shown, cert=cert, key=key, token=token or make_token(), bind=bind or shown)


def apply_lan(wslink_server, config: LanConfig) -> None:
    """Call from `ctrl.on_server_bind` (before the server listens): serve over TLS and refuse requests without the
    token on every route (the trame app, its websocket, /xr/, /api/state)."""
    app = wslink_server.app
    app.middlewares.append(token_middleware(config.token))
    wslink_server.config["ssl"] = config.ssl_context()


def announcement(config: LanConfig, port: int, qr: bool = True) -> str:
    """What `serve --lan` prints: the app and headset URLs, the certificate fingerprint and a QR code of the
    headset URL."""
    xr = config.url(port, "/xr/")
    lines = [f"somwidget on the LAN (HTTPS, self-signed certificate {config.cert}):",
             f"  desktop: {config.url(port, '/')}",
             f"  headset: {xr}",
             f"  certificate SHA-256: {certificate_fingerprint(config.cert)}",
             "  The browser warns about the certificate once: accept it (see README, 'AR headsets').",
             "  Anyone with the token can edit the session; it changes every time the server starts."]
    text = "\n".join(lines) + "\n"
    if qr:
        text += "Scan with the headset to open the WebXR page:\n" + qr_text(xr)
    return text


__all__ = ["COOKIE", "LanConfig", "data_dir", "lan_address", "make_certificate", "certificate_fingerprint",
           "ssl_context", "make_token", "token_ok", "presented_token", "token_middleware", "forbidden", "lan_url",
           "qr_text", "prepare_lan", "apply_lan", "announcement", "cookie_name", "set_token_cookie",
           "normalise_host", "is_loopback", "host_allowed", "origin_allowed", "request_guard"]
