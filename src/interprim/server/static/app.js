// The interprim live page: simulated high-five and handwriting completion, driven by the server.
// State is exposed on window.ipState (and data-* attributes of the canvases) for tests.
import { InterprimClient } from "/static/ipclient.js";
import { PointerSampler, TOKEN, WS_URL, clamp, fetchJSON, fmt, interpRow } from "/static/common.js";
import { genInit } from "/static/generic.js";

const $ = (id) => document.getElementById(id);

const state = (window.ipState = {
  ready: false,
  info: null,
  hf: { connected: false, frames: 0, predictions: 0, phase: null, robotQ: null, robotHand: null,
        meetingPoint: null, humanQ: null, humanHand: null, active: false, error: null, replayGoal: null,
        sent: [] },
  hw: { connected: false, frames: 0, predictions: 0, model: null, probabilities: null, phase: null,
        active: false, error: null, points: [] },
});

// ---------------------------------------------------------------- kinematics (as interprim.sim.PlanarArm)
const DEFAULT_WORLD = {
  observed_arm: { link_lengths: [0.7, 0.65], base: [0, 0], base_angle: 0, sign: 1, rest: [-1.3, 0.35],
                  joint_limits: [[-1.8, 1.9], [0, 2.6]] },
  controlled_arm: { link_lengths: [0.55, 0.5, 0.25], base: [1.6, 0], base_angle: Math.PI, sign: -1,
                    rest: [-1.3, 0.35, 0.2], joint_limits: [[-1.8, 1.9], [0, 2.6], [-1.3, 1.3]] },
};

function fk(arm, q) {
  let a = arm.base_angle;
  let [x, y] = arm.base;
  const pts = [[x, y]];
  const angles = [];
  for (let i = 0; i < arm.link_lengths.length; i++) {
    a += arm.sign * q[i];
    angles.push(a);
    x += arm.link_lengths[i] * Math.cos(a);
    y += arm.link_lengths[i] * Math.sin(a);
    pts.push([x, y]);
  }
  return { pts, angles };
}

function jacobian(arm, q) {
  const { angles } = fk(arm, q);
  const n = q.length;
  const J = [new Array(n).fill(0), new Array(n).fill(0)];
  for (let j = 0; j < n; j++) {
    for (let i = j; i < n; i++) {
      J[0][j] += arm.sign * -arm.link_lengths[i] * Math.sin(angles[i]);
      J[1][j] += arm.sign * arm.link_lengths[i] * Math.cos(angles[i]);
    }
  }
  return J;
}

// Analytic IK of a 2-link arm, "elbow bends upwards" branch (positive elbow angle).
function ik2(arm, target) {
  const [l1, l2] = arm.link_lengths;
  const dx = target[0] - arm.base[0], dy = target[1] - arm.base[1];
  const r = clamp(Math.hypot(dx, dy), Math.abs(l1 - l2) + 1e-4, l1 + l2 - 1e-4);
  const c2 = clamp((r * r - l1 * l1 - l2 * l2) / (2 * l1 * l2), -1, 1);
  const bend = Math.acos(c2);
  const a1 = Math.atan2(dy, dx) - Math.atan2(l2 * Math.sin(bend), l1 + l2 * Math.cos(bend));
  let q1 = arm.sign * (a1 - arm.base_angle);
  q1 = Math.atan2(Math.sin(q1), Math.cos(q1));
  const lim = arm.joint_limits;
  return [clamp(q1, lim[0][0], lim[0][1]), clamp(bend, lim[1][0], lim[1][1])];
}

// ---------------------------------------------------------------- connection
async function connect(view) {
  const c = new InterprimClient(WS_URL, { token: TOKEN });
  await c.connect();
  c.onClose = (ev) => {
    state[view].connected = false;
    setStatus(`disconnected (${ev.code} ${ev.reason || ""})`);
  };
  state[view].connected = true;
  return c;
}

function setStatus(text) {
  $("status").textContent = text;
}

