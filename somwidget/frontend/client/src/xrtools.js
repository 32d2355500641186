// In the headset: the Stroke tool and radii in the hand. With Stroke chosen in the menu, the trigger or a pinch held
// draws a line where the controller's tip or the pinch goes, and letting go adds it as one control; a ball at each
// hand shows the stroke's radius. A controller's thumbstick (up: larger) sets that radius, or, while a control is
// held, the held control's radius; with hands, pinching with the second hand while the first draws turns the
// gesture into a spread: the distance between the two pinches is the ball's diameter (the line is dropped).

import * as THREE from 'three';

const STICK_DEAD = 0.15; // thumbstick travel ignored
const STICK_RATE = 1.5; // full thumbstick: the radius grows (or shrinks) by e^1.5 a second
const FIRST = 0.08; // the stroke radius to start with, as a share of the clay's bounding radius

export class HandTools {
  constructor({ clay, stroke, radius }) {
    this.clay = clay;
    this.stroke = stroke; // StrokeDraw (stroke.js)
    this.radius = radius; // RadiusBall (radius.js): a control's radius
    this.on = false; // the Stroke tool chosen
    this.strokeRadius = null; // model units
    this.drawer = null; // the input state drawing now
    this.spread = null; // [a, b]: two inputs whose distance sets the radius
    this.lastTick = null;
    this.ballGeometry = new THREE.IcosahedronGeometry(1, 2);
    this.stats = { strokes: 0, spreads: 0, stickTurns: 0 };
  }

  setOn(on) {
    this.on = on;
    if (!on && this.drawer) this.stroke.cancel();
    this.drawer = null;
    this.spread = null;
    if (on && this.strokeRadius === null) this.strokeRadius = FIRST * this.clay.radius;
  }

  // A ball for an input's visual: shows the stroke radius around its point while the tool is on.
  ball() {
    const b = new THREE.Mesh(this.ballGeometry, new THREE.MeshBasicMaterial({ color: 0xd81b60, transparent: true,
      opacity: 0.22, depthWrite: false }));
    b.name = 'stroke-radius';
    b.visible = false;
    return b;
  }

  // A select started (trigger, pinch) by input state `st`: true when the tool takes it.
  start(st) {
    if (!this.on || !st.point) return false;
    if (this.drawer && this.drawer !== st) { // a second hand: the two spread the radius, the line is dropped
      this.stroke.cancel();
      this.spread = [this.drawer, st];
      this.drawer.grabs.select = { type: 'spread' };
      st.grabs.select = { type: 'spread' };
      this.drawer = null;
      this.stats.spreads += 1;
      return true;
    }
    this.drawer = st;
    st.grabs.select = { type: 'stroke' };
    this.stroke.begin(st.point);
    return true;
  }

  // The select of `st` ended: a stroke goes out, a spread ends (both its hands let go of it).
  end(st, g) {
    if (g.type === 'stroke' && this.drawer === st) {
      this.drawer = null;
      if (this.stroke.end(this.strokeRadius)) this.stats.strokes += 1;
    } else if (g.type === 'spread' && this.spread) {
      for (const other of this.spread) if (other !== st) delete other.grabs.select;
      this.spread = null;
    }
  }

  // Every XR frame, with the input states: the line follows its hand, a spread or a thumbstick sets a radius.
  update(inputs) {
    const now = performance.now();
    const dt = this.lastTick === null ? 0 : Math.min((now - this.lastTick) / 1000, 0.1);
    this.lastTick = now;
    if (this.drawer?.point) this.stroke.add(this.drawer.point);
    if (this.spread && this.spread.every((s) => s.point)) {
      const [a, b] = this.spread;
      this.strokeRadius = a.point.distanceTo(b.point) / 2 / this.clay.scale;
    }
    for (const st of inputs) {
      const y = st.source.gamepad?.axes?.[3] ?? 0;
      if (Math.abs(y) > STICK_DEAD && dt > 0) {
        const factor = Math.exp(-y * STICK_RATE * dt); // pushed up (y < 0): larger
        const g = st.grabs.select;
        if (g?.type === 'control') {
          const r = this.radius.radiusOf(g.i);
          this.radius.set(g.i, Math.max(r > 0 ? r : FIRST * this.clay.radius, 1e-6) * factor);
          this.stats.stickTurns += 1;
        } else if (this.on) {
          this.strokeRadius *= factor;
          this.stats.stickTurns += 1;
        }
      }
      const ball = st.visual.userData.radiusBall;
      if (ball) {
        ball.visible = this.on && !!st.point;
        if (ball.visible) {
          ball.position.copy(st.point);
          ball.scale.setScalar(this.strokeRadius * this.clay.scale);
        }
      }
    }
  }

  describe() {
    return { on: this.on, radius: this.strokeRadius, drawing: !!this.drawer, spreading: !!this.spread,
      sent: this.stroke.sent, ...this.stats };
  }
}
