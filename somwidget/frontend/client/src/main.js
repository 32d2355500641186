// somwidget XR: the clay on a headset (WebXR immersive-ar, else immersive-vr) and, without one, a desktop preview.
// It shares the server's modelling session through the websocket /view/ws (link.js, protocol.js).

import * as THREE from 'three';
import { HUD_ACTIONS, trainLabel } from './actions.js';
import { Link, socketURL } from './link.js';
import { Menu } from './menu.js';
import { intents } from './protocol.js';
import { ClayView, WATCHING_TIP } from './view.js';
import { XRApp } from './xr.js';
import { HandTools } from './xrtools.js';

const $ = (id) => document.getElementById(id);

// The HUD's buttons (actions.js) into the page's empty #buttons, with a space between them as in written HTML.
function buildButtons(container) {
  const buttons = {};
  for (const a of HUD_ACTIONS) {
    if (container.childElementCount) container.append(' ');
    const button = document.createElement('button');
    button.id = a.name;
    button.textContent = a.label;
    if (a.title) button.title = a.title;
    button.hidden = !!a.hidden;
    button.disabled = !!a.disabled;
    container.append(button);
    buttons[a.name] = button;
  }
  return buttons;
}

const buttons = buildButtons($('buttons'));
const ui = {
  status: $('status'), error: $('error'), ar: buttons['enter-ar'], vr: buttons['enter-vr'], train: buttons.train,
  title: $('title'), undo: buttons.undo, redo: buttons.redo,
};

let link = null;
const view = new ClayView($('view'), { send: (obj) => (link ? link.send(obj) : false), xr: true });
const { renderer, scene, clay, grabs, desktop } = view;
const state = view.state;
state.mode = null;
state.xrFrames = 0;
state.paused = false;
state.running = false;

// the person's name where they gave one (a studio's lobby passes it on as ?who=): the others see it, not "desktop 2"
const who = (new URLSearchParams(location.search).get('who') || '').trim().slice(0, 40) || undefined;
const handlers = view.handlers;
link = new Link(socketURL(), {
  ...handlers,
  onStatus: (s) => {
    handlers.onStatus(s);
    // a new connection starts as a desktop with no name
    if (s === 'connected' && (state.mode || who)) link.send(intents.hand(state.mode ? 'headset' : 'desktop', who));
    showStatus();
  },
  // a failed autosave stays on the HUD (and the headset menu's status) until a save is on disk again
  onAutosave: (msg) => {
    state.autosave = msg.ok ? null : msg.message;
    showSaving();
    showStatus();
  },
});

// A refused intent, on the HUD's error line for 4 s (not over the view as well: the panel is where it is read).
view.onError = (e) => {
  ui.error.textContent = e.message;
  ui.error.hidden = false;
  clearTimeout(state.hudErrorTimer);
  state.hudErrorTimer = setTimeout(showSaving, 4000);
};

// The HUD's error line: the autosave's failure while saves fail, else nothing (a refused intent shows for 4 s).
function showSaving() {
  ui.error.textContent = state.autosave || '';
  ui.error.hidden = !state.autosave;
}
view.transport = link;
// the page's own name first (a studio's room page names its room: "somwidget: alice"), then the clay's
const pageTitle = ui.title.textContent;
const noXR = $('no-xr');
const noXRText = noXR.textContent;
// the actions that change the clay: disabled on a page that only watches, their tooltip saying why
const EDITS = ['train', 'undo', 'redo', 'reset', 'stroke'];
const watching = () => !!state.topology?.watching;
view.onTopology = (t) => {
  ui.title.textContent = `${pageTitle}: ${t.title}`;
  for (const name of EDITS) {
    const b = buttons[name];
    if (!b) continue;
    b.dataset.title ??= b.title;
    b.title = t.watching ? WATCHING_TIP : b.dataset.title;
  }
  for (const name of EDITS) menu.setEnabled(name, !t.watching); // the headset's menu greys them too
  document.body.classList.toggle('watching', !!t.watching);
  noXR.textContent = t.watching ? `Watching only: drag to orbit, wheel to zoom. To change the clay, ${
    WATCHING_TIP.replace('watching only: ', '')}.` : noXRText;
  showStatus();
};
view.onFirstFrame = () => {
  if (xr.session) xr.wantPlace = true;
  else view.frame();
};
view.onFrame = (f) => {
  state.paused = f.paused;
  state.running = f.running;
};

async function enter(mode) {
  try {
    await xr.enter(mode);
  } catch (err) {
    link.handlers.onError({ message: `could not start ${mode}: ${err.message || err}` });
  }
}

// What each action (actions.js) does, for the HUD's buttons and the headset menu's alike.
const perform = {
  'enter-ar': () => enter('immersive-ar'),
  'enter-vr': () => enter('immersive-vr'),
  train: () => link.send(state.running ? intents.pause() : intents.train()),
  undo: () => link.send(intents.undo()),
  redo: () => link.send(intents.redo()),
  reset: () => link.send(intents.reset()),
  smaller: () => xr.rescale(1 / 1.25),
  bigger: () => xr.rescale(1.25),
  stroke: () => {
    tools.setOn(!tools.on);
    menu.setLabel('stroke', tools.on ? 'Grab' : 'Stroke'); // what a press does next
  },
  here: () => { xr.wantPlace = true; },
  exit: () => xr.exit(),
};

