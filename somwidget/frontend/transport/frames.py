"""The binary frame: the latest state of a session as a view draws it (declared in messages.py: `FrameHeader`,
FRAME_ARRAYS), encoded from a session's Frame and decoded again (for tests and benchmarks). Pure functions over
numpy: no event loop, no server.
"""

from __future__ import annotations

import dataclasses
import struct

import numpy as np

from .display import display_arrays
from .messages import FLAGS, FRAME_ARRAYS, HEADER_FORMAT, HEADER_SIZE, MAGIC, PROTOCOL_VERSION, FrameHeader, frame_size

HEADER = struct.Struct(HEADER_FORMAT)


def _rgb8(colours: np.ndarray) -> np.ndarray:
    return np.clip(np.round(np.asarray(colours, np.float32) * 255.0), 0, 255).astype(np.uint8)


def encode_frame(frame, session) -> bytes:
    """The binary frame message for `frame` of `session` (the outbox encodes each published frame once)."""
    pos, col = display_arrays(frame, session)
    cpos = np.asarray(frame.effective_positions, np.float32).reshape(-1, 3)
    k = int(frame.n_controls)
    undo, redo = frame.history
    set_ = {"running": frame.running, "paused": frame.paused, "mirrored": len(cpos) > k, "can_undo": undo > 0,
            "can_redo": redo > 0}
    header = FrameHeader(magic=MAGIC, version=PROTOCOL_VERSION,
                         flags=sum(bit for name, bit in FLAGS.items() if set_[name]), seq=frame.seq & 0xFFFFFFFF,
                         generation=frame.generation & 0xFFFFFFFF, iteration=frame.iteration,
                         iterations=frame.iterations, n=len(pos), k=k, k_eff=len(cpos))
    arrays = {"positions": pos, "control_positions": cpos, "colours": _rgb8(col),
              "control_colours": _rgb8(frame.control_display_colours)}
    body = b"".join([HEADER.pack(*dataclasses.astuple(header)),
                     *(np.ascontiguousarray(arrays[a.name], a.dtype).tobytes() for a in FRAME_ARRAYS)])
    return body + b"\0" * (-len(body) % 4)


def decode_frame(data: bytes) -> dict:
    """Parse a binary frame (for tests and benchmarks): the header's fields, its flags by name and the arrays;
    ValueError if malformed."""
    if len(data) < HEADER_SIZE:
        raise ValueError(f"frame too short: {len(data)} bytes")
    header = FrameHeader(*HEADER.unpack_from(data, 0))
    if header.magic != MAGIC or header.version != PROTOCOL_VERSION:
        raise ValueError(f"not a somwidget frame (magic {header.magic!r}, version {header.version})")
    if len(data) != frame_size(header.n, header.k_eff):
        raise ValueError(f"frame of {len(data)} bytes, expected {frame_size(header.n, header.k_eff)} for "
                         f"n={header.n}, k_eff={header.k_eff}")
    out = {name: value for name, value in dataclasses.asdict(header).items() if name not in ("magic", "version")}
    out.update({name: bool(header.flags & bit) for name, bit in FLAGS.items()})
    offset = HEADER_SIZE
    for a in FRAME_ARRAYS:
        rows = out[a.rows]
        out[a.name] = np.frombuffer(data, a.dtype, a.width * rows, offset).reshape(rows, a.width)
        offset += a.row_bytes * rows
    return out


__all__ = ["HEADER", "encode_frame", "decode_frame", "frame_size"]
