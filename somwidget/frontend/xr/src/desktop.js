// The page without a headset: a desktop preview. Orbit the camera with the mouse (left drag on empty space, wheel
// to zoom, right drag to pan); drag a control with the left button to move it.

import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

export class Desktop {
  constructor({ renderer, camera, clay, grabs }) {
    this.renderer = renderer;
    this.camera = camera;
    this.clay = clay;
    this.grabs = grabs;
    this.orbit = new OrbitControls(camera, renderer.domElement);
    this.orbit.enableDamping = false;
    this.raycaster = new THREE.Raycaster();
    this.drag = null;
    this.stats = { drags: 0, moves: 0 };
    const el = renderer.domElement;
    el.addEventListener('pointerdown', (ev) => this.down(ev), { capture: true });
    el.addEventListener('pointermove', (ev) => this.move(ev));
    el.addEventListener('pointerup', (ev) => this.up(ev));
    el.addEventListener('pointercancel', (ev) => this.up(ev));
  }

  frame() {
    this.clay.stage.position.set(0, 0, 0);
    this.clay.stage.rotation.set(0, 0, 0);
    this.clay.fit(1.0);
    this.camera.position.set(0.0, 0.9, 2.6);
    this.orbit.target.set(0, 0, 0);
    this.orbit.update();
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
    this.drag = { i, j, plane, offset: centre.clone().sub(onPlane), pointer: ev.pointerId };
    this.renderer.domElement.setPointerCapture?.(ev.pointerId);
    this.grabs.begin(i);
    this.stats.drags += 1;
  }

  move(ev) {
    if (this.renderer.xr.isPresenting) return;
    if (!this.drag) {
      const hit = this.clay.hitByRay(this.ray(ev), 1.2);
      this.clay.setHover(hit ? new Set([hit.index]) : new Set());
      this.renderer.domElement.style.cursor = hit ? 'grab' : '';
      return;
    }
    const p = this.ray(ev).ray.intersectPlane(this.drag.plane, new THREE.Vector3());
    if (!p) return;
    const world = p.add(this.drag.offset);
    this.grabs.update(this.drag.i, this.clay.toOriginal(this.drag.j, this.clay.worldToModel(world)));
    this.stats.moves += 1;
  }

  up(ev) {
    if (!this.drag) return;
    this.move(ev);
    this.grabs.end(this.drag.i);
    this.renderer.domElement.releasePointerCapture?.(this.drag.pointer);
    this.drag = null;
  }
}
