// The in-headset menu: a row of buttons (the menu's actions in actions.js: Train / Pause, Undo, Redo, Reset, smaller,
// bigger, Stroke / Grab, bring here, exit) and a status line, drawn on canvases, floating below the clay and facing
// the person.
// Pressed by pointing a ray and pulling the trigger (or pinching), or by touching a button with an index finger tip.

import * as THREE from 'three';
import { MENU_ACTIONS } from './actions.js';

const W = 0.07;
const H = 0.034;
const GAP = 0.008;

// A button's face: red while it flashes from a press, greyed (dim face, dim text) while it is disabled.
function drawLabel(canvas, text, active, enabled = true) {
  const ctx = canvas.getContext('2d');
  ctx.fillStyle = active ? '#c62828' : enabled ? '#24283a' : '#4a4c56';
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  ctx.strokeStyle = enabled ? '#8890b0' : '#6a6c76';
  ctx.lineWidth = 4;
  ctx.strokeRect(2, 2, canvas.width - 4, canvas.height - 4);
  ctx.fillStyle = enabled ? '#ffffff' : '#9a9ca6';
  ctx.font = `bold ${Math.round(canvas.height * 0.42)}px sans-serif`;
  ctx.textAlign = 'center';
  ctx.textBaseline = 'middle';
  ctx.fillText(text, canvas.width / 2, canvas.height / 2);
}

export class Menu {
  constructor(perform) {
    this.perform = perform; // action name -> function
    this.group = new THREE.Group();
    this.group.name = 'xr-menu';
    this.buttons = [];
    const total = MENU_ACTIONS.length * W + (MENU_ACTIONS.length - 1) * GAP;
    MENU_ACTIONS.forEach(({ name, label }, i) => {
      const canvas = document.createElement('canvas');
      canvas.width = 256;
      canvas.height = 124;
      drawLabel(canvas, label, false);
      const tex = new THREE.CanvasTexture(canvas);
      const mesh = new THREE.Mesh(new THREE.PlaneGeometry(W, H),
        new THREE.MeshBasicMaterial({ map: tex, transparent: true, opacity: 0.95, side: THREE.DoubleSide }));
      mesh.position.x = -total / 2 + W / 2 + i * (W + GAP);
      mesh.name = `button-${name}`;
      mesh.userData = { name, label, canvas, tex, flash: 0, enabled: true };
      this.group.add(mesh);
      this.buttons.push(mesh);
    });
    const sc = document.createElement('canvas');
    sc.width = 1024;
    sc.height = 96;
    this.statusCanvas = sc;
    this.statusTex = new THREE.CanvasTexture(sc);
    this.status = new THREE.Mesh(new THREE.PlaneGeometry(total, total * 96 / 1024),
      new THREE.MeshBasicMaterial({ map: this.statusTex, transparent: true, side: THREE.DoubleSide }));
    this.status.position.y = H / 2 + 0.006 + total * 48 / 1024;
    this.group.add(this.status);
    this.statusText = '';
    this.pressed = []; // names of the buttons pressed, oldest first
    this.touching = new Map(); // input -> button name being touched
    this.group.visible = false;
  }

  setLabel(name, label) {
    const b = this.buttons.find((m) => m.userData.name === name);
    if (!b || b.userData.label === label) return;
    b.userData.label = label;
    this.redraw(b);
  }

  // A disabled button is drawn greyed and a press on it does nothing (a page that only watches).
  setEnabled(name, enabled) {
    const b = this.buttons.find((m) => m.userData.name === name);
    if (!b || b.userData.enabled === enabled) return;
    b.userData.enabled = enabled;
    this.redraw(b);
  }

  redraw(b) {
    drawLabel(b.userData.canvas, b.userData.label, b.userData.flash > 0, b.userData.enabled);
    b.userData.tex.needsUpdate = true;
  }

  setStatus(text) {
    if (text === this.statusText) return;
    this.statusText = text;
    const ctx = this.statusCanvas.getContext('2d');
    ctx.clearRect(0, 0, 1024, 96);
    ctx.fillStyle = 'rgba(20, 22, 34, 0.8)';
    ctx.fillRect(0, 0, 1024, 96);
    ctx.fillStyle = '#ffffff';
    ctx.font = '44px sans-serif';
    ctx.textBaseline = 'middle';
    ctx.fillText(text, 20, 48);
    this.statusTex.needsUpdate = true;
  }

  press(name) {
    this.pressed.push(name);
    if (this.pressed.length > 100) this.pressed.shift();
    const b = this.buttons.find((m) => m.userData.name === name);
    if (b && !b.userData.enabled) return;
    if (b) {
      b.userData.flash = 12;
      this.redraw(b);
    }
    this.perform[name]?.();
  }

  // The button a ray hits: name or null.
  hit(raycaster) {
    if (!this.group.visible) return null;
    const hits = raycaster.intersectObjects(this.buttons, false);
    return hits.length ? hits[0].object.userData.name : null;
  }

  // The button a point touches (within 1.5 cm of its face): name or null.
  at(worldPoint) {
    if (!this.group.visible) return null;
    const local = new THREE.Vector3();
    for (const b of this.buttons) {
      b.worldToLocal(local.copy(worldPoint));
      if (Math.abs(local.x) < W / 2 && Math.abs(local.y) < H / 2 && Math.abs(local.z) < 0.015) return b.userData.name;
    }
    return null;
  }

  // The world centre and facing normal of a button (for the page's read-only test views).
  describe(name) {
    const b = this.buttons.find((m) => m.userData.name === name);
    if (!b) return null;
    b.updateWorldMatrix(true, false);
    const centre = new THREE.Vector3().setFromMatrixPosition(b.matrixWorld);
    const normal = new THREE.Vector3(0, 0, 1).transformDirection(b.matrixWorld);
    const [r, g, bl] = b.userData.canvas.getContext('2d').getImageData(8, 8, 1, 1).data; // the face's colour
    return { centre: centre.toArray(), normal: normal.toArray(), label: b.userData.label, enabled: b.userData.enabled,
      face: [r, g, bl] };
  }

  // Finger-tip touches: press a button when a tip comes within 1.5 cm of its face, once per touch.
  touch(key, worldPoint) {
    if (!this.group.visible) return;
    const touched = this.at(worldPoint);
    const before = this.touching.get(key) || null;
    if (touched && touched !== before) this.press(touched);
    this.touching.set(key, touched);
  }

  tick() {
    for (const b of this.buttons) {
      if (b.userData.flash > 0) {
        b.userData.flash -= 1;
        if (b.userData.flash === 0) this.redraw(b);
      }
    }
  }
}
