// The view's camera: perspective or orthographic, orbited by the mouse (OrbitControls: drag to orbit, right-drag to
// pan), zoomed by the wheel towards the point under the cursor (in to 5% of the Fit distance, out freely), the six
// axis views and Fit. Nothing here refits by itself: a control out of sight gets a marker (markers.js).
//
// Model axes (clay.js): x forward, y to the left, z up; in three's world (y up) model (x, y, z) is (x, z, -y).

import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

const FIRST_LOOK = new THREE.Vector3(0.55, 0.55, 1).normalize(); // model (0.55, -1, 0.55), as the pictures
const MARGIN = 1.0; // the fitted sphere (around the clay and its controls) just fills the view
export const CLOSEST = 0.05; // the nearest the camera comes to its target, as a share of the Fit distance
const WHEEL_STEP = 0.9; // one wheel notch (100 px of deltaY) takes the camera to this share of its distance
const FOV = 45;
export const DEGREES_PER_PIXEL = 0.35; // an orbit drag turns the view this much a pixel, whatever the view's size
const ABOVE_GROUND = Math.PI / 2; // the orbit's largest polar angle: the camera stays above the ground plane

// The axis views: where the camera looks from (world direction from the target) and the key that picks each. Top
// and bottom lean a hair towards the right side so that the model's x runs left to right on screen.
export const VIEWS = {
  front: { from: [1, 0, 0], key: '1', label: 'Front', help: 'Look at the front (from +x)' },
  back: { from: [-1, 0, 0], key: '2', label: 'Back', help: 'Look at the back (from -x)' },
  left: { from: [0, 0, -1], key: '3', label: 'Left', help: 'Look at the left side (from +y)' },
  right: { from: [0, 0, 1], key: '4', label: 'Right', help: 'Look at the right side (from -y)' },
  top: { from: [0, 1, 1e-4], key: '5', label: 'Top', help: 'Look down from above (from +z)' },
  bottom: { from: [0, -1, 1e-4], key: '6', label: 'Bottom', help: 'Look up from below (from -z)' },
};

export class CameraRig {
  constructor(domElement) {
    this.perspective = new THREE.PerspectiveCamera(FOV, 1, 0.01, 100);
    this.orthographic = new THREE.OrthographicCamera(-1, 1, 1, -1, -100, 100);
    this.camera = this.perspective;
    this.orbit = new OrbitControls(this.camera, domElement);
    this.orbit.enableDamping = false;
    this.orbit.maxPolarAngle = ABOVE_GROUND; // orbiting never shows the underside (Bottom, key 6, looks from below)
    this.setOrbitSpeed(domElement.clientHeight || 600);
    this.orbit.enableZoom = false; // the wheel is ours: towards the cursor, and a control's radius over a control
    this.domElement = domElement;
    this.aspect = 1;
    this.fitDistance = 3; // the distance Fit chose last (what CLOSEST is a share of)
    this.stats = { fits: 0, zooms: 0, views: 0 };
    this.onChange = null; // the camera moved (the view redraws)
    this.orbit.addEventListener('change', () => this.changed());
  }

  get orthographicOn() {
    return this.camera === this.orthographic;
  }

  get target() {
    return this.orbit.target;
  }

  // How far the camera is from its target; for the orthographic camera, the perspective distance that shows as much.
  get distance() {
    const d = this.camera.position.distanceTo(this.orbit.target);
    return this.orthographicOn ? this.fitDistance / this.orthographic.zoom : d;
  }

  // OrbitControls turns 2 pi rotateSpeed over the view's height: DEGREES_PER_PIXEL at this height (a 180 px drag
  // turns about 63 degrees; 0.6 turned a 180 px drag about 90 in a 720 px view).
  setOrbitSpeed(height) {
    this.orbit.rotateSpeed = (DEGREES_PER_PIXEL * Math.max(1, height)) / 360;
  }

  changed() {
    // after a look from below, orbiting up past the ground plane brings the limit back
    const polar = this.orbit.getPolarAngle();
    if (this.orbit.maxPolarAngle > ABOVE_GROUND && polar <= ABOVE_GROUND + 1e-6) this.orbit.maxPolarAngle = ABOVE_GROUND;
    this.clip();
    this.onChange?.();
  }

  resize(width, height) {
    this.setOrbitSpeed(height);
    this.aspect = width / height;
    this.perspective.aspect = this.aspect;
    this.perspective.updateProjectionMatrix();
    this.shapeOrthographic();
  }

  // The orthographic frustum at zoom 1 shows what the perspective camera shows at the Fit distance.
  shapeOrthographic() {
    const h = this.fitDistance * Math.tan(THREE.MathUtils.degToRad(FOV) / 2);
    const o = this.orthographic;
    o.top = h;
    o.bottom = -h;
    o.left = -h * this.aspect;
    o.right = h * this.aspect;
    o.near = -100 * this.fitDistance; // what lies behind the camera's place is in view too: there is no perspective
    o.far = 100 * this.fitDistance;
    o.updateProjectionMatrix();
  }

