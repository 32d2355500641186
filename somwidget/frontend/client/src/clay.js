// The clay in three.js: the mesh (surface, lines or points) with its vertex colours, and the control objects.
//
// Scene graph: stage (placement in the room: position, yaw) > scaler (uniform scale) > frame (the model's z-up
// turned to three's y-up) > content (centred on the start mesh) > the meshes. Model coordinates are the session's
// own (x forward, y sideways, z up): `worldToModel` / `modelToWorld` convert.

import * as THREE from 'three';
import { StrokeCopies, strokeCopy } from './strokecopies.js';
import { Tethers } from './tethers.js';

const HELD = new THREE.Color(0xff2020);
const WIREFRAME_LIMIT = 16384; // display vertices above which a surface has no wireframe to show (display.js)
const THROUGH_OPACITY = 0.3; // a control hidden behind the clay is drawn this faintly through it
const LIGHT_SEGMENTS = 4096; // synapses above which moving clay on a software rasteriser shows the points alone
const WHITE = new THREE.Color(0xffffff);
const HOVER_LIGHTEN = 0.35; // a hovered control's colour moves this far towards white
const IDENTITY = [1, 0, 0, 0, 1, 0, 0, 0, 1];
const GHOST_SIZE = 0.6; // a symmetric copy (a ghost) is drawn this many times a control's size ...
const GHOST_OPACITY = 0.3; // ... and this faint
export const DRAWN_PX = { control: 6, ghost: 4 }; // the smallest radius a control (a ghost) is drawn at, in pixels

// A 3 x 3 map (row-major, 9 numbers) of a position p: M p, and its inverse (the transpose: the maps are orthogonal).
export const applyMap = (M, p) => [M[0] * p[0] + M[1] * p[1] + M[2] * p[2], M[3] * p[0] + M[4] * p[1] + M[5] * p[2],
  M[6] * p[0] + M[7] * p[1] + M[8] * p[2]];
export const applyInverse = (M, p) => [M[0] * p[0] + M[3] * p[1] + M[6] * p[2],
  M[1] * p[0] + M[4] * p[1] + M[7] * p[2], M[2] * p[0] + M[5] * p[1] + M[8] * p[2]];

// The symmetry group a server message names: {name, maps} (maps: 3 x 3 row-major, the identity first; effective
// control j is control j mod k under map floor(j / k)). A message without "group_maps" (an older server) has a
// mirror group at most: its "mirror_axes" make the one copy's map. null when the message says nothing of the group
// (a "controls" message of an older server).
export function groupOf(msg) {
  const maps = msg.group_maps;
  if (Array.isArray(maps) && maps.length) {
    const ok = (m) => Array.isArray(m) && m.length === 9 && m.every((v) => Number.isFinite(v));
    const name = typeof msg.group === 'string' ? msg.group : 'none';
    return { name, maps: maps.map((m) => (ok(m) ? [...m] : IDENTITY)) };
  }
  const axes = msg.mirror_axes;
  if (!Array.isArray(axes)) return msg.type === 'topology' ? { name: 'none', maps: [IDENTITY] } : null;
  const axis = axes.findIndex(Boolean);
  if (axis < 0) return { name: typeof msg.group === 'string' ? msg.group : 'none', maps: [IDENTITY] };
  const mirror = [0, 1, 2].flatMap((r) => [0, 1, 2].map((c) => (r === c ? (axes[r] ? -1 : 1) : 0)));
  return { name: typeof msg.group === 'string' ? msg.group : `mirror-${'xyz'[axis]}`, maps: [IDENTITY, mirror] };
}

// The box of the positions in `array` (x, y, z, x, ...; empty for none).
export function boxOf(array) {
  const box = new THREE.Box3();
  const v = new THREE.Vector3();
  for (let o = 0; o < array.length; o += 3) box.expandByPoint(v.set(array[o], array[o + 1], array[o + 2]));
  return box;
}

