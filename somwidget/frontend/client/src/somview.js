// The clay view as one self-contained ES module (built to dist/somview.js): the web app's page mounts it with
// `mountWebView`, and Jupyter loads it as an anywidget (the default export's `render`).

import { focusHost, routePageKeys } from './keys.js';
import { CommLink, Link, socketURL } from './link.js';
import { intents } from './protocol.js';
import { ClayView } from './view.js';

export { ClayView };

// The web app: a view in `element` fed by the websocket at `url` (default: /view/ws on this page's server); the
// view's keys work from anywhere on the page but a field being typed in (keys.js).
export function mountWebView(element, url) {
  if (element.somview) return element.somview;
  const ws = url || socketURL();
  let link = null;
  const view = new ClayView(element, { send: (obj) => (link ? link.send(obj) : false) });
  link = new Link(ws, view.handlers);
  view.transport = link;
  routePageKeys(view); // the page is the view's: its keys from anywhere but a field being typed in
  return view;
}

const PICTURE_QUIET_MS = 1000; // a view still this long after drawing something new takes the saved picture again

// The picture of the clay a saved notebook keeps in its widget state (`picture`, a PNG data URL): shown over the
// view until the first frame comes (so a notebook opened without its kernel shows the clay as it was last seen), and
// taken again from the canvas once the view has been still for a second after a change.
function keepPicture(view, model, box) {
  let img = null;
  if (model.get('picture')) {
    img = document.createElement('img');
    img.className = 'somview-picture';
    img.alt = 'the clay, as last seen';
    img.src = model.get('picture');
    box.appendChild(img);
  }
  view.onFrame = () => {
    img?.remove();
    img = null;
  };
  let taken = 0;
  const timer = setInterval(() => {
    const s = view.state;
    if (!s.frame || s.frame.running || s.rendered === taken || performance.now() - s.renderedAt < PICTURE_QUIET_MS) {
      return;
    }
    taken = s.rendered;
    view.renderer.render(view.scene, view.camera); // the canvas is read in the task that drew it
    const url = view.renderer.domElement.toDataURL('image/png');
    if (url !== model.get('picture')) {
      model.set('picture', url);
      model.save_changes();
    }
  }, PICTURE_QUIET_MS / 2);
  return () => clearInterval(timer);
}

const SHOW_BOX = 'somwidget-show'; // the class of show()'s box around the panel and the view (notebook/show.py)

// Keys typed in the panel's fields or on the view are theirs: Jupyter's shortcuts skip whatever lies under an element
// marked data-lm-suppress-shortcuts (Notebook 7 otherwise takes Ctrl+Z in a field for the notebook's undo). The mark
// goes on show()'s box once the output is in the page (it may not be when render runs), else on the view's element.
function keepKeys(el) {
  let tries = 50;
  const mark = () => {
    const box = el.closest(`.${SHOW_BOX}`);
    (box || el).setAttribute('data-lm-suppress-shortcuts', 'true');
    if (!box && tries-- > 0) setTimeout(mark, 100);
  };
  mark();
}

// anywidget: the widget's comm is the view's link (link.js CommLink). Each rendered output is its own view (its own
// camera) of the one widget model.
function render({ model, el }) {
  keepKeys(el);
  const box = document.createElement('div');
  box.style.height = `${model.get('height')}px`;
  box.style.width = '100%';
  el.appendChild(box);
  let link = null;
  const view = new ClayView(box, { send: (obj) => (link ? link.send(obj) : false) });
  link = new CommLink(model, view.handlers);
  view.transport = link;
  view.desktop.onEscape = () => focusHost(view.renderer.domElement); // the notebook's keys are its own again
  const h = view.handlers;
  const onHeight = () => { box.style.height = `${model.get('height')}px`; };
  model.on('change:height', onHeight);
  h.onStatus('connected');
  link.send(intents.hello()); // the topology and the latest frame, for this output
  const stopPicture = keepPicture(view, model, box);
  return () => {
    stopPicture();
    link.close();
    model.off('change:height', onHeight);
    view.dispose();
  };
}

export default { render };
