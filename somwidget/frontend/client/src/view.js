// One clay view: a three.js scene of the session's clay inside any element, fed the protocol's topology and frames
// (protocol.js) from any transport (the websocket in the web app and the XR page, the kernel's comm in a notebook)
// and sending intents back through `send`. The browser draws; every view keeps its own camera.
//
// On the canvas: the controls as spheres labelled with their index (a copy with primes: ′ ″ ‴, then ·g; a control
// hidden by the clay drawn faintly through it), hover highlight, the held one red and enlarged, a marker at the
// view's edge for each control out of sight; the camera (camera.js), the mouse and keys (desktop.js), the selected
// control's handle (handle.js), radii (radius.js), strokes (stroke.js), the display settings (display.js) and the
// view's bar (toolbar.js); a status line (iteration, frames/s drawn here, the server's cycle time); who else is on
// the session (presence.js).

import './colour.js';
import * as THREE from 'three';
import { CameraRig } from './camera.js';
import { Clay } from './clay.js';
import { Desktop } from './desktop.js';
import { Display } from './display.js';
import { Grabs } from './grabs.js';
import { Handle } from './handle.js';
import { MARKER_CSS, Markers } from './markers.js';
import { PRESENCE_CSS, Presence } from './presence.js';
import { RadiusBall } from './radius.js';
import { StrokeDraw } from './stroke.js';
import { TOOLBAR_CSS, Toolbar } from './toolbar.js';

const CSS = `
.somview { position: relative; overflow: hidden; background: #eef0f4; font-family: system-ui, sans-serif; }
.somview canvas { display: block; touch-action: none; outline: none; }
.somview-labels { position: absolute; inset: 0; pointer-events: none; overflow: hidden; }
.somview-label { position: absolute; left: 0; top: 0; font-size: 11px; line-height: 1;
  padding: 1px 3px; border-radius: 3px; background: rgba(255,255,255,0.8); color: #222; white-space: nowrap; }
.somview-label.mirror { opacity: 0.6; }
.somview-label.held { background: #d32f2f; color: white; }
.somview-label.behind { opacity: 0.4; pointer-events: auto; cursor: pointer; }
.somview-status { position: absolute; left: 6px; bottom: 4px; font-size: 11px; color: #445;
  background: rgba(255,255,255,0.7); padding: 1px 5px; border-radius: 3px; pointer-events: none; }
.somview-status.offline { background: #fde2e2; color: #8a1010; font-weight: 600; }
.somview-picture { position: absolute; inset: 0; width: 100%; height: 100%; object-fit: contain;
  background: #eef0f4; pointer-events: none; }
.somview-error { position: absolute; left: 6px; top: 36px; right: 6px; font-size: 12px; padding: 3px 6px;
  background: #fde2e2; color: #8a1010; border-radius: 4px; pointer-events: none; }
${MARKER_CSS}${TOOLBAR_CSS}${PRESENCE_CSS}`;

// The view's stylesheet, inside its own element (anywidget's way): it applies wherever the element lives, in a page
// or in a shadow root (marimo renders widgets in one), and goes with it.
function addStyle(container) {
  const style = document.createElement('style');
  style.className = 'somview-style';
  style.textContent = CSS;
  container.appendChild(style);
}

// A cheap checksum of the positions (to tell a changed mesh from an unchanged one).
export function digestOf(positions) {
  let s = 0;
  const step = Math.max(1, Math.floor(positions.length / 4096));
  for (let i = 0; i < positions.length; i += step) s = (s * 31 + positions[i] * 1000.5) % 1e9;
  return s;
}

const OCCLUSION_MS = 300; // labels of controls hidden by the clay are dimmed, checked this often at most
const OCCLUSION_BUDGET = 400000; // ... while controls x triangles stays under this (one ray per control)
const STATUS_MS = 250;
const DRAG_REDRAW_MS = 50;
const PRIMES = ['', '\u2032', '\u2033', '\u2034']; // ′ ″ ‴