// ---------------------------------------------------------------- high-five view
const hf = {
  canvas: $("hf-canvas"),
  world: DEFAULT_WORLD,
  model: null,
  client: null,
  humanQ: null,
  robotQ: null,
  pred: null,
  robotPhase: 0,
  dragging: false,
  replay: null,
  timer: null,
  scale: 200,
  origin: [0, 0],
};

function hfSetupView() {
  const W = hf.canvas.width, H = hf.canvas.height;
  hf.scale = H / 2.8; // 2.8 m of height
  hf.origin = [W / 2 - 0.8 * hf.scale, H / 2]; // world x = 0.8 at the centre
}
const w2c = (p) => [hf.origin[0] + p[0] * hf.scale, hf.origin[1] - p[1] * hf.scale];
const c2w = (p) => [(p[0] - hf.origin[0]) / hf.scale, (hf.origin[1] - p[1]) / hf.scale];

// For tests: world point -> viewport (client) coordinates of the page.
window.ipView = {
  worldToClient(x, y) {
    const r = hf.canvas.getBoundingClientRect();
    const [cx, cy] = w2c([x, y]);
    return [r.left + (cx * r.width) / hf.canvas.width, r.top + (cy * r.height) / hf.canvas.height];
  },
  humanHand() {
    return fk(hf.world.observed_arm, hf.humanQ).pts.at(-1);
  },
};

function drawArm(ctx, arm, q, style) {
  const { pts } = fk(arm, q);
  ctx.save();
  ctx.strokeStyle = style.color;
  ctx.lineWidth = style.width || 8;
  ctx.lineCap = "round";
  ctx.globalAlpha = style.alpha ?? 1;
  if (style.dash) ctx.setLineDash(style.dash);
  ctx.beginPath();
  pts.forEach((p, i) => { const c = w2c(p); i ? ctx.lineTo(c[0], c[1]) : ctx.moveTo(c[0], c[1]); });
  ctx.stroke();
  ctx.setLineDash([]);
  ctx.fillStyle = style.color;
  for (const p of pts.slice(0, -1)) { const c = w2c(p); ctx.beginPath(); ctx.arc(c[0], c[1], 5, 0, 7); ctx.fill(); }
  const h = w2c(pts.at(-1));
  ctx.beginPath(); ctx.arc(h[0], h[1], style.hand || 9, 0, 7); ctx.fill();
  ctx.restore();
  return pts.at(-1);
}

function drawEllipse(ctx, center, cov, k, color) {
  // k-sigma ellipse of a 2x2 covariance (world units)
  const a = cov[0][0], b = cov[0][1], d = cov[1][1];
  const tr = (a + d) / 2, det = Math.sqrt(Math.max(((a - d) / 2) ** 2 + b * b, 0));
  const l1 = tr + det, l2 = Math.max(tr - det, 0);
  const ang = Math.atan2(l1 - a, b || 1e-12);
  const c = w2c(center);
  ctx.save();
  ctx.strokeStyle = color; ctx.fillStyle = color; ctx.globalAlpha = 0.18;
  ctx.beginPath();
  ctx.ellipse(c[0], c[1], Math.max(k * Math.sqrt(l1) * hf.scale, 1.5), Math.max(k * Math.sqrt(l2) * hf.scale, 1.5),
              -ang, 0, 2 * Math.PI);
  ctx.fill(); ctx.globalAlpha = 0.6; ctx.stroke();
  ctx.restore();
}

function handCov(arm, q, std) {
  const J = jacobian(arm, q);
  const cov = [[0, 0], [0, 0]];
  for (let r = 0; r < 2; r++) for (let s = 0; s < 2; s++)
    for (let j = 0; j < q.length; j++) cov[r][s] += J[r][j] * J[s][j] * std[j] * std[j];
  return cov;
}

