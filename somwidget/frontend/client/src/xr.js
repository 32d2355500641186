// The immersive session: entering AR (or VR where AR is missing), placing the clay in front of the person, and the
// hands and controllers: grab the nearest control with the trigger or a pinch, move it, let go; squeeze (or
// trigger / pinch on empty space) moves the whole clay, two of them scale it; the menu below the clay does the rest.
// With Stroke chosen in the menu the trigger or a pinch draws instead, and thumbsticks set radii (xrtools.js).
//
// Inputs are read from the XRFrame every animation frame (grip pose for controllers, the midpoint of thumb and index
// tips for hands); session events only mark what started or ended, the next frame acts on it with fresh poses.
// Controllers and hands are drawn with our own simple geometry (nothing is loaded from a CDN).

import * as THREE from 'three';
import { firstControl, nearestControl } from './picking.js';

const JOINTS = ['wrist', 'thumb-metacarpal', 'thumb-phalanx-proximal', 'thumb-phalanx-distal', 'thumb-tip',
  'index-finger-metacarpal', 'index-finger-phalanx-proximal', 'index-finger-phalanx-intermediate',
  'index-finger-phalanx-distal', 'index-finger-tip', 'middle-finger-metacarpal', 'middle-finger-phalanx-proximal',
  'middle-finger-phalanx-intermediate', 'middle-finger-phalanx-distal', 'middle-finger-tip',
  'ring-finger-metacarpal', 'ring-finger-phalanx-proximal', 'ring-finger-phalanx-intermediate',
  'ring-finger-phalanx-distal', 'ring-finger-tip', 'pinky-finger-metacarpal', 'pinky-finger-phalanx-proximal',
  'pinky-finger-phalanx-intermediate', 'pinky-finger-phalanx-distal', 'pinky-finger-tip'];
const PLACE_DISTANCE = 0.6; // m in front of the eyes
const PLACE_DROP = 0.25; // m below eye height
const CLAY_RADIUS = 0.25; // m: the clay's bounding radius when placed
const GRAB_RADIUS = 0.07; // m: a control within this distance of the hand (or 2x its radius) is grabbed
const RAY_LENGTH = 2.0;

export class XRApp {
  constructor({ renderer, scene, clay, grabs, menu, tools, radius, onMode }) {
    this.renderer = renderer;
    this.scene = scene;
    this.clay = clay;
    this.grabs = grabs;
    this.menu = menu;
    this.tools = tools; // HandTools: the Stroke tool, radii by thumbstick or spread
    this.radius = radius; // RadiusBall: the held control's radius shown
    this.onMode = onMode;
    this.session = null;
    this.mode = null;
    this.needsPlacement = false;
    this.inputs = new Map(); // XRInputSource -> {visual, point, ray, grab, selecting, squeezing}
    this.starts = [];
    this.ends = [];
    this.menuAnchor = new THREE.Group();
    this.menuAnchor.add(menu.group);
    clay.stage.add(this.menuAnchor);
    this.raycaster = new THREE.Raycaster();
    this.floor = new THREE.GridHelper(6, 24, 0x556070, 0x3a4050);
    this.floor.visible = false;
    scene.add(this.floor);
    this.jointGeometry = new THREE.SphereGeometry(1, 10, 8);
    this.stats = { grabs: 0, releases: 0, stageMoves: 0 };
  }

  static async supportedModes() {
    const xr = navigator.xr;
    const out = { ar: false, vr: false };
    if (!xr || !xr.isSessionSupported) return out;
    try { out.ar = await xr.isSessionSupported('immersive-ar'); } catch { out.ar = false; }
    try { out.vr = await xr.isSessionSupported('immersive-vr'); } catch { out.vr = false; }
    return out;
  }

