// The views' wire protocol, client side. GENERATED from somwidget/frontend/transport/messages.py by
//   python -m somwidget.frontend.transport.codegen
// Do not edit: change messages.py and run that again (tests/transport/test_client_protocol.py fails
// while this file is not what it writes).

export const PROTOCOL_VERSION = 1;
export const MAX_MESSAGE_BYTES = 2048;
export const MAX_COORDINATE = 10000;
export const MAX_STROKE_POINTS = 64;
export const AXIS_SNAP = 0.08; // a profile's end this share of the size from the axis is on it
export const HEADER_SIZE = 32;
export const MAGIC = [0x53, 0x4f, 0x4d, 0x46]; // 'SOMF'
export const FLAG_RUNNING = 1;
export const FLAG_PAUSED = 2;
export const FLAG_MIRRORED = 4;
export const FLAG_CAN_UNDO = 8;
export const FLAG_CAN_REDO = 16;

// The binary frame, little-endian: a header of HEADER_SIZE bytes, then the arrays, then zero padding to a
// multiple of 4 bytes. The header:
//     0  4s  magic: b"SOMF"
//     4  H   version: the protocol version (PROTOCOL_VERSION)
//     6  H   flags: FLAGS: 1 running, 2 paused, 4 mirrored copies present, 8 a step to undo, 16 to redo
//     8  I   seq: the session's frame number (one more per published frame)
//    12  I   generation: matches the latest topology message
//    16  I   iteration: the iteration s
//    20  I   iterations: the iterations S
//    24  I   n: display vertices
//    28  H   k: controls (the originals)
//    30  H   k_eff: effective controls (the originals, then the mirrored copies)
// The arrays, in order:
//   positions: n x 3 Float32Array (vertex positions, model units)
//   control_positions: k_eff x 3 Float32Array (effective control positions)
//   colours: n x 3 Uint8Array (vertex colours, RGB)
//   control_colours: k_eff x 3 Uint8Array (effective control colours, RGB)

export function frameSize(n, kEff) {
  const size = HEADER_SIZE + 12 * n + 12 * kEff + 3 * n + 3 * kEff;
  return size + ((4 - (size % 4)) % 4);
}

export function parseFrame(buffer) {
  if (!(buffer instanceof ArrayBuffer) || buffer.byteLength < HEADER_SIZE) {
    throw new Error(`frame too short (${buffer && buffer.byteLength} bytes)`);
  }
  const bytes = new Uint8Array(buffer, 0, MAGIC.length);
  if (MAGIC.some((b, i) => bytes[i] !== b)) throw new Error('not a somwidget frame (bad magic)');
  const dv = new DataView(buffer);
  const version = dv.getUint16(4, true);
  if (version !== PROTOCOL_VERSION) throw new Error(`frame protocol ${version}, expected ${PROTOCOL_VERSION}`);
  const header = {
    flags: dv.getUint16(6, true),
    seq: dv.getUint32(8, true),
    generation: dv.getUint32(12, true),
    iteration: dv.getUint32(16, true),
    iterations: dv.getUint32(20, true),
    n: dv.getUint32(24, true),
    k: dv.getUint16(28, true),
    kEff: dv.getUint16(30, true),
  };
  const size = frameSize(header.n, header.kEff);
  if (buffer.byteLength !== size) throw new Error(`frame of ${buffer.byteLength} bytes, expected ${size}`);
  let o = HEADER_SIZE;
  const positions = new Float32Array(buffer, o, 3 * header.n);
  o += 12 * header.n;
  const controlPositions = new Float32Array(buffer, o, 3 * header.kEff);
  o += 12 * header.kEff;
  const colours = new Uint8Array(buffer, o, 3 * header.n);
  o += 3 * header.n;
  const controlColours = new Uint8Array(buffer, o, 3 * header.kEff);
  return {
    ...header,
    running: (header.flags & FLAG_RUNNING) !== 0,
    paused: (header.flags & FLAG_PAUSED) !== 0,
    mirrored: (header.flags & FLAG_MIRRORED) !== 0,
    canUndo: (header.flags & FLAG_CAN_UNDO) !== 0,
    canRedo: (header.flags & FLAG_CAN_REDO) !== 0,
    positions, controlPositions, colours, controlColours,
    bytes: buffer.byteLength,
  };
}