export class Clay {
  // software: the page draws with a software rasteriser, which pays for every triangle (coarser control spheres)
  constructor({ software = false } = {}) {
    this.stage = new THREE.Group();
    this.stage.name = 'stage';
    this.scaler = new THREE.Group();
    this.frame = new THREE.Group();
    this.frame.rotation.x = -Math.PI / 2; // model z (up) -> world y (up); model y -> world -z
    this.content = new THREE.Group();
    this.stage.add(this.scaler);
    this.scaler.add(this.frame);
    this.frame.add(this.content);
    this.topology = null;
    this.k = 0;
    this.kEff = 0;
    this.controlAnchors = []; // per effective control: its place and size (drawn by controlDraws)
    this.controlDraws = []; // the instanced spheres: originals, copies (the group's images of them)
    this.group = 'none'; // the symmetry group's spec ("none", "mirror-y", "radial-8-z", ...)
    this.groupMaps = [IDENTITY]; // its maps of a position (3 x 3 row-major), the identity first
    this.pendingGroup = null; // a group a "controls" message announced, in effect from the next frame
    this.local = new Map(); // original index -> [x, y, z] model position while this client drags it
    this.held = new Set(); // original indices held by any client (server's grabs)
    this.holders = new Map(); // original index -> its holder's colour ('#rrggbb'), for those other clients hold
    this.hover = new Set(); // effective indices hovered by an input
    this.radius = 1;
    this.controlRadius = 0.05;
    this.objects = [];
    this.lastFrame = null;
    this.sphere = new THREE.IcosahedronGeometry(1, software ? 2 : 4); // 320 or 5,120 triangles, smooth normals
    this.software = software;
    this.onChange = null; // called whenever something drawn changed
    this.segments = null;
    this.showSegments = true; // the mesh's edges drawn (display.js: the wireframe of a surface, a point display's lines)
    this.moving = false;
    this.controlIds = []; // each control's stable id, in index order (what intents name)
    this.radii = []; // each control's radius of influence (model units), from the topology and "controls" messages
    this.strokes = []; // the runs of controls that act as one (a stroke's samples)
    this.pixelSize = null; // (world point) => world units a screen pixel spans there (null: no floor, a headset)
    this.tethers = new Tethers(); // a line from each control off the clay to its nearest node
    this.content.add(this.tethers.lines);
    this.strokeCopies = new StrokeCopies(); // a stroke's copies: a line each, not spheres
    this.content.add(this.strokeCopies.lines);
  }

  get ready() {
    return this.topology !== null;
  }

  setTopology(t) {
    for (const o of this.objects) {
      this.content.remove(o);
      o.geometry?.dispose?.();
      o.material?.dispose?.();
    }
    this.objects = [];
    this.segments = null;
    this.k = 0;
    this.rebuildControls(0);
    this.local.clear();
    this.topology = t;
    this.pendingGroup = null;
    this.setGroup(groupOf(t));
    this.controlIds = t.control_ids || [];
    this.setRuns(t);
    const n = t.n_vertices;
    const pos = new THREE.BufferAttribute(new Float32Array(3 * n), 3);
    pos.setUsage(THREE.DynamicDrawUsage);
    const col = new THREE.BufferAttribute(new Uint8Array(3 * n), 3, true);
    col.setUsage(THREE.DynamicDrawUsage);
    this.positionAttr = pos;
    this.colourAttr = col;
    this.surface = null;
    const lines = t.display === 'lines';
    if (t.triangles.length) {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', pos);
      g.setAttribute('color', col);
      g.setIndex(new THREE.BufferAttribute(new Uint32Array(t.triangles), 1));
      const m = new THREE.Mesh(g, new THREE.MeshLambertMaterial({
        vertexColors: true, side: THREE.DoubleSide,
        transparent: lines, opacity: lines ? 0.55 : 1.0, depthWrite: !lines,
      }));
      m.name = 'clay-surface';
      this.surface = m;
      this.objects.push(m);
    }
    // the mesh's edges as lines: the synapses of a point display, the wireframe of a surface (not of a big one,
    // where thousands of lines are noise on screen and the costliest thing to draw)
    if (t.segments.length && (t.points || lines || n <= WIREFRAME_LIMIT)) {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', pos);
      g.setAttribute('color', col);
      g.setIndex(new THREE.BufferAttribute(new Uint32Array(t.segments), 1));
      const m = new THREE.LineSegments(g, new THREE.LineBasicMaterial(lines
        ? { vertexColors: true }
        : { color: 0x303040, transparent: true, opacity: t.points ? 0.3 : 0.35 }));
      m.name = 'clay-segments';
      this.segments = m;
      this.objects.push(m);
    }
    if (t.points) {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', pos);
      g.setAttribute('color', col);
      this.pointsMaterial = new THREE.PointsMaterial({ vertexColors: true, size: 0.01, sizeAttenuation: true });
      const m = new THREE.Points(g, this.pointsMaterial);
      m.name = 'clay-points';
      this.objects.push(m);
    } else {
      this.pointsMaterial = null;
    }
    for (const o of this.objects) {
      o.frustumCulled = false;
      this.content.add(o);
    }
    const lo = new THREE.Vector3().fromArray(t.bounds.min);
    const hi = new THREE.Vector3().fromArray(t.bounds.max);
    this.centre = lo.clone().add(hi).multiplyScalar(0.5);
    this.radius = Math.max(hi.distanceTo(lo) / 2, 1e-6);
    this.controlRadius = t.control_radius;
    this.tethers.setLimit(t.off_clay_gap);
    this.content.position.copy(this.centre).multiplyScalar(-1);
  }

