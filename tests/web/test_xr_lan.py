"""Serving the XR page on the LAN (somwidget.frontend.web.lan): the self-signed certificate made once and reused, the
access token (403 without it, a cookie with it), the QR code, and HTTPS end to end with a real Session."""

from __future__ import annotations

import asyncio
import json
import os
import ssl
import stat

import aiohttp
import numpy as np
import pytest

from somwidget.frontend.transport import frames as wire_frames
from somwidget.frontend.web import lan
from somwidget.frontend.web.standalone import XRServer


def test_certificate_made_once_and_reused(tmp_path):
    from cryptography import x509

    cert, key = lan.make_certificate(tmp_path, hosts=["192.168.1.20"])
    assert cert.is_file() and key.is_file()
    assert stat.S_IMODE(os.stat(key).st_mode) == 0o600  # the private key: owner only
    c = x509.load_pem_x509_certificate(cert.read_bytes())
    san = c.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "192.168.1.20" in {str(i) for i in san.get_values_for_type(x509.IPAddress)}
    assert "127.0.0.1" in {str(i) for i in san.get_values_for_type(x509.IPAddress)}
    assert "localhost" in san.get_values_for_type(x509.DNSName)
    assert (c.not_valid_after_utc - c.not_valid_before_utc).days <= 825  # Apple's limit
    fingerprint = lan.certificate_fingerprint(cert)
    assert lan.make_certificate(tmp_path, hosts=["192.168.1.20"]) == (cert, key)
    assert lan.certificate_fingerprint(cert) == fingerprint  # reused, not remade
    lan.make_certificate(tmp_path, hosts=["10.0.0.7"])  # another address: a new certificate naming it
    assert lan.certificate_fingerprint(cert) != fingerprint
    assert isinstance(lan.ssl_context(cert, key), ssl.SSLContext)
    cert.write_text("garbage")  # a broken file is replaced
    lan.make_certificate(tmp_path, hosts=["10.0.0.7"])
    lan.ssl_context(cert, key)


def test_data_dir_and_prepare(tmp_path, monkeypatch):
    monkeypatch.setenv("SOMWIDGET_DATA_DIR", str(tmp_path / "data"))
    assert lan.data_dir() == tmp_path / "data"
    cfg = lan.prepare_lan(host="127.0.0.1")
    assert cfg.cert.parent == tmp_path / "data" and cfg.host == "127.0.0.1"
    assert cfg.url(8443, "/xr/") == f"https://127.0.0.1:8443/xr/?token={cfg.token}"
    assert lan.prepare_lan(host="127.0.0.1").token != cfg.token  # a fresh token each time
    wild = lan.prepare_lan(host="0.0.0.0")  # bind everywhere, show the LAN address
    assert wild.bind == "0.0.0.0" and wild.host == lan.lan_address() and cfg.bind == "127.0.0.1"
    text = lan.announcement(cfg, 8443)
    assert cfg.url(8443, "/xr/") in text and "SHA-256" in text and "\u2588" in text
    monkeypatch.delenv("SOMWIDGET_DATA_DIR")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert lan.data_dir() == tmp_path / "xdg" / "somwidget"


def test_lan_address_belongs_to_this_machine():
    """The address is one of this machine's own: a socket can bind to it (a foreign address would refuse)."""
    import socket

    addr = lan.lan_address()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((addr, 0))


def test_tokens_are_fresh_and_url_safe():
    tokens = {lan.make_token() for _ in range(50)}
    assert len(tokens) == 50
    assert all(len(t) >= 24 and t.replace("-", "").replace("_", "").isalnum() for t in tokens)


def test_qr_text_encodes_the_url():
    """Read the terminal drawing back into modules and compare with the QR code segno computes for the URL."""
    import segno

    url = "https://192.168.1.20:8080/xr/?token=abcdefghijklmnopqrstuvwx"
    text = lan.qr_text(url, border=2)
    rows = text.rstrip("\n").split("\n")
    qr = segno.make(url, error="m")
    size = qr.symbol_size(border=2)[0]
    # compact drawing: one character per column and two module rows; light modules are drawn
    dark = np.zeros((2 * len(rows), len(rows[0])), bool)
    for r, line in enumerate(rows):
        for col, ch in enumerate(line):
            top_light = ch in "\u2588\u2580"
            bottom_light = ch in "\u2588\u2584"
            dark[2 * r, col] = not top_light
            dark[2 * r + 1, col] = not bottom_light
    want = np.array([[bool(m) for m in row] for row in qr.matrix_iter(border=2)])
    assert dark.shape[1] == size
    np.testing.assert_array_equal(dark[:size], want)


