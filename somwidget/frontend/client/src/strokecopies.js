// A stroke's symmetric copies drawn quietly: a thin faint line through each copy's samples instead of a ghost
// sphere per sample (a revolved profile of 8 samples under 16 copies drew 120 spheres that crowded the view). The
// stroke itself keeps its spheres; its copies take no pointer (picking.js passes them by).

import * as THREE from 'three';

const OPACITY = 0.45;

export class StrokeCopies {
  constructor() {
    this.capacity = 0;
    this.lines = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({
      transparent: true, opacity: OPACITY, depthWrite: false, vertexColors: true }));
    this.lines.name = 'stroke-copies';
    this.lines.frustumCulled = false;
    this.count = 0; // the copies drawn as lines
  }

  // The lines of `clay`'s stroke copies, where its control anchors lie now, each in its stroke's colour.
  update(clay) {
    const segments = [];
    const colours = [];
    let count = 0;
    for (let j = clay.k; j < clay.kEff; j++) {
      const i = clay.originalOf(j);
      const run = clay.runOf(i);
      if (run[0] !== i || run.length < 2) continue; // one line a copy of a stroke, from its first sample
      const g = clay.copyOf(j);
      count += 1;
      for (let m = 0; m + 1 < run.length; m++) {
        const a = clay.controlAnchors[run[m] + g * clay.k];
        const b = clay.controlAnchors[run[m + 1] + g * clay.k];
        if (!a || !b) continue;
        segments.push(a.position.x, a.position.y, a.position.z, b.position.x, b.position.y, b.position.z);
        const c = a.userData.base || a.userData.colour;
        colours.push(c.r, c.g, c.b, c.r, c.g, c.b);
      }
    }
    this.count = count;
    const geometry = this.lines.geometry;
    if (segments.length > this.capacity) {
      this.capacity = Math.max(segments.length, 2 * this.capacity);
      geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(this.capacity), 3));
      geometry.setAttribute('color', new THREE.BufferAttribute(new Float32Array(this.capacity), 3));
    }
    if (this.capacity) {
      geometry.attributes.position.array.set(segments);
      geometry.attributes.color.array.set(colours);
      geometry.attributes.position.needsUpdate = true;
      geometry.attributes.color.needsUpdate = true;
    }
    geometry.setDrawRange(0, segments.length / 3);
    this.lines.visible = segments.length > 0;
  }
}

// Whether effective control j of `clay` is a copy of a stroke's sample (drawn as part of a line, not a sphere).
export function strokeCopy(clay, j) {
  return j >= clay.k && clay.runOf(clay.originalOf(j)).length > 1;
}