function hfDraw() {
  const ctx = hf.canvas.getContext("2d");
  const W = hf.canvas.width, H = hf.canvas.height;
  ctx.clearRect(0, 0, W, H);
  // floor / grid
  ctx.strokeStyle = "#eee"; ctx.lineWidth = 1;
  for (let x = -1; x <= 3; x += 0.5) { const c = w2c([x, 0]); ctx.beginPath(); ctx.moveTo(c[0], 0); ctx.lineTo(c[0], H); ctx.stroke(); }
  for (let y = -1.5; y <= 1.5; y += 0.5) { const c = w2c([0, y]); ctx.beginPath(); ctx.moveTo(0, c[1]); ctx.lineTo(W, c[1]); ctx.stroke(); }
  const box = hf.world.goal_box;
  if (box) {
    const p0 = w2c([box[0][0], box[1][1]]), p1 = w2c([box[0][1], box[1][0]]);
    ctx.strokeStyle = "#cdb"; ctx.setLineDash([4, 4]); ctx.strokeRect(p0[0], p0[1], p1[0] - p0[0], p1[1] - p0[1]); ctx.setLineDash([]);
  }
  const ca = hf.world.controlled_arm, oa = hf.world.observed_arm;
  const p = hf.pred;
  if (p) {
    const mean = p.mean; // rows: normalised time, columns: the controlled joints
    // predicted hand path and uncertainty along it
    ctx.strokeStyle = "rgba(200,40,40,0.45)"; ctx.lineWidth = 2; ctx.beginPath();
    mean.forEach((q, i) => { const c = w2c(fk(ca, q).pts.at(-1)); i ? ctx.lineTo(c[0], c[1]) : ctx.moveTo(c[0], c[1]); });
    ctx.stroke();
    const final = mean.at(-1);
    if (p.std && $("hf-std").checked) {
      const step = Math.max(1, Math.floor(mean.length / 6));
      for (let i = step; i < mean.length; i += step)
        drawEllipse(ctx, fk(ca, mean[i]).pts.at(-1), handCov(ca, mean[i], p.std[i]), 2, "#c33");
      drawEllipse(ctx, fk(ca, final).pts.at(-1), handCov(ca, final, p.std.at(-1)), 2, "#c33");
    }
    drawArm(ctx, ca, final, { color: "#c33", alpha: 0.35, dash: [6, 6], width: 4, hand: 6 });
    const m = fk(ca, final).pts.at(-1);
    const c = w2c(m);
    ctx.fillStyle = "#c33"; ctx.font = "13px sans-serif";
    ctx.beginPath(); ctx.arc(c[0], c[1], 4, 0, 7); ctx.fill();
    ctx.fillText("predicted meeting point", c[0] + 10, c[1] - 10);
  }
  if (state.hf.replayGoal) {
    const g = w2c(state.hf.replayGoal);
    ctx.strokeStyle = "#2a2"; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(g[0] - 7, g[1] - 7); ctx.lineTo(g[0] + 7, g[1] + 7); ctx.moveTo(g[0] + 7, g[1] - 7); ctx.lineTo(g[0] - 7, g[1] + 7); ctx.stroke();
  }
  const rh = drawArm(ctx, ca, hf.robotQ, { color: "#c33" });
  const hh = drawArm(ctx, oa, hf.humanQ, { color: "#36c" });
  ctx.fillStyle = "#555"; ctx.font = "13px sans-serif";
  ctx.fillText("human (observed, 2 joints)", w2c(oa.base)[0] - 80, w2c(oa.base)[1] + 24);
  ctx.fillText("robot (controlled, 3 joints)", w2c(ca.base)[0] - 60, w2c(ca.base)[1] + 24);
  state.hf.robotQ = hf.robotQ.slice();
  state.hf.robotHand = rh;
  state.hf.humanQ = hf.humanQ.slice();
  state.hf.humanHand = hh;
  hf.canvas.dataset.robotHand = rh.map((v) => v.toFixed(4)).join(",");
}

