// The live page's generic view ("Any model"): any served model, its columns plotted over time.
//
// Pick a model, stream an observation to it (replay one of its interactions from /api/replay/MODEL, or drag one
// observed DoF up and down with the mouse), and see every DoF of both agents over time: the frames sent (black),
// the predicted mean (blue: observed agent, red: controlled agent) with its ±2σ band, the true continuation of a
// replay (green, dashed), the estimated phase (vertical line) and the out-of-range flag. Labels come from the
// `opened` reply (column names and units). State for tests: window.ipState.gen and data-* of the canvas.
import { InterprimClient } from "/static/ipclient.js";
import { PointerSampler, TOKEN, WS_URL, clamp, fetchJSON, fmt, interpRow } from "/static/common.js";

const $ = (id) => document.getElementById(id);
const POINTS = 100; // points of the predicted trajectories (normalised time 0..1)
const MARGIN = { left: 170, right: 16, top: 8, bottom: 40 };
const COLORS = {
  observed: { line: "#2a5db0", band: "rgba(42,93,176,0.16)" },
  controlled: { line: "#c33", band: "rgba(204,51,51,0.16)" },
};

const g = {
  canvas: null, client: null, info: null, model: null, opened: null, rows: [], pred: null, sent: [],
  replay: null, replayData: null, timer: null, sampler: null, dragRow: null, dragRange: null, ignoreUpTo: 0,
};
let state = null;

function label(row) {
  return row.unit ? `${row.name} [${row.unit}]` : row.name;
}

// ---------------------------------------------------------------- layout: one row per data column
function layout(opened) {
  const obs = opened.observed_dofs;
  const names = opened.column_names, units = opened.column_units, cols = opened.columns;
  const at = (c) => cols.indexOf(c);
  const rows = [];
  obs.forEach((c, k) => rows.push({ col: c, name: opened.observed_names[k], unit: opened.observed_units[k],
                                    role: "observed", frameIndex: k }));
  cols.forEach((c) => { if (!obs.includes(c)) rows.push({ col: c, name: names[at(c)], unit: units[at(c)], role: "controlled" }); });
  const rowH = clamp(Math.floor(520 / rows.length), 46, 130);
  g.canvas.height = MARGIN.top + rows.length * rowH + MARGIN.bottom;
  rows.forEach((r, i) => { r.top = MARGIN.top + i * rowH; r.height = rowH - 8; });
  g.rows = rows;
  $("gen-dof").textContent = "–";
}

// ---------------------------------------------------------------- time axis
function duration() {
  const p = g.pred;
  return (p && p.duration) || g.model.mean_duration;
}

function timeAxis() {
  const seconds = $("gen-time").value === "s";
  const dur = duration(), dt = g.model.dt;
  let max = seconds ? dur : 1;
  if (seconds) {
    max = Math.max(max, (g.sent.length - 1) * dt);
    if (g.replay) max = Math.max(max, g.replay.truthDuration);
  } else {
    max = Math.max(1, ((g.sent.length - 1) * dt) / dur);
  }
  return {
    seconds, max, label: seconds ? "time [s]" : "normalised time (0 = start, 1 = end of the movement)",
    // a point of the predicted grid (normalised s) / the k-th frame sent / the k-th frame of the replay's truth
    grid: (s) => (seconds ? s * dur : s),
    sent: (k) => (seconds ? k * dt : (k * dt) / dur),
    truth: (k, n) => (seconds ? k * dt : k / Math.max(1, n - 1)),
  };
}

// ---------------------------------------------------------------- drawing
function seriesOf(row) {
  const p = g.pred, out = { mean: null, std: null, sent: null, truth: null };
  if (p) {
    const j = p.columns.indexOf(row.col);
    if (j >= 0) {
      out.mean = p.mean.map((r) => r[j]);
      if (p.std && $("gen-std").checked) out.std = p.std.map((r) => r[j]);
    }
  }
  if (row.role === "observed") out.sent = g.sent.map((f) => f[row.frameIndex]);
  const r = g.replay;
  if (r) out.truth = row.role === "observed" ? r.observedAll.map((f) => f[row.frameIndex])
    : r.truth ? r.truth.map((f) => f[g.model.controlled_dofs.indexOf(row.col)]) : null;
  return out;
}

