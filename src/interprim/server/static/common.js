// Helpers shared by the live page's views (app.js, generic.js): pointer sampling on a model's dt grid,
// interpolation on a normalised-time grid, number formatting and the JSON API.

export const fmt = (v, d = 2) => (v === undefined || v === null ? "–" : Number(v).toFixed(d));
export const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));

const POINTER_DELAY_MS = 40;
// The sampler's clock: performance.now(), unless a test installs window.ipClock (a virtual clock that makes
// the frames sent independent of how busy the machine is).
export const samplerNow = () => (window.ipClock ? window.ipClock() : performance.now());

// Pointer events come every ~8-30 ms and timers jitter; a model wants frames every dt. This samples
// the pointer path on an exact dt grid (catching up after a late timer), by linear interpolation
// between pointer events, POINTER_DELAY_MS behind real time, so that frames are smooth and evenly
// spaced (no staircase, which the model would read as jerky movement).
export class PointerSampler {
  constructor(dtMs) { this.dtMs = dtMs; this.log = []; this.gridT = 0; this.released = false; this.done = false; }
  start(p) {
    const now = samplerNow();
    this.log = [[now, p[0], p[1]]];
    this.gridT = now - POINTER_DELAY_MS;
    this.released = false;
    this.done = false;
  }
  add(p) {
    this.log.push([samplerNow(), p[0], p[1]]);
    if (this.log.length > 4000) this.log.splice(0, 2000);
  }
  release() { this.released = true; }
  due() {
    const out = [], log = this.log, now = samplerNow() - POINTER_DELAY_MS;
    while (!this.done && this.gridT <= now) {
      const T = this.gridT;
      this.gridT += this.dtMs;
      let i = 1;
      while (i < log.length && log[i][0] < T) i++;
      if (i >= log.length) out.push([log[log.length - 1][1], log[log.length - 1][2]]);
      else {
        const [t0, x0, y0] = log[i - 1], [t1, x1, y1] = log[i];
        const w = t1 > t0 ? clamp((T - t0) / (t1 - t0), 0, 1) : 1;
        out.push([x0 + w * (x1 - x0), y0 + w * (y1 - y0)]);
      }
      if (this.released && T >= log[log.length - 1][0]) this.done = true;
    }
    return out;
  }
}

export function interpRow(rows, s) {
  // rows: trajectory on a uniform normalised-time grid 0..1; s in [0, 1]
  const n = rows.length;
  const f = clamp(s, 0, 1) * (n - 1);
  const i = Math.min(Math.floor(f), n - 2);
  const w = f - i;
  return rows[i].map((v, k) => v * (1 - w) + rows[i + 1][k] * w);
}

export const TOKEN = new URLSearchParams(location.search).get("token");
export const WS_URL = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`;

export async function fetchJSON(path) {
  const url = TOKEN ? `${path}?token=${encodeURIComponent(TOKEN)}` : path;
  const r = await fetch(url);
  return r.ok ? r.json() : null;
}
