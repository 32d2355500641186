"""Bounds on what the clients of the trame page's websocket can make the server hold.

wslink splits each client message into chunks with a 12-byte header (message id, offset, total size, unsigned
little-endian 32-bit each) and, once a client has said hello, reassembles them into a buffer of the claimed total
size allocated on the first chunk: one 12-byte header could make the server allocate up to 4 GiB. `bound_messages`
replaces that reassembly for every client of a wslink server: a message may claim at most MAX_MESSAGE_BYTES, nothing
is allocated before the content arrives, a client may have at most MAX_PENDING messages in flight and
MAX_PENDING_BYTES received but unfinished, and all clients together at most MAX_TOTAL_PENDING_BYTES.

A client that breaks a bound is refused: what it had sent is let go at once (nothing keeps a reference: no exception
leaves the reassembly), its connection is closed (1009, "message too big"), the log has one line saying who and why,
and its further chunks are dropped unread. The session and the other clients carry on.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

import msgpack

log = logging.getLogger(__name__)

HEADER_LENGTH = 12
#: Messages a client may have begun and not finished.
MAX_PENDING = 4
#: Largest message a client may send: an upload field's file (50 MB) and its encoding.
MAX_MESSAGE_BYTES = 64_000_000
#: Bytes a client may have sent in unfinished messages.
MAX_PENDING_BYTES = 80_000_000
#: Bytes all the clients of a server together may have sent in unfinished messages (two uploads at once).
MAX_TOTAL_PENDING_BYTES = 160_000_000


class Refused(Exception):
    """A chunk that breaks a bound (internal: `BoundedUnChunker` turns it into a closed connection)."""


class PendingBudget:
    """The bytes all clients of one server have received in unfinished messages, bounded by `limit`."""

    def __init__(self, limit: int = MAX_TOTAL_PENDING_BYTES) -> None:
        self.limit = int(limit)
        self.used = 0

    def take(self, n: int) -> bool:
        if self.used + n > self.limit:
            return False
        self.used += n
        return True

    def give(self, n: int) -> None:
        self.used = max(0, self.used - n)


class BoundedUnChunker:
    """wslink's un-chunker, bounded (the same interface: process_chunk, set_max_message_size,
    release_pending_messages). `close(reason)` ends the client's connection when it is refused."""

    def __init__(self, budget: PendingBudget | None = None, close: Callable[[str], None] | None = None,
                 name: str = "a client", max_bytes: int = MAX_MESSAGE_BYTES) -> None:
        self.max_bytes = int(max_bytes)
        self.budget = budget if budget is not None else PendingBudget()
        self.close = close or (lambda reason: None)
        self.name = name
        self.pending: dict[int, tuple[int, list[bytes], int]] = {}  # id -> (total, parts, received)
        self.refused: str | None = None  # why this client was refused (its chunks are dropped from then on)

    @property
    def held(self) -> int:
        """Bytes received in this client's unfinished messages."""
        return sum(received for _, _, received in self.pending.values())

    def set_max_message_size(self, size) -> None:
        """wslink lifts the limit to 4 GiB after a hello: the bound stays."""

    def release_pending_messages(self) -> None:
        self.budget.give(self.held)
        self.pending = {}

    def process_chunk(self, chunk: bytes):
        """The whole message once its last chunk came (None before, and for a refused client)."""
        if self.refused is not None:
            return None
        try:
            return self._take(chunk)
        except Refused as exc:
            reason = str(exc)
        self.refused = reason
        self.release_pending_messages()  # let go of what it sent, now
        log.warning("refused the page websocket's %s and closed it: %s", self.name, reason)
        self.close(reason)
        return None

    def _take(self, chunk: bytes):
        if len(chunk) < HEADER_LENGTH:
            raise Refused("a chunk shorter than its header")
        mid = int.from_bytes(chunk[0:4], "little")
        offset = int.from_bytes(chunk[4:8], "little")
        total = int.from_bytes(chunk[8:12], "little")
        size = len(chunk) - HEADER_LENGTH
        entry = self.pending.get(mid)
        if entry is None:
            if total > self.max_bytes:
                raise Refused(f"a message of {total:,} bytes; the limit is {self.max_bytes:,}")
            if len(self.pending) >= MAX_PENDING:
                raise Refused(f"more than {MAX_PENDING} unfinished messages")
            entry = (total, [], 0)
        want_total, parts, received = entry
        if total != want_total or offset != received:
            raise Refused("a chunk out of order or with another total size")
        if received + size > total:
            raise Refused("a message longer than its header said")
        if self.held + size > MAX_PENDING_BYTES:
            raise Refused(f"more than {MAX_PENDING_BYTES:,} bytes in unfinished messages")
        if not self.budget.take(size):
            raise Refused(f"all clients together would hold more than {self.budget.limit:,} bytes in unfinished "
                          "messages")
        parts.append(bytes(chunk[HEADER_LENGTH:]))
        received += size
        if received < total:
            self.pending[mid] = (total, parts, received)
            return None
        self.pending.pop(mid, None)
        self.budget.give(received)
        data = b"".join(parts)
        parts.clear()
        try:
            message = msgpack.unpackb(data)
        except Exception as exc:  # msgpack's errors: not a wslink message
            raise Refused(f"a message that is not msgpack ({type(exc).__name__})") from None
        if not isinstance(message, dict) or ("id" in message and not isinstance(message.get("method"), str)):
            raise Refused("a message that is not a wslink call (a map with an id and a method)")
        return message


class _BoundedTable(dict):
    """The server protocol's table of un-chunkers: whatever wslink puts in for a new client, it gets a bounded one
    sharing the server's budget; a client that goes releases its share."""

    def __init__(self, handler, budget: PendingBudget) -> None:
        super().__init__()
        self.handler = handler
        self.budget = budget

    def __setitem__(self, client_id, _unchunker) -> None:
        super().__setitem__(client_id, BoundedUnChunker(self.budget, self._closer(client_id),
                                                        name=f"client {str(client_id)[:8]}"))

    def __delitem__(self, client_id) -> None:
        unchunker = self.get(client_id)
        if unchunker is not None:
            unchunker.release_pending_messages()
        super().__delitem__(client_id)

    def _closer(self, client_id) -> Callable[[str], None]:
        def close(_reason: str) -> None:
            ws = getattr(self.handler, "connections", {}).get(client_id)
            if ws is not None:
                asyncio.ensure_future(ws.close(code=1009, message=b"message too big"))
        return close


def bound_messages(wslink_server, budget: PendingBudget | None = None) -> bool:
    """Bound every client's reassembly on a wslink aiohttp server (what trame's `on_server_bind` passes): each of its
    websocket handlers gets a bounded table, all of them one budget. False (and nothing changed) where the server
    has none to bound (a wslink whose internals moved: the tests' attack then fails)."""
    handlers = getattr(wslink_server, "_ws_handlers", None)
    if not handlers:
        return False
    budget = budget if budget is not None else PendingBudget()
    for handler in handlers:
        table = _BoundedTable(handler, budget)
        for client_id in list(getattr(handler, "unchunkers", {})):
            table[client_id] = None
        handler.unchunkers = table
    return True