// Server -> client JSON messages, by their type (a view's link hands each to its handler).
export const SERVER_MESSAGES = ['topology', 'grabs', 'presence', 'controls', 'error', 'pong', 'status', 'autosave'];
// Over the notebook's comm, a frame comes as this message with the frame as its one buffer.
export const FRAME_MESSAGE = 'frame';

/**
 * What a view draws, once per connection and again whenever the session's generation changes (a new preset or
 * mesh). `n_vertices`: display vertices in each frame (N nodes; 2N for "lines": roots then tips); `triangles`: a
 * flat triangle list over them (faces fanned; quads for "lines"); `segments`: a flat segment list (mesh edges;
 * root -> tip for "lines"); `points`: draw each vertex as a point; `bounds`: {"min": [x, y, z], "max": [...]} of
 * the start mesh and controls; `control_radius`: a control's drawn radius; `off_clay_gap`: past this distance
 * from the clay a control gets a line to its nearest node (0: none); `parameters`: the settings a "set" may
 * name. The fields after `parameters` are the view's own: its client id (None over the notebook's comm),
 * `watching` (the view only watches: its intents other than hello, hand and ping are refused, so it shows itself
 * read-only) and the controls as a `ControlsMessage` gives them, with `mirror_axes` (the axes a mirrored copy
 * negates), `n_controls` and `n_effective` (originals, then mirrored copies).
 * @typedef {object} TopologyMessage
 * @property {'topology'} type
 * @property {number} protocol
 * @property {number} generation
 * @property {string} preset
 * @property {string} title
 * @property {'surface'|'lines'|'points'} display
 * @property {number} n_vertices
 * @property {number} n_nodes
 * @property {number[]} triangles
 * @property {number[]} segments
 * @property {boolean} points
 * @property {number} up_axis
 * @property {Object<string, number[]>} bounds
 * @property {number} control_radius
 * @property {number} off_clay_gap
 * @property {string} colour_space
 * @property {string[]} feature_names
 * @property {number} max_coordinate
 * @property {number} max_message_bytes
 * @property {object[]} parameters
 * @property {number|null} client
 * @property {boolean} watching
 * @property {number[]} control_ids
 * @property {string} group
 * @property {number[][]} group_maps
 * @property {boolean[]} mirror_axes
 * @property {number} n_controls
 * @property {number} n_effective
 * @property {number[]} radii
 * @property {number[]} strokes
 */

/**
 * The controls held now, as the view it is sent to sees them.
 * @typedef {object} GrabsMessage
 * @property {'grabs'} type
 * @property {{index: number, id: number, own: boolean, hand: number, holder: string, colour: string}[]} grabs
 */

/**
 * Who is on the session now, in the order they came: sent to every view whenever someone comes, goes, grabs or
 * lets go.
 * @typedef {object} PresenceMessage
 * @property {'presence'} type
 * @property {{id: number, kind: string, name: string, colour: string, holds: number[], you: boolean}[]} hands
 */

/**
 * Each control's stable id in index order, the symmetry group (its maps of a position, 3 x 3 row-major, the
 * identity first: effective control j is control j mod k under map j // k), each control's radius of influence
 * (model units) and the runs of controls that act as one (a stroke's samples). Sent before the frame whenever
 * one of them changes.
 * @typedef {object} ControlsMessage
 * @property {'controls'} type
 * @property {number[]} ids
 * @property {string} group
 * @property {number[][]} group_maps
 * @property {number[]} radii
 * @property {number[]} strokes
 */

/**
 * A refused intent: why, and its type when that much was readable.
 * @typedef {object} ErrorMessage
 * @property {'error'} type
 * @property {string} message
 * @property {string|null} intent
 */