// The label of copy g of control i: "3" (the control), "3′", "3″", "3‴", then "3·4", "3·5", ...
export function labelOf(i, g) {
  return g < PRIMES.length ? `${i}${PRIMES[g]}` : `${i}\u00b7${g}`;
}

// A software rasteriser (SwiftShader, llvmpipe: a browser without a GPU) draws every pixel on the CPU that also
// trains the clay: there the view skips multisampling and draws at one pixel per CSS pixel.
let softwareGL = null;
export function isSoftwareGL() {
  if (softwareGL !== null) return softwareGL;
  softwareGL = false;
  try {
    const gl = document.createElement('canvas').getContext('webgl2');
    const info = gl && gl.getExtension('WEBGL_debug_renderer_info');
    const name = info ? String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) : '';
    softwareGL = /swiftshader|llvmpipe|software/i.test(name);
    gl?.getExtension('WEBGL_lose_context')?.loseContext();
  } catch {
    softwareGL = false;
  }
  return softwareGL;
}

export class ClayView {
  // container: the element to fill; send(intent): deliver an intent object (false when it could not be sent);
  // xr: let the renderer present immersive sessions (the XR page).
  constructor(container, { send, xr = false, background = 0xeef0f4 } = {}) {
    addStyle(container);
    this.container = container;
    container.classList.add('somview');
    if (!container.style.height && container.clientHeight === 0) container.style.height = '480px';
    this.link = { send: (obj) => (send ? send(obj) : false) };
    const software = isSoftwareGL();
    this.renderer = new THREE.WebGLRenderer({ antialias: !software, alpha: true });
    this.renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    this.renderer.setPixelRatio(software ? 1 : Math.min(window.devicePixelRatio, 2));
    this.renderer.xr.enabled = xr;
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.background = new THREE.Color(background);
    this.scene.background = this.background;
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x667080, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1.5, 3, 2);
    this.scene.add(sun);
    this.rig = new CameraRig(this.renderer.domElement);
    this.rig.onChange = () => { this.dirty = true; };
    this.clay = new Clay({ software });
    this.scene.add(this.clay.stage);
    this.grabs = new Grabs(this.link, this.clay);
    this.software = software;
    const redraw = () => { this.dirty = true; };
    this.display = new Display(this.clay, redraw);
    this.radius = new RadiusBall(this.clay, this.link);
    this.stroke = new StrokeDraw(this.clay, this.link, this.scene);
    this.stroke.onChange = redraw;
    this.handle = new Handle({ rig: this.rig, clay: this.clay, grabs: this.grabs, scene: this.scene,
      domElement: this.renderer.domElement, onChange: redraw });
    const act = { // what the view's bar and keys do
      fit: () => this.rig.fit(this.clay.worldBounds()),
      look: (name) => this.rig.look(name),
      orthographic: (on) => {
        this.rig.setOrthographic(on);
        this.handle.controls.camera = this.rig.camera; // aimed and sized for the camera now drawing
      },
      stroke: (on) => { this.desktop.strokeTool = on; this.desktop.hover(null); },
      display: (name, value) => this.display.set(name, value),
    };
    const refreshBar = (f) => (...args) => { f(...args); this.toolbar.refresh(); };
    for (const name of Object.keys(act)) act[name] = refreshBar(act[name]);
    this.desktop = new Desktop({ renderer: this.renderer, rig: this.rig, clay: this.clay, grabs: this.grabs,
      link: this.link, handle: this.handle, radius: this.radius, stroke: this.stroke, act,
      onDragStart: () => this.clay.setMoving(true),
      onDragEnd: () => this.clay.setMoving(!!this.state.frame?.running) });

