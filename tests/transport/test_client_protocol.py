"""The browser client's protocol (client/src/protocol.js, link.js) in step with its Python declaration
(transport/messages.py): the version, header size, magic, flag bits, the frame header's offsets, the intents and
the server's message types. The JavaScript is read as text (no node needed); each test names what is out of step.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

from somwidget.frontend.transport import messages

CLIENT_SRC = Path(__file__).resolve().parents[2] / "somwidget" / "frontend" / "client" / "src"
#: The frame header's fields, in HEADER_FORMAT's order (messages.py documents them).
HEADER_FIELDS = ("magic", "version", "flags", "seq", "generation", "iteration", "iterations", "n", "k", "k_eff")


def read_js(name: str) -> str:
    """A client source file without its // comments (none of the code read here has // inside a string)."""
    text = (CLIENT_SRC / name).read_text(encoding="utf-8")
    return re.sub(r"(^|\s)//.*$", r"\1", text, flags=re.MULTILINE)


def js_constants(text: str) -> dict[str, int]:
    """`export const NAME = <integer>;` declarations."""
    return {m[1]: int(m[2], 0) for m in re.finditer(r"^export const (\w+) = (\d+|0x[0-9a-fA-F]+);", text, re.M)}


def block(text: str, opening: str, what: str) -> str:
    """The text between `opening` (which ends with "{") and its matching "}"."""
    start = text.find(opening)
    assert start >= 0, f"{what}: `{opening}` not found"
    depth, i = 1, start + len(opening)
    while depth:
        assert i < len(text), f"{what}: no closing brace"
        depth += {"{": 1, "}": -1}.get(text[i], 0)
        i += 1
    return text[start + len(opening):i - 1]


def out_of_step(problems: list[str]) -> str:
    return "the browser client is out of step with transport/messages.py:\n  " + "\n  ".join(problems)


def test_header_layout_declared_consistently_in_python():
    codes = re.findall(r"\d*[a-zA-Z?]", messages.HEADER_FORMAT)
    assert len(codes) == len(HEADER_FIELDS), f"HEADER_FORMAT {messages.HEADER_FORMAT!r} vs fields {HEADER_FIELDS}"
    assert struct.calcsize(messages.HEADER_FORMAT) == messages.HEADER_SIZE


def test_version_header_size_flags_and_magic():
    js = read_js("protocol.js")
    consts = js_constants(js)
    problems = []
    for name in ("PROTOCOL_VERSION", "HEADER_SIZE", "MAX_STROKE_POINTS"):
        if consts.get(name) != getattr(messages, name):
            problems.append(f"protocol.js {name} = {consts.get(name)}, messages.{name} = {getattr(messages, name)}")
    js_flags = {name.removeprefix("FLAG_").lower(): value for name, value in consts.items() if name.startswith("FLAG_")}
    for flag, bit in messages.FLAGS.items():
        if flag not in js_flags:
            problems.append(f"protocol.js has no FLAG_{flag.upper()} (messages.FLAGS[{flag!r}] = {bit})")
        elif js_flags[flag] != bit:
            problems.append(f"protocol.js FLAG_{flag.upper()} = {js_flags[flag]}, messages.FLAGS[{flag!r}] = {bit}")
    for flag in js_flags.keys() - messages.FLAGS.keys():
        problems.append(f"protocol.js FLAG_{flag.upper()} is not in messages.FLAGS")
    magic = re.search(r"const MAGIC = \[([^\]]*)\]", js)
    js_magic = bytes(int(b, 0) for b in magic[1].split(",")) if magic else None
    if js_magic != messages.MAGIC:
        problems.append(f"protocol.js MAGIC = {js_magic!r}, messages.MAGIC = {messages.MAGIC!r}")
    assert not problems, out_of_step(problems)