function yRange(sr, row) {
  if (g.dragRow === row && g.dragRange) return g.dragRange;
  let lo = Infinity, hi = -Infinity;
  const add = (v) => { if (Number.isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); } };
  if (sr.mean) sr.mean.forEach((v, i) => { add(v + 2 * (sr.std ? sr.std[i] : 0)); add(v - 2 * (sr.std ? sr.std[i] : 0)); });
  (sr.sent || []).forEach(add);
  (sr.truth || []).forEach(add);
  const st = g.model.start;
  if (st) add(st[row.col]);
  if (!(hi > lo)) { lo = (Number.isFinite(lo) ? lo : 0) - 1; hi = lo + 2; }
  const pad = 0.08 * (hi - lo);
  return [lo - pad, hi + pad];
}

function draw() {
  requestAnimationFrame(draw);
  if ($("view-generic").hidden || !g.opened) return;
  const c = g.canvas, ctx = c.getContext("2d"), W = c.width;
  ctx.clearRect(0, 0, W, c.height);
  const ax = timeAxis();
  const x0 = MARGIN.left, x1 = W - MARGIN.right;
  const X = (t) => x0 + (t / ax.max) * (x1 - x0);
  const drawn = { series: [], band: 0, phaseLine: false, xLabel: ax.label, mean: 0, sent: 0 };
  const p = g.pred;
  for (const row of g.rows) {
    const sr = seriesOf(row);
    const [lo, hi] = yRange(sr, row);
    row.range = [lo, hi];
    const Y = (v) => row.top + row.height - ((v - lo) / (hi - lo)) * row.height;
    ctx.fillStyle = row.role === "observed" ? "#f3f6fb" : "#fbf4f4";
    ctx.fillRect(x0, row.top, x1 - x0, row.height);
    ctx.fillStyle = "#222"; ctx.font = "13px sans-serif";
    ctx.fillText(label(row), 6, row.top + 16);
    ctx.fillStyle = COLORS[row.role].line; ctx.font = "11px sans-serif";
    ctx.fillText(row.role, 6, row.top + 30);
    ctx.fillStyle = "#777";
    ctx.fillText(fmt(hi, 3), x0 - 52, row.top + 10);
    ctx.fillText(fmt(lo, 3), x0 - 52, row.top + row.height);
    const line = (vals, tf, color, dash, width = 2) => {
      ctx.save(); ctx.beginPath(); ctx.strokeStyle = color; ctx.lineWidth = width; if (dash) ctx.setLineDash(dash);
      vals.forEach((v, k) => { const px = X(tf(k)), py = Y(v); k ? ctx.lineTo(px, py) : ctx.moveTo(px, py); });
      ctx.stroke(); ctx.restore();
    };
    const n = sr.mean ? sr.mean.length : 0, grid = (k) => ax.grid(k / Math.max(1, n - 1));
    if (sr.std) { // the ±2σ band: upper edge forwards, lower edge backwards
      ctx.beginPath(); ctx.fillStyle = COLORS[row.role].band;
      sr.mean.forEach((v, k) => { const px = X(grid(k)), py = Y(v + 2 * sr.std[k]); k ? ctx.lineTo(px, py) : ctx.moveTo(px, py); });
      for (let k = n - 1; k >= 0; k--) ctx.lineTo(X(grid(k)), Y(sr.mean[k] - 2 * sr.std[k]));
      ctx.closePath(); ctx.fill();
      drawn.band += 1;
    }
    if (sr.truth) line(sr.truth, (k) => ax.truth(k, sr.truth.length), "#2a2", [5, 4], 1.5);
    if (sr.mean) { line(sr.mean, grid, COLORS[row.role].line, null); drawn.mean += 1; }
    if (sr.sent && sr.sent.length) { line(sr.sent, ax.sent, "#111", null, 2.5); drawn.sent += 1; }
    drawn.series.push({ label: label(row), name: row.name, unit: row.unit, role: row.role, column: row.col,
                        mean: !!sr.mean, band: !!sr.std, sent: sr.sent ? sr.sent.length : 0 });
  }
  const bottom = g.rows.length ? g.rows.at(-1).top + g.rows.at(-1).height : MARGIN.top;
  if (p && p.phase !== null) { // the current instant of the movement: phase of normalised time
    const px = X(ax.grid(p.phase));
    ctx.save(); ctx.strokeStyle = "#555"; ctx.setLineDash([3, 3]); ctx.beginPath();
    ctx.moveTo(px, MARGIN.top); ctx.lineTo(px, bottom); ctx.stroke(); ctx.restore();
    // the label at the foot of the line: the top of the plot holds the out-of-range banner
    const text = `phase ${fmt(p.phase, 2)}`;
    ctx.fillStyle = "#555"; ctx.font = "12px sans-serif"; ctx.fillText(text, px + 4, bottom - 6);
    drawn.phaseLine = true;
    drawn.phaseLabel = { x: px + 4, y: bottom - 18, w: ctx.measureText(text).width, h: 14 }; // canvas pixels
  }
  ctx.fillStyle = "#444"; ctx.font = "12px sans-serif";
  for (let i = 0; i <= 4; i++) { const t = (i / 4) * ax.max; ctx.fillText(fmt(t, 2), X(t) - 10, bottom + 14); }
  ctx.fillText(ax.label, x0 + (x1 - x0) / 2 - 120, bottom + 30);
  if (p && p.out_of_range) {
    const banner = `input out of range (${fmt(p.input_distance, 0)} σ): the prediction extrapolates`;
    ctx.font = "bold 14px sans-serif";
    ctx.fillStyle = "rgba(255,255,255,0.85)"; // legible over the curves
    ctx.fillRect(x0 + 4, MARGIN.top + 2, ctx.measureText(banner).width + 12, 20);
    ctx.fillStyle = "#b00";
    ctx.fillText(banner, x0 + 10, MARGIN.top + 16);
    drawn.banner = { x: x0 + 4, y: MARGIN.top + 2, w: ctx.measureText(banner).width + 12, h: 20 };
  }
  state.gen.drawn = drawn;
  c.dataset.series = JSON.stringify(drawn.series.map((s) => s.label));
  c.dataset.band = String(drawn.band);
}

