// interprim streaming protocol v1 — a minimal JavaScript client (browser or any runtime with a
// standard WebSocket). See docs/protocol.md. No dependencies, no build step.
//
//   import { InterprimClient } from "/static/ipclient.js";
//   const c = new InterprimClient("ws://127.0.0.1:8765/ws", { token });
//   const welcome = await c.connect();
//   await c.open("highfive", { points: 50, std: true });
//   c.onPrediction = (p) => console.log(p.seq, p.phase, p.mean);  // phase null until p.conditioned
//   c.sendFrame([q0, q1]);          // one reply (prediction or error) per frame, in order

export const PROTOCOL_VERSION = 1;

export class InterprimError extends Error {
  constructor(reply) {
    super(`${reply.code}: ${reply.message}`);
    this.code = reply.code;
    this.reply = reply;
  }
}

export class InterprimClient {
  constructor(url, { token = null, binary = false } = {}) {
    this.url = url;
    this.token = token;
    this.binary = binary; // send frames as little-endian float64 binary messages
    this.ws = null;
    this.welcome = null;
    this.seq = 0; // frames sent in this connection (the server numbers them the same way)
    this.pending = []; // control requests waiting for their reply, in order
    this.onPrediction = () => {};
    this.onError = (err) => console.warn("interprim:", err.message);
    this.onClose = () => {};
  }

  connect() {
    return new Promise((resolve, reject) => {
      const ws = new WebSocket(this.url);
      ws.binaryType = "arraybuffer";
      this.ws = ws;
      ws.onopen = () => {
        const hello = { type: "hello", version: PROTOCOL_VERSION, client: "ipclient.js" };
        if (this.token) hello.token = this.token;
        this._request(hello).then((w) => { this.welcome = w; resolve(w); }, reject);
      };
      ws.onmessage = (ev) => this._dispatch(ev.data);
      ws.onerror = () => reject(new Error(`cannot connect to ${this.url}`));
      ws.onclose = (ev) => {
        for (const p of this.pending.splice(0)) p.reject(new Error(`closed ${ev.code} ${ev.reason}`));
        this.onClose(ev);
      };
    });
  }

  get isOpen() {
    return this.ws !== null && this.ws.readyState === WebSocket.OPEN;
  }

  _request(msg) {
    return new Promise((resolve, reject) => {
      this.pending.push({ resolve, reject });
      this.ws.send(JSON.stringify(msg));
    });
  }

  _dispatch(data) {
    let msg;
    try {
      msg = JSON.parse(data);
    } catch (e) {
      this.onError(new Error("server sent invalid JSON"));
      return;
    }
    if (msg.type === "prediction") {
      this.onPrediction(msg);
    } else if (msg.type === "error") {
      const err = new InterprimError(msg);
      // An error about a frame carries its seq; otherwise it answers the oldest control request.
      if (msg.seq === undefined && this.pending.length) this.pending.shift().reject(err);
      else this.onError(err);
    } else if (this.pending.length) {
      this.pending.shift().resolve(msg);
    }
  }

  open(model = "recognise", { points, std = false, candidates, dofs, robotState } = {}) {
    const msg = { type: "open", model, std };
    if (points !== undefined) msg.points = points;
    if (candidates !== undefined) msg.candidates = candidates;
    if (dofs !== undefined) msg.dofs = dofs;
    if (robotState !== undefined) msg.robot_state = robotState; // positions, or [positions, velocities]
    return this._request(msg);
  }

  sendFrame(frame, t) {
    if (!this.isOpen) return -1;
    this.seq += 1;
    if (this.binary) {
      const view = new DataView(new ArrayBuffer(8 * frame.length));
      frame.forEach((v, i) => view.setFloat64(8 * i, v, true));
      this.ws.send(view.buffer);
    } else {
      const msg = { type: "frame", frame: Array.from(frame, Number) };
      if (t !== undefined) msg.t = t;
      this.ws.send(JSON.stringify(msg));
    }
    return this.seq;
  }

  reset(robotState) {
    const msg = { type: "reset" };
    if (robotState !== undefined) msg.robot_state = robotState;
    return this._request(msg);
  }

  closeSession() {
    return this._request({ type: "close" });
  }

  close() {
    if (this.ws) this.ws.close(1000, "bye");
  }
}
