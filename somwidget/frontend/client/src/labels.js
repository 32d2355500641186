// The controls' numbers over the view: a label by each control a person placed (its number stays with it while
// others come and go: its stable id; a symmetric copy, a ghost, and a stroke's later samples carry none), the held
// one red, one the clay hides dimmed (a click on it selects the control: its handle is drawn over the clay), and a
// marker at the view's edge for each numbered control out of sight (markers.js).

import * as THREE from 'three';
import { MARKER_CSS, Markers } from './markers.js';
import { hidesControl } from './picking.js';

const OCCLUSION_MS = 300; // labels of controls hidden by the clay are dimmed, checked this often at most
const OCCLUSION_BUDGET = 400000; // ... while controls x triangles stays under this (one to six rays a control)

export const LABEL_CSS = `
.somview-labels { position: absolute; inset: 0; pointer-events: none; overflow: hidden; }
.somview-label { position: absolute; left: 0; top: 0; font-size: 11px; line-height: 1;
  padding: 1px 3px; border-radius: 3px; background: rgba(255,255,255,0.8); color: #222; white-space: nowrap; }
.somview-label.held { background: #d32f2f; color: white; }
.somview-label.behind { opacity: 0.4; pointer-events: auto; cursor: pointer; }
${MARKER_CSS}`;

// Control i's number: its stable id (a stroke's sample: its stroke's).
export function labelOf(clay, i) {
  return String(clay.numberOf(i));
}

export class ControlLabels {
  // clay: the Clay; display: the Display (labels on or off); onPick(j): a dimmed label was clicked; onPress(j, ev):
  // a dimmed label was pressed; onMarker(j): a marker was clicked
  constructor({ clay, display, onPick, onPress, onMarker }) {
    this.clay = clay;
    this.display = display;
    this.onPick = onPick;
    this.onPress = onPress;
    this.layer = document.createElement('div');
    this.layer.className = 'somview-labels';
    this.divs = [];
    this.markers = new Markers(this.layer, onMarker);
    this.occluded = new Set(); // effective controls the clay hides from the camera
    this.ray = new THREE.Raycaster();
    this.lastOcclusion = 0;
    this.again = false; // the occlusion is to be looked at again (what is drawn may have changed)
    this.p = new THREE.Vector3();
  }

  // Whether the labels want a drawing now (to look again which controls the clay hides).
  due(now) {
    return this.again && now - this.lastOcclusion >= OCCLUSION_MS;
  }

  // Place the labels and markers for `camera` over a view of `size` [w, h] px.
  update(camera, size) {
    const clay = this.clay;
    while (this.divs.length < clay.kEff) this.divs.push(this.div(this.divs.length));
    const [w, h] = size; // kept by the view's resize(): reading the layout here would force one every frame
    const p = this.p;
    camera.updateMatrixWorld();
    this.updateOcclusion(camera);
    const shown = this.display.settings.labels;
    for (let j = 0; j < this.divs.length; j++) {
      const d = this.divs[j];
      if (j >= clay.kEff || !shown || !clay.numbered(j)) { // a ghost, a stroke's later sample: not numbered
        if (!d.hidden) d.hidden = true;
        continue;
      }
      const i = clay.originalOf(j);
      const text = labelOf(clay, i);
      if (d.textContent !== text) d.textContent = text;
      clay.controlWorld(j, p);
      p.project(camera);
      const out = p.z > 1 || Math.abs(p.x) > 1 || Math.abs(p.y) > 1; // out of sight: a marker instead
      if (d.hidden !== out) d.hidden = out;
      // a transform moves the label without a new layout of the page; only what changed is written
      const place = `translate(${(((p.x + 1) / 2) * w).toFixed(1)}px, ${(((1 - p.y) / 2) * h).toFixed(1)}px) `
        + 'translate(-50%, -130%)';
      if (d.somPlace !== place) {
        d.somPlace = place;
        d.style.transform = place;
      }
      const held = clay.held.has(i) || clay.local.has(i);
      if (d.classList.contains('held') !== held) d.classList.toggle('held', held);
      const holder = clay.local.has(i) ? '' : clay.holders.get(i) || ''; // another hand's: in its colour (presence.js)
      if (d.somHolder !== holder) {
        d.somHolder = holder;
        d.style.background = holder;
      }
      const behind = this.occluded.has(j);
      if (d.classList.contains('behind') !== behind) d.classList.toggle('behind', behind);
    }
    this.markers.update(clay, camera, size, (j) => labelOf(clay, clay.originalOf(j)));
  }

  // The label of effective control j: the dimmed label of a control behind the clay takes a press, which drags the
  // control as a press on its sphere would (onPress), and a click, which selects it, so it can be moved by its
  // handle; neither turns the view.
  div(j) {
    const d = document.createElement('div');
    d.className = 'somview-label';
    d.addEventListener('pointerdown', (ev) => {
      ev.stopPropagation();
      if (d.classList.contains('behind')) this.onPress?.(j, ev);
    });
    d.addEventListener('click', (ev) => {
      ev.stopPropagation();
      this.onPick(j);
    });
    this.layer.appendChild(d);
    return d;
  }

  // Which controls the clay hides from the camera (their labels dimmed): one ray each, a few times a second, on a
  // clay small enough for it.
  updateOcclusion(camera) {
    const now = performance.now();
    if (now - this.lastOcclusion < OCCLUSION_MS) {
      this.again = true;
      return;
    }
    this.lastOcclusion = now;
    this.again = false;
    const clay = this.clay;
    const triangles = (clay.topology?.triangles.length ?? 0) / 3;
    this.occluded = new Set();
    if (!clay.surface || triangles * clay.kEff > OCCLUSION_BUDGET) return;
    for (let j = 0; j < clay.kEff; j++) if (hidesControl(clay, j, camera, this.ray)) this.occluded.add(j);
  }

  // For describe(): the labels shown (their text), the controls the clay hides, the markers' labels.
  describe() {
    const clay = this.clay;
    return { labels: this.divs.filter((d) => !d.hidden).map((d) => d.textContent), behind: [...this.occluded],
      markers: this.markers.shown.map((j) => labelOf(clay, clay.originalOf(j))) };
  }
}