const menu = new Menu(perform);
const tools = new HandTools({ clay, stroke: view.stroke, radius: view.radius });

const xr = new XRApp({
  renderer, scene, clay, grabs, menu, tools, radius: view.radius,
  onMode: (mode) => {
    state.mode = mode;
    link.send(intents.hand(mode ? 'headset' : 'desktop', who)); // what the others see this view as
    if (!mode) {
      scene.background = view.background;
      if (state.frame) view.frame();
    }
    document.body.classList.toggle('immersive', !!mode);
    showStatus();
  },
});

for (const [name, action] of Object.entries(perform)) { // a page that only watches sends no change
  if (EDITS.includes(name)) perform[name] = () => (watching() ? undefined : action());
}
for (const [name, button] of Object.entries(buttons)) button.addEventListener('click', () => perform[name]());
// Ctrl+Z undoes, Ctrl+Shift+Z (or Ctrl+Y) redoes; Cmd on a Mac
window.addEventListener('keydown', (e) => {
  if (!(e.ctrlKey || e.metaKey) || e.altKey) return;
  const key = e.key.toLowerCase();
  if (key === 'z' && !e.shiftKey) perform.undo();
  else if ((key === 'z' && e.shiftKey) || key === 'y') perform.redo();
  else return;
  e.preventDefault();
});

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
  ui.train.textContent = trainLabel(f);
  ui.undo.disabled = watching() || !(f && f.canUndo);
  ui.redo.disabled = watching() || !(f && f.canRedo);
  ui.train.disabled = watching();
  buttons.reset.disabled = watching();
  menu.setLabel('train', trainLabel(f));
  const others = view.presence.summary(); // who else is on the session, in the headset's menu
  menu.setStatus(state.autosave ? 'NOT SAVED: autosave failed, trying again' : f ? `${watching() ? 'WATCHING ONLY  ' : ''}${
    t ? t.title : ''}  ${
    f.iteration}/${f.iterations}  ${f.running ? 'training' : f.paused ? 'paused' : 'converged'}${
    others ? `  ${others}` : ''}` : text);
}

let lastStatus = 0;
view.hooks.push((time, xrFrame) => {
  if (xrFrame) {
    xr.update(xrFrame);
    state.xrFrames += 1;
  }
  const now = performance.now();
  if (now - lastStatus > 250) {
    lastStatus = now;
    showStatus();
  }
});

// Read-only views of the page for tests, benchmarks and the console (nothing here sends an intent).
window.somxr = {
  state: () => ({
    connected: state.connected, hasTopology: !!state.topology, frames: state.frames, fps: state.fps,
    seq: state.frame ? state.frame.seq : null, generation: state.frame ? state.frame.generation : null,
    iteration: state.frame ? state.frame.iteration : null, paused: state.paused, running: state.running,
    watching: watching(), mode: state.mode, transparent: scene.background === null, xrFrames: state.xrFrames, presenting: renderer.xr.isPresenting, supported: state.supported || null,
    digest: state.digest, k: clay.k, kEff: clay.kEff, held: [...clay.held], local: [...clay.local.keys()],
    group: clay.group, groupMaps: clay.groupMaps.map((m) => [...m]),
    hover: [...clay.hover], errors: state.errors.map((e) => e.message), lastError: state.lastError,
    autosave: state.autosave || null, hudError: ui.error.hidden ? null : ui.error.textContent,
    menuStatus: menu.statusText, link: { ...link.stats }, moves: grabs.moves, latencies: [...grabs.latencies],
    controlLatencies: [...grabs.controlLatencies], xr: { ...xr.stats }, pressed: [...menu.pressed], desktop: { ...desktop.stats },
    scale: clay.scale, stage: clay.stage.position.toArray(), inputs: xr.describeInputs(), tools: tools.describe(),
    radii: [...clay.radii], strokes: [...clay.strokes], presence: view.presence.describe(),
  }),
  controlWorld: (j) => clay.controlWorld(j)?.toArray() ?? null,
  controlScreen: (j) => {
    const w = clay.controlWorld(j);
    if (!w) return null;
    const p = w.project(view.camera);
    const r = renderer.domElement.getBoundingClientRect();
    return [r.left + ((p.x + 1) / 2) * r.width, r.top + ((1 - p.y) / 2) * r.height];
  },
  controlModel: (j) => view.controlModel(j),
  controlLook: (j) => view.controlLook(j),
  button: (name) => menu.describe(name),
  serverControl: (j) => clay.controlAnchors[j]?.userData.server ?? null,
  modelToWorld: (p) => clay.modelToWorld(p).toArray(),
  worldToModel: (p) => clay.worldToModel(new THREE.Vector3().fromArray(p)),
  positions: (count = 12) => (state.frame ? Array.from(state.frame.positions.slice(0, 3 * count)) : []),
  inputs: () => xr.describeInputs(),
  latencyLog: () => grabs.latencyLog.map((e) => ({ ...e })),
  now: () => performance.now(),
  worldRadius: () => clay.worldRadius,
  worldControlRadius: () => clay.worldControlRadius,
};
