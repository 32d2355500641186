// Mouse, touch and keys on a flat screen. A press goes to what is visible under it: the selected control's handle
// (handle.js), a control (also while the Stroke or Revolve tool is on, save a control on the revolve axis: a press
// there starts the profile on the axis, revolve.js; before the clay: a
// control lying on the surface is taken even where the clay shows in front of part of it, and a small one within
// PICKED_PX of it; a control the clay hides is not; a placed control before its ghosts), the Stroke or Revolve tool
// while it is on (stroke.js, revolve.js: a press off every control draws), else the orbit (camera.js:
// drag to orbit, right-drag to pan; an orbit stopped by the ground says so). A drag moves the control on the plane facing the camera (a radial copy seen
// nearly side-on: in its meridian plane; with Shift along the model axis closest to the motion only). A click on
// a control selects it (its handle shows), a double click on the clay adds a control there (the radius the disc
// shows), the wheel over a control sets its radius (radius.js) and elsewhere zooms towards the cursor; Alt+wheel
// sets the radius the disc under the cursor shows (the control's, or a new control's). The keys: keys.js.

import * as THREE from 'three';
import { VIEWS } from './camera.js';
import { isTyping, viewAction } from './keys.js';
import { controlsAlong, hidesControl } from './picking.js';
import { intents } from './protocol.js';

const PAD = 1.2; // a control is hit within this many times its drawn radius
const CLICK_PX = 4; // a press and release closer than this is a click
const KEY_NOTCH = 100; // [ and ] turn a radius as one wheel notch does
const READ_ONLY_KEYS = new Set(['fit', 'ortho', 'escape']); // a view that only watches: these and the looks
const MERIDIAN_FACING = (30 * Math.PI) / 180; // a radial copy faced this near its meridian plane is dragged in it

export class Desktop {
  // rig: the CameraRig; handle: the Handle; radius: the RadiusBall; stroke: the StrokeDraw; guide: the RevolveGuide;
  // act: the view's actions for keys {fit(), look(name), orthographic(on), stroke(on), revolve(on)}; onDragStart /
  // onDragEnd: a control drag begins / ends
  constructor({ renderer, rig, clay, grabs, link, handle, radius, disc, stroke, guide, act, onDragStart, onDragEnd }) {
    this.renderer = renderer;
    this.disc = disc; // the RadiusDisc: the radius under the cursor
    this.rig = rig;
    this.clay = clay;
    this.grabs = grabs;
    this.link = link;
    this.handle = handle;
    this.radius = radius;
    this.stroke = stroke;
    this.guide = guide;
    this.act = act;
    this.onDragStart = onDragStart;
    this.onDragEnd = onDragEnd;
    this.raycaster = new THREE.Raycaster();
    this.sightRay = new THREE.Raycaster(); // from the eye to a control (is it hidden?)
    this.drag = null;
    this.press = null; // where the last left press went down (to tell a click)
    this.strokeTool = false;
    this.revolveTool = false; // a profile drawn beside the axis lathes the clay
    this.hovered = null; // the effective control under the pointer
    this.readOnly = false; // the view only watches: a press orbits, nothing is sent (view.js setReadOnly)
    this.pointer = null; // the last pointer event over the view (null: the pointer is elsewhere)
    this.onGroundStop = null; // an orbit drag upward met the ground (the view says so)
    this.onEscape = null; // after Escape's own work (a notebook: the focus goes back to it, keys.js focusHost)
    this.stats = { drags: 0, moves: 0, adds: 0, removes: 0, strokes: 0, revolves: 0, radii: 0, hiddenPresses: 0,
      keys: 0, undos: 0, redos: 0, groundStops: 0 };
    const el = renderer.domElement;
    el.tabIndex = 0; // keys go to the view that has the focus
    el.dataset.lmSuppressShortcuts = 'true'; // JupyterLab leaves its own keys to the view while it has the focus
    el.addEventListener('pointerdown', (ev) => this.down(ev), { capture: true });
    el.addEventListener('pointermove', (ev) => this.move(ev));
    el.addEventListener('pointerup', (ev) => this.up(ev));
    el.addEventListener('pointercancel', (ev) => this.up(ev));
    el.addEventListener('pointerenter', () => {
      if (!isTyping(document.activeElement)) el.focus({ preventScroll: true });
    });
    el.addEventListener('pointerleave', () => {
      this.pointer = null;
      this.hover(null);
      this.disc?.hide();
    });
    el.addEventListener('wheel', (ev) => this.wheel(ev), { capture: true, passive: false });
    el.addEventListener('dblclick', (ev) => this.doubleClick(ev));
    // every key in the view (its canvas, its bar, its Display menu) is the view's first
    el.parentElement?.addEventListener('keydown', (ev) => this.key(ev), true);
  }

