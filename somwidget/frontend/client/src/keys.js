// Which keys reach the view, and what they do there. The view's keys: 1-6 the axis views, F fit, O orthographic,
// S the Stroke tool, R the Revolve tool, Delete (Backspace) removes the control under the pointer (else the selected one), [ and ] make
// the radius under the pointer smaller or larger (radius.js), Esc lets go (a stroke, a tool, the selection),
// Ctrl+Z undoes and Ctrl+Shift+Z or Ctrl+Y redoes (Cmd on a Mac).
//
// A key the view takes goes no further: no panel field, menu or notebook shortcut sees it. The view takes its keys
// while the focus is in it (a press, or the pointer coming in, gives it the focus), and on the web app's page from
// anywhere but a field being typed in (`routePageKeys`): a focused menu, switch or button never changes by a view
// key. There Escape leaves the field (what was typed and not entered is dropped) and gives the view its keys back;
// so does the pointer coming into the view when all that was typed is entered (a radius typed and Enter, then 1 for
// Front: the 1 went into the field, and its change on the next press made the radius 0.41, a step of its own).
// In a notebook Escape gives the focus back to the notebook (`focusHost`), whose own keys work again.

const TEXT_TYPES = new Set(['text', 'number', 'search', 'email', 'url', 'tel', 'password', '']);

// Whether `el` is a field a person is typing in: a text area, an editable element, a text or number input that
// takes typing (not a menu's read-only box: Vuetify's select is an input with inputmode "none").
export function isTyping(el) {
  if (!el) return false;
  if (el.isContentEditable) return true;
  if (el.tagName === 'TEXTAREA') return !el.readOnly && !el.disabled;
  if (el.tagName !== 'INPUT') return false;
  return TEXT_TYPES.has(el.type) && !el.readOnly && !el.disabled && el.inputMode !== 'none';
}

// The view's key map: ev -> the action's name (or null when the key is not the view's).
export function viewAction(ev) {
  const k = ev.key.toLowerCase();
  if (ev.altKey) return null;
  if (ev.ctrlKey || ev.metaKey) {
    if (k === 'z') return ev.shiftKey ? 'redo' : 'undo';
    return k === 'y' ? 'redo' : null;
  }
  if (k >= '1' && k <= '6' && k.length === 1) return `look:${k}`;
  return { f: 'fit', o: 'ortho', s: 'stroke', r: 'revolve', delete: 'delete', backspace: 'delete', escape: 'escape',
    '[': 'smaller', ']': 'larger' }[k] || null;
}

// The web app's page: the view's keys from anywhere on the page but a field being typed in (before any field,
// menu or page shortcut sees them); Escape in a field leaves it. `view` is the ClayView. Returns a function that
// stops the routing.
export function routePageKeys(view, doc = document) {
  const entered = new WeakMap(); // a text field -> its value when it took the focus, or was last entered
  const keep = (ev) => {
    if (isTyping(ev.target)) entered.set(ev.target, ev.target.value);
  };
  const onKey = (ev) => {
    const target = ev.composedPath?.()[0] || ev.target;
    if (view.container.contains(target)) return; // the view's own listener has it
    if (isTyping(target)) {
      if (ev.key === 'Enter') entered.set(target, target.value);
      else if (ev.key === 'Escape' && !ev.isComposing) leaveField(target, entered.get(target), view);
      return;
    }
    if (ev.key === 'Escape') { // a focused menu, switch or button: Vuetify closes its menu; the view has the keys
      setTimeout(() => view.focus(), 0);
      return;
    }
    view.desktop.key(ev);
  };
  const onEnter = () => { // the pointer came into the view: a field with nothing typed and not entered lets go
    const field = doc.activeElement;
    if (isTyping(field) && !view.container.contains(field) && entered.get(field) === field.value) {
      field.blur();
      view.focus();
    }
  };
  doc.addEventListener('focusin', keep, true);
  doc.addEventListener('change', keep, true);
  doc.addEventListener('keydown', onKey, true);
  view.container.addEventListener('pointerenter', onEnter);
  return () => {
    view.container.removeEventListener('pointerenter', onEnter);
    doc.removeEventListener('focusin', keep, true);
    doc.removeEventListener('change', keep, true);
    doc.removeEventListener('keydown', onKey, true);
  };
}

// Escape in a text field: what was typed there and not entered is dropped (the field shows what it showed when it
// took the focus or was last entered, and no change event sends it), and the focus goes to the view.
function leaveField(field, before, view) {
  if (before !== undefined && field.value !== before) {
    field.value = before;
    field.dispatchEvent(new Event('input', { bubbles: true }));
  }
  field.blur();
  view.focus();
}

// The notebook around `el` takes the focus back (JupyterLab and Notebook 7: the notebook's own element, in command
// mode, its keys working again); elsewhere the element just lets go of it. Returns what has the focus now.
export function focusHost(el) {
  el.blur?.();
  const notebook = el.closest?.('.jp-Notebook');
  if (notebook) notebook.focus({ preventScroll: true });
  return document.activeElement;
}
