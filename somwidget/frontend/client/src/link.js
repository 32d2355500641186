// A view's link to its session: the websocket /view/ws of the page's server (`Link`), or the notebook's comm
// (`CommLink`, anywidget's model). Both take what the server sends (binary frames, JSON messages: protocol.js) and
// hand it to the view's handlers through one table (`HANDLERS`), and send intents as JSON.
// When the websocket drops (the server stopped, restarted, the network went), the view says "reconnecting" and the
// link tries again, every RETRY_MS at first, then at most every MAX_RETRY_MS, until the server answers; the server
// then sends the topology and the latest frame as to any new view.

import { FRAME_MESSAGE, parseFrame } from './protocol.js';

// Each JSON message type of the server (protocol.js SERVER_MESSAGES) -> the view's handler that takes it.
export const HANDLERS = {
  topology: (h, msg) => h.onTopology?.(msg),
  grabs: (h, msg) => h.onGrabs?.(msg.grabs),
  presence: (h, msg) => h.onPresence?.(msg.hands), // who else is on the session, and what each holds
  controls: (h, msg) => h.onControls?.(msg.ids, msg), // the whole message: its group too
  error: (h, msg) => h.onError?.(msg),
  pong: (h, msg) => h.onPong?.(msg),
  status: (h, msg) => h.onServerStatus?.(msg),
  autosave: (h, msg) => h.onAutosave?.(msg), // a save failed ({ok: false, message}), or works again
};

// A JSON message from the server to the handler that takes it (shared by every transport).
export function dispatchText(msg, handlers) {
  if (msg && Object.hasOwn(HANDLERS, msg.type)) HANDLERS[msg.type](handlers, msg);
}

// A binary frame to the view's onFrame (false, counted in stats.badFrames, when it does not parse).
function takeFrame(buffer, handlers, stats) {
  let frame;
  try {
    frame = parseFrame(buffer);
  } catch (err) {
    stats.badFrames += 1;
    console.warn('somwidget: bad frame', err);
    return false;
  }
  stats.frames += 1;
  stats.bytes += buffer.byteLength;
  handlers.onFrame?.(frame);
  return true;
}

// The view's websocket next to a page: /view/ws on the page's server (the XR page lives under /xr/, the web app's
// page at the root; a prefix in front of either is kept), with the page's ?token= if it has one.
export function socketURL(loc = window.location) {
  const scheme = loc.protocol === 'https:' ? 'wss:' : 'ws:';
  const dir = loc.pathname.endsWith('/') ? loc.pathname : loc.pathname.replace(/[^/]*$/, '');
  const base = dir.replace(/xr\/$/, '');
  const token = new URLSearchParams(loc.search).get('token');
  return `${scheme}//${loc.host}${base}view/ws${token ? `?token=${encodeURIComponent(token)}` : ''}`;
}

const RETRY_MS = 250;
const MAX_RETRY_MS = 2000;

export class Link {
  constructor(url, handlers) {
    this.url = url;
    this.handlers = handlers; // {onTopology, onFrame, onGrabs, onError, onPong, onStatus, onServerStatus, onControls}
    this.ws = null;
    this.connected = false;
    this.retry = RETRY_MS;
    this.stats = { frames: 0, bytes: 0, messages: 0, sent: 0, reconnects: 0, badFrames: 0 };
    this.closedByUser = false;
    this.connect();
  }

  connect() {
    const ws = new WebSocket(this.url);
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    ws.onopen = () => {
      this.connected = true;
      this.retry = RETRY_MS;
      this.handlers.onStatus?.('connected');
    };
    ws.onmessage = (ev) => this.receive(ev.data);
    ws.onclose = (ev) => {
      this.connected = false;
      this.stats.closeCode = ev.code;
      if (this.closedByUser) {
        this.handlers.onStatus?.('closed');
        return;
      }
      this.handlers.onStatus?.('reconnecting');
      setTimeout(() => {
        this.stats.reconnects += 1;
        this.connect();
      }, this.retry);
      this.retry = Math.min(this.retry * 2, MAX_RETRY_MS);
    };
    ws.onerror = () => {};
  }

  receive(data) {
    if (typeof data !== 'string') {
      takeFrame(data, this.handlers, this.stats);
      return;
    }
    this.stats.messages += 1;
    this.stats.bytes += data.length;
    let msg;
    try {
      msg = JSON.parse(data);
    } catch {
      return;
    }
    dispatchText(msg, this.handlers);
  }

  send(obj) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return false;
    this.ws.send(JSON.stringify(obj));
    this.stats.sent += 1;
    return true;
  }

  close() {
    this.closedByUser = true;
    this.ws?.close();
  }
}

// anywidget's model as a link: frames come as custom messages {type: FRAME_MESSAGE} with the frame as their one
// buffer, everything else as JSON; intents go back as custom messages.
export class CommLink {
  constructor(model, handlers) {
    this.model = model;
    this.handlers = handlers;
    this.connected = true;
    this.stats = { frames: 0, bytes: 0, messages: 0, sent: 0, badFrames: 0 };
    this.onMessage = (msg, buffers) => this.receive(msg, buffers);
    model.on('msg:custom', this.onMessage);
  }

  receive(msg, buffers) {
    this.stats.messages += 1;
    if (msg && msg.type === FRAME_MESSAGE && buffers && buffers.length) {
      takeFrame(bufferOf(buffers[0]), this.handlers, this.stats);
    } else {
      dispatchText(msg, this.handlers);
    }
  }

  send(obj) {
    this.model.send(obj);
    this.stats.sent += 1;
    return true;
  }

  close() {
    this.model.off('msg:custom', this.onMessage);
  }
}

function bufferOf(b) {
  if (b instanceof ArrayBuffer) return b;
  const view = ArrayBuffer.isView(b) ? b : new Uint8Array(b);
  return view.buffer.slice(view.byteOffset, view.byteOffset + view.byteLength);
}