// ---------------------------------------------------------------- replies
function onPrediction(p) {
  if (p.seq <= g.ignoreUpTo) return; // a reply to a frame of the previous interaction
  g.pred = p;
  const s = state.gen;
  s.predictions += p.covers || 1; // frames answered (a coalesced reply covers several)
  s.phase = p.phase; s.conditioned = p.conditioned; s.outOfRange = p.out_of_range;
  s.inputDistance = p.input_distance; s.lastSeq = p.seq;
  g.canvas.dataset.predictions = String(s.predictions);
  g.canvas.dataset.phase = p.phase === null ? "" : p.phase.toFixed(4);
  g.canvas.dataset.outOfRange = String(p.out_of_range);
  $("gen-phase").textContent = p.phase === null ? `– (prior: fewer than ${g.opened.min_frames} frames)` : fmt(p.phase, 3);
  $("gen-speed").textContent = fmt(p.speed);
  $("gen-duration").textContent = p.duration === null ? "–" : `${fmt(p.duration, 2)} s`;
  $("gen-conditioned").textContent = String(p.conditioned);
  const oor = $("gen-oor");
  oor.textContent = String(p.out_of_range);
  oor.style.color = p.out_of_range ? "#b00" : "#171";
  $("gen-dist").textContent = p.input_distance === null ? "–" : `${fmt(p.input_distance, 1)} σ`;
  $("gen-compute").textContent = `${fmt(p.compute_ms, 2)} ms`;
}

// ---------------------------------------------------------------- streaming: replay or drag
function send(frame) {
  g.sent.push(frame.slice());
  g.client.sendFrame(frame);
  state.gen.frames += 1;
  state.gen.lastFrame = frame.slice();
  $("gen-frames").textContent = String(state.gen.frames);
}

