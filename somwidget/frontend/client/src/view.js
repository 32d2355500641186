// One clay view: a three.js scene of the session's clay inside any element, fed the protocol's topology and frames
// (protocol.js) from any transport (the websocket in the web app and the XR page, the kernel's comm in a notebook)
// and sending intents back through `send`. The browser draws; every view keeps its own camera.
//
// On the canvas: the controls as spheres numbered by their stable ids (labels.js; symmetric copies as ghosts
// without numbers; a control hidden by the clay drawn faintly through it), hover highlight, the held one red and
// enlarged, a marker at the view's edge for each control out of sight; the camera (camera.js: nothing refits it, a
// Refine neither), the mouse (desktop.js) and keys (keys.js), the selected control's handle (handle.js), radii
// (radius.js: the ball, the disc under the cursor), strokes (stroke.js), the display settings (display.js) and the
// view's bar (toolbar.js); a status line (iteration, frames/s drawn here, the server's cycle time); who else is
// on the session (presence.js).

import './colour.js';
import * as THREE from 'three';
import { CameraRig } from './camera.js';
import { Clay, boxOf } from './clay.js';
import { Desktop } from './desktop.js';
import { Display } from './display.js';
import { Grabs } from './grabs.js';
import { Handle } from './handle.js';
import { ControlLabels, LABEL_CSS } from './labels.js';
import { RadiusBall, RadiusDisc } from './radius.js';
import { PRESENCE_CSS, Presence } from './presence.js';
import { RevolveGuide } from './revolve.js';
import { StrokeDraw } from './stroke.js';
import { TOOLBAR_CSS, Toolbar } from './toolbar.js';

const CSS = `
.somview { position: relative; overflow: hidden; background: #eef0f4; font-family: system-ui, sans-serif; }
.somview canvas { display: block; touch-action: none; outline: none; }
.somview-radius { position: absolute; left: 0; top: 0; font-size: 11px; line-height: 1.2; padding: 1px 4px;
  border-radius: 3px; background: rgba(29, 66, 138, 0.85); color: white; white-space: nowrap; pointer-events: none; }
.somview-status { position: absolute; left: 6px; bottom: 4px; font-size: 11px; color: #445;
  background: rgba(255,255,255,0.7); padding: 1px 5px; border-radius: 3px; pointer-events: none; }
.somview-status.offline { background: #fde2e2; color: #8a1010; font-weight: 600; }
.somview-picture { position: absolute; inset: 0; width: 100%; height: 100%; object-fit: contain;
  background: #eef0f4; pointer-events: none; }
.somview-hint { position: absolute; left: 50%; top: 40px; transform: translateX(-50%); font-size: 13px;
  padding: 4px 10px; border-radius: 4px; background: rgba(29, 66, 138, 0.88); color: white; pointer-events: none; }
.somview-bar button:disabled { cursor: not-allowed; opacity: 0.45; }
.somview-error { position: absolute; left: 6px; top: 36px; right: 6px; font-size: 12px; padding: 3px 6px;
  background: #fde2e2; color: #8a1010; border-radius: 4px; pointer-events: none; }
${LABEL_CSS}${TOOLBAR_CSS}${PRESENCE_CSS}`;

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