    this.grabs.onMoved = (i, j, k) => { // a control this view drags changed place: the copy dragged follows it
      const drag = this.desktop.drag;
      if (drag && this.grabs.current(drag.i) === i && j >= 0) drag.j = j + drag.copy * k;
    };
    this.labels = document.createElement('div');
    this.labels.className = 'somview-labels';
    this.statusLine = document.createElement('div');
    this.statusLine.className = 'somview-status';
    this.statusLine.textContent = 'connecting';
    this.errorBox = document.createElement('div');
    this.errorBox.className = 'somview-error';
    this.errorBox.hidden = true;
    container.append(this.labels, this.statusLine, this.errorBox);
    this.presence = new Presence(container, this.clay);
    this.toolbar = new Toolbar(container, act, () => ({ orthographic: this.rig.orthographicOn,
      stroke: this.desktop.strokeTool, display: this.display.describe() }));
    this.labelDivs = [];
    this.markers = new Markers(this.labels, (j) => { // centred and selected: its handle moves it
      this.rig.centreOn(this.clay.controlWorld(j));
      this.handle.select(j);
    });
    this.occluded = new Set(); // effective controls the clay hides from the camera
    this.occlusionRay = new THREE.Raycaster();
    this.occlusionScratch = { eye: new THREE.Vector3(), c: new THREE.Vector3(), dir: new THREE.Vector3(),
      back: new THREE.Vector3() };
    this.lastOcclusion = 0;

