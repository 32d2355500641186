// somwidget XR: the clay on a headset (WebXR immersive-ar, else immersive-vr) and, without one, a desktop preview.
// It shares the server's modelling session through the websocket /xr/ws (see protocol.js).

import './colour.js';
import * as THREE from 'three';
import { Clay } from './clay.js';
import { Desktop } from './desktop.js';
import { Grabs } from './grabs.js';
import { Link, socketURL } from './link.js';
import { Menu } from './menu.js';
import { intents } from './protocol.js';
import { XRApp } from './xr.js';

const $ = (id) => document.getElementById(id);
const ui = {
  status: $('status'), error: $('error'), ar: $('enter-ar'), vr: $('enter-vr'), train: $('train'),
  reset: $('reset'), title: $('title'), undo: $('undo'), redo: $('redo'),
};

const renderer = new THREE.WebGLRenderer({ antialias: true, alpha: true });
renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
renderer.setSize(window.innerWidth, window.innerHeight);
renderer.xr.enabled = true;
document.body.appendChild(renderer.domElement);

const scene = new THREE.Scene();
const desktopBackground = new THREE.Color(0xeef0f4);
scene.background = desktopBackground;
scene.add(new THREE.HemisphereLight(0xffffff, 0x667080, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(1.5, 3, 2);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(50, window.innerWidth / window.innerHeight, 0.01, 100);

const clay = new Clay();
scene.add(clay.stage);

const state = {
  connected: false, topology: null, frame: null, frames: 0, fps: 0, errors: [], paused: false, running: false,
  lastError: null, mode: null, digest: 0, xrFrames: 0, fpsCount: 0, fpsStart: performance.now(),
};

function digestOf(positions) {
  // a cheap checksum of the positions (to tell a changed mesh from an unchanged one)
  let s = 0;
  const step = Math.max(1, Math.floor(positions.length / 4096));
  for (let i = 0; i < positions.length; i += step) s = (s * 31 + positions[i] * 1000.5) % 1e9;
  return s;
}

let grabs = null;
const link = new Link(socketURL(), {
  onStatus: (s) => {
    state.connected = s === 'connected';
    state.linkStatus = s;
    showStatus();
  },
  onTopology: (t) => {
    state.topology = t;
    clay.setTopology(t);
    if (xr.session) {
      xr.wantPlace = true;
    } else {
      desktop.frame();
    }
    ui.title.textContent = `somwidget XR: ${t.title}`;
  },
  onFrame: (f) => {
    if (!clay.applyFrame(f)) return;
    state.frame = f;
    state.frames += 1;
    state.fpsCount += 1;
    state.paused = f.paused;
    state.running = f.running;
    const d = digestOf(f.positions);
    state.digest = d;
    grabs.onFrame(f, d);
  },
  onGrabs: (list) => grabs.onGrabs(list),
  onError: (e) => {
    state.lastError = e.message;
    state.errors.push(e);
    if (state.errors.length > 50) state.errors.shift();
    ui.error.textContent = e.message;
    ui.error.hidden = false;
    clearTimeout(state.errorTimer);
    state.errorTimer = setTimeout(() => { ui.error.hidden = true; }, 4000);
  },
});
grabs = new Grabs(link, clay);

function toggleTraining() {
  link.send(state.paused ? intents.train() : intents.pause());
}

const menu = new Menu({
  train: toggleTraining,
  undo: () => link.send(intents.undo()),
  redo: () => link.send(intents.redo()),
  reset: () => link.send(intents.reset()),
  smaller: () => xr.rescale(1 / 1.25),
  bigger: () => xr.rescale(1.25),
  here: () => { xr.wantPlace = true; },
  exit: () => xr.exit(),
});

const xr = new XRApp({
  renderer, scene, clay, grabs, menu,
  onMode: (mode) => {
    state.mode = mode;
    if (!mode) {
      scene.background = desktopBackground;
      if (state.topology) desktop.frame();
    }
    document.body.classList.toggle('immersive', !!mode);
    showStatus();
  },
});
const desktop = new Desktop({ renderer, camera, clay, grabs });

ui.train.addEventListener('click', toggleTraining);
ui.reset.addEventListener('click', () => link.send(intents.reset()));
ui.undo.addEventListener('click', () => link.send(intents.undo()));
ui.redo.addEventListener('click', () => link.send(intents.redo()));
// Ctrl+Z undoes, Ctrl+Shift+Z (or Ctrl+Y) redoes; Cmd on a Mac
window.addEventListener('keydown', (e) => {
  if (!(e.ctrlKey || e.metaKey) || e.altKey) return;
  const key = e.key.toLowerCase();
  if (key === 'z' && !e.shiftKey) link.send(intents.undo());
  else if ((key === 'z' && e.shiftKey) || key === 'y') link.send(intents.redo());
  else return;
  e.preventDefault();
});
async function enter(mode) {
  try {
    await xr.enter(mode);
  } catch (err) {
    link.handlers.onError({ message: `could not start ${mode}: ${err.message || err}` });
  }
}
ui.ar.addEventListener('click', () => enter('immersive-ar'));
ui.vr.addEventListener('click', () => enter('immersive-vr'));

XRApp.supportedModes().then((m) => {
  state.supported = m;
  ui.ar.hidden = !m.ar;
  ui.vr.hidden = !m.vr;
  if (!m.ar && !m.vr) $('no-xr').hidden = false;
});

function showStatus() {
  const f = state.frame;
  const t = state.topology;
  const parts = [state.connected ? 'connected' : (state.linkStatus || 'connecting')];
  if (t) parts.push(`${t.preset}, ${t.n_nodes} nodes`);
  if (f) {
    parts.push(`iteration ${f.iteration} / ${f.iterations}`);
    parts.push(f.running ? 'training' : f.paused ? 'paused' : 'converged');
    parts.push(`${state.fps.toFixed(0)} frames/s`);
  }
  if (state.mode) parts.push(state.mode.replace('immersive-', '').toUpperCase());
  const text = parts.join(' \u00b7 ');
  ui.status.textContent = text;
  ui.train.textContent = state.paused ? 'Train' : 'Pause';
  ui.undo.disabled = !(f && f.canUndo);
  ui.redo.disabled = !(f && f.canRedo);
  menu.setLabel('train', state.paused ? 'Train' : 'Pause');
  menu.setStatus(f ? `${t ? t.title : ''}  ${f.iteration}/${f.iterations}  ${f.running ? 'training' : f.paused
    ? 'paused' : 'converged'}` : text);
}

function onResize() {
  camera.aspect = window.innerWidth / window.innerHeight;
  camera.updateProjectionMatrix();
  if (!renderer.xr.isPresenting) renderer.setSize(window.innerWidth, window.innerHeight);
}
window.addEventListener('resize', onResize);

let lastStatus = 0;
renderer.setAnimationLoop((time, xrFrame) => {
  if (xrFrame) {
    xr.update(xrFrame);
    state.xrFrames += 1;
  }
  grabs.flush();
  const now = performance.now();
  if (now - state.fpsStart >= 1000) {
    state.fps = (1000 * state.fpsCount) / (now - state.fpsStart);
    state.fpsCount = 0;
    state.fpsStart = now;
  }
  if (now - lastStatus > 250) {
    lastStatus = now;
    showStatus();
  }
  renderer.render(scene, camera);
});

// Read-only views of the page for tests, benchmarks and the console (nothing here sends an intent).
window.somxr = {
  state: () => ({
    connected: state.connected, hasTopology: !!state.topology, frames: state.frames, fps: state.fps,
    seq: state.frame ? state.frame.seq : null, generation: state.frame ? state.frame.generation : null,
    iteration: state.frame ? state.frame.iteration : null, paused: state.paused, running: state.running,
    mode: state.mode, transparent: scene.background === null, xrFrames: state.xrFrames, presenting: renderer.xr.isPresenting, supported: state.supported || null,
    digest: state.digest, k: clay.k, kEff: clay.kEff, held: [...clay.held], local: [...clay.local.keys()],
    hover: [...clay.hover], errors: state.errors.map((e) => e.message), lastError: state.lastError,
    link: { ...link.stats }, moves: grabs.moves, latencies: [...grabs.latencies],
    controlLatencies: [...grabs.controlLatencies], xr: { ...xr.stats }, pressed: [...menu.pressed], desktop: { ...desktop.stats },
    scale: clay.scale, stage: clay.stage.position.toArray(), inputs: xr.describeInputs(),
  }),
  controlWorld: (j) => clay.controlWorld(j)?.toArray() ?? null,
  controlScreen: (j) => {
    const w = clay.controlWorld(j);
    if (!w) return null;
    const p = w.project(camera);
    const r = renderer.domElement.getBoundingClientRect();
    return [r.left + ((p.x + 1) / 2) * r.width, r.top + ((1 - p.y) / 2) * r.height];
  },
  controlModel: (j) => {
    const m = clay.controlMeshes[j];
    return m ? [m.position.x, m.position.y, m.position.z] : null;
  },
  controlLook: (j) => {
    const m = clay.controlMeshes[j];
    return m ? { colour: `#${m.material.color.getHexString()}`, scale: m.scale.x / clay.controlRadius } : null;
  },
  button: (name) => menu.describe(name),
  serverControl: (j) => clay.controlMeshes[j]?.userData.server ?? null,
  modelToWorld: (p) => clay.modelToWorld(p).toArray(),
  worldToModel: (p) => clay.worldToModel(new THREE.Vector3().fromArray(p)),
  positions: (count = 12) => (state.frame ? Array.from(state.frame.positions.slice(0, 3 * count)) : []),
  inputs: () => xr.describeInputs(),
  latencyLog: () => grabs.latencyLog.map((e) => ({ ...e })),
  now: () => performance.now(),
  worldRadius: () => clay.worldRadius,
  worldControlRadius: () => clay.worldControlRadius,
};
