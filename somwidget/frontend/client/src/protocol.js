// The /xr/ws protocol, client side: the twin of somwidget/frontend/transport/messages.py (the layout is documented
// there; tests/test_client_protocol.py keeps the two in step).
//
// Binary frame, little-endian: a 32-byte header (magic "SOMF", u16 version, u16 flags, u32 seq, u32 generation,
// u32 iteration, u32 iterations, u32 n, u16 k, u16 kEff), then Float32 positions (n x 3), Float32 control
// positions (kEff x 3), Uint8 RGB colours (n x 3), Uint8 RGB control colours (kEff x 3), zero padding to 4 bytes.

export const PROTOCOL_VERSION = 1;
export const HEADER_SIZE = 32;
export const FLAG_RUNNING = 1;
export const FLAG_PAUSED = 2;
export const FLAG_MIRRORED = 4;
export const FLAG_CAN_UNDO = 8;
export const FLAG_CAN_REDO = 16;
const MAGIC = [0x53, 0x4f, 0x4d, 0x46]; // "SOMF"

export function parseFrame(buffer) {
  if (!(buffer instanceof ArrayBuffer) || buffer.byteLength < HEADER_SIZE) {
    throw new Error(`frame too short (${buffer && buffer.byteLength} bytes)`);
  }
  const bytes = new Uint8Array(buffer, 0, 4);
  for (let i = 0; i < 4; i++) {
    if (bytes[i] !== MAGIC[i]) throw new Error('not a somwidget frame (bad magic)');
  }
  const dv = new DataView(buffer);
  const version = dv.getUint16(4, true);
  if (version !== PROTOCOL_VERSION) throw new Error(`frame protocol ${version}, expected ${PROTOCOL_VERSION}`);
  const flags = dv.getUint16(6, true);
  const n = dv.getUint32(24, true);
  const k = dv.getUint16(28, true);
  const kEff = dv.getUint16(30, true);
  let size = HEADER_SIZE + 15 * (n + kEff);
  size += (4 - (size % 4)) % 4;
  if (buffer.byteLength !== size) throw new Error(`frame of ${buffer.byteLength} bytes, expected ${size}`);
  let o = HEADER_SIZE;
  const positions = new Float32Array(buffer, o, 3 * n);
  o += 12 * n;
  const controlPositions = new Float32Array(buffer, o, 3 * kEff);
  o += 12 * kEff;
  const colours = new Uint8Array(buffer, o, 3 * n);
  o += 3 * n;
  const controlColours = new Uint8Array(buffer, o, 3 * kEff);
  return {
    flags,
    running: (flags & FLAG_RUNNING) !== 0,
    paused: (flags & FLAG_PAUSED) !== 0,
    canUndo: (flags & FLAG_CAN_UNDO) !== 0,
    canRedo: (flags & FLAG_CAN_REDO) !== 0,
    seq: dv.getUint32(8, true),
    generation: dv.getUint32(12, true),
    iteration: dv.getUint32(16, true),
    iterations: dv.getUint32(20, true),
    n, k, kEff, positions, controlPositions, colours, controlColours,
    bytes: buffer.byteLength,
  };
}

// Intents (client -> server), one JSON object per message.
export const intents = {
  // controls are named by their stable id (the topology's control_ids, then "controls" messages)
  grab: (id) => ({ type: 'grab', id }),
  move: (id, position) => ({ type: 'move', id, position }),
  release: (id, position) => (position ? { type: 'release', id, position } : { type: 'release', id }),
  reset: () => ({ type: 'reset' }),
  train: () => ({ type: 'train' }),
  pause: () => ({ type: 'pause' }),
  undo: () => ({ type: 'undo' }),
  redo: () => ({ type: 'redo' }),
  ping: (t) => ({ type: 'ping', t }),
  hello: () => ({ type: 'hello' }),
  set: (name, value) => ({ type: 'set', name, value }),
  // a control placed at a point of the clay (radius: model units; left out, the preset's)
  add: (position, radius) => (radius === undefined ? { type: 'add', position } : { type: 'add', position, radius }),
  remove: (id) => ({ type: 'remove', id }),
  radius: (id, radius) => ({ type: 'radius', id, radius }),
  // a polyline of 2 to MAX_STROKE_POINTS points [x, y, z] as one control
  stroke: (points, radius) => (radius === undefined ? { type: 'stroke', points } : { type: 'stroke', points, radius }),
};

export const MAX_STROKE_POINTS = 64;
