// Who else is on the session: one row per hand (a desktop page, a notebook, a headset; Python while it holds a
// control), its colour, its name and the controls it holds, from the server's "presence" messages. Drawn in the
// view's corner; the controls another hand holds are drawn in that hand's colour (clay.js), and `summary()` is the
// line a headset's menu shows.

export const PRESENCE_CSS = `
.somview-presence { position: absolute; left: 6px; bottom: 22px; display: flex; flex-direction: column-reverse;
  align-items: flex-start; gap: 2px; pointer-events: none; font-size: 11px; }
.somview-hand { display: flex; align-items: center; gap: 4px; padding: 1px 5px; border-radius: 3px;
  background: rgba(255,255,255,0.75); color: #223; white-space: nowrap; }
.somview-hand.you { font-weight: 600; }
.somview-hand i { display: inline-block; width: 9px; height: 9px; border-radius: 50%; }
`;

export class Presence {
  constructor(container, clay) {
    this.clay = clay;
    this.hands = []; // as the server sends them: {id, kind, name, colour, holds: [control ids], you}
    this.box = document.createElement('div');
    this.box.className = 'somview-presence';
    container.append(this.box);
  }

  // The indices now of the controls with these ids (a control gone is left out).
  indices(ids) {
    return ids.map((id) => this.clay.controlIds.indexOf(id)).filter((i) => i >= 0);
  }

  // What each row says: "headset 2 · holds 3, 4" ("(you)" after this view's own).
  text(h) {
    const holds = this.indices(h.holds);
    return `${h.name}${h.you ? ' (you)' : ''}${holds.length ? ` \u00b7 holds ${holds.join(', ')}` : ''}`;
  }

  update(hands) {
    this.hands = hands;
    this.refresh();
  }

  // Rows again (the hands changed, or the controls' places did).
  refresh() {
    const rows = this.hands.length > 1 || this.hands.some((h) => !h.you) ? this.hands : []; // alone: nothing to show
    while (this.box.childElementCount > rows.length) this.box.lastChild.remove();
    while (this.box.childElementCount < rows.length) {
      const row = document.createElement('div');
      row.className = 'somview-hand';
      row.append(document.createElement('i'), document.createElement('span'));
      this.box.append(row);
    }
    rows.forEach((h, n) => {
      const row = this.box.children[n];
      row.classList.toggle('you', h.you);
      row.firstChild.style.background = h.colour;
      row.lastChild.textContent = this.text(h);
      row.title = `${h.kind}${h.you ? ': this view' : ''}`;
    });
  }

  // One line for a headset's menu: who else is here ("" when nobody).
  summary() {
    const others = this.hands.filter((h) => !h.you);
    return others.length ? `with ${others.map((h) => this.text(h)).join('; ')}` : '';
  }

  describe() {
    return this.hands.map((h) => ({ ...h, text: this.text(h) }));
  }
}