def test_frame_parser_reads_the_header_at_its_offsets():
    """Each DataView read in parseFrame (`name = dv.getUint16(offset, true)` or `name: dv.get...`) is the header
    field of that name at the offset and size HEADER_FORMAT gives it, little-endian; every field is read."""
    parser = block(read_js("protocol.js"), "export function parseFrame(buffer) {", "parseFrame")
    codes = re.findall(r"\d*[a-zA-Z?]", messages.HEADER_FORMAT.lstrip("<>=!@"))
    offsets = {f: struct.calcsize("<" + "".join(codes[:i])) for i, f in enumerate(HEADER_FIELDS)}
    sizes = {f: struct.calcsize("<" + c) for f, c in zip(HEADER_FIELDS, codes)}
    reads = re.findall(r"(\w+)\s*[:=]\s*dv\.getUint(\d+)\((\d+), true\)", parser)
    problems = []
    if len(reads) != parser.count("dv.get"):
        problems.append("parseFrame has DataView reads that are not `name = dv.getUintN(offset, true)`")
    seen = set()
    for js_name, bits, offset in reads:
        field = re.sub(r"([A-Z])", r"_\1", js_name).lower()  # kEff -> k_eff
        if field not in offsets:
            problems.append(f"parseFrame reads {js_name} at {offset}: no such header field {HEADER_FIELDS}")
            continue
        seen.add(field)
        if (int(offset), int(bits) // 8) != (offsets[field], sizes[field]):
            problems.append(f"parseFrame reads {js_name} as {bits} bits at offset {offset}; HEADER_FORMAT "
                            f"{messages.HEADER_FORMAT!r} has {field} as {8 * sizes[field]} bits at {offsets[field]}")
    for field in set(HEADER_FIELDS) - {"magic"} - seen:
        problems.append(f"parseFrame does not read the header field {field} (offset {offsets[field]})")
    assert not problems, out_of_step(problems)


def test_intent_builders_match_intents():
    """The `intents` object's builders: one per type in messages.INTENTS, each object literal it builds of its own
    type, with the type's required fields and no field that INTENTS does not allow (values are names or strings)."""
    body = block(read_js("protocol.js"), "export const intents = {", "protocol.js intents")
    builders = dict(re.findall(r"^\s*(\w+):\s*(.*?)(?=^\s*\w+:\s*\(|\Z)", body, re.M | re.S))
    problems = []
    for kind in messages.INTENTS.keys() - builders.keys():
        problems.append(f"protocol.js intents has no builder for the intent {kind!r}")
    for kind in builders.keys() - messages.INTENTS.keys():
        problems.append(f"protocol.js intents.{kind} is not an intent in messages.INTENTS")
    for kind, code in builders.items():
        literals = re.findall(r"\{([^{}]*)\}", code)
        if not literals:
            problems.append(f"protocol.js intents.{kind} builds no object literal")
        required, optional = messages.INTENTS.get(kind, (set(), set()))
        for literal in literals:
            fields = {}
            for item in filter(None, (s.strip() for s in literal.split(","))):
                key, _, value = item.partition(":")
                fields[key.strip()] = value.strip()
            if fields.get("type") != f"'{kind}'":
                problems.append(f"protocol.js intents.{kind} builds type {fields.get('type')}, not '{kind}'")
            fields.pop("type", None)
            if kind not in messages.INTENTS:
                continue
            if extra := sorted(fields.keys() - required - optional):
                problems.append(f"protocol.js intents.{kind} sends {extra}; messages.INTENTS[{kind!r}] allows "
                                f"{sorted(required | optional)}")
            if missing := sorted(required - fields.keys()):
                problems.append(f"protocol.js intents.{kind} leaves out the required {missing}")
    assert not problems, out_of_step(problems)


def test_dispatch_text_takes_every_server_message():
    """link.js's dispatchText takes each JSON message type a server sends; the notebook's frames, {"type": "frame"}
    with the frame as a binary buffer, are somview.js's to parse before it hands the rest to dispatchText."""
    body = block(read_js("link.js"), "export function dispatchText(msg, handlers) {", "link.js dispatchText")
    handled = set(re.findall(r"msg\.type === '(\w+)'", body))
    problems = [f"link.js dispatchText does not handle the server message {t!r}"
                for t in messages.SERVER_MESSAGES if t not in handled]
    problems += [f"link.js dispatchText handles {t!r}, which is not in messages.SERVER_MESSAGES"
                 for t in sorted(handled - set(messages.SERVER_MESSAGES))]
    if "msg.type === 'frame'" not in read_js("somview.js"):
        problems.append("somview.js does not take the notebook's {\"type\": \"frame\"} messages")
    assert not problems, out_of_step(problems)