  // Each control's radius and the strokes, from a topology or "controls" message (an older server sends none).
  setRuns(msg) {
    if (Array.isArray(msg.radii)) this.radii = msg.radii.map(Number);
    if (Array.isArray(msg.strokes)) this.strokes = msg.strokes.map(Number);
  }

  // Whether effective control j carries a number: a control a person placed (not a ghost, a symmetric copy; of a
  // stroke, its first sample).
  numbered(j) {
    return j < this.k && this.runOf(j)[0] === j;
  }

  // Control i's number, as the views and the controls table show it: its stable id, a stroke's sample its stroke's
  // (the first sample's; the later samples' ids, from 2^30 on, are never shown).
  numberOf(i) {
    const first = this.runOf(i)[0];
    return this.controlIds[first] ?? first;
  }

  // The indices of the controls that act as one with control i (a stroke's samples; i alone otherwise).
  runOf(i) {
    let first = 0;
    for (const n of this.strokes) {
      if (i < first + n) return Array.from({ length: n }, (_, m) => first + m);
      first += n;
    }
    return [i];
  }

  setGroup(g) {
    if (!g) return;
    this.group = g.name;
    this.groupMaps = g.maps;
  }

  // A "controls" message (the ids, and the group from a server that sends it): it comes just before the first frame
  // whose controls changed, so the group takes effect with the next frame drawn.
  announceGroup(msg) {
    const g = groupOf(msg);
    if (g) this.pendingGroup = g;
  }

  // While the clay moves (training, or a drag) on a software rasteriser, a point display with many synapses draws
  // its points only: thousands of lines are what such a rasteriser draws slowest, on the cores that also train, and
  // they would halve the frames drawn. The lines come back when the clay is still.
  setMoving(moving) {
    this.moving = moving;
    const many = this.topology?.points && this.topology.segments.length / 2 > LIGHT_SEGMENTS;
    const visible = this.showSegments && !(moving && this.software && many);
    if (this.segments && this.segments.visible !== visible) {
      this.segments.visible = visible;
      this.onChange?.();
    }
  }

  // Scale so that the model's bounding radius is `worldRadius` (metres in XR, scene units on the desktop).
  fit(worldRadius) {
    this.setScale(worldRadius / this.radius);
  }

  setScale(s) {
    this.scaler.scale.setScalar(s);
    if (this.pointsMaterial) this.pointsMaterial.size = 0.3 * this.controlRadius * s;
  }

  get scale() {
    return this.scaler.scale.x;
  }

  get worldRadius() {
    return this.radius * this.scale;
  }

  get worldControlRadius() {
    return this.controlRadius * this.scale;
  }

  applyFrame(f) {
    if (!this.topology || f.n !== this.topology.n_vertices || f.generation !== this.topology.generation) return false;
    this.positionAttr.array.set(f.positions);
    this.positionAttr.needsUpdate = true;
    this.colourAttr.array.set(f.colours);
    this.colourAttr.needsUpdate = true;
    if (this.surface) this.surface.geometry.computeVertexNormals();
    for (const o of this.objects) o.geometry.boundingSphere = null; // raycasts take the clay as it is now
    if (this.pendingGroup) {
      this.setGroup(this.pendingGroup);
      this.pendingGroup = null;
    }
    if (f.kEff !== this.kEff || f.k !== this.k) {
      this.k = f.k;
      this.rebuildControls(f.kEff);
    }
    const c = new THREE.Color();
    for (let j = 0; j < this.kEff; j++) {
      const m = this.controlAnchors[j];
      m.userData.base = c.setRGB(f.controlColours[3 * j] / 255, f.controlColours[3 * j + 1] / 255,
        f.controlColours[3 * j + 2] / 255).clone();
      m.userData.server = [f.controlPositions[3 * j], f.controlPositions[3 * j + 1], f.controlPositions[3 * j + 2]];
      m.userData.mirror = j >= this.k; // a copy (the group's image of a control), drawn translucent
      m.userData.copy = this.copyOf(j); // the map that makes it: 0 for an original
      m.userData.original = this.originalOf(j);
      m.userData.quiet = strokeCopy(this, j); // drawn as part of its copy's line (strokecopies.js)
    }
    this.lastFrame = f;
    this.refreshControls();
    return true;
  }