function hfApplyPrediction(p) {
  hf.pred = p;
  state.hf.predictions += p.covers || 1; // frames answered (a coalesced reply covers several)
  state.hf.phase = p.phase;
  state.hf.speed = p.speed;
  state.hf.duration = p.duration;
  const meet = fk(hf.world.controlled_arm, p.mean.at(-1)).pts.at(-1);
  state.hf.meetingPoint = meet;
  hf.canvas.dataset.meetingPoint = meet.map((v) => v.toFixed(4)).join(",");
  hf.canvas.dataset.phase = p.phase === null ? "" : p.phase.toFixed(4);
  hf.canvas.dataset.predictions = String(state.hf.predictions);
  // phase is null while the prediction is the prior (the first frames): the robot waits at its start
  if ((hf.dragging || hf.replay) && p.phase !== null) hf.robotPhase = p.phase;
  $("hf-model").textContent = p.model;
  $("hf-phase").textContent = fmt(p.phase);
  $("hf-speed").textContent = fmt(p.speed);
  $("hf-meet").textContent = `(${fmt(meet[0])}, ${fmt(meet[1])}) m`;
  $("hf-compute").textContent = `${fmt(p.compute_ms, 2)} ms`;
}

function hfTick() {
  if (!hf.client || !hf.client.isOpen) return;
  if (hf.replay) {
    const r = hf.replay;
    if (r.i >= r.frames.length) { hfStop(); return; }
    hf.humanQ = r.frames[r.i++].slice();
  }
  if (hf.dragging) {
    for (const p of hf.sampler.due()) {
      hf.humanQ = ik2(hf.world.observed_arm, p);
      hf.client.sendFrame(hf.humanQ);
      state.hf.frames += 1;
      if (state.hf.sent.length < 5000) state.hf.sent.push(hf.humanQ.slice());
    }
    $("hf-frames").textContent = state.hf.frames;
    if (hf.sampler.done) hfStop();
    return;
  }
  hf.client.sendFrame(hf.humanQ);
  state.hf.frames += 1;
  if (state.hf.sent.length < 5000) state.hf.sent.push(hf.humanQ.slice());
  $("hf-frames").textContent = state.hf.frames;
}

function hfStart() {
  hfStop();
  hf.pred = null;
  hf.robotPhase = 0;
  hf.robotQ = hf.restRobot.slice();
  state.hf.frames = 0;
  state.hf.sent = [];
  state.hf.active = true;
  $("hf-error").textContent = "";
  hf.client.reset().catch((e) => ($("hf-error").textContent = e.message));
  hf.timer = setInterval(hfTick, 1000 * hf.model.dt);
}

function hfStop() {
  if (hf.timer) clearInterval(hf.timer);
  hf.timer = null;
  hf.replay = null;
  hf.dragging = false;
  state.hf.active = false;
}

function hfAnimate(now) {
  // After the human stops, the robot finishes its predicted movement at the estimated speed.
  const last = hfAnimate.last ?? now;
  hfAnimate.last = now;
  if (hf.pred) {
    if (!state.hf.active && hf.robotPhase < 1) hf.robotPhase = Math.min(1, hf.robotPhase + (now - last) / 1000 / (hf.pred.duration || hf.model.mean_duration));
    hf.robotQ = interpRow(hf.pred.mean, hf.robotPhase);
  }
  state.hf.robotPhase = hf.robotPhase;
  hfDraw();
  requestAnimationFrame(hfAnimate);
}

function canvasPoint(canvas, ev) {
  const r = canvas.getBoundingClientRect();
  return [((ev.clientX - r.left) * canvas.width) / r.width, ((ev.clientY - r.top) * canvas.height) / r.height];
}

// the demo's model, or a saved copy of it (a file named highfive*.npz with its 2 + 3 joints)
function highfiveModel(info) {
  return info.models.find((m) => m.world === "highfive") ||
    info.models.find((m) => m.name.startsWith("highfive") && m.controlled_dofs.length === 3 && m.observed_dofs.length === 2);
}

const handwritingModels = (info) =>
  info.models.filter((m) => m.world === "handwriting" || (m.kind === "single" && m.n_dofs === 2));

