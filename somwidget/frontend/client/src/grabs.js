// Holding controls: grab / move / release intents, the local preview while dragging, and the move -> mesh latency.
//
// While this client drags control i, its sphere (and each copy of it) follows the hand at once (a local
// override); the server's frames bring the clay. Moves go out at most every MOVE_INTERVAL ms, the last one always;
// the release is bare (it ends the drag, nothing more). While it holds something and sends nothing (a hand held
// still) the view pings every KEEPALIVE_MS: the server lets go of a silent view's controls.

import { intents } from './protocol.js';

const MOVE_INTERVAL = 22; // ms: about 45 moves a second at most
const SETTLE_MS = 1000; // keep the local position after a release until a frame shows it (or this long)
const KEEPALIVE_MS = 2000; // while holding, a ping when nothing else was sent for this long

const round6 = (v) => Math.round(v * 1e6) / 1e6;

export class Grabs {
  constructor(link, clay) {
    this.link = link;
    this.clay = clay;
    this.active = new Map(); // original index -> {pos, lastSent, pending}
    this.settling = new Map(); // original index -> {pos, until}
    this.pendingMoves = []; // {t, index, pos, digest}
    this.latencies = []; // ms from a move's send to the first frame showing it with a changed mesh
    this.controlLatencies = []; // ms from a move's send to the first frame showing the control there
    this.latencyLog = []; // {sent, arrived, index, seq} (page clock, ms) for the latencies above
    this.moves = 0;
    this.answered = false; // a frame arrived that answers one of our moves and is not drawn yet
    this.lastDigest = 0;
    this.renamed = new Map(); // index a drag began at -> its control's index now
    this.lastSent = 0; // when this view last sent a grab or a move (page clock, ms)
  }

  // A drag begun at index i whose control has since moved to another index (a control removed elsewhere): the
  // callers (mouse, hands) go on naming the index they began with.
  current(i) {
    return this.renamed.has(i) ? this.renamed.get(i) : i;
  }

  holds(i) {
    return this.active.has(this.current(i));
  }

  begin(i) {
    if (this.active.has(i)) return false;
    const id = this.clay.controlIds[i] ?? i;
    if (this.clay.holders.has(i)) { // another hand holds it: the server says who (an error), nothing moves here
      this.link.send(intents.grab(id));
      return false;
    }
    this.renamed.delete(i);
    const m = this.clay.controlAnchors[i];
    const p = m ? [m.position.x, m.position.y, m.position.z] : [0, 0, 0];
    this.active.set(i, { id, began: i, pos: p, lastSent: 0, pending: null, sentPos: p.map(round6), moved: false });
    this.settling.delete(i);
    this.clay.setLocal(i, p);
    this.link.send(intents.grab(id));
    this.lastSent = performance.now();
    return true;
  }

  update(i, pos) {
    i = this.current(i);
    const g = this.active.get(i);
    if (!g) return;
    g.pos = pos;
    this.clay.setLocal(i, pos);
    // a hand held still sends nothing: every move restarts the map's schedule
    const p = pos.map(round6);
    const eps = 1e-5 * this.clay.radius;
    const same = (a) => a && Math.max(...a.map((v, a2) => Math.abs(v - p[a2]))) <= eps;
    g.pending = same(g.sentPos) ? null : p;
    g.moved ||= g.pending !== null;
    this.flushOne(i, g, performance.now());
  }

  flushOne(i, g, now) {
    if (!g.pending || now - g.lastSent < MOVE_INTERVAL) return;
    const p = g.pending;
    g.pending = null;
    g.lastSent = now;
    this.lastSent = now;
    g.sentPos = p;
    if (this.link.send(intents.move(g.id, p))) {
      this.moves += 1;
      this.pendingMoves.push({ t: now, index: i, pos: p.map(Math.fround), digest: this.lastDigest });
      if (this.pendingMoves.length > 64) this.pendingMoves.shift();
    }
  }

  flush() {
    const now = performance.now();
    for (const [i, g] of this.active) this.flushOne(i, g, now);
    if (this.active.size && now - this.lastSent >= KEEPALIVE_MS && this.link.send(intents.ping(now))) {
      this.lastSent = now;
    }
    for (const [i, s] of this.settling) {
      if (now > s.until) {
        this.settling.delete(i);
        if (!this.active.has(i)) this.clay.clearLocal(i);
      }
    }
  }

