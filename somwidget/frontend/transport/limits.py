"""Bounds on what a client of the trame page's websocket can make the server hold.

wslink splits each client message into chunks with a 12-byte header (message id, offset, total size, unsigned
little-endian 32-bit each) and, once a client has said hello, reassembles them into a buffer of the claimed total
size allocated on the first chunk: one 12-byte header could make the server allocate up to 4 GiB. `bound_messages`
replaces that reassembly for every client of a wslink server: a message may claim at most `max_bytes`,
nothing is allocated before the content arrives, a client may have at most MAX_PENDING messages in flight and
MAX_PENDING_BYTES received but unfinished. Refused chunks raise ValueError, which ends that client's connection;
the session and the other clients carry on.
"""

from __future__ import annotations

import msgpack

HEADER_LENGTH = 12
#: Messages a client may have begun and not finished.
MAX_PENDING = 4
#: Largest message a client may send: an upload field's file (50 MB) and its encoding.
MAX_MESSAGE_BYTES = 64_000_000
#: Bytes a client may have sent in unfinished messages.
MAX_PENDING_BYTES = 80_000_000


class BoundedUnChunker:
    """wslink's un-chunker, bounded (the same interface: process_chunk, set_max_message_size,
    release_pending_messages)."""

    def __init__(self, max_bytes: int = MAX_MESSAGE_BYTES):
        self.max_bytes = int(max_bytes)
        self.pending: dict[int, tuple[int, list[bytes], int]] = {}  # id -> (total, parts, received)

    def set_max_message_size(self, size) -> None:
        """wslink lifts the limit to 4 GiB after a hello: the bound stays."""

    def release_pending_messages(self) -> None:
        self.pending = {}

    def process_chunk(self, chunk: bytes):
        if len(chunk) < HEADER_LENGTH:
            raise ValueError("websocket: a chunk shorter than its header")
        mid = int.from_bytes(chunk[0:4], "little")
        offset = int.from_bytes(chunk[4:8], "little")
        total = int.from_bytes(chunk[8:12], "little")
        content = bytes(chunk[HEADER_LENGTH:])
        entry = self.pending.get(mid)
        if entry is None:
            if total > self.max_bytes:
                raise ValueError(f"websocket: a message of {total:,} bytes; the limit is {self.max_bytes:,}")
            if len(self.pending) >= MAX_PENDING:
                raise ValueError(f"websocket: more than {MAX_PENDING} unfinished messages")
            entry = (total, [], 0)
        want_total, parts, received = entry
        if total != want_total or offset != received:
            self.pending.pop(mid, None)
            raise ValueError("websocket: a chunk out of order or with another total size")
        received += len(content)
        if received > total:
            self.pending.pop(mid, None)
            raise ValueError("websocket: a message longer than its header said")
        if sum(r for _, _, r in self.pending.values()) + len(content) > MAX_PENDING_BYTES:
            self.pending.pop(mid, None)
            raise ValueError(f"websocket: more than {MAX_PENDING_BYTES:,} bytes in unfinished messages")
        parts.append(content)
        if received < total:
            self.pending[mid] = (total, parts, received)
            return None
        self.pending.pop(mid, None)
        return msgpack.unpackb(b"".join(parts))


class _BoundedTable(dict):
    """The server protocol's table of un-chunkers: whatever wslink puts in for a new client, it gets a bounded one."""

    def __setitem__(self, client_id, _unchunker) -> None:
        super().__setitem__(client_id, BoundedUnChunker())


def bound_messages(wslink_server) -> bool:
    """Bound every client's reassembly on a wslink aiohttp server (what trame's `on_server_bind` passes): each of
    its websocket handlers gets a bounded table. False (and nothing changed) where the server has none to bound (a
    wslink whose internals moved: the tests' attack then fails)."""
    handlers = getattr(wslink_server, "_ws_handlers", None)
    if not handlers:
        return False
    for handler in handlers:
        table = _BoundedTable()
        for client_id in list(getattr(handler, "unchunkers", {})):
            table[client_id] = None
        handler.unchunkers = table
    return True
