// Controls out of sight (the numbered ones): a marker at the view's edge for each, pointing the way to it, with its label; a click on
// the marker centres the view on that control (the camera keeps its direction and distance) and selects it.

import * as THREE from 'three';

const EDGE = 18; // px from the view's border to the marker's centre
const TOP = 46; // ... from its top, below the view's bar
const INSIDE = 1.0; // a control projected beyond this share of the half-view is out of sight

export const MARKER_CSS = `
.somview-marker { position: absolute; left: 0; top: 0; width: 26px; height: 26px; margin: -13px 0 0 -13px;
  border-radius: 13px; background: rgba(40,44,60,0.82); color: white; font-size: 10px; line-height: 26px;
  text-align: center; cursor: pointer; pointer-events: auto; user-select: none; }
.somview-marker::before { content: ''; position: absolute; left: 9px; top: -7px; border: 4px solid transparent;
  border-bottom: 6px solid rgba(40,44,60,0.82); transform-origin: 4px 20px; transform: rotate(var(--angle)); }
`;

export class Markers {
  // layer: the element the markers go in (over the canvas); onPick(j): a marker of effective control j was clicked
  constructor(layer, onPick) {
    this.layer = layer;
    this.onPick = onPick;
    this.divs = [];
    this.shown = []; // the effective indices with a marker now
    this.p = new THREE.Vector3(); // scratch, for update()
    this.to = new THREE.Vector3();
    this.forward = new THREE.Vector3();
  }

  // Place a marker for each control out of sight (`camera` the view's, `size` [w, h] px); returns their indices.
  update(clay, camera, size, labelOf) {
    const [w, h] = size;
    const p = this.p;
    const forward = camera.getWorldDirection(this.forward);
    const shown = [];
    for (let j = 0; j < clay.kEff; j++) {
      if (!clay.numbered(j)) continue; // ghosts and a stroke's later samples: their control's marker says it
      clay.controlWorld(j, p);
      const behind = camera.isPerspectiveCamera && this.to.subVectors(p, camera.position).dot(forward) <= 0;
      p.project(camera);
      if (!behind && Math.abs(p.x) <= INSIDE && Math.abs(p.y) <= INSIDE) continue;
      let x = behind ? -p.x : p.x; // behind the camera the projection is mirrored
      let y = behind ? -p.y : p.y;
      if (behind && Math.abs(x) < 1e-6 && Math.abs(y) < 1e-6) y = -1;
      // from the view's centre towards the control, to where that line meets the edge
      const ex = (w / 2 - EDGE) / (w / 2);
      const ey = (h / 2 - (y > 0 ? TOP : EDGE)) / (h / 2);
      const t = Math.min(ex / Math.max(Math.abs(x), 1e-9), ey / Math.max(Math.abs(y), 1e-9));
      x *= t;
      y *= t;
      const d = this.div(shown.length);
      const text = labelOf(j);
      if (d.textContent !== text) { // a marker's control changed: its label, index and title
        d.textContent = text;
        d.dataset.index = String(j);
        d.title = `Control ${text} is out of sight: click to bring it into view`;
      }
      const angle = `${Math.atan2(x * w, y * h).toFixed(3)}rad`; // 0: up
      const place = `translate(${(((x + 1) / 2) * w).toFixed(1)}px, ${(((1 - y) / 2) * h).toFixed(1)}px)`;
      if (d.somAngle !== angle) {
        d.somAngle = angle;
        d.style.setProperty('--angle', angle);
      }
      if (d.somPlace !== place) {
        d.somPlace = place;
        d.style.transform = place;
      }
      if (d.hidden) d.hidden = false;
      shown.push(j);
    }
    for (let m = shown.length; m < this.divs.length; m++) if (!this.divs[m].hidden) this.divs[m].hidden = true;
    this.shown = shown;
    return shown;
  }

  div(m) {
    while (this.divs.length <= m) {
      const d = document.createElement('div');
      d.className = 'somview-marker';
      d.addEventListener('pointerdown', (ev) => ev.stopPropagation());
      d.addEventListener('click', (ev) => {
        ev.stopPropagation();
        this.onPick(Number(d.dataset.index));
      });
      this.layer.appendChild(d);
      this.divs.push(d);
    }
    return this.divs[m];
  }
}
