// Mouse and touch on a flat screen: orbit the camera (left drag on empty space), zoom (wheel), pan (right drag),
// and drag a control with the left button on the plane facing the camera; with Shift held the control moves
// along the model axis closest to the motion only. Fit to view frames the clay and every control.

import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

const VIEW_DIRECTION = new THREE.Vector3(0.55, 0.55, 1).normalize(); // first look: model (0.55, -1, 0.55), as pictures
const MARGIN = 1.0; // the fitted sphere (around the box of clay and controls) just fills the view
const INSIDE = 0.96; // a control projected beyond this share of the half-view is about to leave it

export class Desktop {
  constructor({ renderer, camera, clay, grabs, onDragStart, onDragEnd }) {
    this.renderer = renderer;
    this.camera = camera;
    this.clay = clay;
    this.grabs = grabs;
    this.onDragStart = onDragStart;
    this.onDragEnd = onDragEnd;
    this.orbit = new OrbitControls(camera, renderer.domElement);
    this.orbit.enableDamping = false;
    this.raycaster = new THREE.Raycaster();
    this.drag = null;
    this.stats = { drags: 0, moves: 0, fits: 0 };
    const el = renderer.domElement;
    el.addEventListener('pointerdown', (ev) => this.down(ev), { capture: true });
    el.addEventListener('pointermove', (ev) => this.move(ev));
    el.addEventListener('pointerup', (ev) => this.up(ev));
    el.addEventListener('pointercancel', (ev) => this.up(ev));
    el.addEventListener('pointerleave', () => this.clay.setHover(new Set()));
  }

  // A new model: unit scale at the origin, then fit the camera to it.
  frame() {
    this.clay.stage.position.set(0, 0, 0);
    this.clay.stage.rotation.set(0, 0, 0);
    this.clay.fit(1.0);
    this.orbit.target.set(0, 0, 0);
    this.camera.position.copy(VIEW_DIRECTION).multiplyScalar(3);
    this.fit();
  }

  // Look at the bounding sphere of the clay and its controls from the current direction, filling the view.
  fit() {
    const s = this.clay.worldBounds();
    if (!s) return;
    const dir = this.camera.position.clone().sub(this.orbit.target);
    if (dir.lengthSq() < 1e-12) dir.copy(VIEW_DIRECTION);
    dir.normalize();
    const vfov = THREE.MathUtils.degToRad(this.camera.fov);
    const hfov = 2 * Math.atan(Math.tan(vfov / 2) * this.camera.aspect);
    const distance = (MARGIN * s.radius) / Math.sin(Math.min(vfov, hfov) / 2);
    this.orbit.target.copy(s.center);
    this.camera.position.copy(s.center).addScaledVector(dir, distance);
    this.camera.near = Math.max(distance / 1000, 1e-4);
    this.camera.far = distance * 100;
    this.camera.updateProjectionMatrix();
    this.orbit.update();
    this.stats.fits += 1;
  }

  // Every control on screen? If one has left the view (or sits behind the camera), fit again; never mid-drag.
  keepControlsInView() {
    if (this.drag || this.clay.kEff === 0) return false;
    this.camera.updateMatrixWorld();
    const p = new THREE.Vector3();
    for (let j = 0; j < this.clay.kEff; j++) {
      this.clay.controlWorld(j, p);
      const behind = p.clone().sub(this.camera.position).dot(this.camera.getWorldDirection(new THREE.Vector3())) <= 0;
      p.project(this.camera);
      if (behind || Math.abs(p.x) > INSIDE || Math.abs(p.y) > INSIDE) {
        this.fit();
        return true;
      }
    }
    return false;
  }

  ray(ev) {
    const r = this.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((ev.clientX - r.left) / r.width) * 2 - 1, -((ev.clientY - r.top) / r.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    return this.raycaster;
  }

  down(ev) {
    if (ev.button !== 0 || this.renderer.xr.isPresenting) return;
    const hit = this.clay.hitByRay(this.ray(ev), 1.2);
    if (!hit) return;
    ev.stopImmediatePropagation(); // the orbit controls do not see this press
    ev.preventDefault();
    const j = hit.index;
    const i = this.clay.originalOf(j);
    const centre = this.clay.controlWorld(j);
    const normal = this.camera.getWorldDirection(new THREE.Vector3());
    const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(normal, centre);
    const onPlane = this.raycaster.ray.intersectPlane(plane, new THREE.Vector3()) || centre.clone();
    this.drag = { i, j, copy: this.clay.copyOf(j), plane, offset: centre.clone().sub(onPlane), pointer: ev.pointerId,
      start: this.clay.worldToModel(centre) };
    this.renderer.domElement.setPointerCapture?.(ev.pointerId);
    this.renderer.domElement.style.cursor = 'grabbing';
    this.grabs.begin(i);
    this.stats.drags += 1;
    this.onDragStart?.();
  }

  move(ev) {
    if (this.renderer.xr.isPresenting) return;
    if (!this.drag) {
      if (ev.buttons) return; // orbiting or panning
      const hit = this.clay.hitByRay(this.ray(ev), 1.2);
      this.clay.setHover(hit ? new Set([hit.index]) : new Set());
      this.renderer.domElement.style.cursor = hit ? 'grab' : '';
      return;
    }
    const p = this.ray(ev).ray.intersectPlane(this.drag.plane, new THREE.Vector3());
    if (!p) return;
    let model = this.clay.worldToModel(p.add(this.drag.offset));
    if (ev.shiftKey) { // along one axis: the one the hand moved along most
      const d = model.map((v, a) => v - this.drag.start[a]);
      const axis = d.reduce((best, v, a) => (Math.abs(v) > Math.abs(d[best]) ? a : best), 0);
      model = this.drag.start.map((v, a) => (a === axis ? v + d[a] : v));
    }
    this.grabs.update(this.drag.i, this.clay.unmap(this.drag.copy, model)); // a copy's point, mapped back
    this.stats.moves += 1;
  }

  up(ev) {
    if (!this.drag) return;
    this.move(ev);
    this.grabs.end(this.drag.i);
    this.renderer.domElement.releasePointerCapture?.(this.drag.pointer);
    this.renderer.domElement.style.cursor = '';
    this.drag = null;
    this.onDragEnd?.();
  }
}