def test_https_with_token_end_to_end(tmp_path):
    """The XR route over TLS with the token middleware: 403 without the token, the page and the websocket with it
    (the client checks the server's certificate is the one made)."""
    from somwidget.frontend.model import Session

    cfg = lan.prepare_lan(host="127.0.0.1", directory=tmp_path)
    client_ctx = ssl.create_default_context()
    client_ctx.check_hostname = False
    client_ctx.verify_mode = ssl.CERT_NONE  # self-signed: compare the fingerprint instead

    with Session("car", device="cpu", paused=True) as session, \
            XRServer(session, host="127.0.0.1", token=cfg.token, ssl_context=cfg.ssl_context()) as srv:
        assert srv.base.startswith("https://")

        async def main():
            conn = aiohttp.TCPConnector(ssl=client_ctx)
            async with aiohttp.ClientSession(connector=conn, cookie_jar=aiohttp.CookieJar(unsafe=True)) as cs:
                async with cs.get(srv.base + "/xr/") as r:
                    assert r.status == 403
                with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                    await cs.ws_connect(srv.base.replace("https", "wss") + "/view/ws")
                assert info.value.status == 403
                async with cs.get(srv.url) as r:
                    assert r.status == 200
                    assert "Secure" in r.headers.get("Set-Cookie", "") and "HttpOnly" in r.headers["Set-Cookie"]
                    # named per port: two servers on one machine keep their own tokens
                    assert r.headers["Set-Cookie"].startswith(f"somwidget_token_{srv.port}=")
                async with cs.ws_connect(srv.base.replace("https", "wss") + "/view/ws") as ws:  # the cookie
                    topo = json.loads((await ws.receive(timeout=10)).data)
                    msg = await ws.receive(timeout=10)
                    while msg.type != aiohttp.WSMsgType.BINARY:  # replies (grabs) go out before frames
                        msg = await ws.receive(timeout=10)
                    frame = wire_frames.decode_frame(msg.data)
                return topo, frame

        topo, frame = asyncio.run(main())
        # the certificate the server presents (read on a connection of its own: aiohttp may have released the
        # response's connection by the time its headers are checked)
        der = ssl.PEM_cert_to_DER_cert(ssl.get_server_certificate(("127.0.0.1", srv.port)))

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    seen = ":".join(f"{b:02X}" for b in x509.load_der_x509_certificate(der).fingerprint(hashes.SHA256()))
    assert seen == lan.certificate_fingerprint(cfg.cert)
    assert topo["type"] == "topology" and frame["n"] == 602


# -- loopback or not; the Host / Origin guard; refusing to serve the LAN without a token --------------------------
@pytest.mark.parametrize("host, loopback", [
    (None, True), ("localhost", True), ("LocalHost", True), ("127.0.0.1", True), ("127.1.2.3", True),
    ("::1", True), ("[::1]", True), (" 127.0.0.1 ", True),
    ("0.0.0.0", False), ("::", False), ("192.168.1.20", False), ("example.org", False), ("localhost.evil", False),
])
def test_is_loopback(host, loopback):
    assert lan.is_loopback(host) is loopback


@pytest.mark.parametrize("host", ["", "   ", "[]"])
def test_an_empty_host_is_an_error_not_lan_mode(host):
    with pytest.raises(ValueError, match="empty host.*0.0.0.0"):
        lan.is_loopback(host)
    with pytest.raises(ValueError, match="empty host"):
        lan.prepare_lan(host)
    from somwidget.frontend.web.serve import run_server

    with pytest.raises(ValueError, match="empty host"):
        run_server(host=host, device="cpu")


def test_no_lan_address_is_said_clearly(tmp_path, monkeypatch):
    """Without a LAN address, `--lan` (or a wildcard host) refuses instead of printing a 127.x headset URL."""
    monkeypatch.setattr(lan, "lan_address", lambda: "127.0.1.1")
    for host in (None, "0.0.0.0"):
        with pytest.raises(ValueError, match="no LAN address found"):
            lan.prepare_lan(host, directory=tmp_path)
    assert lan.prepare_lan("127.0.0.1", directory=tmp_path).host == "127.0.0.1"  # asked for: served as asked


