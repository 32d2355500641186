// The studio's wall: every room as a live thumbnail, its name, who is in it and when it last changed. The feed is
// the websocket /wall/ws (studio/wall.py): a "rooms" list, a "shape" per room and generation (what to draw: triangles,
// segments or points over n nodes), then binary thumbnails (b"SOMT", slot, seq, n; n float32 x, y, z; n RGB bytes),
// at most one a second a room. Each is drawn here in a 2-D canvas (a fixed three-quarter view, flat shading, the
// triangles far to near): nothing of the clay is drawn on the server. A click on a thumbnail opens the room to watch;
// "Take part" opens it to act (the teacher's cookie lets the wall's person in); "Copy link" copies the room's own.
'use strict';

(() => {
  const rooms = new Map(); // slot -> {info, card, canvas, shape, generation, thumb, view, drawn, seq}
  const stats = { messages: 0, thumbs: 0, connected: false };
  let latest = null; // the latest list of rooms
  const main = document.getElementById('rooms');
  const summary = document.getElementById('summary');
  const OPENING_MS = 60000; // the longest a card says its room is opening
  const COPIED_MS = 2500; // how long "Copied" shows
  const AZIMUTH = (-55 * Math.PI) / 180;
  const ELEVATION = (25 * Math.PI) / 180;

  function ago(seconds) {
    if (!seconds) return 'never changed';
    const s = Math.max(0, Date.now() / 1000 - seconds);
    if (s < 5) return 'changed just now';
    if (s < 90) return `changed ${Math.round(s)} s ago`;
    if (s < 5400) return `changed ${Math.round(s / 60)} min ago`;
    return `changed ${Math.round(s / 3600)} h ago`;
  }

  function card(slot) {
    let room = rooms.get(slot);
    if (room) return room;
    const el = document.createElement('section');
    el.className = 'room';
    el.innerHTML = '<canvas width="320" height="240"></canvas><div class="caption"><span class="state"></span>' +
      '<div class="name"></div><div class="people"></div><div class="links"><a class="watch" target="_blank">' +
      'Watch</a><a class="part" target="_blank">Take part</a><a class="copy" href="#">Copy link</a></div></div>';
    el.insertAdjacentHTML('afterbegin', '<div class="opening" hidden></div>');
    room = { card: el, canvas: el.querySelector('canvas'), info: null, shape: null, generation: -1, thumb: null,
      view: null, drawn: 0, seq: -1 };
    room.canvas.addEventListener('click', () => openRoom(room, room.info.watch));
    for (const a of el.querySelectorAll('a.watch, a.part')) {
      a.addEventListener('click', (ev) => {
        ev.preventDefault();
        openRoom(room, a.href);
      });
    }
    el.querySelector('.copy').addEventListener('click', (ev) => {
      ev.preventDefault();
      copyLink(room, ev.currentTarget);
    });
    rooms.set(slot, room);
    return room;
  }

  // The room in a new tab, the card saying "Opening" until that tab shows the clay (a busy studio takes seconds).
  function openRoom(room, url) {
    const tab = window.open(url, '_blank');
    const note = room.card.querySelector('.opening');
    note.textContent = `Opening ${room.info.name}\u2026`;
    note.hidden = false;
    room.card.classList.add('busy');
    const started = Date.now();
    clearInterval(room.opening);
    room.opening = setInterval(() => {
      let shown = false;
      try {
        shown = !tab || tab.closed || (tab.somxr && tab.somxr.state().frames > 0);
      } catch {
        shown = true; // the tab went elsewhere: nothing more to tell here
      }
      if (shown || Date.now() - started > OPENING_MS) {
        clearInterval(room.opening);
        note.hidden = true;
        room.card.classList.remove('busy');
      }
    }, 200);
  }

  // The room's own link to the clipboard, the link saying "Copied" for a moment; where the browser refuses the
  // clipboard, the link in a field, selected, to copy by hand.
  async function copyLink(room, a) {
    const link = new URL(room.info.link, location.href).href;
    const caption = room.card.querySelector('.caption');
    caption.querySelector('.by-hand')?.remove();
    try {
      await navigator.clipboard.writeText(link);
      a.textContent = 'Copied';
      clearTimeout(room.copied);
      room.copied = setTimeout(() => { a.textContent = 'Copy link'; }, COPIED_MS);
    } catch {
      const by = document.createElement('label');
      by.className = 'by-hand';
      by.textContent = 'Copy this link (Ctrl+C): ';
      const field = Object.assign(document.createElement('input'), { value: link, readOnly: true });
      by.append(field);
      caption.append(by);
      field.focus();
      field.select();
      field.addEventListener('blur', () => setTimeout(() => by.remove(), COPIED_MS));
    }
  }

  function showRooms(list) {
    const slots = new Set();
    let people = 0;
    for (const info of list) {
      const room = card(info.slot);
      slots.add(info.slot);
      room.info = info;
      room.card.dataset.name = info.name;
      room.card.classList.toggle('parked', !info.live);
      room.card.querySelector('.name').textContent = info.name;
      room.card.querySelector('.state').textContent = `${info.live ? '' : 'parked, '}${ago(info.last_change)}`;
      const who = room.card.querySelector('.people');
      who.replaceChildren(...info.people.map((p) => {
        const span = document.createElement('span');
        span.className = 'person';
        const dot = document.createElement('span');
        dot.className = 'dot';
        dot.style.background = p.colour;
        span.append(dot, p.name);
        return span;
      }));
      if (!info.people.length) who.textContent = 'nobody';
      if (info.watchers) who.append(` \u00b7 ${info.watchers} watching`);
      people += info.people.length;
      room.card.querySelector('.watch').href = info.watch;
      room.card.querySelector('.part').href = info.part;
      main.append(room.card); // in the list's order (by name)
    }
    for (const [slot, room] of rooms) {
      if (!slots.has(slot)) {
        room.card.remove();
        rooms.delete(slot);
      }
    }
    summary.textContent = `${list.length} room${list.length === 1 ? '' : 's'}, ${people} ` +
      `${people === 1 ? 'person' : 'people'}`;
  }

  // The view of a generation: centred on its first thumbnail, the whole clay in the canvas.
  function viewOf(positions) {
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < positions.length; i += 3) {
      for (let a = 0; a < 3; a += 1) {
        lo[a] = Math.min(lo[a], positions[i + a]);
        hi[a] = Math.max(hi[a], positions[i + a]);
      }
    }
    const centre = lo.map((v, a) => (v + hi[a]) / 2);
    const radius = Math.max(1e-6, Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2);
    const d = [Math.cos(ELEVATION) * Math.cos(AZIMUTH), Math.cos(ELEVATION) * Math.sin(AZIMUTH), Math.sin(ELEVATION)];
    const right = [-Math.sin(AZIMUTH), Math.cos(AZIMUTH), 0];
    const up = [d[1] * right[2] - d[2] * right[1], d[2] * right[0] - d[0] * right[2], d[0] * right[1] - d[1] * right[0]];
    return { centre, radius: radius * 1.15, d, right, up }; // d: from the clay towards the eye
  }

  function draw(room) {
    const { canvas, shape, thumb } = room;
    if (!shape || !thumb) return;
    const ctx = canvas.getContext('2d');
    const w = canvas.width;
    const h = canvas.height;
    ctx.clearRect(0, 0, w, h);
    const { positions, colours } = thumb;
    const v = room.view;
    const n = shape.n;
    const scale = Math.min(w, h) / (2 * v.radius);
    const sx = new Float32Array(n);
    const sy = new Float32Array(n);
    const depth = new Float32Array(n);
    for (let i = 0; i < n; i += 1) {
      const x = positions[3 * i] - v.centre[0];
      const y = positions[3 * i + 1] - v.centre[1];
      const z = positions[3 * i + 2] - v.centre[2];
      sx[i] = w / 2 + scale * (x * v.right[0] + y * v.right[1] + z * v.right[2]);
      sy[i] = h / 2 - scale * (x * v.up[0] + y * v.up[1] + z * v.up[2]);
      depth[i] = x * v.d[0] + y * v.d[1] + z * v.d[2];
    }
    const colour = (i, shade) =>
      `rgb(${colours[3 * i] * shade | 0},${colours[3 * i + 1] * shade | 0},${colours[3 * i + 2] * shade | 0})`;
    const tris = shape.triangles;
    if (tris.length) {
      const order = [];
      for (let t = 0; t < tris.length; t += 3) order.push(t);
      const near = (t) => depth[tris[t]] + depth[tris[t + 1]] + depth[tris[t + 2]];
      order.sort((a, b) => near(a) - near(b)); // far to near
      for (const t of order) {
        const [a, b, c] = [tris[t], tris[t + 1], tris[t + 2]];
        const ux = positions[3 * b] - positions[3 * a];
        const uy = positions[3 * b + 1] - positions[3 * a + 1];
        const uz = positions[3 * b + 2] - positions[3 * a + 2];
        const wx = positions[3 * c] - positions[3 * a];
        const wy = positions[3 * c + 1] - positions[3 * a + 1];
        const wz = positions[3 * c + 2] - positions[3 * a + 2];
        const nx = uy * wz - uz * wy;
        const ny = uz * wx - ux * wz;
        const nz = ux * wy - uy * wx;
        const len = Math.hypot(nx, ny, nz) || 1;
        const shade = 0.35 + 0.65 * Math.abs((nx * v.d[0] + ny * v.d[1] + nz * v.d[2]) / len);
        ctx.fillStyle = colour(a, shade);
        ctx.beginPath();
        ctx.moveTo(sx[a], sy[a]);
        ctx.lineTo(sx[b], sy[b]);
        ctx.lineTo(sx[c], sy[c]);
        ctx.closePath();
        ctx.fill();
      }
    } else if (shape.segments.length) {
      ctx.lineWidth = 1;
      const segs = shape.segments;
      for (let s = 0; s < segs.length; s += 2) {
        ctx.strokeStyle = colour(segs[s], 1);
        ctx.beginPath();
        ctx.moveTo(sx[segs[s]], sy[segs[s]]);
        ctx.lineTo(sx[segs[s + 1]], sy[segs[s + 1]]);
        ctx.stroke();
      }
    } else {
      const order = Array.from({ length: n }, (_, i) => i).sort((a, b) => depth[a] - depth[b]);
      for (const i of order) {
        ctx.fillStyle = colour(i, 1);
        ctx.fillRect(sx[i] - 1.5, sy[i] - 1.5, 3, 3);
      }
    }
    room.drawn += 1;
  }

  function onThumb(buffer) {
    const head = new DataView(buffer);
    const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
    if (magic !== 'SOMT') return;
    const slot = head.getUint32(4, true);
    const seq = head.getUint32(8, true);
    const n = head.getUint32(12, true);
    const room = rooms.get(slot);
    if (!room || !room.shape || room.shape.n !== n || buffer.byteLength < 16 + 15 * n) return;
    const positions = new Float32Array(buffer.slice(16, 16 + 12 * n));
    const colours = new Uint8Array(buffer, 16 + 12 * n, 3 * n);
    room.thumb = { positions, colours };
    room.seq = seq;
    // framed anew when the clay has outgrown its view, shrunk to under half of it or moved off its centre (a new
    // room's first thumbnail is its clay before training); small changes keep the view, so the thumbnail stays still
    const fitted = viewOf(positions);
    const v = room.view;
    if (!v || fitted.radius > v.radius * 1.05 || fitted.radius < v.radius * 0.5 ||
        Math.hypot(...fitted.centre.map((c, a) => c - v.centre[a])) > 0.25 * v.radius) room.view = fitted;
    stats.thumbs += 1;
    draw(room);
  }

  function onMessage(data) {
    stats.messages += 1;
    if (typeof data !== 'string') {
      onThumb(data);
      return;
    }
    const msg = JSON.parse(data);
    if (msg.type === 'rooms') {
      latest = msg.rooms;
      showRooms(latest);
    }
    else if (msg.type === 'shape') {
      const room = card(msg.slot);
      room.shape = msg.shape;
      room.generation = msg.generation;
      room.view = null; // the next thumbnail frames it anew
    }
  }

  function connect() {
    const scheme = location.protocol === 'https:' ? 'wss:' : 'ws:';
    const ws = new WebSocket(`${scheme}//${location.host}/wall/ws`);
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => { stats.connected = true; };
    ws.onmessage = (ev) => onMessage(ev.data);
    ws.onclose = () => {
      stats.connected = false;
      summary.textContent = 'reconnecting';
      setTimeout(connect, 1000);
    };
  }

  document.getElementById('make').addEventListener('submit', async (ev) => {
    ev.preventDefault();
    const error = document.getElementById('error');
    error.textContent = '';
    const r = await fetch('/api/rooms', { method: 'POST', headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify({ name: document.getElementById('name').value }) });
    const answer = await r.json().catch(() => ({ error: `the studio answered ${r.status}` }));
    if (!r.ok) error.textContent = answer.error;
    else document.getElementById('name').value = '';
  });

  // Read-only views of the wall for tests and the console.
  window.somwall = {
    state: () => ({
      connected: stats.connected,
      thumbs: stats.thumbs,
      rooms: [...rooms.values()].filter((r) => r.info).map((r) => ({
        name: r.info.name, live: r.info.live, people: r.info.people.map((p) => p.name), seq: r.seq,
        drawn: r.drawn, generation: r.generation,
      })),
    }),
  };
  setInterval(() => { if (latest) showRooms(latest); }, 10000); // "changed ... ago" moves on
  connect();
})();