async function hfInit(info) {
  hf.world = info.highfive_world || DEFAULT_WORLD;
  // the demo's model, or a saved copy of it (a file named highfive*.npz with its 2 + 3 joints); any other model
  // is shown by the generic view (generic.js)
  hf.model = highfiveModel(info);
  hfSetupView();
  hf.restHuman = hf.world.observed_arm.rest.slice();
  hf.restRobot = hf.world.controlled_arm.rest.slice();
  hf.humanQ = hf.restHuman.slice();
  hf.robotQ = hf.restRobot.slice();
  requestAnimationFrame(hfAnimate);
  if (!hf.model) {
    $("hf-error").textContent = "no high-five model loaded (start the server with --demo); your models are on the Any model tab";
    return;
  }
  // Start postures of the model's interactions (the arms' rest postures may differ from the data's).
  const start = await fetchJSON(`/api/replay/${encodeURIComponent(hf.model.name)}`);
  if (start && start.interactions.length) {
    hf.restHuman = start.interactions[0].observed[0].slice();
    if (start.interactions[0].controlled_truth) hf.restRobot = start.interactions[0].controlled_truth[0].slice();
  }
  hf.humanQ = hf.restHuman.slice();
  hf.robotQ = hf.restRobot.slice();
  hf.client = await connect("hf");
  hf.client.onPrediction = hfApplyPrediction;
  hf.client.onError = (e) => { state.hf.error = e.message; $("hf-error").textContent = e.message; };
  await hf.client.open(hf.model.name, { points: 50, std: true });
  hf.canvas.addEventListener("pointerdown", (ev) => {
    const p = c2w(canvasPoint(hf.canvas, ev));
    const hand = fk(hf.world.observed_arm, hf.humanQ).pts.at(-1);
    if (Math.hypot(p[0] - hand[0], p[1] - hand[1]) * hf.scale > 30) return;
    try { hf.canvas.setPointerCapture(ev.pointerId); } catch (e) { /* a synthetic pointer has nothing to capture */ }
    state.hf.replayGoal = null;
    $("hf-goal").textContent = "–";
    hf.humanQ = ik2(hf.world.observed_arm, p); // the first frame is where the hand really is
    hf.sampler = new PointerSampler(1000 * hf.model.dt);
    hf.sampler.start(p);
    hfStart();
    hf.dragging = true;
  });
  hf.canvas.addEventListener("pointermove", (ev) => {
    if (!hf.dragging) return;
    hf.sampler.add(c2w(canvasPoint(hf.canvas, ev)));
  });
  const up = () => { if (hf.dragging) hf.sampler.release(); }; // the tick stops after the last event
  hf.canvas.addEventListener("pointerup", up);
  hf.canvas.addEventListener("pointercancel", up);
  $("hf-reset").onclick = () => {
    hfStop();
    hf.pred = null; state.hf.replayGoal = null;
    hf.humanQ = hf.restHuman.slice();
    hf.robotQ = hf.restRobot.slice();
  };
  let replayIndex = 0;
  $("hf-replay").onclick = async () => {
    const data = await fetchJSON(`/api/replay/${encodeURIComponent(hf.model.name)}`);
    if (!data) { $("hf-error").textContent = "no replay data for this model"; return; }
    const it = data.interactions[replayIndex++ % data.interactions.length];
    state.hf.replayGoal = it.goal || null;
    $("hf-goal").textContent = it.goal ? `(${fmt(it.goal[0])}, ${fmt(it.goal[1])}) m` : "–";
    hf.humanQ = it.observed[0].slice();
    hfStart();
    const frac = Number($("hf-replay-frac").value) || 1; // stop the human early: the robot anticipates
    hf.replay = { frames: it.observed.slice(0, Math.max(2, Math.round(frac * it.observed.length))), i: 0 };
  };
}

// ---------------------------------------------------------------- handwriting view
const hw = { canvas: $("hw-canvas"), client: null, models: [], extent: [[-0.1, 1.1], [-0.1, 1.1]], pen: null,
             stroke: [], pred: null, timer: null, drawing: false, replay: null, dt: 0.01 };
