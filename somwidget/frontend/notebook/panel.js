// The panel as an anywidget (notebook/anypanel.py): every host that draws anywidgets (marimo through
// mo.ui.anywidget, JupyterLab, Notebook 7, VS Code, Colab) shows it. Its fields come from the settings' declaration
// (the `fields` trait: backend/schedule.py SETTINGS through the panel model); values, status, rows and choices come
// as traits, a person's edits go back as messages ({type: 'set' | 'metric' | 'group' | 'preset' | 'action' |
// 'radius' | 'position' | 'export'}). Laid out for widths from 320 px: rows wrap, fields shrink, labels keep their
// words. The style lives inside the widget's element (marimo draws widgets in shadow roots).

const STYLE = `
.somwidget-panel { font: 13px/1.35 system-ui, sans-serif; color: #1d1d28; box-sizing: border-box; width: 100%;
  max-width: 440px; min-width: 0; padding: 4px 28px 4px 4px; }
.somwidget-panel * { box-sizing: border-box; }
.somwidget-panel .row { display: flex; flex-wrap: wrap; align-items: center; gap: 4px 6px; margin: 3px 0; }
.somwidget-panel label { display: flex; align-items: center; gap: 6px; flex: 1 1 140px; min-width: 0;
  white-space: nowrap; }
.somwidget-panel label > span { flex: 0 0 auto; }
.somwidget-panel label.wide { flex-basis: 100%; }
.somwidget-panel input, .somwidget-panel select { flex: 1 1 60px; min-width: 0; font: inherit; padding: 2px 4px;
  border: 1px solid #b8bccb; border-radius: 3px; background: #fff; color: inherit; }
.somwidget-panel input[type=checkbox] { flex: 0 0 auto; }
.somwidget-panel input[type=range] { padding: 0; }
.somwidget-panel output { flex: 0 0 3.5em; text-align: right; font-variant-numeric: tabular-nums; }
.somwidget-panel button { font: inherit; padding: 3px 10px; flex: 0 0 auto; white-space: nowrap; cursor: pointer;
  border: 1px solid #b8bccb; border-radius: 3px; background: #eef0f5; color: inherit; }
.somwidget-panel button:disabled { opacity: 0.5; cursor: default; }
.somwidget-panel h4 { margin: 8px 0 2px; font-size: 13px; white-space: normal; }
.somwidget-panel h4 small { font-weight: normal; }
.somwidget-panel .help, .somwidget-panel .status { font-size: 11px; color: #555; white-space: normal; }
.somwidget-panel .error { color: #b00020; white-space: normal; }
.somwidget-panel progress { width: 100%; }
.somwidget-panel table { border-collapse: collapse; font-size: 11px; width: 100%; table-layout: fixed; }
.somwidget-panel td, .somwidget-panel th { padding: 1px 3px; overflow-wrap: anywhere; text-align: left; }
.somwidget-panel td input { width: 100%; }
`;

function el(tag, props = {}, children = []) {
  const e = document.createElement(tag);
  Object.assign(e, props);
  for (const c of children) e.append(c);
  return e;
}

function field(f, send) {
  // one setting from its declaration: a checkbox, a slider with its value, or a number field
  const span = el('span', { textContent: f.short || f.label, title: f.help });
  if (f.kind === 'bool') {
    const input = el('input', { type: 'checkbox', title: f.help });
    input.addEventListener('change', () => send({ type: 'set', name: f.name, value: input.checked }));
    return { node: el('label', { className: 'wide' }, [input, span]), input };
  }
  if (f.widget === 'slider') {
    const input = el('input', { type: 'range', min: f.min, max: f.max, step: f.step, title: f.help });
    const out = el('output');
    input.addEventListener('input', () => { out.textContent = input.value; });
    input.addEventListener('change', () => send({ type: 'set', name: f.name, value: Number(input.value) }));
    return { node: el('label', { className: 'wide' }, [span, input, out]), input, out };
  }
  const input = el('input', { type: 'number', step: f.kind === 'int' ? 1 : 'any', title: f.help });
  input.addEventListener('change', () => send({ type: 'set', name: f.name, value: Number(input.value) }));
  return { node: el('label', {}, [span, input]), input };
}

function setValue(input, value) {
  // never under a person's fingers: a focused field keeps what is being typed
  if (input.getRootNode().activeElement === input) return;
  if (input.type === 'checkbox') input.checked = Boolean(value);
  else if (String(input.value) !== String(value)) input.value = value;
}

function options(select, items) {
  const key = JSON.stringify(items);
  if (select.dataset.items === key) return;
  select.dataset.items = key;
  select.replaceChildren(...items.map(([label, value]) => el('option', { textContent: label, value })));
}