const STATUS_MS = 250;
const HINT_MS = 3000;
const GROUND_HINT = 'The camera stays above the ground: 6 looks from below';
const SAME_CLAY = 0.02; // a new topology whose clay's bounds moved less than this share of its size is the same clay
const DRAG_REDRAW_MS = 50;
// The tooltip of what a view that only watches (a studio's watch page: topology.watching) cannot do.
export const WATCHING_TIP = 'watching only: open the room with its own link, or Take part on the wall';

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
    this.rig.onChange = () => { // the camera moved: controls keep their smallest size on screen
      this.dirty = true;
      this.clay.refreshControls();
    };
    this.clay = new Clay({ software });
    this.clay.pixelSize = (w) => this.pixelSize(w);
    this.scene.add(this.clay.stage);
    this.grabs = new Grabs(this.link, this.clay);
    this.software = software;
    const redraw = () => { this.dirty = true; };
    this.display = new Display(this.clay, redraw);
    this.radius = new RadiusBall(this.clay, this.link);
    this.stroke = new StrokeDraw(this.clay, this.link, this.scene);
    this.stroke.onChange = redraw;
    this.guide = new RevolveGuide(this.clay, this.rig, this.scene);
    this.handle = new Handle({ rig: this.rig, clay: this.clay, grabs: this.grabs, scene: this.scene,
      domElement: this.renderer.domElement, onChange: redraw });
    const act = { // what the view's bar and keys do
      fit: () => this.rig.fit(this.clay.worldBounds()),
      look: (name) => this.rig.look(name),
      orthographic: (on) => {
        this.rig.setOrthographic(on);
        this.handle.controls.camera = this.rig.camera; // aimed and sized for the camera now drawing
      },
      stroke: (on) => this.useTool(on && !this.readOnly ? 'stroke' : null),
      revolve: (on) => this.useTool(on && !this.readOnly ? 'revolve' : null),
      display: (name, value) => this.display.set(name, value),
    };
    const refreshBar = (f) => (...args) => { f(...args); this.toolbar.refresh(); };
    for (const name of Object.keys(act)) act[name] = refreshBar(act[name]);
    this.radiusLabel = document.createElement('div');
    this.radiusLabel.className = 'somview-radius';
    this.radiusLabel.hidden = true;
    this.disc = new RadiusDisc({ clay: this.clay, radius: this.radius, scene: this.scene, label: this.radiusLabel,
      onChange: redraw });
    this.desktop = new Desktop({ renderer: this.renderer, rig: this.rig, clay: this.clay, grabs: this.grabs,
      link: this.link, handle: this.handle, radius: this.radius, disc: this.disc, stroke: this.stroke, guide: this.guide, act,
      onDragStart: () => this.clay.setMoving(true),
      onDragEnd: () => this.clay.setMoving(!!this.state.frame?.running) });

    this.grabs.onMoved = (i, j, k) => { // a control this view drags changed place: the copy dragged follows it
      const drag = this.desktop.drag;
      if (drag && this.grabs.current(drag.i) === i && j >= 0) drag.j = j + drag.copy * k;
    };
    this.labels = new ControlLabels({ clay: this.clay, display: this.display,
      onPick: (j) => this.handle.select(this.readOnly ? null : j),
      onPress: (j, ev) => this.desktop.pressLabel(j, ev),
      onMarker: (j) => { // centred and selected: its handle moves it
        this.rig.centreOn(this.clay.controlWorld(j));
        this.handle.select(this.readOnly ? null : j);
      } });
    this.statusLine = document.createElement('div');
    this.statusLine.className = 'somview-status';
    this.statusLine.textContent = 'connecting';
    this.errorBox = document.createElement('div');
    this.errorBox.className = 'somview-error';
    this.errorBox.hidden = true;
    this.hint = document.createElement('div');
    this.hint.className = 'somview-hint';
    this.hint.hidden = true;
    this.desktop.onGroundStop = () => this.showHint(GROUND_HINT);
    container.append(this.labels.layer, this.radiusLabel, this.statusLine, this.errorBox, this.hint);
    this.presence = new Presence(container, this.clay);
    this.toolbar = new Toolbar(container, act, () => ({ orthographic: this.rig.orthographicOn,
      stroke: this.desktop.strokeTool, revolve: this.desktop.revolveTool, display: this.display.describe() }));
    this.pixelScratch = new THREE.Vector3();
    this.pixelForward = new THREE.Vector3();

    this.state = { connected: false, topology: null, frame: null, frames: 0, fps: 0, fpsCount: 0,
      fpsStart: performance.now(), digest: 0, errors: [], lastError: null, cycleMs: null, serverFps: null,
      painted: 0, paintedDigest: 0, rendered: 0, renderedAt: 0, kept: 0 };
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
    const clay = this.clay;
    // the clay drawn now, and where: a new topology of the same clay (Refine, its Undo) stays where it is
    this.state.before = clay.lastFrame && clay.positionAttr ? { box: boxOf(clay.positionAttr.array),
      offset: clay.content.position.clone(), centre: clay.centre.clone() } : null;
    this.state.topology = t;
    this.handle.select(null);
    this.desktop.dropDrag();
    this.disc.hide();
    this.clay.setTopology(t);
    this.display.apply();
    this.setReadOnly(!!t.watching);
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

  // The clay of a new topology where it was before (the camera untouched) when it is the same clay as drawn before
  // (its bounds within SAME_CLAY of its size: Refine, the Undo of a Refine); returns whether it was.
  keepPlace(before) {
    if (!before) return false;
    const box = boxOf(this.clay.positionAttr.array);
    const size = before.box.getSize(new THREE.Vector3()).length();
    const moved = Math.max(box.min.distanceTo(before.box.min), box.max.distanceTo(before.box.max));
    if (!(moved <= SAME_CLAY * size)) return false;
    this.clay.content.position.copy(before.offset);
    this.clay.centre.copy(before.centre);
    this.display.placeHelpers();
    this.clay.refreshControls();
    this.state.kept += 1;
    return true;
  }

  // World units one screen pixel spans at world point w (0 in a headset: no floor on the controls' size there).
  pixelSize(w) {
    if (this.renderer.xr.isPresenting || !this.size) return 0;
    const cam = this.rig.camera;
    const h = this.size[1];
    if (cam.isOrthographicCamera) return (cam.top - cam.bottom) / cam.zoom / h;
    const depth = this.pixelScratch.subVectors(w, cam.position).dot(cam.getWorldDirection(this.pixelForward));
    return (2 * Math.max(depth, cam.near) * Math.tan(THREE.MathUtils.degToRad(cam.fov) / 2)) / h;
  }

  // Keys to the view (its canvas takes the focus, without scrolling the page).
  focus() {
    this.renderer.domElement.focus({ preventScroll: true });
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
    if (s.needsFrame) { // the first frame of a model: frame the camera on it, unless it is the same clay
      s.needsFrame = false;
      if (!this.keepPlace(s.before)) {
        this.radius.chosen = null; // another clay: a new control's radius is its controls' again
        this.onFirstFrame ? this.onFirstFrame() : this.frame();
      }
      s.before = null;
    }
    this.onFrame?.(f);
    return true;
  }

  // A short line over the view for HINT_MS (what a gesture could not do, and what does it).
  showHint(text) {
    this.hint.textContent = text;
    this.hint.hidden = false;
    clearTimeout(this.hintTimer);
    this.hintTimer = setTimeout(() => { this.hint.hidden = true; }, HINT_MS);
  }

  // An error the server sent (a refused intent): kept for describe(), shown for 4 s over the view, or by the page's
  // own `onError` where it has one.
  showError(e) {
    const s = this.state;
    s.lastError = e.message;
    s.errors.push(e);
    if (s.errors.length > 50) s.errors.shift();
    if (this.onError) { // the page shows it itself (the XR page's panel): said once, where it is read
      this.onError(e);
      return;
    }
    this.errorBox.textContent = e.message;
    this.errorBox.hidden = false;
    clearTimeout(s.errorTimer);
    s.errorTimer = setTimeout(() => { this.errorBox.hidden = true; }, 4000);
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
      if (this.labels.due(now)) this.dirty = true;
      if (!this.dirty) return;
      // a software rasteriser dragging: draw each answer to a move at once, the frames between at most every
      // DRAG_REDRAW_MS (each drawing holds the page's thread while the CPU draws; the next answer waits behind it)
      if (this.software && this.desktop.drag && !this.grabs.answered && now - this.lastRender < DRAG_REDRAW_MS) return;
      this.labels.update(this.camera, this.size);
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
      ...this.labels.describe(), // labels, behind, markers
      ...this.rig.describe(), // camera, target, distance (to the target), fitDistance, projection, zoom
      display: this.display.describe(), selected: this.handle.selected, readOnly: !!this.readOnly,
      tool: this.desktop.strokeTool ? 'stroke' : this.desktop.revolveTool ? 'revolve' : null,
      radii: [...clay.radii], strokes: [...clay.strokes], controlIds: [...clay.controlIds],
      radiusBall: { of: this.radius.shownFor, shown: this.radius.ball.visible, radius: this.radius.ball.scale.x },
      radiusDisc: { ...this.disc.describe(), px: this.disc.disc.visible
        ? this.disc.disc.scale.x / this.pixelSize(this.disc.disc.position) : 0 }, newRadius: this.radius.newRadius, keptPlace: s.kept,
      numbered: Array.from({ length: clay.kEff }, (_, j) => clay.numbered(j)),
      tethers: clay.tethers.describe(), // the lines from controls off the clay: {control, node, gap}
      ghostSpheres: clay.controlAnchors.filter((m) => m.userData.mirror && !m.userData.quiet).length,
      strokeCopyLines: clay.strokeCopies.count, // a stroke's copies, a line each
      presence: this.presence.describe(), hint: this.hint.hidden ? null : this.hint.textContent,
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
  // The drawing tool in use: 'stroke', 'revolve' (the axis shown) or null (grab and orbit).
  // A view that only watches (the server refuses its changes): it orbits, zooms and changes its display, but takes no
  // control and draws nothing; its bar's tools are disabled with WATCHING_TIP.
  setReadOnly(on) {
    this.readOnly = on;
    this.desktop.readOnly = on;
    if (on) this.useTool(null);
    this.toolbar.setReadOnly(on, WATCHING_TIP);
    this.container.classList.toggle('somview-watching', on);
  }

  useTool(name) {
    this.desktop.strokeTool = name === 'stroke';
    this.desktop.revolveTool = name === 'revolve';
    this.guide.show(name === 'revolve');
    this.desktop.hover(null);
    this.dirty = true;
  }

  selectControl(j) {
    this.handle.select(Number.isInteger(j) && j >= 0 && j < this.clay.kEff ? j : null);
  }

  controlModel(j) {
    const m = this.clay.controlAnchors[j];
    return m ? [m.position.x, m.position.y, m.position.z] : null;
  }

  // What control j looks like as drawn: its colour, its radius over the control radius, whether it is a ghost (a
  // symmetric copy) and how opaque.
  controlLook(j) {
    const clay = this.clay;
    if (j < 0 || j >= clay.kEff) return null;
    const [d, i] = j < clay.k ? [clay.controlDraws[0], j] : [clay.controlDraws[1], j - clay.k];
    const c = new THREE.Color();
    d.getColorAt(i, c);
    const m = new THREE.Matrix4();
    d.getMatrixAt(i, m);
    return { colour: `#${c.getHexString()}`, scale: m.getMaxScaleOnAxis() / clay.controlRadius, ghost: j >= clay.k,
      opacity: d.material.opacity };
  }

  // How big effective control j is drawn on screen: its radius in page pixels (null when there is none).
  controlScreenRadius(j) {
    const w = this.clay.controlWorld(j);
    const m = this.clay.controlAnchors[j];
    if (!w || !m) return null;
    const px = this.pixelSize(w);
    return px > 0 ? (m.scale.x * this.clay.scale) / px : null;
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
