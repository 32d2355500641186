"""The browser's side of the wire protocol (client/src/protocol.js) is generated from its declaration in Python
(transport/messages.py) by transport/codegen.py: the committed file must be what the generator writes now, and the
generated code, run by Node, must read what Python writes and write what Python accepts: a frame encoded from a real
session parses to the same header, flags and arrays as Python's decoder gives; each intent builder's message passes
`parse_intent` as the intent it names; link.js hands each server message type to a handler of the view.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from somwidget.frontend.transport import codegen, frames, messages

CLIENT_SRC = Path(__file__).resolve().parents[2] / "somwidget" / "frontend" / "client" / "src"
NODE = shutil.which("node")
needs_node = pytest.mark.skipif(NODE is None, reason="Node.js is not installed (the client's build needs it too)")


def run_node(tmp_path: Path, body: str, data) -> object:
    """Run an ES module importing the client's protocol.js and link.js (`data` is the JSON on stdin as `input`);
    what it prints as JSON."""
    script = tmp_path / "check.mjs"
    script.write_text(
        f"import * as protocol from {json.dumps((CLIENT_SRC / 'protocol.js').as_uri())};\n"
        f"import * as link from {json.dumps((CLIENT_SRC / 'link.js').as_uri())};\n"
        "import { readFileSync } from 'node:fs';\n"
        "const input = JSON.parse(readFileSync(0, 'utf8'));\n"
        f"{body}\n", encoding="utf-8")
    done = subprocess.run([NODE, str(script)], input=json.dumps(data), capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, f"node failed:\n{done.stderr}"
    return json.loads(done.stdout)


def test_protocol_js_is_what_the_generator_writes():
    committed = codegen.TARGET.read_text(encoding="utf-8")
    assert committed == codegen.render(), (
        f"{codegen.TARGET} is out of date with transport/messages.py: run "
        "`python -m somwidget.frontend.transport.codegen` and commit the file")
    assert codegen.main(["--check"]) == 0


def test_the_frame_layout_is_declared_consistently():
    assert struct.calcsize(messages.HEADER_FORMAT) == messages.HEADER_SIZE == 32
    assert frames.HEADER.size == messages.HEADER_SIZE
    assert [f.name for f in dataclasses.fields(messages.FrameHeader)][:2] == ["magic", "version"]
    assert messages.frame_size(602, 18) == 32 + 15 * (602 + 18)  # already a multiple of 4
    assert messages.frame_size(1, 0) == 48  # 32 + 15, padded
    assert len(set(messages.FLAGS.values())) == len(messages.FLAGS)
    assert all(bit & (bit - 1) == 0 for bit in messages.FLAGS.values())  # one bit each


@pytest.fixture(scope="module")
def encoded():
    """A frame of the car (9 controls, mirrored) as the outbox encodes it, and the same with every flag set."""
    from somwidget.frontend.model import Session

    with Session("car", device="cpu", start=False) as s:
        data = frames.encode_frame(s.frame, s)
    flagged = bytearray(data)
    struct.pack_into("<H", flagged, 6, sum(messages.FLAGS.values()))
    return [data, bytes(flagged)]


@needs_node
def test_the_generated_parser_reads_what_python_encodes(tmp_path, encoded):
    body = """
const out = input.map((b64) => {
  const buf = Buffer.from(b64, 'base64');
  const f = protocol.parseFrame(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength));
  for (const [k, v] of Object.entries(f)) if (ArrayBuffer.isView(v)) f[k] = Array.from(v);
  return f;
});
let refused = null;
try {
  const buf = Buffer.from(input[0], 'base64');
  protocol.parseFrame(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength - 4));
} catch (err) {
  refused = err.message;
}
console.log(JSON.stringify({ out, refused }));
"""
    result = run_node(tmp_path, body, [base64.b64encode(d).decode() for d in encoded])
    assert "expected" in result["refused"]  # a frame cut short is refused
    for data, js in zip(encoded, result["out"]):
        py = frames.decode_frame(data)
        assert js["bytes"] == len(data)
        for name, value in py.items():
            js_name = codegen.camel(name)
            assert js_name in js, f"parseFrame gives no {js_name} (Python's decoder gives {name})"
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(np.asarray(js[js_name], value.dtype), value.ravel(), err_msg=name)
            else:
                assert js[js_name] == value, name
    assert result["out"][1]["canUndo"] and result["out"][1]["running"] and not result["out"][0]["canRedo"]


#: Arguments for each wire type's field, as a view would pass them.
SAMPLES = {"id": 3, "position": [0.5, -0.25, 1.0], "radius": 0.3, "t": 12.5, "name": "reach", "value": 0.2,
           "points": [[0.0, 0.0, 0.0], [1.0, 0.5, 0.25]], "kind": "headset"}


@needs_node
def test_every_intent_builder_makes_a_message_python_accepts(tmp_path):
    calls = {}
    for kind, cls in messages.INTENTS.items():
        fields = [f for f in messages.declared_fields(cls) if f.browser]
        calls[kind] = [[SAMPLES[f.name] for f in fields]]
        while fields and not fields[-1].required and fields[-1].name not in cls.one_of:  # optional ones left out
            fields = fields[:-1]
            calls[kind].append([SAMPLES[f.name] for f in fields])
    body = """