  // The control spheres: an anchor (Object3D) per effective control carries its place and size, and two instanced
  // meshes draw them, the originals solid and the copies (ghosts) smaller and faint (two draw calls whatever the
  // count). A control is never drawn smaller than DRAWN_PX on screen (`pixelSize`).
  rebuildControls(kEff) {
    for (const m of this.controlAnchors) this.content.remove(m);
    for (const d of this.controlDraws) {
      const through = d.userData.through;
      this.content.remove(d, through);
      through.material.dispose();
      d.material.dispose();
      d.dispose();
    }
    this.controlAnchors = [];
    for (let j = 0; j < kEff; j++) {
      const m = new THREE.Object3D();
      m.name = `control-${j}`;
      m.userData.index = j;
      m.userData.colour = new THREE.Color();
      this.controlAnchors.push(m);
      this.content.add(m);
    }
    const draw = (count, ghost) => {
      const d = new THREE.InstancedMesh(this.sphere, new THREE.MeshLambertMaterial({
        transparent: ghost, opacity: ghost ? GHOST_OPACITY : 1.0, depthWrite: !ghost }), Math.max(count, 1));
      d.count = count;
      d.name = ghost ? 'control-mirrors' : 'control-spheres';
      d.frustumCulled = false;
      d.setColorAt(0, HELD);
      // the same spheres once more, drawn only where the clay hides them: faintly, through it
      const through = new THREE.InstancedMesh(this.sphere, new THREE.MeshBasicMaterial({
        transparent: true, opacity: THROUGH_OPACITY, depthWrite: false, depthFunc: THREE.GreaterDepth }), 1);
      through.instanceMatrix = d.instanceMatrix;
      through.instanceColor = d.instanceColor;
      through.count = count;
      through.name = `${d.name}-through`;
      through.frustumCulled = false;
      through.renderOrder = 3; // after the clay and the spheres
      d.userData.through = through;
      this.content.add(d, through);
      return d;
    };
    this.controlDraws = [draw(this.k, false), draw(kEff - this.k, true)];
    this.kEff = kEff;
  }

  // Positions, colours and highlights of the control spheres (local drags win over the server's positions).
  refreshControls() {
    this.onChange?.();
    for (const m of this.controlAnchors) {
      const j = m.userData.index;
      const i = m.userData.original;
      let p = m.userData.server;
      if (this.local.has(i)) p = this.imageOf(m.userData.copy, this.local.get(i)); // the local drag, echoed
      if (p) m.position.set(p[0], p[1], p[2]);
      const held = this.held.has(i) || this.local.has(i);
      const hovered = this.hover.has(j);
      const other = this.local.has(i) ? undefined : this.holders.get(i); // another hand's: drawn in its colour
      const c = other ? m.userData.colour.set(other) : m.userData.colour.copy(held ? HELD : (m.userData.base || HELD));
      if (hovered && !held) c.lerp(WHITE, HOVER_LIGHTEN);
      const ghost = m.userData.mirror;
      const grow = (held ? (ghost ? 1.35 : 1.6) : hovered ? 1.3 : 1.0) * (ghost ? GHOST_SIZE : 1.0);
      m.scale.setScalar(Math.max(this.controlRadius * grow, this.floorAt(m, ghost ? DRAWN_PX.ghost : DRAWN_PX.control)));
      m.updateMatrix();
      if (m.userData.quiet) m.matrix.makeScale(0, 0, 0); // no sphere: its copy's line shows it
      const [d, at] = j < this.k ? [this.controlDraws[0], j] : [this.controlDraws[1], j - this.k];
      if (!d || at >= d.count) continue;
      d.setMatrixAt(at, m.matrix);
      d.setColorAt(at, c);
    }
    for (const d of this.controlDraws) {
      d.instanceMatrix.needsUpdate = true;
      if (d.instanceColor) d.instanceColor.needsUpdate = true;
    }
    this.refreshTethers();
    this.strokeCopies.update(this);
  }

