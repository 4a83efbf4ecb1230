// cmosnoise explore: two sensors side by side; every parameter; the picture follows at once.
// No build step and nothing from other origins: this file, explore.css and the server's /api.
"use strict";

const S = {
  meta: null,
  panes: { A: null, B: null },          // {config, scene}
  edit: "A", view: "pre", mode: "AB", frame: 0, fps: 5, playing: false, couplets: false,
  zoom: null, cx: 0, cy: 0,             // screen pixels per sensor pixel; the view's centre in sensor pixels
  seq: { A: 0, B: 0 }, shown: { A: -1, B: -1 }, busy: { A: false, B: false },
  drawnAt: { A: 0, B: 0 },              // performance.now() when each pane's newest picture reached its canvas
  images: { A: null, B: null },         // last good picture of each pane: {bitmap, region, step, couplets}
  client: Math.random().toString(36).slice(2),
  valid: { A: null, B: null },          // each pane's last {config, scene} the server drew: what the URL keeps
};
const $ = (id) => document.getElementById(id);
// a JSON request to the server, with the header it asks of the page's requests (it refuses others)
const postJson = (path, body, init = {}) => fetch(path, { method: "POST", body: JSON.stringify(body), ...init,
  headers: { "Content-Type": "application/json", "X-Cmosnoise": "1" } });
const clone = (x) => JSON.parse(JSON.stringify(x));

// ------------------------------------------------------------------ configuration paths
function getPath(obj, key) {
  let node = obj;
  for (const p of key.split(".")) { if (node == null) return undefined; node = node[/^\d+$/.test(p) ? Number(p) : p]; }
  return node;
}
function setPath(obj, key, value) {
  const parts = key.split(".");
  let node = obj;
  for (let i = 0; i < parts.length - 1; i++) {
    const p = /^\d+$/.test(parts[i]) ? Number(parts[i]) : parts[i];
    if (node[p] == null) node[p] = /^\d+$/.test(parts[i + 1]) ? [] : {};
    node = node[p];
  }
  node[parts[parts.length - 1]] = value;
}
function diff(a, b) {              // what b changes in a (for the URL)
  if (JSON.stringify(a) === JSON.stringify(b)) return undefined;
  if (a && b && typeof a === "object" && typeof b === "object" && !Array.isArray(a) && !Array.isArray(b)) {
    const out = {};
    for (const k of Object.keys(b)) { const d = diff(a[k], b[k]); if (d !== undefined) out[k] = d; }
    return out;
  }
  return b;
}
function merge(a, d) {
  if (d === undefined) return clone(a);
  if (a && d && typeof a === "object" && typeof d === "object" && !Array.isArray(a) && !Array.isArray(d)) {
    const out = clone(a);
    for (const k of Object.keys(d)) out[k] = merge(a[k], d[k]);
    return out;
  }
  return clone(d);
}