function render({ model, el: host }) {
  const send = (msg) => model.send(msg);
  const root = el('div', { className: 'somwidget-panel' }, [el('style', { textContent: STYLE })]);
  const title = el('div');
  const preset = el('select', { title: 'Load a preset (one undo step)' });
  preset.addEventListener('change', () => send({ type: 'preset', name: preset.value }));
  const actions = model.get('actions'); // name -> [label, help], the same words as the web page's tooltips
  const button = (name) => {
    const [label, help] = actions[name];
    const b = el('button', { textContent: label, title: help });
    b.addEventListener('click', () => send({ type: 'action', name }));
    return b;
  };
  const train = button('toggle_training');
  const undo = button('undo');
  const redo = button('redo');
  const status = el('div', { className: 'status' });
  const progress = el('progress', { max: 1, value: 0 });
  const error = el('div', { className: 'error', role: 'alert' });
  root.append(title,
    el('div', { className: 'row' }, [el('label', {}, [el('span', { textContent: 'preset' }), preset]),
      button('reload_preset'),
      button('refine')]),
    el('div', { className: 'row' }, [train, undo, redo, button('reset')]),
    progress, status, error);

  const sections = model.get('sections');
  const inputs = {};
  for (const name of ['schedule', 'symmetry']) {
    const [head, about] = sections[name];
    root.append(el('h4', {}, [head, ' ', el('small', { textContent: `(${about})` })]));
    const row = el('div', { className: 'row' });
    for (const f of model.get('fields').filter((x) => x.section === name)) {
      const made = field(f, send);
      inputs[f.name] = made;
      row.append(made.node);
      if (f.widget === 'slider') row.append(el('div', { className: 'help', textContent: f.help }));
    }
    root.append(row);
  }
  const group = el('select', { title: 'The symmetry group' });
  group.addEventListener('change', () => send({ type: 'group', spec: group.value }));
  root.lastChild.append(el('label', {}, [el('span', { textContent: 'group' }), group]));

  const [fhead, fabout] = sections.features;
  const features = el('div', { className: 'row' });
  root.append(el('h4', {}, [fhead, ' ', el('small', { textContent: `(${fabout})` })]), features);
  const controls = el('table');
  const [chead] = sections.controls;
  root.append(el('h4', { textContent: chead }), controls);

  const format = el('select', { title: 'What the next tool reads' });
  const exportButton = el('button', { textContent: 'Export', title: 'Download the clay in the chosen format' });
  exportButton.addEventListener('click', () => send({ type: 'export', ext: format.value }));
  root.append(el('h4', { textContent: 'Export' }),
    el('div', { className: 'row' }, [el('label', {}, [el('span', { textContent: 'format' }), format]),
      exportButton]));
  host.append(root);

  let featureKey = '';
  let controlKey = '';
  const update = () => {
    const values = model.get('values');
    const st = model.get('status');
    title.replaceChildren(el('b', { textContent: st.title || '' }));
    options(preset, model.get('presets'));
    setValue(preset, st.preset);
    for (const [name, made] of Object.entries(inputs)) {
      setValue(made.input, values[name]);
      if (made.out) made.out.textContent = values[name];
    }
    options(group, model.get('groups'));
    setValue(group, values.group);
    options(format, model.get('exports'));
    train.textContent = st.train_label || 'Train';
    undo.disabled = !st.can_undo;
    redo.disabled = !st.can_redo;
    progress.max = Math.max(1, st.S || 1);
    progress.value = Math.min(st.iteration || 0, st.S || 0);
    status.textContent = `iteration ${st.iteration} / ${st.S} (${st.state}); ${st.n_vertices} nodes, ${st.k} controls`;
    error.textContent = model.get('error');
    const rows = model.get('features');
    if (JSON.stringify(rows.map((r) => r.name)) !== featureKey) {
      featureKey = JSON.stringify(rows.map((r) => r.name));
      features.replaceChildren(...rows.map((r) => {
        const input = el('input', { type: 'number', step: 'any', min: 0, title: `metric weight of ${r.name}` });
        input.addEventListener('change', () => send({ type: 'metric', d: r.d, value: Number(input.value) }));
        return el('label', { title: r.role }, [el('span', { textContent: r.name }), input]);
      }));
    }
    rows.forEach((r, i) => setValue(features.children[i].querySelector('input'), r.weight));
    const cs = model.get('controls');
    if (String(cs.length) !== controlKey) {
      controlKey = String(cs.length);
      controls.replaceChildren(el('tr', {}, ['#', 'x, y, z', 'gap', 'radius'].map((t) => el('th', { textContent: t }))),
        ...cs.map((c) => {
          const position = el('input', { title: 'x, y, z: type a position and press Enter' });
          position.addEventListener('change', () => send({ type: 'position', i: c.i, text: position.value }));
          const radius = el('input', { type: 'number', step: 'any', min: 0, title: 'radius of influence' });
          radius.addEventListener('change', () => send({ type: 'radius', i: c.i, value: Number(radius.value) }));
          return el('tr', {}, [el('td', { textContent: c.i }), el('td', {}, [position]), el('td'),
            el('td', {}, [radius])]);
        }));
    }
    cs.forEach((c, i) => {
      const cells = controls.children[i + 1].children;
      cells[0].style.color = c.colour;
      setValue(cells[1].firstChild, c.position);
      cells[2].textContent = c.gap;
      const [offStyle, offWords] = model.get('off_clay'); // a control off the clay: the web page's amber mark
      cells[2].style.cssText = c.off ? offStyle : '';
      cells[2].title = c.off ? offWords : '';
      setValue(cells[3].firstChild, c.radius);
    });
  };
  const onDownload = (msg, buffers) => {
    if (msg.type !== 'download') return;
    const url = URL.createObjectURL(new Blob([buffers[0]], { type: msg.mime }));
    const a = el('a', { href: url, download: msg.name });
    root.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
  };
  const names = ['values', 'status', 'presets', 'groups', 'features', 'controls', 'error', 'exports'];
  for (const n of names) model.on(`change:${n}`, update);
  model.on('msg:custom', onDownload);
  update();
  return () => {
    for (const n of names) model.off(`change:${n}`, update);
    model.off('msg:custom', onDownload);
  };
}

export default { render };
