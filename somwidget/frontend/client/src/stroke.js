// Drawing a stroke: a polyline drawn by the mouse (on the clay, or on the view plane off it) or by a hand in the
// headset, shown as it is drawn and sent on release as one control (the server samples it evenly; its samples act
// as one). Points come in world coordinates and go out in the model's.

import * as THREE from 'three';
import { MAX_STROKE_POINTS, intents } from './protocol.js';

const MOST_DRAWN = 2048; // points the preview holds
const SENT_POINTS = Math.min(32, MAX_STROKE_POINTS); // a stroke goes out as at most this many points, evenly spaced
const SPACING = 0.01; // a new point comes at least this share of the clay's world radius from the last

// `points` (model, [x, y, z] each) evenly resampled to at most `most` along their length, to 5 significant digits.
export function resampled(points, most = SENT_POINTS) {
  const along = [0];
  for (let m = 1; m < points.length; m++) {
    along.push(along[m - 1] + Math.hypot(...points[m].map((v, a) => v - points[m - 1][a])));
  }
  const total = along[along.length - 1];
  const count = Math.min(most, points.length);
  const out = [];
  let m = 0;
  for (let n = 0; n < count; n++) {
    const at = count > 1 ? (total * n) / (count - 1) : 0;
    while (m < points.length - 2 && along[m + 1] < at) m++;
    const span = along[m + 1] - along[m];
    const t = span > 0 ? Math.min(1, Math.max(0, (at - along[m]) / span)) : 0;
    out.push(points[m].map((v, a) => Number((v + t * (points[m + 1][a] - v)).toPrecision(5))));
  }
  return out;
}

export class StrokeDraw {
  constructor(clay, link, scene) {
    this.clay = clay;
    this.link = link;
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(3 * MOST_DRAWN), 3));
    g.setDrawRange(0, 0);
    this.line = new THREE.Line(g, new THREE.LineBasicMaterial({ color: 0xd81b60, depthTest: false }));
    this.line.name = 'stroke-drawn';
    this.line.renderOrder = 5;
    this.line.frustumCulled = false;
    this.line.visible = false;
    scene.add(this.line);
    this.points = null; // world points of the stroke being drawn
    this.sent = 0;
    this.onChange = null;
  }

  get drawing() {
    return this.points !== null;
  }

  begin(world) {
    this.points = [];
    this.line.visible = true;
    this.add(world);
  }

  add(world) {
    if (!this.points || this.points.length >= MOST_DRAWN) return;
    const last = this.points[this.points.length - 1];
    if (last && last.distanceTo(world) < SPACING * this.clay.worldRadius) return;
    this.points.push(world.clone());
    this.line.geometry.attributes.position.setXYZ(this.points.length - 1, world.x, world.y, world.z);
    this.line.geometry.attributes.position.needsUpdate = true;
    this.line.geometry.setDrawRange(0, this.points.length);
    this.onChange?.();
  }

  // The stroke ends: sent as one control (radius: model units, or undefined for the preset's) when it has a length,
  // or with `kind` 'revolve' as the profile that lathes the clay (revolve.js); returns whether it went.
  end(radius, kind = 'stroke') {
    const points = this.points;
    this.cancel();
    if (!points || points.length < 2) return false;
    const model = points.map((p) => this.clay.worldToModel(p));
    const out = resampled(model);
    const sent = this.link.send(intents[kind](out, radius === undefined ? undefined : Number(radius.toPrecision(5))));
    if (sent) this.sent += 1;
    return sent;
  }

  cancel() {
    this.points = null;
    this.line.visible = false;
    this.line.geometry.setDrawRange(0, 0);
    this.onChange?.();
  }
}
