// Mouse, touch and keys on a flat screen. A press goes to what is visible under it: the selected control's handle
// (handle.js), the Stroke tool while it is on (stroke.js), a control not hidden by the clay (drag it on the plane
// facing the camera; with Shift along the model axis closest to the motion only), else the orbit (camera.js: drag to
// orbit, right-drag to pan). A click on a control selects it (its handle shows), a double click on the clay adds a
// control there, the wheel over a control sets its radius (radius.js) and elsewhere zooms towards the cursor.
//
// Keys while the pointer is over the view (or it has the focus): 1-6 the axis views, F fit, O orthographic, S the
// Stroke tool, Delete (Backspace) removes the control under the pointer, Esc lets the selection (or a stroke) go.

import * as THREE from 'three';
import { VIEWS } from './camera.js';
import { intents } from './protocol.js';

const PAD = 1.2; // a control is hit within this many times its drawn radius
const CLICK_PX = 4; // a press and release closer than this is a click

const editable = (el) => el && (el.tagName === 'INPUT' || el.tagName === 'TEXTAREA' || el.tagName === 'SELECT'
  || el.isContentEditable);

export class Desktop {
  // rig: the CameraRig; handle: the Handle; radius: the RadiusBall; stroke: the StrokeDraw; act: the view's actions
  // for keys {fit(), look(name), orthographic(on), stroke(on)}; onDragStart / onDragEnd: a control drag begins / ends
  constructor({ renderer, rig, clay, grabs, link, handle, radius, stroke, act, onDragStart, onDragEnd }) {
    this.renderer = renderer;
    this.rig = rig;
    this.clay = clay;
    this.grabs = grabs;
    this.link = link;
    this.handle = handle;
    this.radius = radius;
    this.stroke = stroke;
    this.act = act;
    this.onDragStart = onDragStart;
    this.onDragEnd = onDragEnd;
    this.raycaster = new THREE.Raycaster();
    this.drag = null;
    this.press = null; // where the last left press went down (to tell a click)
    this.strokeTool = false;
    this.hovered = null; // the effective control under the pointer
    this.stats = { drags: 0, moves: 0, adds: 0, removes: 0, strokes: 0, radii: 0, hiddenPresses: 0 };
    const el = renderer.domElement;
    el.tabIndex = 0; // keys go to the view that has the focus
    el.dataset.lmSuppressShortcuts = 'true'; // JupyterLab leaves its own keys to the view while it has the focus
    el.addEventListener('pointerdown', (ev) => this.down(ev), { capture: true });
    el.addEventListener('pointermove', (ev) => this.move(ev));
    el.addEventListener('pointerup', (ev) => this.up(ev));
    el.addEventListener('pointercancel', (ev) => this.up(ev));
    el.addEventListener('pointerenter', () => {
      if (!editable(document.activeElement)) el.focus({ preventScroll: true });
    });
    el.addEventListener('pointerleave', () => this.hover(null));
    el.addEventListener('wheel', (ev) => this.wheel(ev), { capture: true, passive: false });
    el.addEventListener('dblclick', (ev) => this.doubleClick(ev));
    el.addEventListener('keydown', (ev) => this.key(ev));
  }

  get presenting() {
    return this.renderer.xr.isPresenting;
  }

  ray(ev) {
    const r = this.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((ev.clientX - r.left) / r.width) * 2 - 1, -((ev.clientY - r.top) / r.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.rig.camera);
    return this.raycaster;
  }

  // The control under the pointer that the person can see: a control behind the clay is taken only where no clay
  // is in front of it. {index, distance, point} or null; `hidden` counts a press on a hidden one.
  visibleControl(raycaster, hidden = null) {
    const hit = this.clay.hitByRay(raycaster, PAD);
    if (!hit) return null;
    const surface = this.clay.surfaceHit(raycaster);
    if (surface && surface.distance < hit.distance) {
      if (hidden) hidden.count += 1;
      return null;
    }
    return hit;
  }

  hover(j) {
    this.hovered = j;
    this.clay.setHover(j === null ? new Set() : new Set([j]));
    this.radius.show(j ?? this.handle.selected);
    this.renderer.domElement.style.cursor = this.strokeTool ? 'crosshair' : j !== null ? 'grab' : '';
  }

  down(ev) {
    if (this.presenting) return;
    this.renderer.domElement.focus({ preventScroll: true });
    if (ev.button !== 0) return;
    if (this.handle.wants()) { // the handle's own listener takes it from here
      this.press = null;
      this.rig.orbit.enabled = false;
      return;
    }
    this.press = { x: ev.clientX, y: ev.clientY, control: null };
    if (this.strokeTool) {
      ev.stopImmediatePropagation();
      ev.preventDefault();
      this.renderer.domElement.setPointerCapture?.(ev.pointerId);
      this.stroke.begin(this.strokePoint(ev));
      return;
    }
    const hidden = { count: 0 };
    const hit = this.visibleControl(this.ray(ev), hidden);
    this.stats.hiddenPresses += hidden.count;
    if (!hit) return;
    ev.stopImmediatePropagation(); // the orbit controls do not see this press
    ev.preventDefault();
    this.press.control = hit.index;
    this.beginDrag(hit.index, ev);
  }

