// The websocket to the server (/xr/ws next to the page). When it drops (the server stopped, restarted, the network
// went), the view says "reconnecting" and the link tries again, every RETRY_MS at first, then at most every
// MAX_RETRY_MS, until the server answers; the server then sends the topology and the latest frame as to any new view.

import { parseFrame } from './protocol.js';

// A JSON message from the server to the handler that takes it (shared by every transport).
export function dispatchText(msg, handlers) {
  if (msg.type === 'topology') handlers.onTopology?.(msg);
  else if (msg.type === 'grabs') handlers.onGrabs?.(msg.grabs);
  else if (msg.type === 'error') handlers.onError?.(msg);
  else if (msg.type === 'pong') handlers.onPong?.(msg);
  else if (msg.type === 'status') handlers.onServerStatus?.(msg);
  else if (msg.type === 'autosave') handlers.onAutosave?.(msg); // a save failed ({ok: false, message}), or works again
  else if (msg.type === 'controls') handlers.onControls?.(msg.ids, msg); // the whole message: its group too
}

export function socketURL(loc = window.location) {
  const scheme = loc.protocol === 'https:' ? 'wss:' : 'ws:';
  const base = loc.pathname.endsWith('/') ? loc.pathname : loc.pathname.replace(/[^/]*$/, '');
  const token = new URLSearchParams(loc.search).get('token');
  return `${scheme}//${loc.host}${base}ws${token ? `?token=${encodeURIComponent(token)}` : ''}`;
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
      let frame;
      try {
        frame = parseFrame(data);
      } catch (err) {
        this.stats.badFrames += 1;
        console.warn('somwidget xr: bad frame', err);
        return;
      }
      this.stats.frames += 1;
      this.stats.bytes += data.byteLength;
      this.handlers.onFrame?.(frame);
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