  // The lines from the controls off the clay (a stroke as one) to their nearest nodes, where the controls are drawn.
  refreshTethers() {
    const t = this.topology;
    const runs = [];
    for (let i = 0; i < this.k;) {
      const run = this.runOf(i);
      runs.push(run);
      i = Math.max(i + 1, run[run.length - 1] + 1);
    }
    this.tethers.update(t && this.lastFrame ? this.positionAttr.array : null, t ? Math.min(t.n_nodes, t.n_vertices) : 0,
      runs, (i) => this.controlAnchors[i]?.position.toArray());
  }

  // The model radius that `px` screen pixels make at anchor m (0 without a camera to measure: a headset).
  floorAt(m, px) {
    if (!this.pixelSize) return 0;
    const w = m.getWorldPosition(this.scratchWorld || (this.scratchWorld = new THREE.Vector3()));
    return (px * this.pixelSize(w)) / this.scale;
  }

  setLocal(i, modelPos) {
    this.local.set(i, modelPos);
    this.refreshControls();
  }

  clearLocal(i) {
    this.local.delete(i);
    this.refreshControls();
  }

  setHover(set) {
    const same = set.size === this.hover.size && [...set].every((j) => this.hover.has(j));
    if (same) return;
    this.hover = set;
    this.refreshControls();
  }

  modelToWorld(p, target = new THREE.Vector3()) {
    this.stage.updateWorldMatrix(true, true);
    return this.content.localToWorld(target.set(p[0], p[1], p[2]));
  }

  worldToModel(v) {
    this.stage.updateWorldMatrix(true, true);
    const p = this.content.worldToLocal(v.clone());
    return [p.x, p.y, p.z];
  }

  // The world-space sphere around the drawn clay and every control (null before the first frame).
  worldBounds() {
    if (!this.lastFrame) return null;
    const box = boxOf(this.positionAttr.array);
    for (const m of this.controlAnchors) box.expandByPoint(m.position);
    if (box.isEmpty()) return null;
    const centre = box.getCenter(new THREE.Vector3());
    const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2 + this.controlRadius * 1.6, 1e-6);
    const c = centre.toArray();
    return { center: this.modelToWorld(c), radius: radius * this.scale };
  }

  controlWorld(j, target = new THREE.Vector3()) {
    const m = this.controlAnchors[j];
    if (!m) return null;
    this.stage.updateWorldMatrix(true, true);
    return m.getWorldPosition(target);
  }

  // Where a ray first meets the clay (its surface; a point display's nearest node within `pointPad` x the control
  // radius of the ray): {point (world), distance, normal (world, towards the ray; null for a point)} or null.
  surfaceHit(raycaster, pointPad = 0.5) {
    const target = this.surface || this.objects.find((o) => o.isPoints);
    if (!target || !this.lastFrame) return null;
    raycaster.params.Points.threshold = this.worldControlRadius * pointPad;
    const hits = raycaster.intersectObject(target, false);
    if (!hits.length) return null;
    const h = hits[0];
    let normal = null;
    if (h.face) {
      normal = h.face.normal.clone().transformDirection(target.matrixWorld);
      if (normal.dot(raycaster.ray.direction) > 0) normal.negate();
    }
    return { point: h.point.clone(), distance: h.distance, normal };
  }

  // Effective control j is control j mod k under the group's map floor(j / k): which control an effective index
  // moves, which map makes it, and the model point to send for a wanted model point of the copy (the inverse map).
  originalOf(j) {
    return this.k > 0 ? j % this.k : j;
  }

  copyOf(j) {
    return this.k > 0 ? Math.floor(j / this.k) : 0;
  }

  mapOf(g) {
    return this.groupMaps[g] || IDENTITY; // a copy beyond the group (a group changed mid-drag): as the original
  }

  // Copy g of a control at modelPos (g = 0: the control itself).
  imageOf(g, modelPos) {
    return g > 0 ? applyMap(this.mapOf(g), modelPos) : modelPos;
  }

  // The control's place for copy g at modelPos.
  unmap(g, modelPos) {
    return g > 0 ? applyInverse(this.mapOf(g), modelPos) : modelPos;
  }
}
