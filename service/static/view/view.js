// The planner's page of a finished greybench job (served by service/view.py).
// Reads the job's sections from <prefix>/<id>/view/data and renders each by its type; a job kind plugs in
// by returning sections of the types below. Access: a signed link (?token=...) or an API key that the
// planner enters once (sessionStorage: this tab's session) and that is exchanged for a signed link.
// three.js loads only for a page with a 3D part (loadThree): a circle or search page does without its 0.4 MB
let THREE = null;
let OrbitControls = null;

let threeLoading = null;

// the three modules fetched at once (three.module.js imports three.core.js: one after the other otherwise)
function loadThree() {
  if (!threeLoading) {
    threeLoading = Promise.all([import('three'), import('/view-static/vendor/three/three.core.js'),
      import('/view-static/vendor/three/OrbitControls.js')]).then(([three, , orbit]) => {
      THREE = three;
      OrbitControls = orbit.OrbitControls;
    });
  }
  return threeLoading;
}

const KEY_STORE = 'greybench-api-key';
const params = new URLSearchParams(location.search);
const token = params.get('token');
const match = location.pathname.match(/^(.*)\/([0-9a-f]{32})\/view$/);
const prefix = match ? match[1] : '';
const jobId = match ? match[2] : '';
const $ = (sel) => document.querySelector(sel);
const fmt = (v, d = 3) => (v === null || v === undefined || Number.isNaN(v)) ? '-' : Number(v).toFixed(d);
const esc = (s) => String(s).replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' }[c]));

// hooks for the browser tests and for scripting the page
window.greybenchView = { ready: false, views: [] };

function status(text) { $('#status').textContent = text; }

async function api(url, opts = {}) {
  const headers = { ...(opts.headers || {}) };
  const key = sessionStorage.getItem(KEY_STORE);
  if (!token && key) headers['X-API-Key'] = key;
  const r = await fetch(url, { ...opts, headers });
  if (!r.ok) {
    let detail = r.statusText;
    try { const j = await r.json(); detail = typeof j.detail === 'string' ? j.detail : (j.detail.message || JSON.stringify(j.detail)); } catch (e) { /* not JSON */ }
    const err = new Error(`${r.status}: ${detail}`);
    err.status = r.status;
    throw err;
  }
  return r;
}

// ---- access ---------------------------------------------------------------------------------------
function showLogin(message) {
  $('#login').hidden = false;
  $('#login-error').textContent = message || '';
  $('#login-key').focus();
}

async function exchange(key) {
  // the key buys a signed link to this job's page; the page then runs on the link alone
  const r = await fetch(`${prefix}/${jobId}/view-link`, {
    method: 'POST', headers: { 'X-API-Key': key, 'Content-Type': 'application/json' }, body: '{}' });
  if (r.ok) { location.replace((await r.json()).url); return; }
  if (r.status === 401) { sessionStorage.removeItem(KEY_STORE); showLogin('The key was refused.'); return; }
  let detail = r.statusText;
  try { detail = (await r.json()).detail; } catch (e) { /* not JSON */ }
  showLogin(`${r.status}: ${typeof detail === 'string' ? detail : JSON.stringify(detail)}`);
}

$('#login-form').addEventListener('submit', (ev) => {
  ev.preventDefault();
  const key = $('#login-key').value.trim();
  sessionStorage.setItem(KEY_STORE, key);
  exchange(key);
});

// ---- sections --------------------------------------------------------------------------------------
function card(section) {
  const el = document.createElement('section');
  el.className = `card ${section.type}`;
  el.dataset.type = section.type;
  el.innerHTML = `<h2>${esc(section.title || section.type)}</h2>`;
  $('#sections').appendChild(el);
  return el;
}

// A Table-2 cell answers "is it good" first: green where |deviation| <= tolerance, orange to red where it is
// not, darker the more times over its tolerance (log scale, full red at 10x); the rank among the poses comes
// second, as a neutral badge (filled: the best pose of the row), so the best of poses out of tolerance is red.
function cellStyle(cell) {
  if (!cell || cell.in_tolerance === null || cell.in_tolerance === undefined) return { cls: 'no-value', hue: null, background: '#fff' };
  if (cell.in_tolerance) return { cls: 'in-tol', hue: 120, background: 'hsl(120, 45%, 84%)' };
  const t = Math.min(1, Math.log10(Math.max(1, cell.factor || 1)));
  const hue = Math.round(40 * (1 - t));
  return { cls: 'out-tol', hue, background: `hsl(${hue}, 80%, ${Math.round(80 - 14 * t)}%)` };
}

window.greybenchView.cellStyle = cellStyle;

function factorText(f) { return f === null || f === undefined ? '' : (f >= 10 ? f.toFixed(0) : f.toFixed(1)); }