// ------------------------------------------------------------------ the URL holds the state
function saveUrl() {                  // an invalid value stays out of the URL: a pane is kept as it was last drawn
  const base = S.meta.base, A = S.valid.A || S.panes.A, B = S.valid.B || S.panes.B;
  const st = { A: diff(base, A.config) || {}, B: diff(base, B.config) || {},
    sa: A.scene, sb: B.scene, v: S.view, m: S.mode, f: S.frame, z: S.zoom, x: S.cx, y: S.cy,
    c: S.couplets ? 1 : 0 };
  const text = btoa(unescape(encodeURIComponent(JSON.stringify(st)))).replace(/\+/g, "-").replace(/\//g, "_").replace(/=+$/, "");
  history.replaceState(null, "", "#" + text);
}
function loadUrl() {
  if (location.hash.length < 2) return false;
  try {
    const b64 = location.hash.slice(1).replace(/-/g, "+").replace(/_/g, "/");
    const st = JSON.parse(decodeURIComponent(escape(atob(b64))));
    S.panes.A = { config: merge(S.meta.base, st.A), scene: st.sa || S.meta.scene };
    S.panes.B = { config: merge(S.meta.base, st.B), scene: st.sb || S.meta.scene };
    Object.assign(S, { view: st.v || "pre", mode: st.m || "AB", frame: st.f || 0, zoom: st.z || null,
      cx: st.x || 0, cy: st.y || 0, couplets: !!st.c });
    return true;
  } catch (e) { return false; }
}

// ------------------------------------------------------------------ the parameter panel
const SKIP = /^(description|run\.)/;
// the keys carry their units in their names (docs/model.md's convention): sigma_e is e-, integration_time_s is s, ...
const UNITS = [["_e_per_s", "e-/s"], ["_nA_per_cm2", "nA/cm2"], ["_aA", "aA"], ["_pct", "%"], ["_um", "um"], ["_dn", "DN"],
  ["_fps", "1/s"], ["_lux", "lux"], ["_cd_m2", "cd/m2"], ["_mm", "mm"], ["_nm", "nm"], ["_deg", "deg"], ["_px", "px"],
  ["_c", "C"], ["_s", "s"], ["_e", "e-"]];
function unitOf(key) { const last = key.split(".").pop(); const u = UNITS.find(([s]) => last.endsWith(s)); return u ? u[1] : ""; }

function buildPanel() {
  const box = $("fields");
  box.textContent = "";
  const cfg = S.panes[S.edit].config;
  const keys = S.meta.fields.filter((f) => !SKIP.test(f.key));
  const parents = new Set(keys.map((f) => f.key.split(".").slice(0, -1).join(".")));
  const sections = {};
  const quick = ["seed", "sensor.iso", "sensor.gain_db", "sensor.temperature_c", "exposure.integration_time_s",
                 "light.enabled", "light.illuminance_lux", "optics.f_number", "adc.full_scale_e",
                 "dark_current.white_threshold_e_per_s", "source_follower.rts.enabled", "dark_current.rts.enabled",
                 "sensor.frame_rate_hz"];  // RTS: press play
  const add = (section, f, key) => {
    if (!sections[section]) {
      const d = document.createElement("details");
      const s = document.createElement("summary");
      s.textContent = section;
      d.appendChild(s);
      if (section === "quick") d.open = true;
      sections[section] = d;
      box.appendChild(d);
    }
    sections[section].appendChild(fieldRow(f, key, cfg, section === "quick"));
  };
  for (const k of quick) { const f = keys.find((x) => x.key === k); if (f) add("quick", f, k); }
  for (const f of keys) {
    if (f.kind === "json" && [...parents].some((p) => p === f.key || p.startsWith(f.key + ".N"))) continue;  // has sub-keys
    const section = f.key.split(".")[0];
    if (f.key.includes(".N.")) {
      const [head, tail] = f.key.split(".N.");
      const list = getPath(cfg, head) || [];
      list.forEach((item, i) => {
        const key = `${head}.${i}.${tail}`;
        const parent = key.split(".").slice(0, -1).join(".");
        if (getPath(cfg, parent) == null) return;                       // e.g. a point without a tail
        add(section, f, key);
      });
    } else if (f.key === `${section}.enabled`) {
      add(section, f, f.key);
    } else {
      const parent = f.key.split(".").slice(0, -1).join(".");
      if (parent && getPath(cfg, parent) == null) continue;
      add(section, f, f.key);
    }
  }
}

function fieldRow(f, key, cfg, whole = false) {
  const row = document.createElement("div");
  row.className = whole ? "field whole" : "field";  // a whole key's label on a line of its own, never cut
  row.dataset.key = key;
  const name = document.createElement("span");
  name.className = "name";
  const unit = unitOf(key);
  // in its section the last two parts name a key; among the quick settings (from several sections) the whole key
  const label = whole ? key : key.split(".").slice(-2).join(".").replace(/^\d+\./, "");
  name.textContent = label + (unit ? ` [${unit}]` : "");
  name.title = `${key}: ${f.description}${f.limits ? " (" + f.limits + ")" : ""}; default ${JSON.stringify(f.default)}`;
  row.appendChild(name);
  const value = getPath(cfg, key);
  const err = document.createElement("span");
  err.className = "err";
  err.dataset.key = key;
  if (f.kind === "bool") {
    const box = document.createElement("input");
    box.type = "checkbox"; box.checked = !!value; box.className = "wide"; box.dataset.key = key;
    box.addEventListener("change", () => change(key, box.checked));
    row.appendChild(box);
  } else if ((key === "sensor.iso" || key === "sensor.gain_db") &&
             (cfg.gain_table || []).some((r) => r[key.split(".")[1]] != null)) {
    // a gain setting picks a row of the camera's gain table: offer those settings only
    const field = key.split(".")[1];
    const sel = document.createElement("select");
    sel.className = "wide"; sel.dataset.key = key;
    const settings = cfg.gain_table.filter((r) => r[field] != null).map((r) => [r[field], r.mode]);
    for (const [v, mode] of [[null, null], ...settings.sort((a, b) => a[0] - b[0])]) {
      const o = document.createElement("option");
      o.value = v == null ? "" : String(v);
      o.textContent = v == null ? "(none)" : `${v}${mode ? " (" + mode + ")" : ""}`;
      sel.appendChild(o);
    }
    sel.value = value == null ? "" : String(value);
    sel.addEventListener("change", () => change(key, sel.value === "" ? null : Number(sel.value)));
    row.appendChild(sel);
  } else if (f.kind === "enum") {
    const sel = document.createElement("select");
    sel.className = "wide"; sel.dataset.key = key;
    for (const c of f.choices) { const o = document.createElement("option"); o.value = o.textContent = c; sel.appendChild(o); }
    sel.value = value;
    sel.addEventListener("change", () => change(key, sel.value));
    row.appendChild(sel);
  } else if (f.kind === "number" || f.kind === "integer") {
    const num = document.createElement("input");
    num.type = "number"; num.step = "any"; num.dataset.key = key;
    num.value = value == null ? "" : value;
    if (f.nullable) num.placeholder = "null";
    const slider = document.createElement("input");
    slider.type = "range"; slider.min = 0; slider.max = 1000; slider.dataset.key = key;
    const scale = sliderScale(f, value);
    slider.value = scale.toPos(value == null ? scale.lo : Number(value));
    slider.addEventListener("input", () => {
      let v = scale.toValue(Number(slider.value));
      v = f.kind === "integer" ? Math.round(v) : Number(v.toPrecision(4));
      num.value = v;
      change(key, v);
    });
    num.addEventListener("change", () => {
      const t = num.value.trim();
      const v = t === "" ? null : Number(t);
      if (v !== null && Number.isFinite(v)) slider.value = scale.toPos(v);
      change(key, t === "" ? null : (Number.isFinite(v) ? v : t));
    });
    row.appendChild(slider);
    row.appendChild(num);
  } else {
    const text = document.createElement("input");
    text.type = "text"; text.className = "wide"; text.dataset.key = key;
    text.value = f.kind === "json" ? JSON.stringify(value) : (value == null ? "" : value);
    text.addEventListener("change", () => {
      if (f.kind !== "json") return change(key, text.value);
      try { change(key, JSON.parse(text.value)); } catch (e) { showErrors({ [key]: "not valid JSON" }, S.edit); }
    });
    row.appendChild(text);
  }
  row.appendChild(err);
  return row;
}

function sliderScale(f, value) {
  const d = typeof f.default === "number" ? f.default : (typeof value === "number" ? value : 1);
  let lo = f.min != null ? f.min : Math.min(0, d);
  let hi = f.max != null ? f.max : Math.max(10 * Math.abs(d), 10);
  const ref = Math.max(Math.abs(d), Math.abs(value || 0), 1e-3);
  if (hi - lo > 1e4 * ref) {              // a huge allowed range: a log slider around the value
    lo = Math.max(lo, ref / 1000, 1e-9);
    hi = Math.min(hi, ref * 1000);
    return { lo, toPos: (v) => 1000 * Math.log(Math.max(v, lo) / lo) / Math.log(hi / lo),
      toValue: (p) => lo * Math.pow(hi / lo, p / 1000) };
  }
  return { lo, toPos: (v) => 1000 * (v - lo) / (hi - lo || 1), toValue: (p) => lo + (hi - lo) * p / 1000 };
}

function change(key, value) {
  setPath(S.panes[S.edit].config, key, value);
  const structural = /\.(enabled|tail)$|points$/.test(key);
  if (structural) buildPanel();
  saveUrl();
  schedule(S.edit);
  if (S.mode === "diff") schedule(S.edit === "A" ? "B" : "A");
}

function showErrors(errors, pane) {
  if (pane !== S.edit) return;
  document.querySelectorAll(".field").forEach((r) => r.classList.remove("bad"));
  document.querySelectorAll(".field .err").forEach((e) => { e.textContent = ""; });
  $("paneError").textContent = "";
  for (const [key, msg] of Object.entries(errors || {})) {
    const span = document.querySelector(`.field .err[data-key="${CSS.escape(key)}"]`);
    if (span) {
      span.textContent = msg; span.parentElement.classList.add("bad");
      const section = span.closest("details"); if (section) section.open = true;   // show where the problem is
    }
    else $("paneError").textContent = `${key}: ${msg}`;
  }
}

// ------------------------------------------------------------------ rendering
function sensorSize() { const c = S.panes.A.config.sensor; return { rows: c.height, cols: c.width }; }
function canvasFor(p) { return $("canvas" + p); }
// both panes side by side at any width from 1280 pixels, their key figures below them above the fold
const CANVAS_MAX = [640, 420];
function layout() {
  const box = $("pictures"), gap = 10;
  const avail = box.clientWidth - 16 - gap;                // #pictures' padding, the gap between the panes
  const w = Math.max(240, Math.min(CANVAS_MAX[0], Math.floor(avail / 2)));
  const h = Math.round(w * CANVAS_MAX[1] / CANVAS_MAX[0]);
  const wasFit = !S.zoom || (S.panes.A && Math.abs(S.zoom - fitZoom()) < 1e-9);
  for (const p of ["A", "B"]) { canvasFor(p).width = w; canvasFor(p).height = h; $("figures" + p).style.width = `${w}px`; }
  $("quality").style.width = `${2 * w + 10}px`;   // under both panes
  canvasFor("Diff").width = 2 * w + gap; canvasFor("Diff").height = h;
  if (wasFit) S.zoom = null;
}
function fitZoom() {
  const c = canvasFor("A"), { rows, cols } = sensorSize();
  return Math.min(c.width / cols, c.height / rows);
}
function geometry() {
  const c = canvasFor("A"), { rows, cols } = sensorSize();
  if (!S.zoom) { S.zoom = fitZoom(); S.cx = cols / 2; S.cy = rows / 2; }
  const z = S.zoom;
  let step = 1;
  while (step < 64 && z * step * 2 <= 1.0001) step *= 2;
  const r0 = Math.max(0, Math.floor(S.cy - c.height / (2 * z)) & ~1);
  const c0 = Math.max(0, Math.floor(S.cx - c.width / (2 * z)) & ~1);
  const r1 = Math.min(rows, Math.ceil(S.cy + c.height / (2 * z)) + 1);
  const c1 = Math.min(cols, Math.ceil(S.cx + c.width / (2 * z)) + 1);
  return { region: [r0, r1, c0, c1], step, z };
}

// changes made in one task (one event) are sent once: the render starts in a microtask, not after a timer
const pending = {};
function schedule(p) {
  if (pending[p]) return;
  pending[p] = true;
  queueMicrotask(() => { pending[p] = false; render(p); });
}
function scheduleAll() { schedule("A"); schedule("B"); }

const controllers = {};
async function render(p) {
  const g = geometry();
  const seq = ++S.seq[p];
  if (controllers[p]) controllers[p].abort();            // a newer move makes the older request stale: dropped
  const ctl = new AbortController();
  controllers[p] = ctl;
  S.busy[p] = true;
  const pane = S.panes[p];
  const body = { client: S.client, pane: p, seq, config: pane.config, scene: pane.scene, view: S.view, frame: S.frame,
    region: g.region, step: g.step, couplets: S.couplets };
  let resp;
  try {
    resp = await postJson("api/render", body, { signal: ctl.signal });
  } catch (e) { if (seq === S.seq[p]) S.busy[p] = false; return; }
  if (seq !== S.seq[p]) return;                            // stale
  S.busy[p] = false;
  if (resp.status === 204) return;                        // dropped by the server: a newer request is on its way
  if (!resp.ok) {
    const j = await resp.json().catch(() => ({ error: resp.statusText, errors: {} }));
    if (seq !== S.seq[p]) return;
    $("status" + p).textContent = "invalid: " + j.error + " (the last valid picture stays)";
    $("status" + p).classList.add("bad");
    showErrors(Object.keys(j.errors || {}).length ? j.errors : { config: j.error }, p);
    return;
  }
  const info = JSON.parse(resp.headers.get("X-Render") || "{}");
  S.lastInfo = info;
  let bitmap;
  try {
    bitmap = await toBitmap(new Uint8Array(await resp.arrayBuffer()), info.shape);
  } catch (e) {                                            // aborted while the body arrived: a newer request took over
    if (e.name === "AbortError" || seq !== S.seq[p]) return;
    throw e;
  }
  if (seq !== S.seq[p]) return;
  S.images[p] = { bitmap, region: info.region, step: info.step, couplets: info.couplets || [] };
  S.shown[p] = seq;
  S.valid[p] = { config: clone(body.config), scene: body.scene };
  saveUrl();
  $("status" + p).textContent = `frame ${S.frame}, ${info.ms} ms on the server`;
  $("status" + p).classList.remove("bad");
  showErrors({}, p);
  draw(p);
  if (S.mode === "diff") drawDiff();
  S.drawnAt[p] = performance.now();
  figures(p);
}

function toBitmap(px, shape) {          // the server's raw 8-bit RGBA (rows, cols, 4) to a bitmap, no copy
  const [h, w] = shape;
  return createImageBitmap(new ImageData(new Uint8ClampedArray(px.buffer, px.byteOffset, w * h * 4), w, h));
}

function drawImage(ctx, img, c) {
  const z = S.zoom;
  const [r0, , c0] = img.region;
  const x = c.width / 2 + (c0 - S.cx) * z, y = c.height / 2 + (r0 - S.cy) * z;
  ctx.imageSmoothingEnabled = false;                      // nearest neighbour: single white pixels stay single
  ctx.drawImage(img.bitmap, x, y, img.bitmap.width * img.step * z, img.bitmap.height * img.step * z);
  if (S.couplets) {
    ctx.strokeStyle = "#ff3b30"; ctx.lineWidth = 2;
    for (const [ra, ca, rb, cb] of img.couplets) {
      const px = c.width / 2 + ((ca + cb) / 2 + 0.5 - S.cx) * z, py = c.height / 2 + ((ra + rb) / 2 + 0.5 - S.cy) * z;
      ctx.beginPath(); ctx.arc(px, py, Math.max(8, 2.5 * z), 0, 2 * Math.PI); ctx.stroke();
    }
  }
}
function draw(p) {
  const c = canvasFor(p), ctx = c.getContext("2d");
  ctx.fillStyle = "#111"; ctx.fillRect(0, 0, c.width, c.height);
  if (S.images[p]) drawImage(ctx, S.images[p], c);
  $("zoomText").textContent = ` ${S.zoom >= 1 ? S.zoom.toFixed(S.zoom < 10 ? 1 : 0) + ":1" : "1:" + (1 / S.zoom).toFixed(1)}`;
}
function drawDiff() {
  const a = S.images.A, b = S.images.B, c = $("canvasDiff"), ctx = c.getContext("2d");
  if (!a || !b) return;
  const w = a.bitmap.width, h = a.bitmap.height;
  if (b.bitmap.width !== w || b.bitmap.height !== h) return;
  const off = new OffscreenCanvas(w, h), o = off.getContext("2d");
  o.drawImage(a.bitmap, 0, 0); const da = o.getImageData(0, 0, w, h);
  o.drawImage(b.bitmap, 0, 0); const db = o.getImageData(0, 0, w, h);
  for (let i = 0; i < da.data.length; i += 4)
    for (let k = 0; k < 3; k++) da.data[i + k] = Math.max(0, Math.min(255, 128 + 4 * (db.data[i + k] - da.data[i + k])));
  o.putImageData(da, 0, 0);
  ctx.fillStyle = "#111"; ctx.fillRect(0, 0, c.width, c.height);
  const img = { bitmap: off, region: a.region, step: a.step, couplets: [] };
  drawImage(ctx, img, c);
}
function redraw() { draw("A"); draw("B"); if (S.mode === "diff") drawDiff(); }

// ------------------------------------------------------------------ key figures and the budget
const figTimers = {};
function figures(p) {
  clearTimeout(figTimers[p]);
  figTimers[p] = setTimeout(async () => {
    const pane = S.panes[p];
    const resp = await postJson("api/figures", { config: pane.config, scene: pane.scene }).catch(() => null);
    if (!resp || !resp.ok) return;
    showFigures(p, await resp.json());
  }, 500);   // once the slider rests: the figures never take the CPU from the next picture
}
// the figures' names and units (the server's FIGURE_NAMES and SOURCE_NAMES: one table for the docs and the pages)
const figName = (k, level) => { const n = (S.meta.names || {}).figures || {}; return n[k] ? n[k].replace("{level}", level) : (level ? `${k} ${level}` : k); };
const sourceName = (k) => ((S.meta.names || {}).budget || {})[k] || k;
const fmt = (v, d = 3) => (v == null ? "-" : typeof v === "number" ? Number(v.toPrecision(d)).toLocaleString("en") : String(v));
function showFigures(p, d) {
  const box = $("figures" + p);
  box.textContent = "";
  const t = document.createElement("table");
  const row = (k, v) => { const r = t.insertRow(); r.insertCell().textContent = k; const c = r.insertCell(); c.className = "v"; c.textContent = v; };
  const kf = d.key_figures || {};
  const title = document.createElement("strong");
  title.textContent = `${p}: key figures`;
  box.appendChild(title);
  for (const [k, v] of Object.entries(kf)) {
    if (typeof v === "object" && v !== null) { for (const [k2, v2] of Object.entries(v)) row(figName(k, k2), fmt(v2)); }
    else row(figName(k), fmt(v));
  }
  if (d.dark) {
    for (const [k, v] of Object.entries(d.dark)) {
      if (k === "threshold" || k === "threshold_source") continue;       // threshold: = threshold_e_per_s
      row(figName(k), fmt(v));
      if (k === "threshold_e_per_s") t.rows[t.rows.length - 1].title = `from ${d.dark.threshold_source}`;
    }
  }
  box.appendChild(t);
  const b = d.budget || {};
  const h = document.createElement("strong");
  h.textContent = `noise budget of this scene (e- rms): temporal ${fmt(b.temporal_total_e)}, fixed pattern ${fmt(b.fixed_total_e)}`;
  box.appendChild(h);
  const bars = document.createElement("table");
  const all = [...Object.entries(b.temporal_e || {}).map(([k, v]) => [k, v, ""]), ...Object.entries(b.fixed_e || {}).map(([k, v]) => [k, v, "fixed"])];
  const top = Math.max(1e-9, ...all.map((x) => x[1]));
  for (const [k, v, cls] of all) {
    const r = bars.insertRow();
    r.insertCell().textContent = sourceName(k) + (cls ? " (fixed)" : "");
    const c = r.insertCell(); const bar = document.createElement("span");
    bar.className = "bar " + cls; bar.style.width = `${Math.round(260 * v / top)}px`; c.appendChild(bar);
    const n = r.insertCell(); n.className = "v"; n.textContent = fmt(v);
  }
  box.appendChild(bars);
}

// ------------------------------------------------------------------ image quality of both panes at one illuminance
// (the server's quality metrics: analysis/quality.py's METRICS, one table for the command, the sweep and this page)
async function qualityOf(p, lux) {
  const resp = await postJson("api/quality", { config: S.panes[p].config, lux });
  const d = await resp.json().catch(() => ({ error: `HTTP ${resp.status}` }));
  if (!resp.ok) throw new Error(`${p}: ${d.error || resp.status}`);
  return d;
}
async function measureQuality() {
  const lux = Number($("qLux").value), status = $("qStatus");
  $("qTable").textContent = ""; $("qNotes").textContent = "";
  status.classList.remove("err");
  if (!(lux > 0)) { status.classList.add("err"); status.textContent = `lux = ${$("qLux").value}: give an illuminance above 0`; return; }
  status.textContent = `measuring A and B at ${fmt(lux)} lux ...`;
  let a, b;
  try { a = await qualityOf("A", lux); b = await qualityOf("B", lux); }
  catch (e) { status.classList.add("err"); status.textContent = e.message; return; }
  status.textContent = `${fmt(a.lux)} lux: the charts (18 % grey, slanted edge, ColorChecker), ${a.frames} frames each, on each pane's sensor`;
  showQuality(a, b);
}
function showQuality(a, b) {
  const t = $("qTable");
  const head = t.createTHead().insertRow();
  for (const h of ["metric", "A", "B", "A - B"]) {
    const c = document.createElement("th"); c.textContent = h; if (h !== "metric") c.className = "v"; head.appendChild(c);
  }
  const body = t.createTBody();
  for (const [k, [label, unit, better]] of Object.entries(a.labels)) {
    const va = a.metrics[k], vb = b.metrics[k], r = body.insertRow();
    r.dataset.metric = k;
    r.insertCell().textContent = unit ? `${label} (${unit})` : label;
    for (const v of [va, vb]) { const c = r.insertCell(); c.className = "v"; c.textContent = fmt(v); }
    const d = r.insertCell(); d.className = "v";
    if (va == null || vb == null) { d.textContent = "-"; continue; }
    const diff = va - vb;
    let text = fmt(diff) + (unit === "JND" ? " JND" : unit ? ` ${unit}` : "");
    // visual noise in thresholds: the L* sigma at which noise becomes just visible (one JND at detection)
    if (k === "visual_noise_l" && a.visual_threshold_l > 0) text += ` (${fmt(diff / a.visual_threshold_l, 2)} thresholds)`;
    const winner = diff === 0 ? "" : (better === "lower") === (diff < 0) ? "A" : "B";
    if (winner) { text += `, ${winner} better`; d.classList.add("better" + winner); }
    d.textContent = text;
  }
  const notes = [...new Set([...a.notes, ...b.notes])].map((n) =>
    `${a.notes.includes(n) && b.notes.includes(n) ? "A and B" : a.notes.includes(n) ? "A" : "B"}: ${n}.`);
  $("qNotes").textContent = notes.join(" ");
}

// ------------------------------------------------------------------ pan, zoom, video, panes
function zoomBy(f, sx, sy) {
  const c = canvasFor("A");
  sx = sx == null ? c.width / 2 : sx; sy = sy == null ? c.height / 2 : sy;
  const wx = S.cx + (sx - c.width / 2) / S.zoom, wy = S.cy + (sy - c.height / 2) / S.zoom;
  S.zoom = Math.min(64, Math.max(fitZoom() / 4, S.zoom * f));
  S.cx = wx - (sx - c.width / 2) / S.zoom; S.cy = wy - (sy - c.height / 2) / S.zoom;
  saveUrl(); redraw(); scheduleAll();
}
function attachPan(c) {
  let drag = null;
  c.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY, cx: S.cx, cy: S.cy }; c.setPointerCapture(e.pointerId); });
  c.addEventListener("pointermove", (e) => {
    if (!drag) return;
    S.cx = drag.cx - (e.clientX - drag.x) / S.zoom; S.cy = drag.cy - (e.clientY - drag.y) / S.zoom;
    redraw();
  });
  c.addEventListener("pointerup", () => { if (drag) { drag = null; saveUrl(); scheduleAll(); } });
  c.addEventListener("wheel", (e) => { e.preventDefault(); const r = c.getBoundingClientRect();
    zoomBy(e.deltaY < 0 ? 1.25 : 0.8, e.clientX - r.left, e.clientY - r.top); }, { passive: false });
}

