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

// Whether the clay hides effective control j from `camera`: the line of sight to its centre meets the clay more than
// `slack` x its drawn radius before it (a control lying on the surface shows, one behind the clay does not).
export function hidesControl(clay, j, camera, slack = 1.0, raycaster = new THREE.Raycaster()) {
  const c = clay.controlWorld(j);
  if (!c || !clay.surface) return false;
  const eye = camera.isOrthographicCamera
    ? c.clone().addScaledVector(camera.getWorldDirection(new THREE.Vector3()), -20 * clay.worldRadius)
    : camera.getWorldPosition(new THREE.Vector3());
  const far = eye.distanceTo(c);
  raycaster.set(eye, c.clone().sub(eye).normalize());
  const hit = clay.surfaceHit(raycaster);
  return !!hit && hit.distance < far - slack * clay.controlAnchors[j].scale.x * clay.scale;
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
    clay.controlWorld(j, w);
    const d = w.distanceTo(worldPoint);
    if (d <= maxDistance && (!best || d < best.distance)) best = { index: j, distance: d };
  }
  return best;
}
