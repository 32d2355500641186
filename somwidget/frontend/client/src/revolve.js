// The Revolve tool: a profile drawn beside the axis lathes the clay (Session.revolve). While the tool is on, the
// axis (the radial group's, else the model's z) is drawn through the clay, and the pointer draws on the plane that
// holds the axis and faces the camera, so the profile is read as distances from the axis and heights along it
// whatever the clay's surface under the pointer. The drawn profile goes out as a "revolve" intent (stroke.js).
// A press on a control lying on the axis (within AXIS_SNAP of the clay's size; the bowl's bottom control) of a clay
// that closes about it starts the profile there, on the axis, rather than moving the control (desktop.js).

import * as THREE from 'three';
import { AXIS_SNAP } from './protocol.js';

const AXIS_COLOUR = 0xd81b60;
const ON_POLE = 1e-3; // a node this share of the clay's size from the axis is the clay's pole

// The axis a revolve turns about: the radial group's ("radial-8-z" -> 2), else the model's z.
export function revolveAxis(group) {
  const m = /^radial-\d+-([xyz])/.exec(group || '');
  return m ? 'xyz'.indexOf(m[1]) : 2;
}

export class RevolveGuide {
  constructor(clay, rig, scene) {
    this.clay = clay;
    this.rig = rig;
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6), 3));
    this.line = new THREE.Line(g, new THREE.LineDashedMaterial({ color: AXIS_COLOUR, dashSize: 0.06, gapSize: 0.04,
      depthTest: false }));
    this.line.name = 'revolve-axis';
    this.line.renderOrder = 5;
    this.line.frustumCulled = false;
    this.line.visible = false;
    scene.add(this.line);
  }

  // The axis in world coordinates: {origin, direction (unit)}.
  axis() {
    const a = revolveAxis(this.clay.group);
    const unit = [0, 0, 0];
    unit[a] = 1;
    const origin = this.clay.modelToWorld([0, 0, 0]);
    const direction = this.clay.modelToWorld(unit).sub(origin).normalize();
    return { origin, direction };
  }

  // Show (or hide) the axis, through the clay's height and a little past it.
  show(on) {
    this.line.visible = Boolean(on);
    if (!on) return;
    const { origin, direction } = this.axis();
    const bounds = this.clay.worldBounds();
    const reach = bounds ? bounds.center.distanceTo(origin) + 1.2 * bounds.radius : 1;
    const pos = this.line.geometry.attributes.position;
    const a = origin.clone().addScaledVector(direction, -reach);
    const b = origin.clone().addScaledVector(direction, reach);
    pos.setXYZ(0, a.x, a.y, a.z);
    pos.setXYZ(1, b.x, b.y, b.z);
    pos.needsUpdate = true;
    this.line.computeLineDistances();
    this.line.material.dashSize = reach / 25;
    this.line.material.gapSize = reach / 40;
  }

  // Where a profile begun on control j starts: the axis's point (world) at the control's height when the control
  // lies within AXIS_SNAP of the clay's size of the axis and the drawn clay has a node on it (a pole, as the bowl's
  // bottom: the server puts a profile's end on the axis only then, model/revolving.py); else null (a press there
  // moves the control).
  startOn(j) {
    const centre = this.clay.controlWorld(j);
    if (!centre || !this.clay.lastFrame) return null;
    const a = revolveAxis(this.clay.group);
    const [b, c] = [(a + 1) % 3, (a + 2) % 3];
    const size = 2 * this.clay.radius;
    const p = this.clay.worldToModel(centre);
    if (Math.hypot(p[b], p[c]) > AXIS_SNAP * size) return null;
    const nodes = this.clay.positionAttr.array;
    let pole = false;
    for (let m = 0; m < nodes.length && !pole; m += 3) {
      pole = Math.hypot(nodes[m + b], nodes[m + c]) <= ON_POLE * size;
    }
    if (!pole) return null;
    const on = [0, 0, 0];
    on[a] = p[a];
    return this.clay.modelToWorld(on);
  }

  // Where the ray meets the plane that holds the axis and faces the camera (the camera's own plane when it looks
  // along the axis).
  pointOn(ray) {
    const { origin, direction } = this.axis();
    const view = this.rig.camera.getWorldDirection(new THREE.Vector3());
    const normal = view.clone().addScaledVector(direction, -view.dot(direction));
    if (normal.length() < 0.1) return this.rig.onTargetPlane(ray);
    const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(normal.normalize(), origin);
    return ray.intersectPlane(plane, new THREE.Vector3()) || this.rig.onTargetPlane(ray);
  }
}