  beginDrag(j, ev) {
    const i = this.clay.originalOf(j);
    const centre = this.clay.controlWorld(j);
    const normal = this.rig.camera.getWorldDirection(new THREE.Vector3());
    const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(normal, centre);
    const onPlane = this.raycaster.ray.intersectPlane(plane, new THREE.Vector3()) || centre.clone();
    this.drag = { i, j, copy: this.clay.copyOf(j), plane, offset: centre.clone().sub(onPlane), pointer: ev.pointerId,
      start: this.clay.worldToModel(centre) };
    this.renderer.domElement.setPointerCapture?.(ev.pointerId);
    this.renderer.domElement.style.cursor = 'grabbing';
    this.grabs.begin(i);
    this.stats.drags += 1;
    this.onDragStart?.();
  }

  move(ev) {
    if (this.presenting) return;
    if (this.stroke.drawing) {
      this.stroke.add(this.strokePoint(ev));
      return;
    }
    if (!this.drag) {
      if (ev.buttons || this.handle.held) return; // orbiting, panning or moving by the handle
      const hit = this.strokeTool ? null : this.visibleControl(this.ray(ev));
      this.hover(hit ? hit.index : null);
      return;
    }
    const p = this.ray(ev).ray.intersectPlane(this.drag.plane, new THREE.Vector3());
    if (!p) return;
    let model = this.clay.worldToModel(p.add(this.drag.offset));
    if (ev.shiftKey) { // along one axis: the one the hand moved along most
      const d = model.map((v, a) => v - this.drag.start[a]);
      const axis = d.reduce((best, v, a) => (Math.abs(v) > Math.abs(d[best]) ? a : best), 0);
      model = this.drag.start.map((v, a) => (a === axis ? v + d[a] : v));
    }
    this.grabs.update(this.drag.i, this.clay.unmap(this.drag.copy, model)); // a copy's point, mapped back
    this.stats.moves += 1;
  }

  up(ev) {
    this.rig.orbit.enabled = true;
    const press = this.press;
    this.press = null;
    const click = press && ev.button === 0 && Math.hypot(ev.clientX - press.x, ev.clientY - press.y) < CLICK_PX;
    if (this.stroke.drawing) {
      this.renderer.domElement.releasePointerCapture?.(ev.pointerId);
      if (this.stroke.end()) this.stats.strokes += 1;
      return;
    }
    if (this.drag) {
      this.move(ev);
      this.grabs.end(this.drag.i);
      this.renderer.domElement.releasePointerCapture?.(this.drag.pointer);
      this.renderer.domElement.style.cursor = '';
      this.drag = null;
      this.onDragEnd?.();
    }
    if (click && !this.handle.held) this.handle.select(press.control); // a click on empty space lets go
  }

  // Where a stroke goes under the pointer: on the clay, else on the plane through the target facing the camera.
  strokePoint(ev) {
    const rc = this.ray(ev);
    const surface = this.clay.surfaceHit(rc);
    return surface ? surface.point : this.rig.onTargetPlane(rc.ray);
  }

  wheel(ev) {
    if (this.presenting) return;
    ev.preventDefault();
    ev.stopImmediatePropagation();
    const j = this.drag ? this.drag.j : this.hovered;
    if (j !== null && j !== undefined && !this.strokeTool) {
      this.radius.show(j);
      this.radius.turn(j, ev.deltaY);
      this.stats.radii += 1;
      return;
    }
    const rc = this.ray(ev);
    const surface = this.clay.surfaceHit(rc);
    this.rig.zoomAt(ev.deltaY, surface ? surface.point : this.rig.onTargetPlane(rc.ray));
  }

  // A double click on the clay (not on a control) adds a control at that point of its surface.
  doubleClick(ev) {
    if (this.presenting || this.strokeTool) return;
    const rc = this.ray(ev);
    if (this.visibleControl(rc)) return;
    const surface = this.clay.surfaceHit(rc);
    if (!surface) return;
    if (this.link.send(intents.add(this.clay.worldToModel(surface.point).map((v) => Number(v.toPrecision(7)))))) {
      this.stats.adds += 1;
    }
  }

  key(ev) {
    if (ev.ctrlKey || ev.metaKey || ev.altKey || editable(ev.target) || this.presenting) return;
    const k = ev.key.toLowerCase();
    const view = Object.entries(VIEWS).find(([, v]) => v.key === k);
    if (view) this.act.look(view[0]);
    else if (k === 'f') this.act.fit();
    else if (k === 'o') this.act.orthographic(!this.rig.orthographicOn);
    else if (k === 's') this.act.stroke(!this.strokeTool);
    else if (k === 'delete' || k === 'backspace') this.removeHovered();
    else if (k === 'escape') {
      if (this.stroke.drawing) this.stroke.cancel();
      else if (this.strokeTool) this.act.stroke(false);
      else this.handle.select(null);
    } else return;
    ev.preventDefault();
    ev.stopPropagation();
  }

  removeHovered() {
    const j = this.hovered ?? this.handle.selected;
    if (j === null || this.drag) return;
    const i = this.clay.originalOf(j);
    if (this.link.send(intents.remove(this.clay.controlIds[i] ?? i))) {
      this.stats.removes += 1;
      if (this.handle.selected !== null && this.clay.originalOf(this.handle.selected) === i) this.handle.select(null);
      this.hover(null);
    }
  }
}