const RENDER = {
  // program, robot, pose file, spacing, friction per axis, when it ran; the printable report
  header(section, el) {
    const num = (v, d) => (typeof v === 'number' ? fmt(v, d ?? 3) : esc(v ?? '-'));
    const items = section.items.map(([k, v, d]) => `<tr><th>${esc(k)}</th><td class="text">${num(v, d)}</td></tr>`).join('');
    const fr = section.friction.map(([a, t]) => `<tr><th>${esc(a)}</th><td class="text">${esc(t)}</td></tr>`).join('');
    el.insertAdjacentHTML('beforeend', `<div class="header-grid"><table class="job-items">${items}</table>
      <table class="job-friction"><tr><th colspan="2" class="text">friction model per axis: kind (registered name and version, or source)</th></tr>${fr || '<tr><td>-</td></tr>'}</table>
      ${section.pdf ? `<p><a class="pdf-link" href="${esc(section.pdf)}" download>printable report (PDF)</a></p>` : ''}</div>`);
  },

  ranking(section, el) {
    const poses = section.ranking.map((e) => e.pose);
    const head = section.ranking.map((e) => `<th data-pose="${esc(e.pose)}">${esc(e.pose)}<br><small>rank ${e.rank}</small></th>`).join('');
    const rows = section.rows.map((r) => {
      const cells = poses.map((p) => {
        const v = r.deviation_mm[p], c = (r.cells || {})[p] || {};
        const st = cellStyle(c);
        const what = c.in_tolerance ? 'in tolerance' : c.in_tolerance === false ? `out of tolerance: ${factorText(c.factor)} x the tolerance` : 'no value';
        // the rank badge and the factor are drawn by the style sheet (::before, ::after): the cell's text stays the value
        const times = c.in_tolerance === false ? ` data-times="${factorText(c.factor)}"` : '';
        return `<td class="${st.cls}${c.rank === 1 ? ' best' : ''}" data-pose="${esc(p)}" data-rank="${c.rank ?? ''}" data-factor="${c.factor ?? ''}"${times} style="background:${st.background}" title="${what}; rank ${c.rank ?? '-'} of ${poses.length} poses in this row">${fmt(v, 4)}</td>`;
      }).join('');
      return `<tr><td>${esc(r.name)}</td><td class="text">${esc(r.nominal_text)}</td><td>${fmt(r.tolerance_mm, 3)}</td>${cells}</tr>`;
    }).join('');
    const score = section.ranking.map((e) => `<td>${fmt(e.score, 2)}</td>`).join('');
    const inTol = section.ranking.map((e) => `<td>${e.in_tolerance} / ${section.rows.length}</td>`).join('');
    const swatch = (c) => `<span class="swatch" style="background:${cellStyle(c).background}"></span>`;
    el.insertAdjacentHTML('beforeend', `<table class="table2"><thead><tr><th>row</th><th>nominal</th><th>tolerance [mm]</th>${head}</tr></thead>
      <tbody>${rows}</tbody><tfoot><tr><th colspan="3">score (sum of |deviation| / tolerance, lower is better) [-]</th>${score}</tr>
      <tr><th colspan="3">rows in tolerance</th>${inTol}</tr></tfoot></table>
      <p class="legend-note key">Deviation [mm] per pose, poses best first. Colour: is it good.
        ${swatch({ in_tolerance: true })} in tolerance (|deviation| &le; tolerance, bold &#10003;);
        ${swatch({ in_tolerance: false, factor: 1.2 })} ${swatch({ in_tolerance: false, factor: 3 })} ${swatch({ in_tolerance: false, factor: 10 })}
        out of tolerance, 1.2&times;, 3&times;, 10&times; or more its tolerance (the factor in the cell).
        Badge: the rank of the pose in that row (<span class="rank best">1</span> smallest |deviation|, filled), which says nothing about the tolerance.
        Tolerances: ISO 10791-7 rows as the paper's Table 2 prints them.</p>`);
    const withShares = section.poses.filter((p) => p.shares && p.shares.score);
    if (withShares.length) {
      const rowsS = withShares.map((p) => `<tr><td>${esc(p.pose)}</td>${['deflection', 'friction', 'switching'].map((c) => `<td>${fmt(100 * (p.shares.score[c] || 0), 0)}</td>`).join('')}</tr>`).join('');
      el.insertAdjacentHTML('beforeend', `<h3>Share of the score per component [%]</h3><table><tr><th>pose</th><th>deflection</th><th>friction</th><th>switching (backlash)</th></tr>${rowsS}</table>`);
    }
  },

  workpiece(section, el) {
    if (!section.poses.length) { el.insertAdjacentHTML('beforeend', `<p>${esc(section.note)}</p>`); return; }
    // the first pose's mesh downloads while three.js loads
    const first = binary(section.urls[section.poses[0]].mesh);
    first.catch(() => { /* reported when the viewer uses it */ });
    section.prefetched = { pose: section.poses[0], mesh: first };
    loadThree().then(() => {
      const viewer = new WorkpieceView(section, el);
      window.greybenchView.views.push(viewer);
      window.greybenchView.workpiece = viewer;
      viewer.start();
    }).catch((e) => { el.insertAdjacentHTML('beforeend', `<p class="error">${esc(e.message)}</p>`); });
  },

  files(section, el) {
    const items = section.files.map((f) => `<li><a href="${esc(f.url)}" download>${esc(f.name)}</a> <small>(${f.bytes === null ? '?' : (f.bytes / 1024).toFixed(1)} KiB)</small></li>`).join('');
    el.insertAdjacentHTML('beforeend', `<ul class="files">${items}</ul>`);
  },

  summary(section, el) {
    // an item may give its decimals third ([label, value, digits]): one format per row, whole values too
    const num = (v, d) => (d === undefined || d === null ? (Number.isInteger(v) ? v : fmt(v, 3)) : fmt(v, d));
    const items = section.items.map(([k, v, d]) => `<tr><td>${esc(k)}</td><td>${typeof v === "number" ? num(v, d) : esc(v ?? "-")}</td></tr>`).join('');
    el.insertAdjacentHTML('beforeend', `<table>${items}</table>`);
  },

  'before-after'(section, el) {
    const rows = section.rows.map((r) => {
      const cls = (v) => (v !== null && Math.abs(v) <= r.tolerance_um ? 'in-tol' : 'out-tol');
      const better = Math.abs(r.after_um) <= Math.abs(r.before_um);
      return `<tr><td>${esc(r.name)}</td><td>${fmt(r.tolerance_um, 0)}</td><td class="${cls(r.before_um)}">${fmt(r.before_um, 1)}</td>
        <td class="${cls(r.after_um)}" style="background:${better ? 'hsl(120,65%,80%)' : 'hsl(0,65%,80%)'}">${fmt(r.after_um, 1)}</td>
        <td>${r.before_um ? fmt(Math.abs(r.after_um) / Math.abs(r.before_um), 2) : '-'}</td></tr>`;
    }).join('');
    el.insertAdjacentHTML('beforeend', `<table><tr><th>row</th><th>tolerance [µm]</th><th>before [µm]</th><th>after [µm]</th><th>|after| / |before| [-]</th></tr>${rows}</table>
      <p class="legend-note">After: green where |deviation| did not grow, red where it did; bold with &#10003;: in tolerance.</p>`);
  },

  image(section, el) {
    el.insertAdjacentHTML('beforeend', `<img src="${esc(section.url)}" alt="${esc(section.title)}" style="max-width:100%">`
      + (section.note ? `<p class="legend-note">${esc(section.note)}</p>` : ''));
  },

  // a table of numbers: columns with units, digits per column, highlighted rows
  table(section, el) {
    const digits = section.digits || [];
    const hl = new Set(section.highlight || []);
    const cell = (v, j) => {
      if (v === null || v === undefined) return '<td>-</td>';
      if (typeof v === 'number') return `<td>${digits[j] === null || digits[j] === undefined ? v : fmt(v, digits[j])}</td>`;
      if (typeof v === 'boolean') return `<td>${v ? 'yes' : 'no'}</td>`;
      return `<td class="text">${esc(v)}</td>`;
    };
    const body = section.rows.map((r, i) => `<tr${hl.has(i) ? ' class="highlight"' : ''}>${r.map(cell).join('')}</tr>`).join('');
    const textCol = section.columns.map((c, j) => section.rows.length > 0 && typeof section.rows[0][j] === 'string');
    const head = section.columns.map((c, j) => `<th${textCol[j] ? ' class="text"' : ''}>${esc(c)}</th>`).join('');
    el.insertAdjacentHTML('beforeend', section.rows.length
      ? `<div class="scroll"><table data-id="${esc(section.id || '')}"><thead><tr>${head}</tr></thead><tbody>${body}</tbody></table></div>`
      : `<p class="empty">${esc(section.empty || 'none')}</p>`);
    if (section.note) el.insertAdjacentHTML('beforeend', `<p class="legend-note">${esc(section.note)}</p>`);
  },

  // an x-y chart (SVG): points, lines or steps, axes with ticks and labels in units
  plot(section, el) {
    const W = 640, H = 320, L = 64, R = 16, T = 12, B = 44;
    const xs = section.series.flatMap((s) => s.x), ys = section.series.flatMap((s) => s.y).filter((v) => v !== null);
    if (!xs.length || !ys.length) { el.insertAdjacentHTML('beforeend', '<p class="empty">nothing to plot</p>'); return; }
    let [x0, x1] = [Math.min(...xs), Math.max(...xs)], [y0, y1] = [Math.min(...ys), Math.max(...ys)];
    if (x1 === x0) { x0 -= 1; x1 += 1; }
    const xpad = (x1 - x0) * 0.03; x0 -= xpad; x1 += xpad;   // points at the ends stay inside the frame
    if (y1 === y0) { y0 -= Math.abs(y0) * 0.1 || 1; y1 += Math.abs(y1) * 0.1 || 1; }
    const pad = (y1 - y0) * 0.06; y0 -= pad; y1 += pad;
    const px = (x) => L + ((x - x0) / (x1 - x0)) * (W - L - R), py = (y) => T + (1 - (y - y0) / (y1 - y0)) * (H - T - B);
    const ticks = (a, b) => {
      const step = Math.pow(10, Math.floor(Math.log10((b - a) / 4)));
      const k = [1, 2, 5, 10].find((m) => (b - a) / (m * step) <= 6) * step;
      const out = [];
      for (let v = Math.ceil(a / k) * k; v <= b + 1e-12; v += k) out.push(v);
      return out;
    };
    const dec = (a, b) => Math.max(0, -Math.floor(Math.log10((b - a) / 5)));
    const grid = ticks(y0, y1).map((v) => `<line x1="${L}" x2="${W - R}" y1="${py(v)}" y2="${py(v)}" stroke="#eee"/>
      <text x="${L - 4}" y="${py(v) + 4}" text-anchor="end">${v.toFixed(dec(y0, y1))}</text>`).join('')
      + ticks(x0, x1).map((v) => `<text x="${px(v)}" y="${H - B + 16}" text-anchor="middle">${v.toFixed(dec(x0, x1))}</text>`).join('');
    const marks = section.series.map((s) => {
      const pts = s.x.map((x, i) => [x, s.y[i]]).filter((p) => p[1] !== null);
      const c = s.colour || '#1f77b4';
      if (s.style === 'points') return pts.map(([x, y]) => `<circle class="pt" cx="${px(x).toFixed(1)}" cy="${py(y).toFixed(1)}" r="3" fill="${c}"><title>${esc(s.label)}: ${x}, ${fmt(y, 4)}</title></circle>`).join('');
      const path = pts.map(([x, y], i) => (s.style === 'step' && i ? `${px(x).toFixed(1)},${py(pts[i - 1][1]).toFixed(1)} ` : '') + `${px(x).toFixed(1)},${py(y).toFixed(1)}`).join(' ');
      return `<polyline fill="none" stroke="${c}" stroke-width="1.5" points="${path}"><title>${esc(s.label)}</title></polyline>`;
    }).join('');
    const legend = section.series.map((s) => `<span style="color:${s.colour || '#1f77b4'}">&#9632; ${esc(s.label)}</span>`).join(' ');
    el.insertAdjacentHTML('beforeend', `<svg class="plot" width="${W}" height="${H}" viewBox="0 0 ${W} ${H}" font-size="11">
      <rect x="${L}" y="${T}" width="${W - L - R}" height="${H - T - B}" fill="none" stroke="#999"/>${grid}${marks}
      <text x="${(L + W - R) / 2}" y="${H - 6}" text-anchor="middle">${esc(section.x_label)}</text>
      <text transform="translate(14 ${(T + H - B) / 2}) rotate(-90)" text-anchor="middle">${esc(section.y_label)}</text></svg>
      <p class="legend-note">${legend}</p>`);
  },

  // a circle (ballbar) test: radial deviation over the angle; deviation scaled about the nominal circle. The
  // drawing has room for the labels on either side (text measured after drawing): nothing outside the SVG
  polar(section, el) {
    const size = 420, c = size / 2, r0 = size * 0.3;
    const all = section.series.flatMap((s) => s.deviation_um);
    const span = Math.max(1e-9, ...all.map(Math.abs));
    const k = (size * 0.15) / span;
    const colours = ['#1f77b4', '#d62728', '#2ca02c', '#9467bd'];
    const paths = section.series.map((s, i) => {
      const pts = s.angle_deg.map((a, j) => {
        const r = r0 + k * s.deviation_um[j];
        const t = (a * Math.PI) / 180;
        return `${(c + r * Math.cos(t)).toFixed(1)},${(c - r * Math.sin(t)).toFixed(1)}`;
      });
      return `<polyline fill="none" stroke="${colours[i % colours.length]}" stroke-width="1.2" points="${pts.join(' ')}"><title>${esc(s.label)}</title></polyline>`;
    }).join('');
    // marks (e.g. joint reversals): a tick across the rings and a label outside
    const marks = (section.marks || []).filter((m) => m.angle_deg !== null).map((m) => {
      const t = (m.angle_deg * Math.PI) / 180, a = r0 - span * k - 6, b = r0 + span * k + 6, lr = b + 8;
      const X = (r) => (c + r * Math.cos(t)).toFixed(1), Y = (r) => (c - r * Math.sin(t)).toFixed(1);
      return `<line x1="${X(a)}" y1="${Y(a)}" x2="${X(b)}" y2="${Y(b)}" stroke="#555"/>` +
        `<text class="mark" x="${(c + lr * Math.cos(t)).toFixed(1)}" y="${(c - lr * Math.sin(t) + 4).toFixed(1)}" font-size="10" text-anchor="${Math.cos(t) > 0.3 ? 'start' : Math.cos(t) < -0.3 ? 'end' : 'middle'}">${esc(m.label)}</text>`;
    }).join('');
    const rings = [-1, 0, 1].map((f) => `<circle cx="${c}" cy="${c}" r="${r0 + f * span * k}" fill="none" stroke="#bbb" stroke-dasharray="${f ? '3,3' : ''}"/>`).join('');
    const legend = section.series.map((s, i) => `<span style="color:${colours[i % colours.length]}">&#9632; ${esc(s.label)}</span>`).join(' ');
    el.insertAdjacentHTML('beforeend', `<svg class="polar" width="${size}" height="${size}" viewBox="0 0 ${size} ${size}">${rings}${paths}${marks}</svg>
      <p class="legend-note">${legend}; rings: nominal and &plusmn;${fmt(span, 1)} µm radial deviation.</p>`);
    // widen the view box to the drawn labels' extent (plus a margin), so none is clipped
    const svg = el.querySelector('svg.polar');
    const box = svg.getBBox();
    const m = 6, x0 = Math.min(0, box.x - m), y0 = Math.min(0, box.y - m);
    const x1 = Math.max(size, box.x + box.width + m), y1 = Math.max(size, box.y + box.height + m);
    svg.setAttribute('viewBox', `${x0.toFixed(1)} ${y0.toFixed(1)} ${(x1 - x0).toFixed(1)} ${(y1 - y0).toFixed(1)}`);
    svg.setAttribute('width', (x1 - x0).toFixed(0));
    svg.setAttribute('height', (y1 - y0).toFixed(0));
  },
};