    this.state = { connected: false, topology: null, frame: null, frames: 0, fps: 0, fpsCount: 0,
      fpsStart: performance.now(), digest: 0, errors: [], lastError: null, cycleMs: null, serverFps: null,
      painted: 0, paintedDigest: 0, rendered: 0, renderedAt: 0 };
    this.paints = []; // {digest, t}: when a changed mesh was first drawn (page clock, ms)
    this.hooks = []; // (time, xrFrame) => void, run before each render
    this.lastStatus = 0;
    this.lastRender = 0;
    this.dirty = true; // draw on the next animation frame (only then: a software rasteriser shares the CPU)
    this.clay.onChange = () => { this.dirty = true; };
    this.resize();
    this.resizer = new ResizeObserver(() => this.resize());
    this.resizer.observe(container);
    this.renderer.setAnimationLoop((time, xrFrame) => this.tick(time, xrFrame));
    container.somview = this;
  }

  // Handlers for a transport (Link in link.js, or a notebook comm): what arrives goes here.
  get handlers() {
    return {
      onStatus: (s) => { this.state.connected = s === 'connected'; this.state.linkStatus = s; },
      onTopology: (t) => this.setTopology(t),
      onFrame: (f) => this.applyFrame(f),
      onGrabs: (list) => this.grabs.onGrabs(list),
      onPresence: (hands) => this.presence.update(hands),
      onError: (e) => this.showError(e),
      onServerStatus: (s) => { this.state.cycleMs = s.cycle_ms; this.state.serverFps = s.fps; },
      onControls: (ids, msg) => {
        if (msg) this.clay.announceGroup(msg); // the group (a server that sends it), from the next frame on
        if (msg) this.clay.setRuns(msg); // the radii and strokes
        this.grabs.onControls(ids);
        this.radius.update();
        this.presence.refresh();
      },
    };
  }

  setTopology(t) {
    this.state.topology = t;
    this.handle.select(null);
    this.clay.setTopology(t);
    this.display.apply();
    this.state.needsFrame = true;
    this.onTopology?.(t);
  }

  // A new model: unit scale at the origin, the camera framed on it.
  frame() {
    this.clay.stage.position.set(0, 0, 0);
    this.clay.stage.rotation.set(0, 0, 0);
    this.clay.fit(1.0);
    this.rig.frame(this.clay.worldBounds());
    this.display.placeHelpers();
  }

  // The camera the view draws with: the rig's (perspective or orthographic), the perspective one in a headset.
  get camera() {
    return this.renderer.xr.isPresenting ? this.rig.perspective : this.rig.camera;
  }

  applyFrame(f) {
    if (!this.clay.applyFrame(f)) return false;
    const s = this.state;
    s.frame = f;
    s.frames += 1;
    s.fpsCount += 1;
    s.connected = true;
    s.digest = digestOf(f.positions);
    this.grabs.onFrame(f, s.digest);
    this.clay.setMoving(f.running || !!this.desktop.drag);
    this.handle.follow();
    this.radius.update();
    if (s.needsFrame) { // the first frame of a model: frame the camera on it
      s.needsFrame = false;
      this.onFirstFrame ? this.onFirstFrame() : this.frame();
    }
    this.onFrame?.(f);
    return true;
  }

  showError(e) {
    const s = this.state;
    s.lastError = e.message;
    s.errors.push(e);
    if (s.errors.length > 50) s.errors.shift();
    this.errorBox.textContent = e.message;
    this.errorBox.hidden = false;
    clearTimeout(s.errorTimer);
    s.errorTimer = setTimeout(() => { this.errorBox.hidden = true; }, 4000);
    this.onError?.(e);
  }

  resize() {
    if (this.renderer.xr.isPresenting) return;
    const w = Math.max(this.container.clientWidth, 1);
    const h = Math.max(this.container.clientHeight, 1);
    this.renderer.setSize(w, h);
    this.size = [w, h];
    this.rig.resize(w, h);
    this.dirty = true;
  }

  tick(time, xrFrame) {
    for (const hook of this.hooks) hook(time, xrFrame);
    this.grabs.flush();
    this.radius.flush();
    const now = performance.now();
    const s = this.state;
    if (now - s.fpsStart >= 1000) {
      s.fps = (1000 * s.fpsCount) / (now - s.fpsStart);
      s.fpsCount = 0;
      s.fpsStart = now;
    }
    const presenting = this.renderer.xr.isPresenting;
    if (!presenting) {
      if (now - this.lastStatus >= STATUS_MS) { // a few times a second: it is read, not watched
        this.lastStatus = now;
        this.updateStatus();
      }
      if (this.dirtyOcclusion && now - this.lastOcclusion >= OCCLUSION_MS) this.dirty = true;
      if (!this.dirty) return;
      // a software rasteriser dragging: draw each answer to a move at once, the frames between at most every
      // DRAG_REDRAW_MS (each drawing holds the page's thread while the CPU draws; the next answer waits behind it)
      if (this.software && this.desktop.drag && !this.grabs.answered && now - this.lastRender < DRAG_REDRAW_MS) return;
      this.updateLabels();
    }
    this.dirty = false;
    this.renderer.render(this.scene, this.camera);
    this.lastRender = now;
    this.grabs.answered = false;
    s.rendered += 1;
    s.renderedAt = now;
    if (s.frame && s.digest !== s.paintedDigest) { // a changed mesh is on screen from now on
      s.paintedDigest = s.digest;
      s.painted += 1;
      this.paints.push({ digest: s.digest, t: now });
      if (this.paints.length > 400) this.paints.splice(0, 200);
    }
  }

  updateLabels() {
    const clay = this.clay;
    while (this.labelDivs.length < clay.kEff) {
      const d = document.createElement('div');
      const j = this.labelDivs.length;
      d.className = 'somview-label';
      // the dimmed label of a control behind the clay takes a click: it selects the control, whose handle is drawn
      // over the clay, so it can be moved without turning the view
      d.addEventListener('pointerdown', (ev) => ev.stopPropagation());
      d.addEventListener('click', (ev) => {
        ev.stopPropagation();
        this.handle.select(j);
      });
      this.labels.appendChild(d);
      this.labelDivs.push(d);
    }
    const [w, h] = this.size; // kept by resize(): reading the layout here would force one every frame
    const p = new THREE.Vector3();
    this.camera.updateMatrixWorld();
    this.updateOcclusion();
    const shown = this.display.settings.labels;
    for (let j = 0; j < this.labelDivs.length; j++) {
      const d = this.labelDivs[j];
      if (j >= clay.kEff || !shown) {
        d.hidden = true;
        continue;
      }
      const i = clay.originalOf(j);
      const mirror = j >= clay.k; // a copy
      const text = labelOf(i, clay.copyOf(j));
      if (d.textContent !== text) d.textContent = text;
      clay.controlWorld(j, p);
      p.project(this.camera);
      const out = p.z > 1 || Math.abs(p.x) > 1 || Math.abs(p.y) > 1; // out of sight: a marker instead
      if (d.hidden !== out) d.hidden = out;
      // a transform moves the label without a new layout of the page; only what changed is written
      const place = `translate(${(((p.x + 1) / 2) * w).toFixed(1)}px, ${(((1 - p.y) / 2) * h).toFixed(1)}px) `
        + 'translate(-50%, -130%)';
      if (d.somPlace !== place) {
        d.somPlace = place;
        d.style.transform = place;
      }
      const held = clay.held.has(i) || clay.local.has(i);
      if (d.classList.contains('mirror') !== mirror) d.classList.toggle('mirror', mirror);
      if (d.classList.contains('held') !== held) d.classList.toggle('held', held);
      const holder = clay.local.has(i) ? '' : clay.holders.get(i) || ''; // another hand's: in its colour (presence.js)
      if (d.somHolder !== holder) {
        d.somHolder = holder;
        d.style.background = holder;
      }
      const behind = this.occluded.has(j);
      if (d.classList.contains('behind') !== behind) d.classList.toggle('behind', behind);
    }
    this.markers.update(clay, this.camera, this.size, (j) => labelOf(clay.originalOf(j), clay.copyOf(j)));
  }

  // Which controls the clay hides from the camera (their labels dimmed): one ray each, a few times a second, on a
  // clay small enough for it.
  updateOcclusion() {
    const now = performance.now();
    if (now - this.lastOcclusion < OCCLUSION_MS) {
      this.dirtyOcclusion = true; // look again soon: what is drawn may have changed since
      return;
    }
    this.lastOcclusion = now;
    this.dirtyOcclusion = false;
    const clay = this.clay;
    const triangles = (clay.topology?.triangles.length ?? 0) / 3;
    this.occluded = new Set();
    if (!clay.surface || triangles * clay.kEff > OCCLUSION_BUDGET) return;
    const rc = this.occlusionRay;
    const { eye, c, dir, back } = this.occlusionScratch;
    const ortho = this.camera.isOrthographicCamera;
    if (ortho) this.camera.getWorldDirection(back).negate();
    for (let j = 0; j < clay.kEff; j++) {
      clay.controlWorld(j, c);
      if (ortho) eye.copy(c).addScaledVector(back, 10 * this.rig.fitDistance);
      else eye.copy(this.camera.position);
      const far = eye.distanceTo(c);
      rc.set(eye, dir.subVectors(c, eye).normalize());
      const hit = clay.surfaceHit(rc);
      if (hit && hit.distance < far - clay.worldControlRadius) this.occluded.add(j);
    }
  }

  updateStatus() {
    const s = this.state;
    const f = s.frame;
    // a link that dropped says so until it is back (link.js tries again every few seconds at most)
    let text = s.connected ? 'connected' : s.linkStatus === 'reconnecting' ? 'reconnecting\u2026'
      : (s.linkStatus || 'connecting');
    this.statusLine.classList.toggle('offline', !s.connected && !!s.linkStatus);
    if (f && s.connected) {
      const what = f.running ? 'training' : f.paused ? 'paused' : 'converged';
      text = `iteration ${f.iteration} / ${f.iterations} \u00b7 ${what} \u00b7 ${s.fps.toFixed(0)} frames/s`;
      if (s.cycleMs !== null && s.cycleMs !== undefined) text += ` \u00b7 cycle ${Number(s.cycleMs).toFixed(3)} ms`;
    }
    if (this.statusLine.textContent !== text) this.statusLine.textContent = text;
  }

  // Read-only facts for tests, benchmarks and the console (nothing here sends an intent).
  describe() {
    const s = this.state;
    const clay = this.clay;
    return {
      connected: s.connected, hasTopology: !!s.topology, frames: s.frames, fps: s.fps, painted: s.painted,
      seq: s.frame ? s.frame.seq : null, generation: s.frame ? s.frame.generation : null,
      iteration: s.frame ? s.frame.iteration : null, paused: s.frame ? s.frame.paused : null,
      running: s.frame ? s.frame.running : null, digest: s.digest, k: clay.k, kEff: clay.kEff,
      group: clay.group, groupMaps: clay.groupMaps.map((m) => [...m]),
      held: [...clay.held], local: [...clay.local.keys()], hover: [...clay.hover],
      errors: s.errors.map((e) => e.message), lastError: s.lastError, moves: this.grabs.moves,
      latencies: [...this.grabs.latencies], controlLatencies: [...this.grabs.controlLatencies],
      desktop: { ...this.desktop.stats, ...this.rig.stats, handleMoves: this.handle.stats.moves,
        radiusTurns: this.radius.turns }, status: this.statusLine.textContent, software: this.software,
      synapsesShown: this.clay.segments ? this.clay.segments.visible : null,
      labels: this.labelDivs.filter((d) => !d.hidden).map((d) => d.textContent),
      behind: [...this.occluded], markers: this.markers.shown.map((j) => labelOf(clay.originalOf(j), clay.copyOf(j))),
      ...this.rig.describe(), // camera, target, distance (to the target), fitDistance, projection, zoom
      display: this.display.describe(), selected: this.handle.selected, tool: this.desktop.strokeTool ? 'stroke' : null,
      radii: [...clay.radii], strokes: [...clay.strokes], controlIds: [...clay.controlIds],
      radiusBall: { of: this.radius.shownFor, shown: this.radius.ball.visible, radius: this.radius.ball.scale.x },
      presence: this.presence.describe(),
      size: [this.renderer.domElement.clientWidth, this.renderer.domElement.clientHeight],
    };
  }

  // Where effective control j is drawn, in page pixels (null when there is none).
  controlScreen(j) {
    const w = this.clay.controlWorld(j);
    if (!w) return null;
    const p = w.project(this.camera);
    const r = this.renderer.domElement.getBoundingClientRect();
    return [r.left + ((p.x + 1) / 2) * r.width, r.top + ((1 - p.y) / 2) * r.height];
  }

  // Where a model point [x, y, z] is drawn, in page pixels.
  modelScreen(point) {
    const p = this.clay.modelToWorld(point).project(this.camera);
    const r = this.renderer.domElement.getBoundingClientRect();
    return [r.left + ((p.x + 1) / 2) * r.width, r.top + ((1 - p.y) / 2) * r.height];
  }

  // The model point of the clay under page pixel (x, y), or null where there is no clay.
  surfaceAt(x, y) {
    const hit = this.clay.surfaceHit(this.desktop.ray({ clientX: x, clientY: y }));
    return hit ? this.clay.worldToModel(hit.point) : null;
  }

  // A point on the selected control's handle arrow along model axis 'X', 'Y' or 'Z', in page pixels (or null).
  handlePoint(axis) {
    return this.handle.axisPoint(axis, this.camera, this.renderer.domElement.getBoundingClientRect());
  }

  // Select control j (its handle shows and moves it), as a click on it does; the web panel's table calls this.
  selectControl(j) {
    this.handle.select(Number.isInteger(j) && j >= 0 && j < this.clay.kEff ? j : null);
  }

  controlModel(j) {
    const m = this.clay.controlAnchors[j];
    return m ? [m.position.x, m.position.y, m.position.z] : null;
  }

  controlLook(j) {
    return this.clay.controlLook(j);
  }

  // Move -> changed mesh on screen, per answered move: ms from the move's send to the first paint of the frame.
  moveToPaint() {
    const out = [];
    for (const e of this.grabs.latencyLog) {
      const paint = this.paints.find((p) => p.t >= e.arrived);
      if (paint) out.push(paint.t - e.sent);
    }
    return out;
  }

  positions(count = 12) {
    return this.state.frame ? Array.from(this.state.frame.positions.slice(0, 3 * count)) : [];
  }

  dispose() {
    this.renderer.setAnimationLoop(null);
    this.resizer.disconnect();
    this.renderer.dispose();
    this.container.replaceChildren();
    delete this.container.somview;
  }
}