def test_cookie_name_is_per_port():
    assert lan.cookie_name(8080) == "somwidget_token_8080" != lan.cookie_name(8081)


def test_xr_server_beyond_loopback_needs_a_token():
    from somwidget.frontend.model import Session

    with Session("car", device="cpu", start=False) as session:
        for host in ("0.0.0.0", "192.168.1.20", "example.org"):
            with pytest.raises(ValueError, match="token"):
                XRServer(session, host=host)
        with pytest.raises(ValueError, match="empty host"):
            XRServer(session, host="")
        srv = XRServer(session, host="0.0.0.0", token=lan.make_token())  # with a token: allowed (not started)
        assert srv.host == "0.0.0.0"


def test_xr_server_refuses_other_sites_and_host_names():
    """The standalone XR server: a websocket from another site's page is refused (403), and so is a request whose
    Host is not a loopback name; its own origin is served."""
    from somwidget.frontend.model import Session

    with Session("car", device="cpu", paused=True) as session, XRServer(session) as srv:
        async def main():
            ws = srv.base.replace("http", "ws") + "/view/ws"
            async with aiohttp.ClientSession() as cs:
                with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                    await cs.ws_connect(ws, headers={"Origin": "http://evil.example"})
                assert info.value.status == 403
                for path in ("/xr/", "/xr/status"):
                    async with cs.get(srv.base + path, headers={"Host": "evil.example"}) as r:
                        assert r.status == 403, path
                    async with cs.get(srv.base + path, headers={"Host": f"localhost:{srv.port}"}) as r:
                        assert r.status == 200, path
                async with cs.ws_connect(ws, headers={"Origin": srv.base}) as conn:
                    assert json.loads((await conn.receive(timeout=10)).data)["type"] == "topology"

        asyncio.run(main())


class _Request:
    """What request_guard's checks read from an aiohttp request."""

    def __init__(self, headers, scheme="http", method="GET"):
        self.headers, self.scheme, self.method = headers, scheme, method


@pytest.mark.parametrize("headers, scheme, ok", [
    ({"Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:8080"}, "http", True),
    ({"Host": "localhost", "Origin": "http://localhost:80"}, "http", True),
    ({"Host": "[::1]:9000", "Origin": "http://[::1]:9000"}, "http", True),
    ({"Host": "192.168.1.20:8080", "Origin": "https://192.168.1.20:8080"}, "https", True),
    ({"Host": "192.168.1.20", "Origin": "https://192.168.1.20"}, "https", True),
    ({"Host": "127.0.0.1:8080"}, "http", True),  # no Origin: not a page of another site
    # behind a TLS-terminating proxy (JupyterHub + jupyter-server-proxy): the browser's Host, no port
    ({"Host": "hub.example.org", "Origin": "https://hub.example.org"}, "http", True),
    ({"Host": "hub.example.org", "Origin": "https://hub.example.org:8443"}, "http", False),
    ({"Host": "hub.example.org", "Origin": "https://evil.example"}, "http", False),
    ({"Host": "127.0.0.1:8080", "Origin": "http://evil.example"}, "http", False),
    ({"Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:8081"}, "http", False),
    ({"Host": "127.0.0.1:8080", "Origin": "null"}, "http", False),
    ({"Host": "127.0.0.1:8080", "Origin": "file://"}, "http", False),
    ({"Origin": "http://127.0.0.1:8080"}, "http", False),
])
def test_origin_allowed(headers, scheme, ok):
    assert lan.origin_allowed(_Request(headers, scheme)) is ok


@pytest.mark.parametrize("host, ok", [
    ("127.0.0.1:8080", True), ("localhost", True), ("LOCALHOST:1", True), ("[::1]:8080", True), (None, True),
    ("evil.example", False), ("evil.example:8080", False), ("localhost.evil.example", False),
    ("user@127.0.0.1:8080", False), ("127.0.0.1:8080/x", False), ("[::2]:80", False), ("", False),
])
def test_host_allowed(host, ok):
    assert lan.host_allowed(_Request({} if host is None else {"Host": host})) is ok