function dragFrame(v) {
  // the dragged DoF from the pointer; the other observed DoFs as the model expects them now (its latest
  // prediction one frame ahead), or at the demonstrations' mean start before there is one
  const m = g.model, p = g.pred, row = g.dragRow;
  const f = m.observed_dofs.map((c) => (m.start ? m.start[c] : 0));
  if (p && p.conditioned) {
    const s = Math.min(1, p.phase + m.dt / p.duration);
    const now = interpRow(p.mean, s);
    m.observed_dofs.forEach((c, k) => { const j = p.columns.indexOf(c); if (j >= 0) f[k] = now[j]; });
  } else if (g.sent.length) {
    g.sent.at(-1).forEach((v2, k) => { f[k] = v2; });
  }
  f[row.frameIndex] = v;
  return f;
}

function tick() {
  if (!g.client || !g.client.isOpen) return;
  if (g.replay) {
    const r = g.replay;
    if (r.i >= r.frames.length) { stop(); return; }
    send(r.frames[r.i++]);
  } else if (g.sampler) {
    const [lo, hi] = g.dragRange, row = g.dragRow;
    for (const pt of g.sampler.due()) {
      const v = lo + ((row.top + row.height - pt[1]) / row.height) * (hi - lo);
      send(dragFrame(v));
    }
    if (g.sampler.done) stop();
  }
}

function start() {
  stop();
  g.pred = null; g.sent = [];
  g.ignoreUpTo = g.client.seq; // replies to earlier frames belong to the previous interaction
  Object.assign(state.gen, { frames: 0, predictions: 0, phase: null, conditioned: null, outOfRange: null,
                             inputDistance: null, active: true, error: null });
  $("gen-error").textContent = "";
  g.client.reset().catch((e) => ($("gen-error").textContent = e.message));
  g.timer = setInterval(tick, 1000 * g.model.dt);
}

function stop() {
  if (g.timer) clearInterval(g.timer);
  g.timer = null; g.sampler = null; g.dragRow = null; g.dragRange = null;
  if (g.replay) g.replay.frames = []; // keep its truth on screen, send nothing more
  state.gen.active = false;
}

async function openModel(name) {
  stop();
  g.model = g.info.models.find((m) => m.name === name);
  g.replay = null; g.pred = null; g.sent = [];
  g.ignoreUpTo = g.client.seq;
  const opened = await g.client.open(name, { points: POINTS, std: $("gen-std").checked, dofs: "all" });
  g.opened = opened;
  layout(opened);
  state.gen.model = name;
  state.gen.opened = opened;
  state.gen.predictions = 0; state.gen.frames = 0;
  $("gen-title").textContent = g.model.title || name;
  g.replayData = g.model.replay ? await fetchJSON(`/api/replay/${encodeURIComponent(name)}`) : null;
  const sel = $("gen-replay-index");
  sel.innerHTML = "";
  const its = g.replayData ? g.replayData.interactions : [];
  its.forEach((it, i) => {
    const o = document.createElement("option");
    o.value = String(i); o.textContent = `#${i + 1} (${fmt(it.duration, 2)} s)`; sel.appendChild(o);
  });
  $("gen-replay").disabled = !its.length;
  $("gen-source").textContent = g.replayData ? g.replayData.source || "replay data" :
    "none (interprim serve ... --replay MODEL=DEMOS.csv); drag instead";
  state.gen.replayAvailable = its.length;
  state.gen.ready = true;
}

function startReplay() {
  const its = g.replayData ? g.replayData.interactions : [];
  if (!its.length) return;
  const it = its[Number($("gen-replay-index").value) || 0];
  const scale = Number($("gen-scale").value) || 1; // x1000: what wrong units look like to the model
  const frac = Number($("gen-replay-frac").value) || 1;
  const frames = it.observed.map((f) => f.map((v) => v * scale));
  start();
  g.replay = { frames: frames.slice(0, Math.max(2, Math.round(frac * frames.length))), i: 0,
               observedAll: frames, truth: it.controlled_truth || null,
               truthDuration: (it.observed.length - 1) * g.model.dt };
}