  // Enter `mode` ('immersive-ar' or 'immersive-vr'); 'auto' asks for AR and falls back to VR where AR is missing.
  async enter(mode = 'auto') {
    if (this.session) return this.mode;
    if (mode === 'auto') {
      const m = await XRApp.supportedModes();
      if (m.ar) mode = 'immersive-ar';
      else if (m.vr) mode = 'immersive-vr';
      else throw new Error('this browser offers no immersive WebXR session');
    }
    const options = { optionalFeatures: ['local-floor', 'hand-tracking'] };
    let session;
    try {
      session = await navigator.xr.requestSession(mode, options);
    } catch (err) {
      // AR offered but refused (no camera permission, a busy runtime...): VR where the headset has it
      if (mode !== 'immersive-ar' || !(await XRApp.supportedModes()).vr) throw err;
      console.warn('somwidget xr: immersive-ar refused, falling back to immersive-vr', err);
      mode = 'immersive-vr';
      session = await navigator.xr.requestSession(mode, options);
    }
    try {
      this.renderer.xr.setReferenceSpaceType('local-floor');
      await this.renderer.xr.setSession(session);
    } catch (err) {
      // no floor-level space here (some headsets): eye-level 'local' works everywhere immersive sessions do
      console.warn('somwidget xr: local-floor unavailable, using local', err);
      this.renderer.xr.setReferenceSpaceType('local');
      await this.renderer.xr.setSession(session);
    }
    this.session = session;
    this.mode = mode;
    this.needsPlacement = true;
    const ar = mode === 'immersive-ar';
    this.scene.background = ar ? null : new THREE.Color(0x20232c);
    this.floor.visible = !ar;
    this.menu.group.visible = true;
    for (const type of ['selectstart', 'selectend', 'squeezestart', 'squeezeend']) {
      session.addEventListener(type, (ev) => this.onInputEvent(type, ev.inputSource));
    }
    session.addEventListener('inputsourceschange', (ev) => {
      for (const s of ev.removed || []) this.dropInput(s);
    });
    session.addEventListener('end', () => this.onEnd());
    this.onMode?.(mode);
    return mode;
  }

  async exit() {
    if (this.session) await this.session.end();
  }

  onEnd() {
    for (const s of [...this.inputs.keys()]) this.dropInput(s);
    this.session = null;
    this.mode = null;
    this.menu.group.visible = false;
    this.floor.visible = false;
    this.onMode?.(null);
  }

  onInputEvent(type, source) {
    if (type.endsWith('start')) this.starts.push({ source, kind: type.startsWith('select') ? 'select' : 'squeeze' });
    else this.ends.push({ source, kind: type.startsWith('select') ? 'select' : 'squeeze' });
  }

  dropInput(source) {
    const st = this.inputs.get(source);
    if (!st) return;
    this.endGrab(st, 'select');
    this.endGrab(st, 'squeeze');
    this.scene.remove(st.visual);
    this.inputs.delete(source);
  }

  inputState(source) {
    let st = this.inputs.get(source);
    if (!st) {
      st = { source, visual: this.makeVisual(source), point: null, rayOrigin: null, rayDir: null, grabs: {},
        tip: null };
      this.scene.add(st.visual);
      this.inputs.set(source, st);
    }
    return st;
  }