// ---- the 3D workpiece -----------------------------------------------------------------------------------
async function binary(url) {
  const buf = await (await api(url)).arrayBuffer();
  const n = new DataView(buf).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  let off = 4 + n;
  const arrays = {};
  for (const [name, dtype, width] of header.arrays) {
    const count = (header.vertices !== undefined && name !== 'index' ? header.vertices : header.faces) * width;
    const Type = dtype === 'float32' ? Float32Array : Uint32Array;
    arrays[name] = new Type(buf, off, count);
    off += count * 4;
  }
  return { header, arrays };
}

function srgbToLinear(c) { return c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4); }

class WorkpieceView {
  constructor(section, el) {
    this.section = section;
    this.el = el;
    this.pose = section.poses[0];
    this.variable = section.variables[0].name;
    this.lut = section.colormap.map((rgb) => rgb.map((v) => srgbToLinear(v / 255)));
    this.cat = section.categorical.map((rgb) => rgb.map((v) => srgbToLinear(v / 255)));
    this.shared = true;   // one colour scale for all poses of the job (section.scales); unticked: the pose's own
    this.stock = section.stock_rgb.map((v) => srgbToLinear(v / 255));
    this.noSwitchRgb = [236, 236, 210];
    this.noSwitch = this.noSwitchRgb.map((x) => srgbToLinear(x / 255));
    el.insertAdjacentHTML('beforeend', `
      <div class="wp-controls">
        <label>pose <select class="wp-pose">${section.poses.map((p) => `<option>${esc(p)}</option>`).join('')}</select></label>
        <label>colour by <select class="wp-variable">${section.variables.map((v) => `<option value="${v.name}">${esc(v.label)} [${esc(v.unit)}]</option>`).join('')}</select></label>
        <label title="unticked: each pose's part on its own range"><input type="checkbox" class="wp-shared" checked> one colour scale for all poses</label>
        <span class="legend"><span class="wp-scale"><span class="wp-lo"></span><canvas class="wp-bar" width="240" height="14"></canvas><span class="wp-hi"></span><span class="wp-unit"></span></span>
          <span class="wp-cats"></span>
          <span class="stock-swatch"></span> stock surface</span>
        <span class="wp-scale-note legend-note"></span>
      </div>
      <p class="legend-note">3D: the part in the robot base frame; triads x red, y green, z blue: the workpiece frame at the part's
        origin and the base frame at the robot's base (grey disc), joined by a dashed line. <button type="button" class="wp-cell">show the cell</button>
        <button type="button" class="wp-part">show the part</button></p>
      <div class="wp-layout">
        <div class="wp-canvas"></div>
        <div class="wp-side"><p class="legend-note">Drag: orbit; wheel: zoom; right drag: pan. Click the part: what cut that point.
          Shift + drag: box selection, the program lines that cut it.</p><div class="panel"></div></div>
      </div>`);
    this.box = el.querySelector('.wp-canvas');
    this.panel = el.querySelector('.panel');
    el.querySelector('.wp-variable').value = this.variable;
    el.querySelector('.wp-pose').addEventListener('change', (e) => { this.pose = e.target.value; this.loadMesh(); });
    el.querySelector('.wp-variable').addEventListener('change', (e) => { this.variable = e.target.value; this.loadValues(); });
    el.querySelector('.wp-shared').addEventListener('change', (e) => { this.shared = e.target.checked; this.loadValues(); });
    el.querySelector('.wp-cell').addEventListener('click', () => this.frameCell());
    el.querySelector('.wp-part').addEventListener('click', () => this.framePart());
    this.drawBar();
  }