  // A press draws (a stroke, or a profile to revolve) rather than grabbing or orbiting.
  get drawTool() {
    return this.strokeTool || this.revolveTool;
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

  // The control under the pointer that the person can see, picked before the clay: of the controls the ray passes
  // within their pick radius and the clay does not hide (picking.js: one lying on the surface shows, also where the
  // clay covers part of its sphere), one whose drawn sphere the ray meets wins (the nearest), else the one it passes
  // closest (for its size); a placed control within its pick radius wins over any ghost. {index, distance} or null; `hidden` counts a press that met only hidden controls.
  visibleControl(raycaster, hidden = null) {
    const candidates = controlsAlong(this.clay, raycaster, PAD);
    if (!candidates.length) return null;
    const seen = candidates.filter((c) => !hidesControl(this.clay, c.index, this.rig.camera, this.sightRay));
    if (!seen.length) {
      if (hidden) hidden.count += 1;
      return null;
    }
    // a control the person placed within its pick radius wins over the ghosts (a radial group's copies lie just
    // beside it on screen, in front of it or behind it)
    const placed = seen.filter((c) => !c.ghost);
    const pool = placed.length ? placed : seen;
    const onSphere = pool.filter((c) => c.off <= c.drawn).sort((a, b) => a.along - b.along);
    const best = onSphere[0] || pool.sort((a, b) => a.off / a.reach - b.off / b.reach)[0];
    return { index: best.index, distance: best.along };
  }

  hover(j) {
    this.hovered = j;
    this.clay.setHover(j === null ? new Set() : new Set([j]));
    this.radius.show(j ?? this.handle.selected);
    this.renderer.domElement.style.cursor = j !== null ? 'grab' : this.drawTool ? 'crosshair' : '';
  }

  // The radius under the cursor: the dragged control's, the hovered one's, else a new control's where the cursor is
  // over the clay (or while the Stroke tool is on); hidden elsewhere, while orbiting and while the handle moves.
  showDisc(ev, rc = this.ray(ev)) {
    if (!this.disc) return;
    if (!ev || this.readOnly || this.handle.held || (ev.buttons && !this.drag && !this.stroke.drawing)) {
      this.disc.hide();
      return;
    }
    const r = this.renderer.domElement.getBoundingClientRect();
    const at = [ev.clientX - r.left, ev.clientY - r.top];
    const hit = this.clay.surfaceHit(rc);
    const j = this.drag ? this.drag.j : this.hovered;
    if (j !== null && j !== undefined) {
      this.disc.show(j, { hit, centre: this.clay.controlWorld(j), facing: this.rig.camera.getWorldDirection(
        new THREE.Vector3()), at });
    } else if (hit || this.drawTool) {
      this.disc.show('new', { hit, centre: hit ? null : this.strokePoint(ev), facing:
        this.rig.camera.getWorldDirection(new THREE.Vector3()), at });
    } else {
      this.disc.hide();
    }
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
    if (this.readOnly) return; // the orbit takes it
    const hidden = { count: 0 };
    const hit = this.visibleControl(this.ray(ev), hidden);
    this.stats.hiddenPresses += hidden.count;
    // a press off every control draws, one on a control on the revolve axis starts the profile there (on the axis);
    // one on any other control moves it, tool on or off
    const onAxis = hit && this.revolveTool ? this.guide.startOn(hit.index) : null;
    if ((!hit || onAxis) && this.drawTool) {
      ev.stopImmediatePropagation();
      ev.preventDefault();
      this.renderer.domElement.setPointerCapture?.(ev.pointerId);
      this.stroke.begin(onAxis || this.strokePoint(ev));
      return;
    }
    if (!hit) return;
    ev.stopImmediatePropagation(); // the orbit controls do not see this press
    ev.preventDefault();
    this.press.control = hit.index;
    this.beginDrag(hit.index, ev);
  }

  // A press on the dimmed label of a control the clay hides (labels.js): the control is dragged as a press on its
  // sphere would drag it (the clay in front of it still turns the view when pressed).
  pressLabel(j, ev) {
    if (this.presenting || ev.button !== 0 || this.drag || this.readOnly) return;
    ev.preventDefault();
    this.renderer.domElement.focus({ preventScroll: true });
    this.ray(ev);
    this.press = { x: ev.clientX, y: ev.clientY, control: j };
    this.beginDrag(j, ev);
  }

  beginDrag(j, ev) {
    const i = this.clay.originalOf(j);
    const centre = this.clay.controlWorld(j);
    const facing = this.rig.camera.getWorldDirection(new THREE.Vector3());
    const plane = this.meridianPlane(j, centre, facing)
      || new THREE.Plane().setFromNormalAndCoplanarPoint(facing, centre);
    const onPlane = this.raycaster.ray.intersectPlane(plane, new THREE.Vector3()) || centre.clone();
    this.drag = { i, j, copy: this.clay.copyOf(j), plane, offset: centre.clone().sub(onPlane), pointer: ev.pointerId,
      start: this.clay.worldToModel(centre) };
    this.renderer.domElement.setPointerCapture?.(ev.pointerId);
    this.renderer.domElement.style.cursor = 'grabbing';
    this.grabs.begin(i);
    this.stats.drags += 1;
    this.onDragStart?.();
  }

  // A radial copy faced within MERIDIAN_FACING of its meridian plane (the plane holding the group's axis and the
  // copy) is dragged in that plane, so the ring keeps its angles; null for an original, a mirror copy, or a copy seen
  // at a slant (or on the axis).
  meridianPlane(j, centre, facing) {
    const m = /^radial-\d+-([xyz])/.exec(this.clay.group || '');
    if (!m || this.clay.copyOf(j) === 0) return null;
    const unit = [0, 0, 0];
    unit['xyz'.indexOf(m[1])] = 1;
    const origin = this.clay.modelToWorld([0, 0, 0]);
    const axis = this.clay.modelToWorld(unit).sub(origin).normalize();
    const out = centre.clone().sub(origin);
    const normal = axis.clone().cross(out.addScaledVector(axis, -out.dot(axis)));
    if (normal.length() < 1e-6 * this.clay.worldRadius) return null;
    normal.normalize();
    if (Math.abs(normal.dot(facing)) < Math.cos(MERIDIAN_FACING)) return null;
    return new THREE.Plane().setFromNormalAndCoplanarPoint(normal, centre);
  }

  move(ev) {
    if (this.presenting) return;
    this.pointer = ev;
    if (this.stroke.drawing) {
      this.stroke.add(this.strokePoint(ev));
      this.showDisc(ev);
      return;
    }
    if (!this.drag) {
      if (ev.buttons || this.handle.held) { // orbiting, panning or moving by the handle
        if (ev.buttons === 1 && this.groundStops(ev)) this.onGroundStop?.();
        this.showDisc(ev);
        return;
      }
      const rc = this.ray(ev);
      const hit = this.readOnly ? null : this.visibleControl(rc);
      // a control on the revolve axis is no grab while the Revolve tool is on: a press there starts the profile
      this.hover(hit && !(this.revolveTool && this.guide.startOn(hit.index)) ? hit.index : null);
      this.showDisc(ev, rc);
      return;
    }
    this.showDisc(ev);
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

  // Whether an orbit drag upward is stopped by the ground (the camera at the orbit's lowest, camera.js), once a drag.
  groundStops(ev) {
    const press = this.press;
    if (!press || press.control !== null || press.grounded || this.handle.held || this.drawTool) return false;
    const upward = ev.clientY < (press.lastY ?? press.y);
    press.lastY = ev.clientY;
    const orbit = this.rig.orbit;
    press.grounded = upward && orbit.maxPolarAngle < Math.PI - 1e-6 && orbit.getPolarAngle() >= orbit.maxPolarAngle - 1e-3;
    if (press.grounded) this.stats.groundStops += 1;
    return press.grounded;
  }

  up(ev) {
    this.rig.orbit.enabled = true;
    const press = this.press;
    this.press = null;
    const click = press && ev.button === 0 && Math.hypot(ev.clientX - press.x, ev.clientY - press.y) < CLICK_PX;
    if (this.stroke.drawing) {
      this.renderer.domElement.releasePointerCapture?.(ev.pointerId);
      if (this.revolveTool) { // one profile, one revolve: the tool lets go
        if (this.stroke.end(this.radius.newRadius, 'revolve')) this.stats.revolves += 1;
        this.act.revolve(false);
      } else if (this.stroke.end(this.radius.newRadius)) this.stats.strokes += 1;
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

  // A new clay came mid-drag: the drag ends where the server has the control (nothing more is sent for it).
  dropDrag() {
    if (!this.drag) return;
    this.grabs.drop(this.drag.i);
    this.renderer.domElement.releasePointerCapture?.(this.drag.pointer);
    this.drag = null;
    this.onDragEnd?.();
  }

  // Where a stroke goes under the pointer: on the clay, else on the plane through the target facing the camera; a
  // profile to revolve: on the plane that holds the axis and faces the camera.
  strokePoint(ev) {
    const rc = this.ray(ev);
    if (this.revolveTool) return this.guide.pointOn(rc.ray);
    const surface = this.clay.surfaceHit(rc);
    return surface ? surface.point : this.rig.onTargetPlane(rc.ray);
  }

  wheel(ev) {
    if (this.presenting) return;
    ev.preventDefault();
    ev.stopImmediatePropagation();
    const j = this.drag ? this.drag.j : this.hovered;
    if (j !== null && j !== undefined && !this.drawTool && !this.readOnly) { // over a control (Alt or not): its radius
      this.radius.show(j);
      this.radius.turn(j, ev.deltaY);
      this.stats.radii += 1;
      this.showDisc(ev);
      return;
    }
    const rc = this.ray(ev);
    const surface = this.clay.surfaceHit(rc);
    if (ev.altKey && !this.readOnly) { // over bare clay: the radius a new control gets
      this.radius.turnNew(ev.deltaY);
      this.stats.radii += 1;
      this.showDisc(ev, rc);
      return;
    }
    this.rig.zoomAt(ev.deltaY, surface ? surface.point : this.rig.onTargetPlane(rc.ray));
    this.showDisc(ev);
  }

  // A double click on the clay (not on a control) adds a control at that point of its surface, of the radius the
  // disc showed there.
  doubleClick(ev) {
    if (this.presenting || this.drawTool || this.readOnly) return;
    const rc = this.ray(ev);
    if (this.visibleControl(rc)) return;
    const surface = this.clay.surfaceHit(rc);
    if (!surface) return;
    const at = this.clay.worldToModel(surface.point).map((v) => Number(v.toPrecision(7)));
    if (this.link.send(intents.add(at, this.radius.newRadius))) this.stats.adds += 1;
  }

  // A key for the view (keys.js says which): done, and it goes no further (no field, menu or host shortcut sees it).
  // A key typed into a field of the view's own (its Display menu) stays the field's.
  key(ev) {
    if (this.presenting || isTyping(ev.composedPath?.()[0] || ev.target)) return;
    const action = viewAction(ev);
    if (!action || (this.readOnly && !READ_ONLY_KEYS.has(action) && !action.startsWith('look:'))) return;
    if (action.startsWith('look:')) {
      const view = Object.entries(VIEWS).find(([, v]) => v.key === action.slice(5));
      this.act.look(view[0]);
    } else if (action === 'fit') this.act.fit();
    else if (action === 'ortho') this.act.orthographic(!this.rig.orthographicOn);
    else if (action === 'stroke') this.act.stroke(!this.strokeTool);
    else if (action === 'revolve') this.act.revolve(!this.revolveTool);
    else if (action === 'delete') this.removeHovered();
    else if (action === 'undo' || action === 'redo') {
      if (this.link.send(intents[action]())) this.stats[`${action}s`] += 1;
    } else if (action === 'smaller' || action === 'larger') this.turnRadius(action === 'larger' ? -KEY_NOTCH : KEY_NOTCH);
    else if (action === 'escape') {
      if (this.stroke.drawing) this.stroke.cancel();
      else if (this.strokeTool) this.act.stroke(false);
      else if (this.revolveTool) this.act.revolve(false);
      else this.handle.select(null);
      this.onEscape?.();
    }
    this.stats.keys += 1;
    ev.preventDefault();
    ev.stopPropagation();
  }

  // [ or ]: the radius the disc shows (the dragged or hovered control's; with the pointer over the view, a new
  // control's; with the pointer elsewhere, the selected control's, else a new control's).
  turnRadius(deltaY) {
    const j = this.drag ? this.drag.j : this.hovered ?? (this.pointer ? null : this.handle.selected);
    if (j !== null && j !== undefined) {
      this.radius.show(j);
      this.radius.turn(j, deltaY);
    } else {
      this.radius.turnNew(deltaY);
    }
    this.stats.radii += 1;
    if (this.pointer) this.showDisc(this.pointer);
  }

  removeHovered() {
    const j = this.hovered ?? this.handle.selected;
    if (j === null || this.drag) return;
    const i = this.clay.originalOf(j);
    if (this.link.send(intents.remove(this.clay.controlIds[i] ?? i))) {
      this.stats.removes += 1;
      if (this.handle.selected !== null && this.clay.originalOf(this.handle.selected) === i) this.handle.select(null);
      this.hover(null);
      this.disc?.hide();
    }
  }
}
