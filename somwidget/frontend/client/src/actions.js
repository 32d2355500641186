// The XR page's actions, declared once: the HUD's button bar (main.js builds it into #buttons) and the headset menu
// (menu.js) both take their buttons from this list, in this order; main.js says what each action does.
//
// name: the HUD button's id and the menu button's name (somxr.button(name)); label: its text; title: the HUD
// button's tooltip; where: 'hud', 'menu' or 'both'; hidden / disabled: the HUD button's state until the page knows
// better (the browser's XR modes, the first frame's undo and redo steps).

export const ACTIONS = [
  { name: 'enter-ar', label: 'Enter AR', where: 'hud', hidden: true },
  { name: 'enter-vr', label: 'Enter VR', where: 'hud', hidden: true },
  { name: 'train', label: 'Train', where: 'both' }, // relabelled by trainLabel as frames come
  { name: 'undo', label: 'Undo', title: 'Undo (Ctrl+Z)', where: 'both', disabled: true },
  { name: 'redo', label: 'Redo', title: 'Redo (Ctrl+Shift+Z)', where: 'both', disabled: true },
  { name: 'reset', label: 'Reset', where: 'both' },
  { name: 'smaller', label: '\u2212', where: 'menu' }, // the clay 1.25 times smaller
  { name: 'bigger', label: '+', where: 'menu' },
  { name: 'stroke', label: 'Stroke', where: 'menu' }, // draw strokes with the trigger or a pinch (xrtools.js)
  { name: 'here', label: 'Bring here', where: 'menu' }, // place the clay in front of the person again
  { name: 'exit', label: 'Exit', where: 'menu' }, // leave the immersive session
];

export const HUD_ACTIONS = ACTIONS.filter((a) => a.where !== 'menu');
export const MENU_ACTIONS = ACTIONS.filter((a) => a.where !== 'hud');

// What the run button does now (the panels' rule, model/panel.py): Pause a running map, Resume one stopped part way
// through its schedule, Train a settled one.
export function trainLabel(frame) {
  if (!frame) return 'Train';
  if (frame.running) return 'Pause';
  return frame.iteration < frame.iterations ? 'Resume' : 'Train';
}
