// A control's radius of influence in the hand: a translucent ball of that radius around the control the pointer
// is on (or holds, or has selected), and the wheel (a headset's thumbstick) over it makes the radius larger or
// smaller. The ball follows at once; the radius goes to the server a few times a second, the last value always.

import * as THREE from 'three';
import { intents } from './protocol.js';

const STEP = 1.1; // one wheel notch (100 px of deltaY) up makes the radius this many times larger
const SEND_MS = 80;
const SMALLEST = 0.01; // the smallest radius the wheel sets, as a share of the clay's bounding radius
const FIRST = 0.05; // a point control (radius 0) turned larger starts here, as a share of the clay's radius
const SETTLE_MS = 1500; // the radius this view set wins over the server's messages this long after the last turn

export class RadiusBall {
  constructor(clay, link) {
    this.clay = clay;
    this.link = link;
    this.ball = new THREE.Mesh(new THREE.IcosahedronGeometry(1, 3), new THREE.MeshBasicMaterial({
      color: 0x3d7be0, transparent: true, opacity: 0.16, depthWrite: false }));
    this.ball.name = 'radius-ball';
    this.ball.renderOrder = 4;
    this.ball.visible = false;
    this.ball.frustumCulled = false;
    this.shownFor = null; // the effective control whose radius the ball shows
    this.pending = null; // {id, radius, i} not sent yet
    this.lastSent = 0;
    this.turns = 0;
    this.local = new Map(); // control id -> {radius, until}: set here, on its way to the server
  }

  // The radius of control i now (the one this view set, until the server's messages have caught up).
  radiusOf(i) {
    const own = this.local.get(this.clay.controlIds[i] ?? i);
    if (own && performance.now() < own.until) return own.radius;
    return Number(this.clay.radii[i] ?? 0);
  }

  // Show the ball around effective control j (null: none).
  show(j) {
    this.shownFor = j;
    this.update();
  }

  update() {
    const j = this.shownFor;
    const m = j === null ? null : this.clay.controlAnchors[j];
    const r = m ? this.radiusOf(this.clay.originalOf(j)) : 0;
    this.ball.visible = r > 0;
    if (!m || r <= 0) return;
    if (this.ball.parent !== this.clay.content) this.clay.content.add(this.ball);
    this.ball.position.copy(m.position);
    this.ball.scale.setScalar(r);
  }

  // A wheel turn (deltaY in px, 100 a notch) over effective control j: its radius (its stroke's) changes; returns it.
  turn(j, deltaY) {
    const i = this.clay.originalOf(j);
    const r0 = this.radiusOf(i);
    const size = this.clay.radius;
    const factor = STEP ** (-THREE.MathUtils.clamp(deltaY, -300, 300) / 100);
    const r = Math.max((r0 > 0 ? r0 : FIRST * size) * factor, SMALLEST * size);
    return this.set(i, r);
  }

  // Control i's radius (and its stroke's), at once here and soon on the server.
  set(i, r) {
    r = Number(r.toPrecision(5));
    const until = performance.now() + SETTLE_MS;
    for (const m of this.clay.runOf(i)) this.local.set(this.clay.controlIds[m] ?? m, { radius: r, until });
    this.pending = { id: this.clay.controlIds[i] ?? i, radius: r };
    this.turns += 1;
    this.flush();
    this.update();
    return r;
  }

  flush() {
    const now = performance.now();
    if (!this.pending || now - this.lastSent < SEND_MS) return;
    if (!this.link.send(intents.radius(this.pending.id, this.pending.radius))) return; // tried again next frame
    this.lastSent = now;
    this.pending = null;
  }
}