  end(i) {
    const began = i;
    i = this.current(i);
    this.renamed.delete(began);
    const g = this.active.get(i);
    if (!g) return;
    this.active.delete(i);
    const now = performance.now();
    if (g.pending) { // the last move, not sent yet: now, whatever the interval
      g.lastSent = -Infinity;
      this.flushOne(i, g, now);
    }
    this.link.send(intents.release(g.id)); // bare: the drag ends where the last move put it, nothing restarts
    if (!g.moved) { // a click (a selection): nothing moved
      this.clay.clearLocal(i);
      return;
    }
    const pos = g.sentPos.map(Math.fround); // where the server has it (a hand within a hair of it sent nothing more)
    const shown = this.clay.controlAnchors[i]?.userData.server;
    if (shown && pos.every((v, a) => v === shown[a])) { // a frame shows it there already: nothing to wait for
      this.clay.clearLocal(i);
      return;
    }
    this.clay.setLocal(i, g.sentPos);
    this.settling.set(i, { pos, until: now + SETTLE_MS });
  }

  // Let go of control i at once, where the server has it (a new clay came mid-drag: its ids name other controls).
  drop(i) {
    i = this.current(i);
    const g = this.active.get(i);
    if (!g) return;
    this.link.send(intents.release(g.id));
    this.cancel(i);
  }

  cancel(i) {
    this.active.delete(i);
    this.settling.delete(i);
    this.clay.clearLocal(i);
  }

  // The controls' ids changed (one added or removed elsewhere): our drags follow their controls to their new
  // places; a drag whose control is gone ends (the server says so too).
  onControls(ids) {
    const moved = new Map();
    const renamed = new Map();
    for (const [i, g] of this.active) {
      const j = ids.indexOf(g.id);
      this.clay.local.delete(i);
      if (j >= 0) moved.set(j, g);
      if (j !== g.began) renamed.set(g.began, j); // -1: its control is gone (the server ends the grab)
      this.onMoved?.(i, j, ids.length);
    }
    this.renamed = renamed;
    this.active = moved;
    for (const [j, g] of moved) this.clay.local.set(j, g.pos);
    this.settling.clear();
    this.clay.controlIds = ids;
    this.clay.refreshControls();
  }

  // The server says who holds what: a control we drag that another client holds is not ours; the controls others
  // hold are drawn in their holder's colour.
  onGrabs(list) {
    const held = new Set();
    for (const g of list) {
      held.add(g.index);
      if (!g.own && this.active.has(g.index)) this.cancel(g.index);
    }
    this.clay.held = held;
    this.clay.holders = new Map(list.filter((g) => !g.own && g.colour).map((g) => [g.index, g.colour]));
    this.clay.refreshControls();
  }

  // Every arriving frame: settle released controls, measure latency.
  onFrame(f, digest) {
    const now = performance.now();
    const cp = f.controlPositions;
    const at = (i, pos) => cp[3 * i] === pos[0] && cp[3 * i + 1] === pos[1] && cp[3 * i + 2] === pos[2];
    for (const [i, s] of this.settling) {
      if (i < f.k && at(i, s.pos)) {
        this.settling.delete(i);
        if (!this.active.has(i)) this.clay.clearLocal(i);
      }
    }
    for (let m = this.pendingMoves.length - 1; m >= 0; m--) {
      const pm = this.pendingMoves[m];
      if (pm.index < f.k && at(pm.index, pm.pos)) {
        if (pm.controlLatency === undefined) {
          pm.controlLatency = now - pm.t;
          this.controlLatencies.push(pm.controlLatency);
        }
        if (digest !== pm.digest) {
          this.answered = true; // this frame answers a move: the view draws it at once
          this.latencies.push(now - pm.t);
          this.latencyLog.push({ sent: pm.t, arrived: now, index: pm.index, seq: f.seq });
          if (this.latencyLog.length > 200) this.latencyLog.shift();
          this.pendingMoves.splice(0, m + 1); // this one and every older one are answered
        }
        break;
      }
    }
    if (this.latencies.length > 1000) this.latencies.splice(0, 500);
    if (this.controlLatencies.length > 1000) this.controlLatencies.splice(0, 500);
    this.lastDigest = digest;
  }
}