const hw2c = (p) => {
  const [[x0, x1], [y0, y1]] = hw.extent;
  return [((p[0] - x0) / (x1 - x0)) * hw.canvas.width, hw.canvas.height - ((p[1] - y0) / (y1 - y0)) * hw.canvas.height];
};
const hc2w = (c) => {
  const [[x0, x1], [y0, y1]] = hw.extent;
  return [x0 + (c[0] / hw.canvas.width) * (x1 - x0), y0 + ((hw.canvas.height - c[1]) / hw.canvas.height) * (y1 - y0)];
};
window.ipView.letterToClient = (x, y) => {
  const r = hw.canvas.getBoundingClientRect();
  const [cx, cy] = hw2c([x, y]);
  return [r.left + (cx * r.width) / hw.canvas.width, r.top + (cy * r.height) / hw.canvas.height];
};

function hwDraw() {
  const ctx = hw.canvas.getContext("2d");
  ctx.clearRect(0, 0, hw.canvas.width, hw.canvas.height);
  const p = hw.pred;
  if (p) {
    if (p.std) {
      ctx.fillStyle = "rgba(220,60,60,0.10)";
      p.mean.forEach((m, i) => {
        const c = hw2c(m);
        const r = 2 * Math.hypot(p.std[i][0], p.std[i][1]) * hw.canvas.width / (hw.extent[0][1] - hw.extent[0][0]);
        ctx.beginPath(); ctx.arc(c[0], c[1], Math.max(r, 1), 0, 7); ctx.fill();
      });
    }
    const k = Math.floor(p.phase * (p.mean.length - 1));
    ctx.lineWidth = 3; ctx.strokeStyle = "rgba(220,60,60,0.35)";
    ctx.beginPath(); p.mean.slice(0, k + 1).forEach((m, i) => { const c = hw2c(m); i ? ctx.lineTo(...c) : ctx.moveTo(...c); }); ctx.stroke();
    ctx.strokeStyle = "#d33";
    ctx.beginPath(); p.mean.slice(k).forEach((m, i) => { const c = hw2c(m); i ? ctx.lineTo(...c) : ctx.moveTo(...c); }); ctx.stroke();
  }
  ctx.lineWidth = 4; ctx.strokeStyle = "#111"; ctx.lineCap = "round";
  ctx.beginPath(); hw.stroke.forEach((m, i) => { const c = hw2c(m); i ? ctx.lineTo(...c) : ctx.moveTo(...c); }); ctx.stroke();
  requestAnimationFrame(hwDraw);
}

function hwApplyPrediction(p) {
  hw.pred = p;
  state.hw.predictions += p.covers || 1; // frames answered (a coalesced reply covers several)
  state.hw.model = p.model;
  state.hw.phase = p.phase;
  state.hw.probabilities = p.probabilities || null;
  hw.canvas.dataset.model = p.model;
  hw.canvas.dataset.predictions = String(state.hw.predictions);
  $("hw-model").textContent = p.model;
  $("hw-phase").textContent = fmt(p.phase);
  const probs = p.probabilities || { [p.model]: 1 };
  $("hw-probs").innerHTML = "";
  for (const [name, v] of Object.entries(probs)) {
    const row = document.createElement("div");
    const bar = document.createElement("span");
    bar.className = "bar"; bar.style.width = `${Math.round(v * 150)}px`;
    row.textContent = `${name} ${fmt(v, 2)} `;
    row.appendChild(bar);
    $("hw-probs").appendChild(row);
  }
}

function hwSend(p) {
  hw.stroke.push(p.slice());
  hw.client.sendFrame(p);
  state.hw.frames += 1;
}

function hwTick() {
  if (!hw.client || !hw.client.isOpen) return;
  if (hw.replay) {
    if (hw.replay.i >= hw.replay.frames.length) { hwStop(); return; }
    hwSend(hw.replay.frames[hw.replay.i++]);
  } else if (hw.drawing) {
    for (const p of hw.sampler.due()) hwSend(p);
    if (hw.sampler.done) hwStop();
  }
}

