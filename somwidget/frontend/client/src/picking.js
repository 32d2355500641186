// Which control a pointer, a ray or a hand is on (clay.js draws them): the controls a ray passes within their pick
// radius (at least PICKED_PX on screen where the view measures pixels, so a small control is taken beside it too),
// whether the clay hides a control from the camera, the first control a ray meets, the one nearest a hand.

import * as THREE from 'three';

export const PICKED_PX = { control: 14, ghost: 9 }; // the smallest radius a press or hover takes a control (a ghost)
// within, in pixels

// The effective controls of `clay` a ray passes by, each within its pick radius (its drawn sphere padded by `pad`),
// as {index, along (the ray's length to the point nearest the centre), off (the ray's distance from the centre),
// drawn (world radius), reach (pick radius), ghost, point (world centre)}.
export function controlsAlong(clay, raycaster, pad = 1.5) {
  const out = [];
  const ray = raycaster.ray;
  const w = new THREE.Vector3();
  for (let j = 0; j < clay.kEff; j++) {
    const m = clay.controlAnchors[j];
    if (m.userData.quiet) continue; // a stroke's copy, drawn as a line: not taken
    clay.controlWorld(j, w);
    const along = w.clone().sub(ray.origin).dot(ray.direction);
    if (along < 0) continue;
    const off = ray.at(along, new THREE.Vector3()).distanceTo(w);
    const drawn = m.scale.x * clay.scale;
    const px = clay.pixelSize ? clay.pixelSize(w) : 0;
    const reach = Math.max(drawn * pad, px * (m.userData.mirror ? PICKED_PX.ghost : PICKED_PX.control));
    if (off <= reach) out.push({ index: j, along, off, drawn, reach, ghost: !!m.userData.mirror, point: w.clone() });
  }
  return out;
}

// Whether the clay hides effective control j from `camera`: no part of its sphere as drawn shows, i.e. the line of
// sight to each of five points of it (its centre, the points `reach` x its radius to the camera's left, right, up
// and down, and towards the camera) meets the clay before it. A control lying on the clay shows (also on the clay's
// outline, where the clay covers half its sphere), one behind the clay does not.
export function hidesControl(clay, j, camera, raycaster = new THREE.Raycaster(), reach = 0.8) {
  const c = clay.controlWorld(j);
  if (!c || !clay.surface) return false;
  const r = reach * clay.controlAnchors[j].scale.x * clay.scale;
  camera.updateMatrixWorld();
  const e = camera.matrixWorld.elements; // the camera's right, up and backward axes, in world units
  const sides = [[0, 0, 0], [e[0], e[1], e[2]], [-e[0], -e[1], -e[2]], [e[4], e[5], e[6]], [-e[4], -e[5], -e[6]],
    [e[8], e[9], e[10]]];
  const point = new THREE.Vector3();
  const eye = new THREE.Vector3();
  const dir = new THREE.Vector3();
  for (const [x, y, z] of sides) {
    point.set(x, y, z).normalize().multiplyScalar(r).add(c);
    if (camera.isOrthographicCamera) {
      eye.copy(point).addScaledVector(camera.getWorldDirection(dir), -20 * clay.worldRadius);
    } else {
      camera.getWorldPosition(eye);
    }
    const far = eye.distanceTo(point);
    raycaster.set(eye, dir.subVectors(point, eye).normalize());
    const hit = clay.surfaceHit(raycaster);
    if (!hit || hit.distance >= far - 0.05 * r) return false; // this part of it shows
  }
  return true;
}

// The effective control a ray meets first (spheres padded by `pad` x their radius): {index, distance, point} or null.
export function firstControl(clay, raycaster, pad = 1.5) {
  let best = null;
  for (const c of controlsAlong(clay, raycaster, pad)) {
    const distance = c.along - Math.sqrt(Math.max(c.reach * c.reach - c.off * c.off, 0));
    if (!best || distance < best.distance) best = { index: c.index, distance, point: c.point };
  }
  return best;
}

// The effective control nearest to a world point, within maxDistance (world units): {index, distance} or null.
export function nearestControl(clay, worldPoint, maxDistance) {
  let best = null;
  const w = new THREE.Vector3();
  for (let j = 0; j < clay.kEff; j++) {
    if (clay.controlAnchors[j]?.userData.quiet) continue;
    clay.controlWorld(j, w);
    const d = w.distanceTo(worldPoint);
    if (d <= maxDistance && (!best || d < best.distance)) best = { index: j, distance: d };
  }
  return best;
}
