// Tethers: a thin line from each control left off the clay to its nearest node, so that a person sees which part of
// the clay it pulls and how far away it floats. A control is off the clay when its gap (the distance to its nearest
// node, as the panel's table shows it) is over the topology's `off_clay_gap` (3% of the clay's size, model/panel.py);
// a control on the clay gets no line. A stroke's samples count as one control: the line goes from the sample
// farthest from the clay.

import * as THREE from 'three';

const COLOUR = 0x7a4a00; // the amber-brown of the panel's mark on the gap of a control off the clay
const OPACITY = 0.7;

// The index of the node nearest to `p` among the first `count` of `positions` (a flat x, y, z array) and its distance.
export function nearestNode(positions, count, p) {
  let best = -1;
  let bestD2 = Infinity;
  for (let v = 0; v < count; v++) {
    const dx = positions[3 * v] - p[0];
    const dy = positions[3 * v + 1] - p[1];
    const dz = positions[3 * v + 2] - p[2];
    const d2 = dx * dx + dy * dy + dz * dz;
    if (d2 < bestD2) {
      bestD2 = d2;
      best = v;
    }
  }
  return [best, Math.sqrt(bestD2)];
}

export class Tethers {
  constructor() {
    this.capacity = 0;
    this.lines = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineDashedMaterial({
      color: COLOUR, transparent: true, opacity: OPACITY, depthTest: false, dashSize: 1, gapSize: 1 }));
    this.lines.name = 'control-tethers';
    this.lines.frustumCulled = false;
    this.lines.renderOrder = 4; // over the clay: a line into it stays visible
    this.limit = 0; // model units; 0: no lines
    this.shown = []; // {control, node, gap} of each line drawn, for describe()
  }

  // The gap beyond which a control is off the clay (model units; 0 or none: no lines).
  setLimit(gap) {
    this.limit = Number(gap) > 0 ? Number(gap) : 0;
  }

  // Lines for the controls off the clay: `runs` the index lists of the controls that act as one (each a control, or
  // a stroke's samples), `placeOf(i)` control i's model position, the nodes the first `count` of `positions`.
  update(positions, count, runs, placeOf) {
    const shown = [];
    if (this.limit > 0 && positions && count > 0) {
      for (const run of runs) {
        let far = null;
        for (const i of run) {
          const p = placeOf(i);
          if (!p) continue;
          const [node, gap] = nearestNode(positions, count, p);
          if (node >= 0 && (!far || gap > far.gap)) far = { control: i, node, gap, from: p };
        }
        if (far && far.gap > this.limit) shown.push(far);
      }
    }
    this.draw(shown, positions);
    this.shown = shown;
    return shown;
  }

  draw(shown, positions) {
    if (shown.length > this.capacity) {
      this.capacity = Math.max(2 * shown.length, 8);
      this.lines.geometry.dispose();
      this.lines.geometry = new THREE.BufferGeometry();
      this.lines.geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6 * this.capacity), 3));
    }
    const attr = this.lines.geometry.getAttribute('position');
    shown.forEach((s, m) => {
      attr.array.set(s.from, 6 * m);
      attr.array.set([positions[3 * s.node], positions[3 * s.node + 1], positions[3 * s.node + 2]], 6 * m + 3);
    });
    if (attr) attr.needsUpdate = true;
    this.lines.geometry.setDrawRange(0, 2 * shown.length);
    this.lines.visible = shown.length > 0;
    if (shown.length) {
      this.lines.computeLineDistances(); // dashed: a dash and a gap every off_clay_gap along the line
      this.lines.material.dashSize = this.limit * 0.6;
      this.lines.material.gapSize = this.limit * 0.4;
      this.lines.geometry.boundingSphere = null;
    }
  }

  // For describe(): each line drawn, from which control to which node, and the gap.
  describe() {
    return this.shown.map((s) => ({ control: s.control, node: s.node, gap: s.gap }));
  }
}