  // Near and far planes that keep the clay in view from 5% of the Fit distance out to any distance.
  clip() {
    const p = this.perspective;
    const near = this.fitDistance * CLOSEST * 0.02;
    const far = Math.max(100 * this.fitDistance, 10 * p.position.distanceTo(this.orbit.target));
    if (p.near !== near || p.far !== far) {
      p.near = near;
      p.far = far;
      p.updateProjectionMatrix();
    }
  }

  // Perspective or orthographic, showing the same at the target.
  setOrthographic(on) {
    if (on === this.orthographicOn) return;
    const from = this.camera;
    const dir = from.position.clone().sub(this.orbit.target).normalize();
    const d = this.distance;
    const to = on ? this.orthographic : this.perspective;
    if (on) {
      to.zoom = this.fitDistance / d;
      this.shapeOrthographic();
      to.position.copy(from.position);
    } else {
      to.position.copy(this.orbit.target).addScaledVector(dir, d);
    }
    to.quaternion.copy(from.quaternion);
    this.camera = to;
    this.orbit.object = to;
    this.orbit.update();
    this.changed();
  }

  // Frame the clay for a new model: the first look's direction, then Fit.
  frame(bounds) {
    this.orbit.target.set(0, 0, 0);
    this.camera.position.copy(FIRST_LOOK).multiplyScalar(3);
    this.fit(bounds);
  }

  // Look at the sphere `bounds` ({center, radius}, world) from the current direction, filling the view.
  fit(bounds) {
    if (!bounds) return;
    const dir = this.camera.position.clone().sub(this.orbit.target);
    if (dir.lengthSq() < 1e-12) dir.copy(FIRST_LOOK);
    dir.normalize();
    const vfov = THREE.MathUtils.degToRad(FOV);
    const hfov = 2 * Math.atan(Math.tan(vfov / 2) * this.aspect);
    const distance = (MARGIN * bounds.radius) / Math.sin(Math.min(vfov, hfov) / 2);
    this.fitDistance = distance;
    this.orbit.target.copy(bounds.center);
    this.camera.position.copy(bounds.center).addScaledVector(dir, distance);
    this.orthographic.zoom = 1;
    this.shapeOrthographic();
    this.orbit.update();
    this.stats.fits += 1;
    this.changed();
  }

  // One of VIEWS: the camera looks at the target from that side, at the distance it had.
  look(name) {
    const view = VIEWS[name];
    if (!view) return false;
    const d = this.camera.position.distanceTo(this.orbit.target);
    const dir = new THREE.Vector3().fromArray(view.from).normalize();
    this.orbit.maxPolarAngle = dir.y < 0 ? Math.PI : ABOVE_GROUND; // a view key may look from below
    this.camera.position.copy(this.orbit.target).addScaledVector(dir, d);
    this.orbit.update();
    this.stats.views += 1;
    this.changed();
    return true;
  }

  // The camera's target to `world` (a control brought into view), keeping the direction and the distance.
  centreOn(world) {
    const shift = world.clone().sub(this.orbit.target);
    this.orbit.target.add(shift);
    this.camera.position.add(shift);
    this.orbit.update();
    this.changed();
  }

  // A wheel turn of `deltaY` with the pointer over `point` (world; the clay under the cursor, else the target's
  // plane): the camera comes closer to (or backs away from) that point, which stays under the cursor.
  zoomAt(deltaY, point) {
    const factor = WHEEL_STEP ** (-THREE.MathUtils.clamp(deltaY, -300, 300) / 100); // wheel up: closer
    const cam = this.camera;
    let s; // the share of every distance to `point` that remains
    if (this.orthographicOn) {
      const zoom = THREE.MathUtils.clamp(cam.zoom / factor, 1e-3, 1 / CLOSEST);
      s = cam.zoom / zoom;
      cam.zoom = zoom;
      cam.updateProjectionMatrix();
      const forward = cam.getWorldDirection(new THREE.Vector3());
      const off = point.clone().sub(this.orbit.target);
      off.addScaledVector(forward, -off.dot(forward)); // across the view only: depth does not show
      const shift = off.multiplyScalar(1 - s);
      this.orbit.target.add(shift);
      cam.position.add(shift);
    } else {
      const d = cam.position.distanceTo(this.orbit.target);
      const to = Math.max(d * factor, CLOSEST * this.fitDistance);
      s = to / d;
      cam.position.sub(point).multiplyScalar(s).add(point);
      this.orbit.target.sub(point).multiplyScalar(s).add(point);
    }
    this.orbit.update();
    this.stats.zooms += 1;
    this.changed();
    return s;
  }

  // The point on the plane through the target facing the camera under a ray (where a zoom aims off the clay).
  onTargetPlane(ray) {
    const normal = this.camera.getWorldDirection(new THREE.Vector3());
    const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(normal, this.orbit.target);
    return ray.intersectPlane(plane, new THREE.Vector3()) || this.orbit.target.clone();
  }

  describe() {
    return {
      camera: this.camera.position.toArray(), target: this.orbit.target.toArray(), distance: this.distance,
      fitDistance: this.fitDistance, projection: this.orthographicOn ? 'orthographic' : 'perspective',
      zoom: this.camera.zoom, polar: this.orbit.getPolarAngle(), maxPolar: this.orbit.maxPolarAngle,
    };
  }
}