let playTimer = null;
function setPlaying(on) {
  S.playing = on;
  $("play").textContent = on ? "pause" : "play";
  clearInterval(playTimer);
  if (on) playTimer = setInterval(() => {
    if (S.busy.A || S.busy.B) return;                     // never queue frames: skip a tick instead
    S.frame += 1; $("frame").value = S.frame; scheduleAll();
  }, 1000 / Math.max(1, S.fps));
  else saveUrl();
}

function setEdit(p) {
  S.edit = p;
  $("editA").classList.toggle("on", p === "A"); $("editB").classList.toggle("on", p === "B");
  $("scene").value = S.panes[p].scene;
  buildPanel();
}
function addSceneOption(value, label) {
  if ([...$("scene").options].some((o) => o.value === value)) return;
  const o = document.createElement("option"); o.value = value; o.textContent = label; $("scene").appendChild(o);
}

async function init() {
  S.meta = await (await fetch("api/meta")).json();
  if (!loadUrl()) {
    S.panes.A = { config: clone(S.meta.base), scene: S.meta.scene };
    S.panes.B = { config: clone(S.meta.base), scene: S.meta.scene };
  }
  for (const n of S.meta.presets) { const o = document.createElement("option"); o.value = o.textContent = n; $("preset").appendChild(o); }
  for (const s of ["photo", "flat:0.5", "flat:0", "ramp", "colorchecker", "zoneplate", "siemens", "steps:8", "spot"]) addSceneOption(s, s);
  for (const p of ["A", "B"]) addSceneOption(S.panes[p].scene, S.panes[p].scene.startsWith("upload:") ? "uploaded image" : S.panes[p].scene);
  $("view").value = S.view; $("mode").value = S.mode; $("frame").value = S.frame; $("couplets").checked = S.couplets;
  $("view").addEventListener("change", () => { S.view = $("view").value; saveUrl(); scheduleAll(); });
  $("mode").addEventListener("change", () => {
    S.mode = $("mode").value; const d = S.mode === "diff";
    $("figA").hidden = d; $("figB").hidden = d; $("figD").hidden = !d; saveUrl(); scheduleAll();
  });
  $("mode").dispatchEvent(new Event("change"));
  $("frame").addEventListener("change", () => { S.frame = Math.max(0, Math.round(Number($("frame").value) || 0)); saveUrl(); scheduleAll(); });
  $("fps").addEventListener("change", () => { S.fps = Number($("fps").value) || 5; if (S.playing) setPlaying(true); });
  $("play").addEventListener("click", () => setPlaying(!S.playing));
  $("couplets").addEventListener("change", () => { S.couplets = $("couplets").checked; saveUrl(); scheduleAll(); });
  $("zoomIn").addEventListener("click", () => zoomBy(2));
  $("zoomOut").addEventListener("click", () => zoomBy(0.5));
  $("zoomFit").addEventListener("click", () => { S.zoom = null; geometry(); saveUrl(); redraw(); scheduleAll(); });
  $("zoom1").addEventListener("click", () => zoomBy(1 / S.zoom));
  $("copyAB").addEventListener("click", () => { S.panes.B = clone(S.panes.A); setEdit(S.edit); saveUrl(); scheduleAll(); });
  $("qMeasure").addEventListener("click", measureQuality);
  $("swap").addEventListener("click", () => { [S.panes.A, S.panes.B] = [S.panes.B, S.panes.A]; setEdit(S.edit); saveUrl(); scheduleAll(); });
  $("editA").addEventListener("click", () => setEdit("A"));
  $("editB").addEventListener("click", () => setEdit("B"));
  $("scene").addEventListener("change", () => { S.panes[S.edit].scene = $("scene").value; saveUrl(); schedule(S.edit); });
  $("preset").addEventListener("change", async () => {
    const name = $("preset").value; if (!name) return;
    const r = await fetch("api/preset?name=" + encodeURIComponent(name));
    const j = await r.json();
    if (!r.ok) { $("paneError").textContent = j.error; return; }
    S.panes[S.edit].config = j.config;
    if (j.scene) { addSceneOption(j.scene, j.scene); S.panes[S.edit].scene = j.scene; $("scene").value = j.scene; }
    S.zoom = null; buildPanel(); saveUrl(); scheduleAll();
  });
  $("upload").addEventListener("change", async () => {
    const f = $("upload").files[0]; if (!f) return;
    const r = await fetch("api/upload", { method: "POST", body: f, headers: { "X-Filename": f.name, "Content-Type": "application/octet-stream", "X-Cmosnoise": "1" } });
    const j = await r.json();
    if (!r.ok) { $("paneError").textContent = j.error; return; }
    addSceneOption(j.scene, j.name); S.panes[S.edit].scene = j.scene; $("scene").value = j.scene; saveUrl(); schedule(S.edit);
  });
  $("export").addEventListener("click", async () => {
    const pane = S.panes[S.edit];
    const r = await postJson("api/yaml", { config: pane.config, scene: pane.scene });
    if (!r.ok) { $("paneError").textContent = (await r.json()).error; return; }
    const a = document.createElement("a");
    a.href = URL.createObjectURL(new Blob([await r.text()], { type: "application/x-yaml" }));
    a.download = `config-${S.edit}.yaml`; document.body.appendChild(a); a.click(); a.remove();
  });
  $("load").addEventListener("change", async () => {
    const f = $("load").files[0]; if (!f) return;
    const r = await postJson("api/load", { yaml: await f.text() });
    const j = await r.json();
    if (!r.ok) { $("paneError").textContent = j.error; return; }
    S.panes[S.edit].config = j.config; buildPanel(); saveUrl(); schedule(S.edit);
  });
  for (const p of ["A", "B", "Diff"]) attachPan(canvasFor(p));
  setEdit("A");
  S.valid = { A: clone(S.panes.A), B: clone(S.panes.B) };
  layout();
  let resizing = null;
  window.addEventListener("resize", () => {
    clearTimeout(resizing);
    resizing = setTimeout(() => { layout(); geometry(); redraw(); scheduleAll(); }, 150);
  });
  geometry(); saveUrl(); scheduleAll();
}
window.addEventListener("DOMContentLoaded", init);
