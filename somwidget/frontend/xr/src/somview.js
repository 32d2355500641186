// The clay view as one self-contained ES module (built to dist/somview.js): the web app's page mounts it with
// `mountWebView`, and Jupyter loads it as an anywidget (the default export's `render`).

import { Link, dispatchText } from './link.js';
import { intents, parseFrame } from './protocol.js';
import { ClayView } from './view.js';

export { ClayView };

// The web app: a view in `element` fed by the websocket at `url` (default: /xr/ws on this page's server).
export function mountWebView(element, url) {
  if (element.somview) return element.somview;
  const ws = url || `${window.location.protocol === 'https:' ? 'wss:' : 'ws:'}//${window.location.host}/xr/ws`;
  let link = null;
  const view = new ClayView(element, { send: (obj) => (link ? link.send(obj) : false) });
  link = new Link(ws, view.handlers);
  view.transport = link;
  return view;
}

// anywidget: frames come as binary buffers of custom messages, everything else as JSON; intents go back as custom
// messages. Each rendered output is its own view (its own camera) of the one widget model.
function bufferOf(b) {
  if (b instanceof ArrayBuffer) return b;
  const view = ArrayBuffer.isView(b) ? b : new Uint8Array(b);
  return view.buffer.slice(view.byteOffset, view.byteOffset + view.byteLength);
}

function render({ model, el }) {
  const box = document.createElement('div');
  box.style.height = `${model.get('height')}px`;
  box.style.width = '100%';
  el.appendChild(box);
  const stats = { frames: 0, bytes: 0, messages: 0, sent: 0, badFrames: 0 };
  const view = new ClayView(box, {
    send: (obj) => {
      model.send(obj);
      stats.sent += 1;
      return true;
    },
  });
  view.transport = { stats };
  const h = view.handlers;
  const onMessage = (msg, buffers) => {
    stats.messages += 1;
    if (msg && msg.type === 'frame' && buffers && buffers.length) {
      let frame;
      try {
        frame = parseFrame(bufferOf(buffers[0]));
      } catch (err) {
        stats.badFrames += 1;
        console.warn('somwidget: bad frame', err);
        return;
      }
      stats.frames += 1;
      stats.bytes += frame.bytes;
      h.onFrame(frame);
    } else if (msg) {
      dispatchText(msg, h);
    }
  };
  model.on('msg:custom', onMessage);
  const onHeight = () => { box.style.height = `${model.get('height')}px`; };
  model.on('change:height', onHeight);
  h.onStatus('connected');
  model.send(intents.hello()); // the topology and the latest frame, for this output
  return () => {
    model.off('msg:custom', onMessage);
    model.off('change:height', onHeight);
    view.dispose();
  };
}

export default { render };
