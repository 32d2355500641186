"""Writes the browser's side of the wire protocol, client/src/protocol.js, from its declaration in messages.py: the
constants, the binary frame's parser (from `FrameHeader` and FRAME_ARRAYS), one builder per intent, the server's
message types and their JSDoc.

    python -m somwidget.frontend.transport.codegen            # write client/src/protocol.js
    python -m somwidget.frontend.transport.codegen --check    # exit 1 when the file is not what it would write

tests/transport/test_client_protocol.py fails while the committed file is out of date.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import sys
import textwrap
import types
import typing
from pathlib import Path

from ...backend import revolve as lathe_rule
from . import messages as m

TARGET = Path(__file__).resolve().parents[1] / "client" / "src" / "protocol.js"
WIDTH = 116
#: DataView's getter for each struct code of the frame header.
GETTERS = {"B": ("getUint8", 1), "H": ("getUint16", 2), "I": ("getUint32", 4), "b": ("getInt8", 1),
           "h": ("getInt16", 2), "i": ("getInt32", 4), "f": ("getFloat32", 4)}
TYPED_ARRAYS = {"<f4": "Float32Array", "u1": "Uint8Array"}


def camel(name: str) -> str:
    """k_eff -> kEff."""
    head, *rest = name.split("_")
    return head + "".join(part.capitalize() for part in rest)


def comment(text: str, indent: str = "", prefix: str = "// ") -> list[str]:
    text = " ".join(inspect.cleandoc(text).split())
    return textwrap.wrap(text, WIDTH - len(indent) - len(prefix), initial_indent=indent + prefix,
                         subsequent_indent=indent + prefix)


def js_number(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def js_type(hint) -> str:
    """A Python type hint of a server message's field as a JSDoc type."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.Annotated:
        return js_type(args[0])
    if origin in (typing.Union, types.UnionType):
        return "|".join(js_type(a) for a in args)
    if origin is typing.Literal:
        return "|".join(f"'{a}'" for a in args)
    if origin in (list, tuple):
        return f"{js_type(args[0])}[]" if args else "Array"
    if origin is dict:
        return f"Object<string, {js_type(args[1])}>" if args else "object"
    if dataclasses.is_dataclass(hint):
        fields = typing.get_type_hints(hint)
        return "{" + ", ".join(f"{name}: {js_type(t)}" for name, t in fields.items()) + "}"
    return {int: "number", float: "number", str: "string", bool: "boolean", dict: "object", list: "Array",
            type(None): "null"}[hint]


def _constants() -> list[str]:
    magic = ", ".join(f"0x{b:02x}" for b in m.MAGIC)
    out = [
        f"export const PROTOCOL_VERSION = {m.PROTOCOL_VERSION};",
        f"export const MAX_MESSAGE_BYTES = {m.MAX_MESSAGE_BYTES};",
        f"export const MAX_COORDINATE = {js_number(m.MAX_COORDINATE)};",
        f"export const MAX_STROKE_POINTS = {m.MAX_STROKE_POINTS};",
        f"export const AXIS_SNAP = {js_number(lathe_rule.AXIS_SNAP)}; // a profile's end this share of the size from "
        "the axis is on it",
        f"export const HEADER_SIZE = {m.HEADER_SIZE};",
        f"export const MAGIC = [{magic}]; // {m.MAGIC.decode()!r}",
    ]
    out += [f"export const FLAG_{name.upper()} = {bit};" for name, bit in m.FLAGS.items()]
    return out


def _frame_parser() -> list[str]:
    header = dataclasses.fields(m.FrameHeader)
    offsets, offset = {}, 0
    for f in header:
        offsets[f.name] = offset
        offset += struct_size(f.metadata["struct"])
    assert offset == m.HEADER_SIZE
    rows = list(dict.fromkeys(a.rows for a in m.FRAME_ARRAYS))
    terms = " + ".join(f"{a.row_bytes} * {camel(a.rows)}" for a in m.FRAME_ARRAYS)
    out = ["// The binary frame, little-endian: a header of HEADER_SIZE bytes, then the arrays, then zero padding to a",
           "// multiple of 4 bytes. The header:"]
    out += [f"//   {offsets[f.name]:>3}  {f.metadata['struct']:<3} {f.name}: {f.metadata['doc']}" for f in header]
    out += ["// The arrays, in order:"]
    out += [f"//   {a.name}: {a.rows} x {a.width} {TYPED_ARRAYS[a.dtype]} ({a.doc})" for a in m.FRAME_ARRAYS]
    out += ["",
            f"export function frameSize({', '.join(camel(r) for r in rows)}) {{",
            f"  const size = HEADER_SIZE + {terms};",
            "  return size + ((4 - (size % 4)) % 4);",
            "}",
            "",
            "export function parseFrame(buffer) {",
            "  if (!(buffer instanceof ArrayBuffer) || buffer.byteLength < HEADER_SIZE) {",
            "    throw new Error(`frame too short (${buffer && buffer.byteLength} bytes)`);",
            "  }",
            "  const bytes = new Uint8Array(buffer, 0, MAGIC.length);",
            "  if (MAGIC.some((b, i) => bytes[i] !== b)) throw new Error('not a somwidget frame (bad magic)');",
            "  const dv = new DataView(buffer);",
            f"  const version = dv.{GETTERS[code_of('version')][0]}({offsets['version']}, true);",
            "  if (version !== PROTOCOL_VERSION) throw new Error(`frame protocol ${version}, expected "
            "${PROTOCOL_VERSION}`);",
            "  const header = {"]
    for f in header:
        if f.name in ("magic", "version"):
            continue
        out.append(f"    {camel(f.name)}: dv.{GETTERS[f.metadata['struct']][0]}({offsets[f.name]}, true),")
    out += ["  };",
            f"  const size = frameSize({', '.join('header.' + camel(r) for r in rows)});",
            "  if (buffer.byteLength !== size) throw new Error(`frame of ${buffer.byteLength} bytes, expected "
            "${size}`);",
            "  let o = HEADER_SIZE;"]
    for i, a in enumerate(m.FRAME_ARRAYS):
        count = f"header.{camel(a.rows)}"
        out.append(f"  const {camel(a.name)} = new {TYPED_ARRAYS[a.dtype]}(buffer, o, {a.width} * {count});")
        if i < len(m.FRAME_ARRAYS) - 1:
            out.append(f"  o += {a.row_bytes} * {count};")
    out += ["  return {", "    ...header,"]
    out += [f"    {camel(name)}: (header.flags & FLAG_{name.upper()}) !== 0," for name in m.FLAGS]
    out += [f"    {', '.join(camel(a.name) for a in m.FRAME_ARRAYS)},",
            "    bytes: buffer.byteLength,",
            "  };",
            "}"]
    return out


