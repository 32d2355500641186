// The view's own bar, top right: Fit, the six axis views, perspective / orthographic, the Stroke and Revolve tools
// and the Display menu (wireframe, shading, look, floor grid, axes, labels). Each button's tooltip names its key.

import { VIEWS } from './camera.js';
import { LOOKS, SHADINGS } from './display.js';

export const TOOLBAR_CSS = `
.somview-bar { position: absolute; right: 6px; top: 6px; display: flex; flex-wrap: wrap; justify-content: flex-end;
  gap: 3px; max-width: calc(100% - 12px); pointer-events: none; }
.somview-bar button, .somview-bar select { pointer-events: auto; font-size: 12px; padding: 2px 7px; cursor: pointer;
  border: 1px solid #99a; border-radius: 4px; background: rgba(255,255,255,0.88); color: #223; }
.somview-bar button.on { background: #3d5afe; border-color: #3d5afe; color: white; }
.somview-bar .gap { width: 6px; }
.somview-menu { position: absolute; right: 6px; top: 34px; padding: 6px 8px; font-size: 12px; color: #223;
  background: rgba(255,255,255,0.96); border: 1px solid #99a; border-radius: 4px; display: grid; gap: 4px;
  grid-template-columns: auto auto; align-items: center; }
.somview-menu[hidden] { display: none; }
.somview-menu label { display: contents; }
`;

function button(text, title, onClick, className) {
  const b = document.createElement('button');
  b.type = 'button';
  b.textContent = text;
  b.title = title;
  if (className) b.className = className;
  b.addEventListener('click', (ev) => {
    ev.stopPropagation();
    onClick();
  });
  return b;
}

export class Toolbar {
  // act: {fit(), look(name), orthographic(on), stroke(on), revolve(on), display(name, value)}; state(): what the view
  // shows now
  constructor(container, act, state) {
    this.act = act;
    this.state = state;
    this.bar = document.createElement('div');
    this.bar.className = 'somview-bar';
    this.fit = button('Fit', 'Fit the clay and every control into the view (F)', () => act.fit(), 'somview-fit');
    const views = Object.entries(VIEWS).map(([name, v]) =>
      button(v.label, `${v.help} (${v.key})`, () => act.look(name), `somview-look-${name}`));
    this.ortho = button('Ortho', 'Orthographic (on) or perspective (off) camera (O)',
      () => act.orthographic(!state().orthographic), 'somview-ortho');
    this.stroke = button('Stroke', 'Draw a stroke: drag on the clay (or beside it, on the view plane) to add a line '
      + 'that pulls the clay as one control; Esc cancels (S)', () => act.stroke(!state().stroke), 'somview-stroke');
    this.revolve = button('Revolve', 'Revolve (lathe): draw a profile beside the axis shown (the radial group\'s, '
      + 'else z) and the clay turns into its surface of revolution, the profile its control; Esc cancels (R)',
    () => act.revolve(!state().revolve), 'somview-revolve');
    this.menuButton = button('Display', 'How the clay is drawn: wireframe, shading, look, floor, axes, labels',
      () => this.toggleMenu(), 'somview-display');
    const gap = () => Object.assign(document.createElement('span'), { className: 'gap' });
    this.bar.append(this.fit, gap(), ...views, gap(), this.ortho, this.stroke, this.revolve, this.menuButton);
    this.menu = this.buildMenu();
    this.menu.hidden = true;
    for (const el of [this.bar, this.menu]) {
      el.addEventListener('pointerdown', (ev) => ev.stopPropagation()); // the orbit does not start here
      el.addEventListener('dblclick', (ev) => ev.stopPropagation());
    }
    container.append(this.bar, this.menu);
    this.refresh();
  }

  buildMenu() {
    const menu = document.createElement('div');
    menu.className = 'somview-menu';
    this.fields = {};
    const row = (text, input, name) => {
      const label = document.createElement('label');
      label.append(Object.assign(document.createElement('span'), { textContent: text }), input);
      input.className = `somview-setting-${name}`;
      input.addEventListener('change', () => {
        this.act.display(name, input.type === 'checkbox' ? input.checked : input.value);
        this.refresh();
      });
      this.fields[name] = input;
      menu.append(label);
    };
    const check = () => Object.assign(document.createElement('input'), { type: 'checkbox' });
    const choice = (values) => {
      const s = document.createElement('select');
      for (const v of values) s.append(Object.assign(document.createElement('option'), { value: v, textContent: v }));
      return s;
    };
    row('wireframe', check(), 'wireframe');
    row('shading', choice(SHADINGS), 'shading');
    row('look', choice(LOOKS), 'look');
    row('floor grid', check(), 'grid');
    row('axes', check(), 'axes');
    row('labels', check(), 'labels');
    return menu;
  }

  // The tools that change the clay (Stroke, Revolve) disabled, their tooltip `why` (on), or as they were.
  setReadOnly(on, why) {
    for (const b of [this.stroke, this.revolve]) {
      b.dataset.title ??= b.title;
      b.disabled = on;
      b.title = on ? why : b.dataset.title;
    }
  }

  toggleMenu() {
    this.menu.hidden = !this.menu.hidden;
    this.refresh();
  }

  // The buttons and fields as the view is now (a key may have changed it).
  refresh() {
    const st = this.state();
    this.ortho.classList.toggle('on', st.orthographic);
    this.stroke.classList.toggle('on', st.stroke);
    this.revolve.classList.toggle('on', Boolean(st.revolve));
    this.menuButton.classList.toggle('on', !this.menu.hidden);
    for (const [name, input] of Object.entries(this.fields)) {
      const v = st.display[name];
      if (input.type === 'checkbox') input.checked = Boolean(v);
      else input.value = v;
    }
  }
}