/**
 * The answer to a ping, with its `t`.
 * @typedef {object} PongMessage
 * @property {'pong'} type
 * @property {number|null} t
 */

/**
 * The engine's time per cycle (ms) and the frames published a second, every STATUS_PERIOD while frames flow.
 * @typedef {object} StatusMessage
 * @property {'status'} type
 * @property {number} cycle_ms
 * @property {number} fps
 */

/**
 * The autosave cannot write (`ok` false: what and where; it tries again every second), shown until a message
 * with `ok` true says a save is on disk again.
 * @typedef {object} AutosaveMessage
 * @property {'autosave'} type
 * @property {boolean} ok
 * @property {string} message
 */

// Client -> server intents: one builder per intent, its arguments the intent's fields in order (an
// optional one left undefined is left out).
function compact(message) {
  return Object.fromEntries(Object.entries(message).filter(([, v]) => v !== undefined));
}

export const intents = {
  // Hold a control; refused while another view holds it. A grab to its release is one undo step (a gesture).
  // (id: number)
  grab: (id) => ({ type: 'grab', id }),
  // Move a held control to `position` (model units).
  // (id: number, position: number[])
  move: (id, position) => ({ type: 'move', id, position }),
  // Let go of a held control: the drag ends, nothing more. A last `position` (older clients) moves it first
  // only where it differs from the last move. A held control removed elsewhere ends the grab, with an error
  // message to the view that held it.
  // (id: number, position: number[] (optional))
  release: (id, position) => compact({ type: 'release', id, position }),
  // Train the whole schedule again from the start mesh.
  reset: () => ({ type: 'reset' }),
  // Resume training.
  train: () => ({ type: 'train' }),
  // Pause training.
  pause: () => ({ type: 'pause' }),
  // Take back this view's own latest step (others' steps after it stay), else the last step.
  undo: () => ({ type: 'undo' }),
  // Bring back the step last undone (after this view's undo of an older step of its own: that step).
  redo: () => ({ type: 'redo' }),
  // Answered at once with a `PongMessage` carrying the same `t`.
  // (t: number)
  ping: (t) => ({ type: 'ping', t }),
  // Send the topology and the latest frame again (a new output of the same connection: a notebook's).
  hello: () => ({ type: 'hello' }),
  // Set a setting by name (the topology message lists them: "parameters"), checked against its declaration.
  // (name: string, value: number|boolean)
  set: (name, value) => ({ type: 'set', name, value }),
  // A new control at `position` (its other features the nearest node's; radius left out: the preset's); it
  // moves nothing until it is dragged.
  // (position: number[], radius: number (optional))
  add: (position, radius) => compact({ type: 'add', position, radius }),
  // Remove a control (a stroke goes whole).
  // (id: number)
  remove: (id) => ({ type: 'remove', id }),
  // A control's radius of influence (model units); the same control's radius again within a moment joins its
  // step.
  // (id: number, radius: number)
  radius: (id, radius) => ({ type: 'radius', id, radius }),
  // A polyline of 2 to MAX_STROKE_POINTS points as one control (its samples act as one); radius optional.
  // (points: number[][], radius: number (optional))
  stroke: (points, radius) => compact({ type: 'stroke', points, radius }),
  // What this view is, as the others see it (a `PresenceMessage`): "desktop" (a view's connection starts as
  // one; a notebook's as "notebook"), or "headset" while the page is in its immersive session; `name`: the
  // person's name as they gave it (a studio's lobby), shown in place of "desktop 2" to the others and on the
  // wall.
  // (kind: string, name: string (optional))
  hand: (kind, name) => compact({ type: 'hand', kind, name }),
  // A profile of 2 to MAX_STROKE_POINTS points drawn beside the axis of the radial group in effect (none: the
  // z-axis, 16 copies): the clay is lathed around it and the profile becomes its stroke control
  // (Session.revolve); radius optional.
  // (points: number[][], radius: number (optional))
  revolve: (points, radius) => compact({ type: 'revolve', points, radius }),
};