  makeVisual(source) {
    const g = new THREE.Group();
    g.name = `input-${source.handedness}-${source.hand ? 'hand' : 'controller'}`;
    if (source.hand) {
      const mat = new THREE.MeshStandardMaterial({ color: 0xe8c4a8, roughness: 0.6 });
      const joints = new THREE.InstancedMesh(this.jointGeometry, mat, JOINTS.length);
      joints.frustumCulled = false;
      g.add(joints);
      g.userData.joints = joints;
    } else {
      const body = new THREE.Mesh(new THREE.BoxGeometry(0.035, 0.03, 0.1),
        new THREE.MeshStandardMaterial({ color: 0x3a3f4f, roughness: 0.5 }));
      const tip = new THREE.Mesh(new THREE.SphereGeometry(0.012, 12, 8),
        new THREE.MeshStandardMaterial({ color: 0xf0f0f0, emissive: 0x222222 }));
      tip.position.z = -0.06;
      const grip = new THREE.Group();
      grip.add(body, tip);
      g.add(grip);
      g.userData.grip = grip;
    }
    const rayGeo = new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(0, 0, 0), new THREE.Vector3(0, 0, -1)]);
    const ray = new THREE.Line(rayGeo, new THREE.LineBasicMaterial({ color: 0xffffff, transparent: true, opacity: 0.6 }));
    ray.scale.z = RAY_LENGTH;
    ray.frustumCulled = false;
    g.add(ray);
    g.userData.ray = ray;
    g.userData.point = new THREE.Mesh(new THREE.SphereGeometry(0.006, 10, 8),
      new THREE.MeshBasicMaterial({ color: 0xffee55 }));
    g.add(g.userData.point);
    g.userData.radiusBall = this.tools.ball();
    g.add(g.userData.radiusBall);
    return g;
  }

  place(frame, refSpace) {
    const pose = frame.getViewerPose(refSpace);
    if (!pose) return false;
    const m = new THREE.Matrix4().fromArray(pose.transform.matrix);
    const eye = new THREE.Vector3().setFromMatrixPosition(m);
    const fwd = new THREE.Vector3(0, 0, -1).transformDirection(m);
    fwd.y = 0;
    if (fwd.lengthSq() < 1e-6) fwd.set(0, 0, -1);
    fwd.normalize();
    const stage = this.clay.stage;
    stage.position.copy(eye).addScaledVector(fwd, PLACE_DISTANCE);
    stage.position.y -= PLACE_DROP;
    stage.rotation.set(0, Math.atan2(-fwd.x, -fwd.z), 0);
    this.clay.fit(CLAY_RADIUS);
    this.layoutMenu();
    return true;
  }

  layoutMenu() {
    const r = this.clay.worldRadius;
    this.menuAnchor.position.set(0, -0.75 * r - 0.06, 0.45 * r + 0.05);
    this.menuAnchor.rotation.set(-0.45, 0, 0);
  }

  rescale(factor) {
    this.clay.setScale(THREE.MathUtils.clamp(this.clay.scale * factor, 1e-4, 1e4));
    this.layoutMenu();
  }

  // One XR animation frame: poses, pending starts and ends, drags, hover, visuals.
  update(frame) {
    const refSpace = this.renderer.xr.getReferenceSpace();
    if (!refSpace) return;
    if (this.needsPlacement && this.place(frame, refSpace)) this.needsPlacement = false;
    if (this.wantPlace) {
      if (this.place(frame, refSpace)) this.wantPlace = false;
    }
    for (const source of frame.session.inputSources) this.readInput(this.inputState(source), frame, refSpace);
    for (const s of this.starts.splice(0)) {
      const st = this.inputs.get(s.source);
      if (st) this.startGrab(st, s.kind);
    }
    for (const st of this.inputs.values()) this.dragControl(st);
    this.dragStage();
    this.tools.update(this.inputs.values());
    for (const e of this.ends.splice(0)) {
      const st = this.inputs.get(e.source);
      if (st) this.endGrab(st, e.kind);
    }
    const hover = new Set();
    const near = Math.max(GRAB_RADIUS, 2 * this.clay.worldControlRadius);
    for (const st of this.inputs.values()) {
      if (st.point && !st.grabs.select) {
        const n = nearestControl(this.clay, st.point, near);
        if (n) hover.add(n.index);
      }
      if (st.tip) this.menu.touch(st.source, st.tip);
    }
    this.clay.setHover(hover);
    this.menu.tick();
  }

  readInput(st, frame, refSpace) {
    const source = st.source;
    const v = st.visual;
    st.point = null;
    st.tip = null;
    if (source.hand) {
      const joints = v.userData.joints;
      const mat = new THREE.Matrix4();
      const pos = new THREE.Vector3();
      const q = new THREE.Quaternion();
      const sc = new THREE.Vector3();
      let thumb = null;
      let index = null;
      JOINTS.forEach((name, i) => {
        const space = source.hand.get(name);
        const jp = space && frame.getJointPose ? frame.getJointPose(space, refSpace) : null;
        if (!jp) {
          mat.makeScale(0, 0, 0);
        } else {
          mat.fromArray(jp.transform.matrix);
          mat.decompose(pos, q, sc);
          const r = jp.radius || 0.008;
          mat.compose(pos, q, sc.setScalar(r));
          if (name === 'thumb-tip') thumb = pos.clone();
          if (name === 'index-finger-tip') index = pos.clone();
        }
        joints.setMatrixAt(i, mat);
      });
      joints.instanceMatrix.needsUpdate = true;
      if (thumb && index) st.point = thumb.clone().add(index).multiplyScalar(0.5);
      if (index) st.tip = index;
    } else if (source.gripSpace) {
      const gp = frame.getPose(source.gripSpace, refSpace);
      if (gp) {
        const m = new THREE.Matrix4().fromArray(gp.transform.matrix);
        v.userData.grip.visible = true;
        m.decompose(v.userData.grip.position, v.userData.grip.quaternion, v.userData.grip.scale);
        st.point = new THREE.Vector3(0, 0, -0.06).applyMatrix4(m); // the tip of our controller model
      } else {
        v.userData.grip.visible = false;
      }
    }
    const rp = source.targetRaySpace ? frame.getPose(source.targetRaySpace, refSpace) : null;
    const ray = v.userData.ray;
    if (rp) {
      const m = new THREE.Matrix4().fromArray(rp.transform.matrix);
      st.rayOrigin = new THREE.Vector3().setFromMatrixPosition(m);
      st.rayDir = new THREE.Vector3(0, 0, -1).transformDirection(m);
      ray.visible = source.targetRayMode !== 'gaze';
      m.decompose(ray.position, ray.quaternion, new THREE.Vector3());
      if (!st.point) st.point = st.rayOrigin.clone();
    } else {
      st.rayOrigin = st.rayDir = null;
      ray.visible = false;
    }
    v.userData.point.visible = !!st.point;
    if (st.point) v.userData.point.position.copy(st.point);
  }

  // A controller's ray on a menu button presses it (true); the raycaster is left set along the ray.
  pressMenuByRay(st) {
    if (!st.rayOrigin) return false;
    this.raycaster.set(st.rayOrigin, st.rayDir);
    const button = this.menu.hit(this.raycaster);
    if (button) this.menu.press(button);
    return !!button;
  }

  startGrab(st, kind) {
    if (!st.point) return;
    if (kind === 'select') {
      const touched = st.source.hand ? null : this.menu.at(st.point);
      if (touched) {
        this.menu.press(touched);
        return;
      }
      if (this.tools.on) { // the Stroke tool draws, except on the menu
        if (this.pressMenuByRay(st)) return;
        if (this.tools.start(st)) return;
      }
      const near = nearestControl(this.clay, st.point, Math.max(GRAB_RADIUS, 2 * this.clay.worldControlRadius));
      if (near) return this.grabControl(st, near.index, st.point);
      if (st.rayOrigin) {
        if (this.pressMenuByRay(st)) return;
        const hit = firstControl(this.clay, this.raycaster);
        if (hit) return this.grabControl(st, hit.index, st.point);
      }
    }
    // squeeze, or select on empty space: hold the whole clay
    st.grabs[kind] = { type: 'stage', start: st.point.clone() };
    this.beginStage();
  }

  grabControl(st, j, point) {
    const i = this.clay.originalOf(j);
    if (this.grabs.holds(i)) return;
    const world = this.clay.controlWorld(j);
    this.grabs.begin(i);
    this.radius.show(j);
    this.stats.grabs += 1;
    st.grabs.select = { type: 'control', j, i, copy: this.clay.copyOf(j), offset: world.sub(point) };
  }

  dragControl(st) {
    const g = st.grabs.select;
    if (!g || g.type !== 'control' || !st.point) return;
    const world = st.point.clone().add(g.offset);
    this.grabs.update(g.i, this.clay.unmap(g.copy, this.clay.worldToModel(world))); // a copy's point, mapped back
  }

  beginStage() {
    const holders = [...this.inputs.values()].flatMap((st) =>
      Object.values(st.grabs).filter((g) => g.type === 'stage').map((g) => ({ st, g })));
    for (const { st, g } of holders) g.start = st.point ? st.point.clone() : g.start;
    this.stageStart = {
      position: this.clay.stage.position.clone(), scale: this.clay.scale, holders: holders.length,
    };
  }

  dragStage() {
    const holders = [...this.inputs.values()].flatMap((st) =>
      Object.values(st.grabs).filter((g) => g.type === 'stage' && st.point).map((g) => ({ st, g })));
    if (!holders.length || !this.stageStart) return;
    if (holders.length !== this.stageStart.holders) {
      this.beginStage();
      return;
    }
    const s0 = this.stageStart;
    if (holders.length === 1) {
      const { st, g } = holders[0];
      this.clay.stage.position.copy(s0.position).add(st.point.clone().sub(g.start));
    } else {
      const [a, b] = holders;
      const d0 = a.g.start.distanceTo(b.g.start);
      const d = a.st.point.distanceTo(b.st.point);
      const f = d0 > 1e-3 ? d / d0 : 1;
      const m0 = a.g.start.clone().add(b.g.start).multiplyScalar(0.5);
      const m = a.st.point.clone().add(b.st.point).multiplyScalar(0.5);
      this.clay.setScale(THREE.MathUtils.clamp(s0.scale * f, 1e-4, 1e4));
      this.clay.stage.position.copy(m).add(s0.position.clone().sub(m0).multiplyScalar(f));
      this.layoutMenu();
    }
    this.stats.stageMoves += 1;
  }

  endGrab(st, kind) {
    const g = st.grabs[kind];
    if (!g) return;
    delete st.grabs[kind];
    if (g.type === 'control') {
      this.grabs.end(g.i);
      this.radius.show(null);
      this.stats.releases += 1;
    } else if (g.type === 'stroke' || g.type === 'spread') {
      this.tools.end(st, g);
    } else {
      this.beginStage();
    }
  }

  // Read-only views for the page's status and for tests.
  describeInputs() {
    return [...this.inputs.values()].map((st) => ({
      handedness: st.source.handedness,
      hand: !!st.source.hand,
      point: st.point ? st.point.toArray() : null,
      tip: st.tip ? st.tip.toArray() : null,
      rayOrigin: st.rayOrigin ? st.rayOrigin.toArray() : null,
      grabbing: Object.fromEntries(Object.entries(st.grabs).map(([k, g]) => [k, g.type === 'control' ? g.i : 'stage'])),
    }));
  }
}