const out = {};
for (const [kind, argLists] of Object.entries(input)) {
  out[kind] = argLists.map((args) => (protocol.intents[kind] ? protocol.intents[kind](...args) : null));
}
out.builders = Object.keys(protocol.intents);
console.log(JSON.stringify(out));
"""
    result = run_node(tmp_path, body, calls)
    assert result.pop("builders") == list(messages.INTENTS)
    for kind, built in result.items():
        for message, args in zip(built, calls[kind]):
            intent = messages.parse_intent(json.dumps(message), n_controls=9)
            assert type(intent) is messages.INTENTS[kind] and intent.to_json() == message, (kind, message)
            given = {f.name: getattr(intent, f.name) for f in messages.declared_fields(type(intent))
                     if getattr(intent, f.name) is not None}
            assert len(given) == len(args), (kind, message)  # every argument went out, nothing else


#: What the view's handler for each server message is called with (the handlers of view.js, main.js).
HANDED = {"topology": ("onTopology", lambda j: [j]), "grabs": ("onGrabs", lambda j: [j["grabs"]]),
          "controls": ("onControls", lambda j: [j["ids"], j]), "error": ("onError", lambda j: [j]),
          "pong": ("onPong", lambda j: [j]), "status": ("onServerStatus", lambda j: [j]),
          "autosave": ("onAutosave", lambda j: [j]), "presence": ("onPresence", lambda j: [j["hands"]])}


@needs_node
def test_link_hands_every_server_message_to_a_view_handler(tmp_path):
    samples = [messages.TopologyMessage(generation=1, preset="car", title="Car", display="surface", n_vertices=3,
                                        n_nodes=3, triangles=[0, 1, 2], segments=[0, 1], points=False,
                                        bounds={"min": [0, 0, 0], "max": [1, 1, 1]}, control_radius=0.1,
                                        colour_space="hs", feature_names=["x", "y", "z"]),
               messages.GrabsMessage(grabs=[messages.HeldControl(index=0, id=4, own=True, hand=2, holder="headset 2",
                                                                 colour="#2e8b3e")]),
               messages.PresenceMessage(hands=[messages.PresentHand(id=2, kind="headset", name="headset 2",
                                                                    colour="#2e8b3e", holds=[4], you=True)]),
               messages.ControlsMessage(ids=[4], radii=[0.0], strokes=[1]),
               messages.ErrorMessage(message="no", intent="grab"), messages.PongMessage(t=1.5),
               messages.StatusMessage.of(0.002, 30.0), messages.AutosaveMessage.of("disk full")]
    assert sorted(m.type for m in samples) == sorted(messages.SERVER_MESSAGES) == sorted(HANDED)
    body = """
const out = [];
for (const msg of [...input, { type: 'unknown' }, { type: 'constructor' }, null]) {
  const seen = [];
  const handlers = new Proxy({}, { get: (_, name) => (...args) => seen.push([name, args]) });
  link.dispatchText(msg, handlers);
  out.push(seen);
}
console.log(JSON.stringify({ out, handled: Object.keys(link.HANDLERS), declared: protocol.SERVER_MESSAGES }));
"""
    result = run_node(tmp_path, body, [m.to_json() for m in samples])
    assert result["declared"] == list(messages.SERVER_MESSAGES)
    assert sorted(result["handled"]) == sorted(messages.SERVER_MESSAGES), "link.js HANDLERS vs SERVER_MESSAGES"
    for message, seen in zip(samples, result["out"]):
        name, args = HANDED[message.type]
        assert seen == [[name, args(message.to_json())]], (message.type, seen)
    assert result["out"][len(samples):] == [[], [], []]  # unknown types (and Object's own names) reach no handler