function hwStart() {
  hwStop();
  hw.stroke = []; hw.pred = null; state.hw.frames = 0;
  state.hw.active = true;
  $("hw-error").textContent = "";
  hw.client.reset().catch((e) => ($("hw-error").textContent = e.message));
  hw.timer = setInterval(hwTick, 1000 * hw.dt);
}

function hwStop() {
  if (hw.timer) clearInterval(hw.timer);
  hw.timer = null; hw.drawing = false; hw.replay = null; state.hw.active = false;
}

async function hwInit(info) {
  hw.models = handwritingModels(info);
  requestAnimationFrame(hwDraw);
  if (!hw.models.length) { $("hw-error").textContent = "no handwriting model loaded (start with --demo); your models are on the Any model tab"; return; }
  hw.extent = hw.models[0].extent || hw.extent;
  hw.dt = hw.models[0].dt;
  $("hw-letters").textContent = hw.models.map((m) => m.name.replace(/^letter_/, "")).join(", ");
  hw.client = await connect("hw");
  hw.client.onPrediction = hwApplyPrediction;
  hw.client.onError = (e) => { state.hw.error = e.message; $("hw-error").textContent = e.message; };
  const names = hw.models.map((m) => m.name);
  await hw.client.open(names.length > 1 ? "recognise" : names[0],
                       { points: 80, std: true, candidates: names.length > 1 ? names : undefined, dofs: "all" });
  hw.canvas.addEventListener("pointerdown", (ev) => {
    hw.canvas.setPointerCapture(ev.pointerId);
    hw.sampler = new PointerSampler(1000 * hw.dt);
    hw.sampler.start(hc2w(canvasPoint(hw.canvas, ev)));
    hwStart(); hw.drawing = true;
  });
  hw.canvas.addEventListener("pointermove", (ev) => { if (hw.drawing) hw.sampler.add(hc2w(canvasPoint(hw.canvas, ev))); });
  const up = () => { if (hw.drawing) hw.sampler.release(); }; // the tick stops after the last event
  hw.canvas.addEventListener("pointerup", up);
  hw.canvas.addEventListener("pointercancel", up);
  $("hw-clear").onclick = () => { hwStop(); hw.stroke = []; hw.pred = null; };
  let k = 0;
  $("hw-replay").onclick = async () => {
    const m = hw.models[k++ % hw.models.length];
    const data = await fetchJSON(`/api/replay/${encodeURIComponent(m.name)}`);
    if (!data) return;
    const frames = data.interactions[0].observed;
    hwStart();
    hw.replay = { frames: frames.slice(0, Math.round(frames.length * 0.5)), i: 0 }; // show half, let it complete
  };
}

// ---------------------------------------------------------------- tabs, start-up
function showTab(name) {
  for (const t of ["highfive", "writing", "generic"]) {
    $(`view-${t}`).hidden = t !== name;
    $(`tab-${t}`).classList.toggle("active", t === name);
  }
}
$("tab-highfive").onclick = () => showTab("highfive");
$("tab-writing").onclick = () => showTab("writing");
$("tab-generic").onclick = () => showTab("generic");


(async () => {
  try {
    const info = await fetchJSON("/api/info");
    if (!info) throw new Error("cannot read /api/info (wrong token?)");
    state.info = info;
    // only the user's own models: the generic view, chosen before anything is drawn (the high-five view's
    // "no high-five model loaded" must not flash first)
    if (!highfiveModel(info) && !handwritingModels(info).length) showTab("generic");
    await hfInit(info);
    await hwInit(info);
    await genInit(info, state);
    state.ready = true;
    document.body.dataset.ready = "1";
    setStatus(`connected · ${info.server} · protocol v${info.protocol} · models: ${info.models.map((m) => m.name).join(", ")}`);
  } catch (e) {
    state.error = String(e.message || e);
    setStatus(`error: ${state.error}`);
  }
})();
