// A control's radius of influence in the hand: a translucent ball of that radius around the control the pointer
// is on (or holds, or has selected), and the wheel (a headset's thumbstick) over it makes the radius larger or
// smaller. The ball follows at once; the radius goes to the server a few times a second, the last value always.
//
// On a flat screen, as sculpting apps do, a translucent disc lies on the clay under the cursor (RadiusDisc): the
// radius of the control under the pointer or being dragged, else the radius a new control gets (a double click, a
// stroke), with a small label by the cursor in model units and as a share of the clay's size. Alt+wheel or [ and ]
// change that radius (a control's goes to the server, a new one's stays in the view until it is used).

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
    this.chosen = null; // the radius a new control gets, chosen here (null: the controls' usual one)
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
    return this.set(i, this.turned(this.radiusOf(i), deltaY));
  }

  // A radius r0 after a wheel turn of deltaY px (up, negative: larger); a point control's starts at FIRST.
  turned(r0, deltaY) {
    const size = this.clay.radius;
    const factor = STEP ** (-THREE.MathUtils.clamp(deltaY, -300, 300) / 100);
    return Math.max((r0 > 0 ? r0 : FIRST * size) * factor, SMALLEST * size);
  }

  // The radius a new control gets here: the one chosen by [ ] or Alt+wheel over bare clay, else the controls'
  // usual one (their median: the preset's, or what "all radii" set).
  get newRadius() {
    if (this.chosen !== undefined && this.chosen !== null) return this.chosen;
    const radii = [...this.clay.radii].sort((a, b) => a - b);
    return radii.length ? Number(radii[Math.floor(radii.length / 2)]) : 0;
  }

  // A wheel turn (or a key) for the radius a new control gets; returns it.
  turnNew(deltaY) {
    this.chosen = Number(this.turned(this.newRadius, deltaY).toPrecision(5));
    this.turns += 1;
    return this.chosen;
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

const DISC_COLOUR = 0x3d7be0;
const DISC_SEGMENTS = 72;
const LABEL_OFFSET = [16, 18]; // px from the cursor to the label's corner
const EDGE_PX = 4; // the label keeps this far inside the view's edges

// The radius under the cursor: a disc on the clay (its rim drawn, filled faintly unless it is a new control's radius
// the person has not chosen) and a label by the cursor.
export class RadiusDisc {
  // clay: the Clay; radius: the RadiusBall (radii and the new control's); scene: where the disc is drawn; label: the
  // element the text goes in (placed over the view, by the cursor); onChange(): the disc changed
  constructor({ clay, radius, scene, label, onChange }) {
    this.clay = clay;
    this.onChange = onChange; // something drawn changed (the view draws again)
    this.radius = radius;
    this.label = label;
    this.disc = new THREE.Group();
    this.disc.name = 'radius-disc';
    const fill = new THREE.Mesh(new THREE.CircleGeometry(1, DISC_SEGMENTS), new THREE.MeshBasicMaterial({
      color: DISC_COLOUR, transparent: true, opacity: 0.2, depthTest: false, depthWrite: false,
      side: THREE.DoubleSide }));
    const rim = new THREE.LineLoop(new THREE.BufferGeometry().setFromPoints(Array.from({ length: DISC_SEGMENTS },
      (_, m) => new THREE.Vector3(Math.cos((2 * Math.PI * m) / DISC_SEGMENTS),
        Math.sin((2 * Math.PI * m) / DISC_SEGMENTS), 0))), new THREE.LineBasicMaterial({
      color: DISC_COLOUR, transparent: true, opacity: 0.9, depthTest: false }));
    this.fill = fill;
    for (const o of [fill, rim]) {
      o.renderOrder = 6;
      o.frustumCulled = false;
      this.disc.add(o);
    }
    this.disc.visible = false;
    scene.add(this.disc);
    this.of = null; // what it shows: an effective control's index, 'new' (a new control's radius), or null (hidden)
    this.value = 0; // the radius shown (model units)
    this.at = null; // [x, y] px in the view: the cursor
    this.z = new THREE.Vector3(0, 0, 1);
  }

  // Show radius of `of` (effective control j, or 'new') on the clay at `hit` ({point, normal} world, from the clay's
  // surfaceHit; null: at `centre` (world), facing `facing` (the camera's direction)), its label at `at` (px).
  show(of, { hit = null, centre = null, facing = null, at = null } = {}) {
    const r = of === 'new' ? this.radius.newRadius : this.radius.radiusOf(this.clay.originalOf(of));
    const where = hit ? hit.point : centre;
    this.of = of;
    this.value = r;
    this.at = at;
    this.disc.visible = r > 0 && !!where;
    if (this.disc.visible) {
      const normal = hit?.normal || (facing && facing.clone().negate()) || this.z;
      this.disc.position.copy(where);
      this.disc.quaternion.setFromUnitVectors(this.z, normal.clone().normalize());
      this.disc.scale.setScalar(r * this.clay.scale);
      // a new control's radius the person has not chosen (the controls' usual one, a quarter of the tube's size):
      // its rim alone, so that it does not cover the clay under the cursor
      this.fill.visible = of !== 'new' || this.radius.chosen !== null;
    }
    this.writeLabel(of, r, at);
    this.onChange?.();
  }

  hide() {
    this.of = null;
    this.label.hidden = true;
    if (!this.disc.visible) return;
    this.disc.visible = false;
    this.onChange?.();
  }

  writeLabel(of, r, at) {
    const size = 2 * this.clay.radius; // the clay's size: the diagonal of its bounds
    const who = of === 'new' ? 'new control' : `control ${this.clay.numberOf(this.clay.originalOf(of))}`;
    const text = r > 0 ? `radius ${Number(r.toPrecision(3))} \u00b7 ${(100 * r / size).toFixed(r / size < 0.1 ? 1 : 0)}%`
      + ` of the size \u00b7 ${who}` : `radius 0 (a point control) \u00b7 ${who}`;
    if (this.label.textContent !== text) this.label.textContent = text;
    this.label.hidden = !at;
    if (at) {
      const [x, y] = this.labelPlace(at);
      const place = `translate(${x.toFixed(0)}px, ${y.toFixed(0)}px)`;
      if (this.label.style.transform !== place) this.label.style.transform = place;
    }
  }

  // Where the label's corner goes for the cursor at `at`: below right of it, else (near the view's right or bottom
  // edge) on the cursor's other side, so that the whole label stays in the view.
  labelPlace(at) {
    const box = this.label.parentElement;
    const [w, h] = [this.label.offsetWidth, this.label.offsetHeight];
    let x = at[0] + LABEL_OFFSET[0];
    let y = at[1] + LABEL_OFFSET[1];
    if (box && x + w > box.clientWidth - EDGE_PX) x = Math.max(EDGE_PX, at[0] - LABEL_OFFSET[0] - w);
    if (box && y + h > box.clientHeight - EDGE_PX) y = Math.max(EDGE_PX, at[1] - LABEL_OFFSET[1] - h);
    return [x, y];
  }

  // The radius shown, for describe(): what it is of, its value, its share of the size, the label's text.
  describe() {
    return { of: this.of, shown: this.disc.visible, radius: this.value, share: this.value / (2 * this.clay.radius),
      filled: this.disc.visible && this.fill.visible,
      label: this.label.hidden ? null : this.label.textContent, world: this.disc.visible ? this.disc.scale.x : 0,
      centre: this.disc.visible ? this.disc.position.toArray() : null };
  }
}