function canvasY(ev) {
  const r = g.canvas.getBoundingClientRect();
  return [((ev.clientX - r.left) * g.canvas.width) / r.width, ((ev.clientY - r.top) * g.canvas.height) / r.height];
}

export async function genInit(info, pageState) {
  state = pageState;
  state.gen = { ready: false, connected: false, model: null, opened: null, frames: 0, predictions: 0, phase: null,
                conditioned: null, outOfRange: null, inputDistance: null, active: false, error: null, drawn: null };
  g.info = info;
  g.canvas = $("gen-canvas");
  window.ipView = window.ipView || {};
  // for tests: a data value of an observed row -> viewport coordinates (x at the middle of the plot)
  window.ipView.genValueToClient = (frameIndex, v) => {
    const row = g.rows.find((r) => r.role === "observed" && r.frameIndex === frameIndex);
    const [lo, hi] = (g.dragRow === row && g.dragRange) || row.range;
    const cy = row.top + row.height - ((v - lo) / (hi - lo)) * row.height, cx = (MARGIN.left + g.canvas.width) / 2;
    const r = g.canvas.getBoundingClientRect();
    return [r.left + (cx * r.width) / g.canvas.width, r.top + (cy * r.height) / g.canvas.height];
  };
  const observedRow = (k) => g.rows.find((r) => r.role === "observed" && r.frameIndex === k);
  window.ipView.genRange = (k) => observedRow(k).range;
  window.ipView.genRowHeight = (k) => (observedRow(k).height * g.canvas.getBoundingClientRect().height) / g.canvas.height;
  const sel = $("gen-model");
  for (const m of info.models) {
    const o = document.createElement("option");
    o.value = m.name;
    o.textContent = `${m.name} (${m.observed_dofs.length} observed, ${m.controlled_dofs.length} controlled)`;
    sel.appendChild(o);
  }
  requestAnimationFrame(draw);
  g.client = new InterprimClient(WS_URL, { token: TOKEN });
  await g.client.connect();
  state.gen.connected = true;
  g.client.onClose = () => { state.gen.connected = false; };
  g.client.onPrediction = onPrediction;
  g.client.onError = (e) => { state.gen.error = e.message; $("gen-error").textContent = e.message; };
  // default: the first model that is not a demo model (the user's own), else the first one
  const first = info.models.find((m) => !m.world) || info.models[0];
  sel.value = first.name;
  await openModel(first.name);
  sel.onchange = () => openModel(sel.value).catch((e) => ($("gen-error").textContent = e.message));
  $("gen-std").onchange = () => openModel(sel.value).catch((e) => ($("gen-error").textContent = e.message));
  $("gen-replay").onclick = startReplay;
  $("gen-reset").onclick = () => { stop(); g.replay = null; g.pred = null; g.sent = []; g.ignoreUpTo = g.client.seq; };
  g.canvas.addEventListener("pointerdown", (ev) => {
    const [, cy] = canvasY(ev);
    // the DoF to drag: the observed one whose plot is pressed
    const row = g.rows.find((r) => r.role === "observed" && cy >= r.top && cy <= r.top + r.height);
    if (!row || !row.range) return;
    try { g.canvas.setPointerCapture(ev.pointerId); } catch (e) { /* a synthetic pointer has nothing to capture */ }
    $("gen-dof").textContent = label(row);
    state.gen.dragged = row.name;
    g.replay = null;
    start();
    g.dragRow = row;
    g.dragRange = row.range.slice(); // the value scale stays put while dragging
    g.sampler = new PointerSampler(1000 * g.model.dt);
    g.sampler.start([0, cy]);
  });
  g.canvas.addEventListener("pointermove", (ev) => { if (g.sampler) g.sampler.add([0, canvasY(ev)[1]]); });
  const up = () => { if (g.sampler) g.sampler.release(); };
  g.canvas.addEventListener("pointerup", up);
  g.canvas.addEventListener("pointercancel", up);
}