  start() {
    const w = this.box.clientWidth, h = this.box.clientHeight;
    // preserveDrawingBuffer: the canvas can be read back (screenshots)
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.setSize(w, h);
    this.renderer.setClearColor(0xf4f4f4);
    this.box.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(35, w / h, 1, 1e5);
    this.camera.up.set(0, 0, 1);
    this.scene.add(new THREE.AmbientLight(0xffffff, 1.1));
    const light = new THREE.DirectionalLight(0xffffff, 1.9);
    light.position.set(0.3, 0.2, 1);
    this.camera.add(light);
    this.scene.add(this.camera);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => this.render());
    // the part lives in the workpiece frame [mm]; the group puts it into the base frame (the pose's placement)
    this.group = new THREE.Group();
    this.group.matrixAutoUpdate = false;
    this.scene.add(this.group);
    this.cell = new THREE.Group();
    this.scene.add(this.cell);
    window.addEventListener('resize', () => this.resize());
    this.raycaster = new THREE.Raycaster();
    this.bindPointer();
    this.loadMesh();
  }

  // one draw per frame however many changes asked for one (software WebGL: a draw of the wide canvas is costly)
  render() {
    if (this.pending || !this.renderer) return;
    this.pending = requestAnimationFrame(() => this.renderNow());
  }

  renderNow() {
    if (this.pending) cancelAnimationFrame(this.pending);
    this.pending = null;
    if (this.renderer) this.renderer.render(this.scene, this.camera);
  }

  resize() {
    const w = this.box.clientWidth, h = this.box.clientHeight;
    if (!w || !h) return;
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  // a triad (x red, y green, z blue) of length L [mm] with its name, as a group
  triad(L, name) {
    const g = new THREE.Group();
    g.name = name;
    const cols = [0xd62728, 0x2ca02c, 0x1f55d4];
    const dirs = [new THREE.Vector3(1, 0, 0), new THREE.Vector3(0, 1, 0), new THREE.Vector3(0, 0, 1)];
    dirs.forEach((d, i) => {
      const arrow = new THREE.ArrowHelper(d, new THREE.Vector3(), L, cols[i], L * 0.18, L * 0.08);
      arrow.name = `${name}-${'xyz'[i]}`;
      // drawn over the part: a triad inside the stock would be hidden
      arrow.traverse((o) => { if (o.material) { o.material.depthTest = false; o.renderOrder = 10; } });
      g.add(arrow);
      const label = this.label('xyz'[i], cols[i], L * 0.22);
      label.position.copy(d.clone().multiplyScalar(L * 1.15));
      g.add(label);
    });
    const title = this.label(name, 0x222222, L * 0.14);
    title.position.set(L * 0.2, -L * 0.2, L * 0.05);
    g.add(title);
    return g;
  }

  label(text, colour, size) {
    const cv = document.createElement('canvas');
    const ctx = cv.getContext('2d');
    ctx.font = 'bold 48px sans-serif';
    cv.width = Math.ceil(ctx.measureText(text).width) + 16; cv.height = 64;
    ctx.font = 'bold 48px sans-serif';
    ctx.fillStyle = `#${colour.toString(16).padStart(6, '0')}`;
    ctx.textBaseline = 'middle';
    ctx.fillText(text, 8, 34);
    const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: new THREE.CanvasTexture(cv), depthTest: false, transparent: true }));
    sprite.renderOrder = 11;
    sprite.scale.set(size * cv.width / cv.height, size, 1);
    return sprite;
  }

  // the base frame, the base and a dashed line from the base to the part's origin, in base coordinates [mm]
  drawCell(size) {
    this.scene.remove(this.cell);
    this.cell = new THREE.Group();
    this.cell.name = 'cell';
    const origin = new THREE.Vector3().setFromMatrixPosition(this.group.matrix);
    const reach = Math.max(origin.length(), size);
    this.cell.add(this.triad(Math.max(size * 0.6, reach * 0.12), 'base frame'));
    const base = new THREE.Mesh(new THREE.CylinderGeometry(reach * 0.1, reach * 0.1, reach * 0.02, 48),
      new THREE.MeshLambertMaterial({ color: 0x8a9099 }));
    base.rotation.x = Math.PI / 2;
    base.position.z = -reach * 0.011;
    base.name = 'robot base';
    this.cell.add(base);
    const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), origin]),
      new THREE.LineDashedMaterial({ color: 0x555555, dashSize: reach * 0.02, gapSize: reach * 0.015 }));
    line.computeLineDistances();
    this.cell.add(line);
    this.scene.add(this.cell);
    const wp = this.triad(size * 0.35, 'workpiece');
    wp.name = 'workpiece frame';
    if (this.wpTriad) this.group.remove(this.wpTriad);
    this.wpTriad = wp;
    this.group.add(wp);
  }

  // workpiece frame [mm] <-> base frame [mm] (scene)
  toWorld(x, y, z) { return new THREE.Vector3(x, y, z).applyMatrix4(this.group.matrix); }
  toLocal(v) { return v.clone().applyMatrix4(this.group.matrix.clone().invert()); }

  framePart() {
    const [lo, hi] = this.header.bounds_mm.map((v) => new THREE.Vector3(...v));
    const centre = this.toWorld(...lo.clone().add(hi).multiplyScalar(0.5).toArray());
    const size = hi.clone().sub(lo).length();
    this.camera.near = size / 100; this.camera.far = size * 200; this.camera.updateProjectionMatrix();
    this.camera.position.copy(centre).add(new THREE.Vector3(-0.55, -1.0, 0.85).normalize().multiplyScalar(size * 1.35));
    this.controls.target.copy(centre);
    this.controls.update();
    this.render();
  }

  frameCell() {
    const origin = new THREE.Vector3().setFromMatrixPosition(this.group.matrix);
    const centre = origin.clone().multiplyScalar(0.5);
    const size = Math.max(origin.length(), 1) * 1.4;
    this.camera.position.copy(centre).add(new THREE.Vector3(-0.3, -1.0, 0.7).normalize().multiplyScalar(size * 1.5));
    this.controls.target.copy(centre);
    this.controls.update();
    this.render();
  }

  async loadMesh() {
    window.greybenchView.ready = false;
    status(`loading pose ${this.pose} ...`);
    try {
      const pre = this.section.prefetched;
      this.section.prefetched = null;
      const { header, arrays } = await (pre && pre.pose === this.pose ? pre.mesh : binary(this.section.urls[this.pose].mesh));
      this.header = header;
      if (this.mesh) { this.group.remove(this.mesh); this.mesh.geometry.dispose(); }
      const T = (this.section.frames || {})[this.pose];
      if (T) this.group.matrix.set(...T); else this.group.matrix.identity();
      this.group.matrixWorldNeedsUpdate = true;
      this.group.updateMatrixWorld(true);
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(arrays.position_mm, 3));
      g.setIndex(new THREE.BufferAttribute(arrays.index, 1));
      g.setAttribute('color', new THREE.BufferAttribute(new Float32Array(arrays.position_mm.length), 3));
      g.computeVertexNormals();
      g.computeBoundingBox();
      g.computeBoundingSphere();
      this.mesh = new THREE.Mesh(g, new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide }));
      this.group.add(this.mesh);
      const [lo, hi] = header.bounds_mm.map((v) => new THREE.Vector3(...v));
      this.drawCell(hi.clone().sub(lo).length());
      this.framePart();
      await this.loadValues();
    } catch (e) { this.fail(e); }
  }

  async loadValues() {
    window.greybenchView.ready = false;
    try {
      const v = this.section.variables.find((x) => x.name === this.variable);
      const u = this.section.urls[this.pose].values;
      const { header, arrays } = await binary(u + (u.includes('?') ? '&' : '?') + `variable=${encodeURIComponent(this.variable)}`);
      // the job's scale (every pose alike) unless the planner asks for the pose's own range
      const shared = this.shared && this.section.scales && this.section.scales[this.variable];
      const [lo, hi] = shared ? this.section.scales[this.variable] : header.range;
      const col = this.mesh.geometry.getAttribute('color');
      const n = this.lut.length - 1, nc = this.cat.length;
      const seen = new Map();
      for (let i = 0; i < arrays.value.length; i++) {
        const x = arrays.value[i];
        let c;
        if (Number.isNaN(x)) c = this.stock;
        else if (v.categorical) {
          // a line (a bit pattern) is a category: neighbours get different colours; 0 switching bits: no axis switching
          const k = Math.round(x);
          c = (this.variable === 'switch' && k === 0) ? this.noSwitch : this.cat[((k % nc) + nc) % nc];
          seen.set(k, (seen.get(k) || 0) + 1);
        } else c = this.lut[Math.max(0, Math.min(n, Math.round(((x - lo) / (hi - lo)) * n)))];
        col.setXYZ(i, c[0], c[1], c[2]);
      }
      col.needsUpdate = true;
      const digits = Math.abs(hi - lo) >= 100 ? 0 : Math.abs(hi - lo) >= 1 ? 1 : 3;
      this.el.querySelector('.wp-lo').textContent = fmt(lo, digits);
      this.el.querySelector('.wp-hi').textContent = fmt(hi, digits);
      this.el.querySelector('.wp-unit').textContent = `${v.unit}`;
      this.el.querySelector('.wp-scale').hidden = !!v.categorical;
      this.el.querySelector('.wp-shared').disabled = !!v.categorical;
      this.el.querySelector('.wp-cats').innerHTML = v.categorical ? this.categoryKey(seen) : '';
      this.el.querySelector('.wp-scale-note').textContent = v.categorical ? '' : shared
        ? `scale of the job: the same colour means the same value on every pose (this pose: ${fmt(header.range[0], digits)} .. ${fmt(header.range[1], digits)} ${v.unit})`
        : 'scale of this pose only: colours do not compare between poses';
      this.scaleShown = { lo, hi, shared: !!shared, categorical: !!v.categorical, categories: [...seen.keys()].sort((p, q) => p - q) };
      window.greybenchView.scale = this.scaleShown;
      this.range = [lo, hi];
      this.renderNow();
      status(`pose ${this.pose}: ${header.vertices} vertices, lattice ${fmt(this.header.lattice_mm, 2)} mm`);
      window.greybenchView.ready = true;
      document.body.dataset.ready = '1';
    } catch (e) { this.fail(e); }
  }

  // the key of a categorical variable: a swatch per value when there are few, else how the colours repeat
  categoryKey(seen) {
    const keys = [...seen.keys()].sort((p, q) => p - q);
    const rgb = (k) => (this.variable === 'switch' && k === 0 ? this.noSwitchRgb : this.section.categorical[((k % 20) + 20) % 20]);
    const name = (k) => (this.variable === 'switch'
      ? (k === 0 ? 'no axis switching' : [0, 1, 2, 3, 4, 5].filter((b) => (k >> b) & 1).map((b) => `A${b + 1}`).join('+'))
      : `line ${k}`);
    if (keys.length <= 16) {
      return keys.map((k) => `<span class="cat" data-value="${k}"><span class="swatch" style="background:rgb(${rgb(k).join(',')})"></span> ${esc(name(k))}</span>`).join(' ');
    }
    return `${keys.length} ${this.variable === 'switch' ? 'bit patterns' : 'program lines'}, one of 20 colours each (value mod 20: neighbours differ); click the part to name a line`;
  }

  drawBar() {
    const cv = this.el.querySelector('.wp-bar');
    const ctx = cv.getContext('2d');
    const lut = this.section.colormap;
    for (let x = 0; x < cv.width; x++) {
      const c = lut[Math.round((x / (cv.width - 1)) * (lut.length - 1))];
      ctx.fillStyle = `rgb(${c[0]},${c[1]},${c[2]})`;
      ctx.fillRect(x, 0, 1, cv.height);
    }
  }

  fail(e) {
    status('');
    this.panel.innerHTML = `<p class="error">${esc(e.message)}</p>`;
    if (e.status === 401) showLogin('The link has expired or the key was refused: enter a key.');
  }

  // pointer: a click (little movement) traces a point; shift + drag selects a box
  bindPointer() {
    const dom = this.renderer.domElement;
    let down = null;
    let rect = null;
    dom.addEventListener('pointerdown', (e) => {
      down = { x: e.clientX, y: e.clientY, shift: e.shiftKey };
      if (e.shiftKey) {
        this.controls.enabled = false;
        rect = document.createElement('div');
        rect.className = 'wp-rect';
        this.box.appendChild(rect);
      }
    });
    dom.addEventListener('pointermove', (e) => {
      if (!down || !rect) return;
      const b = this.box.getBoundingClientRect();
      rect.style.left = `${Math.min(down.x, e.clientX) - b.left}px`;
      rect.style.top = `${Math.min(down.y, e.clientY) - b.top}px`;
      rect.style.width = `${Math.abs(e.clientX - down.x)}px`;
      rect.style.height = `${Math.abs(e.clientY - down.y)}px`;
    });
    dom.addEventListener('pointerup', (e) => {
      if (!down) return;
      const moved = Math.hypot(e.clientX - down.x, e.clientY - down.y);
      if (down.shift) {
        this.controls.enabled = true;
        if (rect) rect.remove();
        rect = null;
        if (moved > 4) this.selectBox(down.x, down.y, e.clientX, e.clientY);
      } else if (moved < 4) {
        const hit = this.hitAt(e.clientX, e.clientY);
        if (hit) this.trace(hit);
      }
      down = null;
    });
  }

  hitAt(cx, cy) {
    if (!this.mesh) return null;
    const b = this.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((cx - b.left) / b.width) * 2 - 1, -((cy - b.top) / b.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    const hits = this.raycaster.intersectObject(this.mesh, false);
    return hits.length ? this.toLocal(hits[0].point) : null;   // workpiece frame [mm]
  }

  // client pixel of a point [mm] (tests and scripting)
  project(x, y, z) {
    const v = this.toWorld(x, y, z).project(this.camera);
    const b = this.renderer.domElement.getBoundingClientRect();
    return { x: b.left + ((v.x + 1) / 2) * b.width, y: b.top + ((1 - v.y) / 2) * b.height };
  }

  // look at a point [mm, workpiece frame] from a direction (unit vector in the workpiece frame, from the point
  // towards the camera) at a distance [mm]
  lookAt(point, direction, distance) {
    const p = this.toWorld(...point);
    const d = new THREE.Vector3(...direction).normalize().applyMatrix3(new THREE.Matrix3().setFromMatrix4(this.group.matrix));
    this.controls.target.copy(p);
    this.camera.position.copy(p).add(d.multiplyScalar(distance));
    this.controls.update();
    this.render();
  }

  marker(p) {
    if (this.mark) this.group.remove(this.mark);
    const r = Math.max(0.6, this.section.click_radius_mm);
    this.mark = new THREE.Mesh(new THREE.SphereGeometry(r, 16, 12), new THREE.MeshBasicMaterial({ color: 0xff2020, wireframe: true }));
    this.mark.position.copy(p);
    this.group.add(this.mark);
    this.render();
  }

  async trace(p) {
    this.marker(p);
    const u = this.section.urls[this.pose].click;
    const q = `x_mm=${p.x}&y_mm=${p.y}&z_mm=${p.z}&radius_mm=${this.section.click_radius_mm}`;
    try {
      const r = await (await api(u + (u.includes('?') ? '&' : '?') + q)).json();
      window.greybenchView.lastClick = r;
      const comp = r.components.deflection_um === undefined ? 'none (stock surface)' :
        `deflection ${fmt(r.components.deflection_um, 1)} µm (${fmt(100 * r.components.deflection_share, 0)} %), ` +
        `servo tracking error (friction, backlash, dynamics) ${fmt(r.components.tracking_error_um, 1)} µm (${fmt(100 * r.components.tracking_error_share, 0)} %)`;
      this.panel.innerHTML = `<h3>Point (${r.point_mm.map((v) => fmt(v, 2)).join(', ')}) mm</h3>
        <p class="trace-summary" data-point="${r.point_mm.join(',')}">${r.n_ends} machined dexel ends within ${fmt(r.radius_mm, 1)} mm;
        time ${r.t_first_s === null ? '-' : `${fmt(r.t_first_s, 3)} .. ${fmt(r.t_last_s, 3)} s`};
        axes stopping or reversing: ${r.reversing_axes.length ? r.reversing_axes.map((a) => `A${a}`).join(', ') : 'none'};
        error components: ${comp}.</p>` + linesTable(r.lines, 'trace-lines');
    } catch (e) { this.fail(e); }
  }

  async selectBox(x0, y0, x1, y1) {
    // the visible surface inside the rectangle: a grid of rays, their hit points' bounding box
    const pts = [];
    const n = 14;
    for (let i = 0; i <= n; i++) {
      for (let j = 0; j <= n; j++) {
        const hit = this.hitAt(x0 + ((x1 - x0) * i) / n, y0 + ((y1 - y0) * j) / n);
        if (hit) pts.push(hit);
      }
    }
    if (!pts.length) { this.panel.innerHTML = '<p>No part inside the rectangle.</p>'; return; }
    const box = new THREE.Box3().setFromPoints(pts).expandByScalar(this.header.lattice_mm / 2);
    if (this.boxHelper) this.group.remove(this.boxHelper);
    this.boxHelper = new THREE.Box3Helper(box, 0xd00000);
    this.group.add(this.boxHelper);
    this.render();
    const u = this.section.urls[this.pose].box;
    const q = `min_mm=${box.min.toArray().join(',')}&max_mm=${box.max.toArray().join(',')}`;
    try {
      const r = await (await api(u + (u.includes('?') ? '&' : '?') + q)).json();
      window.greybenchView.lastBox = r;
      this.panel.innerHTML = `<h3>Box (${r.min_mm.map((v) => fmt(v, 1)).join(', ')}) .. (${r.max_mm.map((v) => fmt(v, 1)).join(', ')}) mm</h3>
        <p>${r.n_ends} machined dexel ends; ${r.lines.length} program lines cut it.</p>` + linesTable(r.lines, 'box-lines');
    } catch (e) { this.fail(e); }
  }
}