def code_of(name: str) -> str:
    return next(f.metadata["struct"] for f in dataclasses.fields(m.FrameHeader) if f.name == name)


def struct_size(code: str) -> int:
    if code.endswith("s"):
        return int(code[:-1] or 1)
    return GETTERS[code][1]


def _server_messages() -> list[str]:
    out = ["// Server -> client JSON messages, by their type (a view's link hands each to its handler).",
           f"export const SERVER_MESSAGES = [{', '.join(repr(t) for t in m.SERVER_MESSAGES)}];",
           "// Over the notebook's comm, a frame comes as this message with the frame as its one buffer.",
           f"export const FRAME_MESSAGE = '{m.FrameMessage.type}';"]
    for kind, cls in m.SERVER_MESSAGES.items():
        out += ["", "/**"]
        out += comment(cls.__doc__ or "", prefix=" * ")
        out.append(f" * @typedef {{object}} {cls.__name__}")
        out.append(f" * @property {{'{kind}'}} type")
        for f in m.declared_fields(cls):
            out.append(f" * @property {{{js_type(f.hint)}}} {f.name}")
        out.append(" */")
    return out


def _intents() -> list[str]:
    out = ["// Client -> server intents: one builder per intent, its arguments the intent's fields in order (an",
           "// optional one left undefined is left out).",
           "function compact(message) {",
           "  return Object.fromEntries(Object.entries(message).filter(([, v]) => v !== undefined));",
           "}",
           "",
           "export const intents = {"]
    for kind, cls in m.INTENTS.items():
        fields = [f for f in m.declared_fields(cls) if f.browser]
        # one of several fields, the others not the browser's: required from the browser
        chosen = [f.name for f in fields if f.name in cls.one_of]
        required = {f.name for f in fields if f.required or chosen == [f.name]}
        args = ", ".join(f.name for f in fields)
        body = ", ".join([f"type: '{kind}'", *(f.name for f in fields)])
        optional = any(f.name not in required for f in fields)
        out += comment(cls.__doc__ or "", indent="  ")
        types_ = ", ".join(f"{f.name}: {f.wire_type().js}{'' if f.name in required else ' (optional)'}" for f in fields)
        if types_:
            out += comment(f"({types_})", indent="  ")
        built = f"compact({{ {body} }})" if optional else f"({{ {body} }})"
        out.append(f"  {kind}: ({args}) => {built},")
    out.append("};")
    return out


def render() -> str:
    """The text of client/src/protocol.js."""
    lines = ["// The views' wire protocol, client side. GENERATED from somwidget/frontend/transport/messages.py by",
             "//   python -m somwidget.frontend.transport.codegen",
             "// Do not edit: change messages.py and run that again (tests/transport/test_client_protocol.py fails",
             "// while this file is not what it writes).",
             "",
             *_constants(), "", *_frame_parser(), "", *_server_messages(), "", *_intents()]
    text = "\n".join(lines) + "\n"
    too_long = [line for line in text.splitlines() if len(line) > 120]
    assert not too_long, f"generated lines over 120 characters: {too_long[:3]}"
    assert not re.search(r"[^\x00-\x7f]", text), "generated text must be ASCII"
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 when the file is not what would be written")
    args = parser.parse_args(argv)
    text = render()
    current = TARGET.read_text(encoding="utf-8") if TARGET.is_file() else None
    if args.check:
        if current != text:
            print(f"{TARGET} is out of date: run python -m somwidget.frontend.transport.codegen", file=sys.stderr)
            return 1
        return 0
    if current != text:
        TARGET.write_text(text, encoding="utf-8")
        print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
