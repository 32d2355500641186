"""The binary frame: the latest state of a session as a view draws it (layout in messages.py), encoded from a
session's Frame and decoded again (for tests and benchmarks). Pure functions over numpy: no event loop, no server.
"""

from __future__ import annotations

import struct

import numpy as np

from .display import display_arrays
from .messages import FLAGS, HEADER_FORMAT, HEADER_SIZE, MAGIC, PROTOCOL_VERSION

HEADER = struct.Struct(HEADER_FORMAT)
assert HEADER.size == HEADER_SIZE

def _rgb8(colours: np.ndarray) -> np.ndarray:
    return np.clip(np.round(np.asarray(colours, np.float32) * 255.0), 0, 255).astype(np.uint8)


def encode_frame(frame, session) -> bytes:
    """The binary frame message for `frame` of `session` (the outbox encodes each published frame once)."""
    pos, col = display_arrays(frame, session)
    cpos = np.asarray(frame.effective_positions, np.float32).reshape(-1, 3)
    ccol = frame.control_display_colours
    n, k, k_eff = len(pos), int(frame.n_controls), len(cpos)
    undo, redo = frame.history
    set_ = {"running": frame.running, "paused": frame.paused, "mirrored": k_eff > k, "can_undo": undo > 0,
            "can_redo": redo > 0}
    flags = sum(bit for name, bit in FLAGS.items() if set_[name])
    header = HEADER.pack(MAGIC, PROTOCOL_VERSION, flags, frame.seq & 0xFFFFFFFF, frame.generation & 0xFFFFFFFF,
                         frame.iteration, frame.iterations, n, k, k_eff)
    body = b"".join([header, np.ascontiguousarray(pos, "<f4").tobytes(), np.ascontiguousarray(cpos, "<f4").tobytes(),
                     _rgb8(col).tobytes(), _rgb8(ccol).tobytes()])
    return body + b"\0" * (-len(body) % 4)


def frame_size(n: int, k_eff: int) -> int:
    size = HEADER_SIZE + 15 * (n + k_eff)
    return size + (-size % 4)


def decode_frame(data: bytes) -> dict:
    """Parse a binary frame (for tests and benchmarks): header fields and numpy arrays; ValueError if malformed."""
    if len(data) < HEADER_SIZE:
        raise ValueError(f"frame too short: {len(data)} bytes")
    magic, version, flags, seq, generation, s, S, n, k, k_eff = HEADER.unpack_from(data, 0)
    if magic != MAGIC or version != PROTOCOL_VERSION:
        raise ValueError(f"not a somwidget frame (magic {magic!r}, version {version})")
    if len(data) != frame_size(n, k_eff):
        raise ValueError(f"frame of {len(data)} bytes, expected {frame_size(n, k_eff)} for n={n}, k_eff={k_eff}")
    o = HEADER_SIZE
    pos = np.frombuffer(data, "<f4", 3 * n, o).reshape(n, 3)
    o += 12 * n
    cpos = np.frombuffer(data, "<f4", 3 * k_eff, o).reshape(k_eff, 3)
    o += 12 * k_eff
    col = np.frombuffer(data, np.uint8, 3 * n, o).reshape(n, 3)
    o += 3 * n
    ccol = np.frombuffer(data, np.uint8, 3 * k_eff, o).reshape(k_eff, 3)
    return {"flags": flags, "running": bool(flags & FLAGS["running"]), "paused": bool(flags & FLAGS["paused"]),
            "can_undo": bool(flags & FLAGS["can_undo"]), "can_redo": bool(flags & FLAGS["can_redo"]),
            "seq": seq, "generation": generation, "iteration": s, "iterations": S, "n": n, "k": k, "k_eff": k_eff,
            "positions": pos, "control_positions": cpos, "colours": col, "control_colours": ccol}