function linesTable(lines, cls) {
  if (!lines.length) return '<p>No machined surface here (stock surface or empty space).</p>';
  const rows = lines.map((l) => `<tr data-line="${l.line}"><td>${l.line}</td><td class="text"><code class="line">${esc(l.text)}</code></td>
    <td>${fmt(l.t_first_s, 3)} .. ${fmt(l.t_last_s, 3)}</td><td>${l.n_ends}</td><td>${fmt(l.max_deflection_um, 1)}</td>
    <td>${fmt(l.max_force_n, 1)}</td><td>${l.reversing_axes.map((a) => `A${a}`).join(', ') || '-'}</td></tr>`).join('');
  return `<table class="${cls}"><tr><th>line</th><th>program</th><th>t [s]</th><th>ends</th><th>max deflection [µm]</th>
    <th>max force [N]</th><th>axes reversing</th></tr>${rows}</table>`;
}

// ---- start ------------------------------------------------------------------------------------------------
async function start() {
  $('#job').textContent = jobId;
  if (!token) {
    const key = sessionStorage.getItem(KEY_STORE);
    if (key) { await exchange(key); return; }
    showLogin();
    return;
  }
  // a simulation's page shows a part: fetch three.js while the sections load (other kinds never fetch it)
  if (prefix === '/simulations') loadThree().catch(() => { /* reported by the workpiece section */ });
  try {
    const data = await (await api(`${prefix}/${jobId}/view/data?token=${encodeURIComponent(token)}`)).json();
    document.title = `greybench: ${data.title} ${jobId.slice(0, 8)}`;
    $('#title').textContent = `greybench: ${data.title} job`;
    for (const s of data.sections) {
      const el = card(s);
      const render = RENDER[s.type];
      if (render) render(s, el);
      else el.insertAdjacentHTML('beforeend', `<pre>${esc(JSON.stringify(s, null, 1))}</pre>`);
    }
    if (data.pdf && !data.sections.some((s) => s.type === 'header')) {
      $('header').insertAdjacentHTML('beforeend', `<a class="pdf-link" href="${esc(data.pdf)}" download>printable report (PDF)</a>`);
    }
    window.greybenchView.data = data;
    if (!data.sections.some((s) => s.type === 'workpiece' && s.poses.length)) {
      window.greybenchView.ready = true;
      document.body.dataset.ready = '1';
    }
  } catch (e) {
    if (e.status === 401) showLogin('The link has expired or is not valid: enter a key.');
    else $('#sections').innerHTML = `<p class="error">${esc(e.message)}</p>`;
  }
}

start();
