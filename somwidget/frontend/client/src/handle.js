// The selected control's three-axis handle, for exact moves: drag an arrow to move the control along that model axis
// (x red, y green, z blue), a square to move it in that plane. A click on a control selects it, a click on empty
// space or Escape lets it go. The drag is a grab to its release, as a drag of the sphere is (one undo step).

import * as THREE from 'three';
import { TransformControls } from 'three/examples/jsm/controls/TransformControls.js';

export class Handle {
  constructor({ rig, clay, grabs, scene, domElement, onChange }) {
    this.rig = rig;
    this.clay = clay;
    this.grabs = grabs;
    this.onChange = onChange;
    this.selected = null; // the effective index of the selected control
    this.proxy = new THREE.Object3D(); // where the handle sits: in the model's frame, so its axes are the model's
    this.proxy.name = 'handle-anchor';
    this.controls = new TransformControls(rig.camera, domElement);
    this.controls.setSpace('local');
    this.controls.setSize(0.9);
    this.helper = this.controls.getHelper();
    this.helper.name = 'control-handle';
    scene.add(this.helper);
    this.stats = { moves: 0 };
    this.controls.addEventListener('dragging-changed', (ev) => this.dragging(ev.value));
    this.controls.addEventListener('objectChange', () => this.moved());
    this.controls.addEventListener('change', () => this.onChange?.());
  }

  // The handle takes this press (the pointer is over one of its arrows or squares; its centre is the sphere's).
  wants() {
    const axis = this.controls.axis;
    return this.selected !== null && axis !== null && axis !== 'XYZ' && this.controls.enabled;
  }

  get held() {
    return this.controls.dragging;
  }

  select(j) {
    if (j === this.selected) return;
    if (this.held) return;
    this.selected = j;
    if (j === null || j >= this.clay.kEff) {
      this.selected = null;
      this.controls.detach();
      this.proxy.removeFromParent();
    } else {
      this.clay.content.add(this.proxy);
      this.follow();
      this.controls.attach(this.proxy);
    }
    this.onChange?.();
  }

  // The handle at its control (not while it is dragged: the drag moves the control); a control gone lets go.
  follow() {
    if (this.selected === null) return;
    if (this.selected >= this.clay.kEff) {
      this.select(null);
      return;
    }
    if (this.held) return;
    const m = this.clay.controlAnchors[this.selected];
    if (m && !this.proxy.position.equals(m.position)) this.proxy.position.copy(m.position);
  }

  dragging(on) {
    this.rig.orbit.enabled = !on;
    const j = this.selected;
    if (j === null) return;
    const i = this.clay.originalOf(j);
    if (on) {
      this.drag = { i, copy: this.clay.copyOf(j) };
      this.grabs.begin(i);
    } else if (this.drag) {
      this.grabs.end(this.drag.i);
      this.drag = null;
    }
  }

  moved() {
    if (!this.drag) return;
    const p = this.proxy.position;
    this.grabs.update(this.drag.i, this.clay.unmap(this.drag.copy, [p.x, p.y, p.z])); // a copy's point, mapped back
    this.stats.moves += 1;
  }

  // A point on an axis's arrow (axis 'X', 'Y' or 'Z': the model's), in page pixels: where a person presses to
  // drag along it (read-only, for tests and the console); null with nothing selected.
  axisPoint(axis, camera, rect) {
    if (this.selected === null) return null;
    this.helper.updateMatrixWorld(true);
    const gizmo = this.helper.children.find((c) => c.isTransformControlsGizmo);
    const arrow = gizmo?.gizmo.translate.getObjectByName(axis); // scaled to keep its size on screen
    if (!arrow) return null;
    const unit = new THREE.Vector3(...{ X: [1, 0, 0], Y: [0, 1, 0], Z: [0, 0, 1] }[axis]);
    const centre = this.proxy.getWorldPosition(new THREE.Vector3());
    const p = unit.transformDirection(this.proxy.matrixWorld).multiplyScalar(0.45 * arrow.getWorldScale(
      new THREE.Vector3()).x).add(centre).project(camera);
    return [rect.left + ((p.x + 1) / 2) * rect.width, rect.top + ((1 - p.y) / 2) * rect.height];
  }
}
