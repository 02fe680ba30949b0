/* viewer.js — the browser viewer of splatd (served by `splatd --http`): a thin client that
 * speaks the daemon's own binary protocol (protocol/PROTOCOL.md), one protocol message per
 * binary WebSocket message, and shows the frames the server renders.
 *
 * Frames are requested, not streamed: one CAMERA + RENDER at a time, the next one only when the
 * previous frame has arrived and no decoded frame waits to be drawn, so at most one frame is in
 * flight beyond the one being shown (frame spoiling: input that arrives meanwhile only updates
 * the camera that the next request carries; a slow network never queues stale frames).
 *
 * Same controls as `splat view` (client/splat_view.c): left-drag orbits about the target,
 * right- or shift-drag pans, the wheel zooms; touch: one finger orbits, two pan and pinch-zoom.
 * Keys 1.. pipelines, U/J lambda, I/K t, O/L l_m, F field, E EDL, R reset, S save PNG, H help,
 * Esc/Q disconnect. Progressive quality: while interacting, half size, JPEG quality 50 and a
 * point budget; 150 ms after the last input, full size and quality 95.
 *
 * Query (for links and tests): ?cloud=NAME opens NAME at once; ?size=WxH fixes the frame size;
 * ?pipeline=NAME starts with that pipeline;
 * ?token=... is not read (a token never goes into a URL): the page asks for it. For the bench,
 * window.splatStats() returns one line per frame: its camera and JPEG quality, camera sent ->
 * frame received and -> drawn, and the frame's render + read-back + encode time (ms). */
'use strict';

const P = {
  MAGIC: 0x544c5053, VERSION: 1,
  HELLO: 1, LIST: 2, OPEN: 3, CAMERA: 4, PARAMS: 5, RENDER: 6, STREAM: 7, PING: 8, BYE: 9,
  WELCOME: 129, CLOUDS: 130, INFO: 131, PROGRESS: 132, FRAME: 133, PONG: 134, ERROR: 135, OK: 136,
};
/* Parameter types and the enum lists this page uses, as in protocol/params.h (append-only). */
const T_ENUM = 1, T_FLOAT = 2, T_INT = 3;
const PIPELINES = ['points', 'splat', 'kawata', 'soft'];
const FIELDS = ['uncertainty', 'height', 'intensity'];
const PARAMS = {
  pipeline: {type: T_ENUM, values: PIPELINES, def: 1},
  format: {type: T_ENUM, values: ['jpeg', 'png', 'lz4', 'raw', 'exr'], def: 0},
  quality: {type: T_INT, min: 1, max: 100, def: 85},
  point_budget: {type: T_INT, min: 0, max: 4e9, def: 0},
  shading: {type: T_ENUM, values: ['lambert', 'edl'], def: 0},
  lambda: {type: T_FLOAT, min: 0, max: 1, def: 0.5},
  t: {type: T_FLOAT, min: 0, max: 1, def: 0.5},
  l_m: {type: T_FLOAT, min: 0, max: 1, def: 0},
  field: {type: T_ENUM, values: FIELDS, def: 0},
  provisional: {type: T_INT, min: 0, max: 1, def: 0},
};
const E_BAD_PARAM_NAME = 7, E_BAD_PARAM_VALUE = 8, E_AUTH_FAILED = 13;
const SETTLE_MS = 150, DRAG_QUALITY = 50, REST_QUALITY = 95, DRAG_BUDGET = 300000;

const $ = (id) => document.getElementById(id);
const query = new URLSearchParams(location.search);

/* ---- wire encoding ---------------------------------------------------------------------- */

class Writer {
  constructor() { this.b = new Uint8Array(128); this.n = 0; }
  room(k) {
    if (this.n + k <= this.b.length) return;
    const nb = new Uint8Array(Math.max(this.b.length * 2, this.n + k));
    nb.set(this.b.subarray(0, this.n));
    this.b = nb;
  }
  dv(k) { this.room(k); const v = new DataView(this.b.buffer, this.n, k); this.n += k; return v; }
  u8(x) { this.dv(1).setUint8(0, x); }
  u16(x) { this.dv(2).setUint16(0, x, true); }
  u32(x) { this.dv(4).setUint32(0, x, true); }
  i32(x) { this.dv(4).setInt32(0, x, true); }
  i64(x) { this.dv(8).setBigInt64(0, BigInt(Math.round(x)), true); }
  f32(x) { this.dv(4).setFloat32(0, x, true); }
  f64(x) { this.dv(8).setFloat64(0, x, true); }
  bytes(a) { this.room(a.length); this.b.set(a, this.n); this.n += a.length; }
  str8(s) { const e = new TextEncoder().encode(s); this.u8(e.length); this.bytes(e); }
  done() { return this.b.subarray(0, this.n); }
}

class Reader {
  constructor(buf, off, len) {
    this.v = new DataView(buf, off, len); this.o = 0; this.buf = buf; this.base = off;
  }
  need(k) { if (this.o + k > this.v.byteLength) throw new Error('message truncated'); }
  u8() { this.need(1); return this.v.getUint8(this.o++); }
  u16() { this.need(2); const x = this.v.getUint16(this.o, true); this.o += 2; return x; }
  u32() { this.need(4); const x = this.v.getUint32(this.o, true); this.o += 4; return x; }
  u64() {
    this.need(8); const x = Number(this.v.getBigUint64(this.o, true)); this.o += 8; return x;
  }
  f32() { this.need(4); const x = this.v.getFloat32(this.o, true); this.o += 4; return x; }
  f64() { this.need(8); const x = this.v.getFloat64(this.o, true); this.o += 8; return x; }
  bytes(k) {
    this.need(k); const a = new Uint8Array(this.buf, this.base + this.o, k); this.o += k; return a;
  }
  str8() { return new TextDecoder().decode(this.bytes(this.u8())); }
  str16() { return new TextDecoder().decode(this.bytes(this.u16())); }
  rest() { return this.bytes(this.v.byteLength - this.o); }
}

/* message: a complete protocol message (16-byte header + payload). */
function message(type, seq, payload) {
  const w = new Writer();
  w.u32(P.MAGIC); w.u16(P.VERSION); w.u16(type); w.u32(seq); w.u32(payload ? payload.length : 0);
  if (payload) w.bytes(payload);
  return w.done();
}

/* ---- camera: the same orbit as splat view, the same default framing as the server ---------- */

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                          a[0] * b[1] - a[1] * b[0]];
function norm(a) {
  const l = Math.sqrt(dot(a, a));
  if (l > 0) { a[0] /= l; a[1] /= l; a[2] /= l; }
  return l;
}
function rotate(v, k, ang) {
  const c = Math.cos(ang), s = Math.sin(ang), kxv = cross(k, v), kv = dot(k, v);
  for (let i = 0; i < 3; i++) v[i] = v[i] * c + kxv[i] * s + k[i] * kv * (1 - c);
}

/* frameFit: protocol/framing.c sp_frame_fit on INFO's view (tests/test_browser.c checks that
 * both give the same camera): looking along view.dir with world up, from where the view's
 * points (its box's corners when it has none) fill the frame up to a 4 % margin, their
 * projection centred. */
const FILL_MARGIN = 0.04;
function frameFit(view, w, h, fov) {
  const d = view.dir.slice(); norm(d);
  const u = view.up.slice(), k = dot(u, d);
  for (let i = 0; i < 3; i++) u[i] -= k * d[i];
  norm(u);
  const r = cross(d, u);
  const t = Math.tan(fov * Math.PI / 360), ty = t * (1 - FILL_MARGIN);
  const tx = t * (h > 0 ? w / h : 1) * (1 - FILL_MARGIN);
  const c = [0, 1, 2].map((i) => 0.5 * (view.bmin[i] + view.bmax[i]));
  let loR = Infinity, hiR = -Infinity, loU = Infinity, hiU = -Infinity, diag = 0;
  const pd = [], n = view.pts.length || 8;
  for (let m = 0; m < n; m++) {
    const p = [0, 1, 2].map((i) => (view.pts.length ? view.pts[m][i] :
                                    (m >> i) & 1 ? view.bmax[i] : view.bmin[i]) - c[i]);
    const pr = dot(p, r), pu = dot(p, u);
    pd.push(dot(p, d));
    hiR = Math.max(hiR, pr - tx * pd[m]); loR = Math.min(loR, pr + tx * pd[m]);
    hiU = Math.max(hiU, pu - ty * pd[m]); loU = Math.min(loU, pu + ty * pd[m]);
  }
  for (let i = 0; i < 3; i++) diag += (view.bmax[i] - view.bmin[i]) ** 2;
  diag = Math.sqrt(diag);
  let dist = Math.max((hiR - loR) / (2 * tx), (hiU - loU) / (2 * ty));
  if (!(diag > 0)) dist = Math.max(dist, 1);
  else for (const z of pd) dist = Math.max(dist, -z + 1e-3 * diag);
  const sr = 0.5 * (hiR + loR), su = 0.5 * (hiU + loU);
  const target = [0, 1, 2].map((i) => c[i] + sr * r[i] + su * u[i]);
  const up = view.up.slice(); norm(up);
  return {target, offset: d.map((x) => -x * dist), up, fov};
}

function orbitDrag(o, dx, dy) {
  const k = 0.008;
  rotate(o.offset, o.up, -dx * k);
  const right = cross([-o.offset[0], -o.offset[1], -o.offset[2]], o.up);
  if (norm(right) === 0) return;
  const trial = o.offset.slice();
  rotate(trial, right, -dy * k);
  const t = trial.slice();
  norm(t);
  if (Math.abs(dot(t, o.up)) < Math.cos(2 * Math.PI / 180)) o.offset = trial;
}

function orbitPan(o, dx, dy, h) {
  const dir = [-o.offset[0], -o.offset[1], -o.offset[2]];
  const dist = norm(dir), right = cross(dir, o.up);
  if (norm(right) === 0) return;
  const camup = cross(right, dir);
  const px = 2 * dist * Math.tan(o.fov * Math.PI / 360) / (h || 1);
  for (let i = 0; i < 3; i++) o.target[i] += (-dx * right[i] + dy * camup[i]) * px;
}

function orbitZoom(o, n) {
  const f = Math.pow(0.9, n);
  for (let i = 0; i < 3; i++) o.offset[i] *= f;
}

const cloneOrbit = (o) => ({target: o.target.slice(), offset: o.offset.slice(), up: o.up.slice(),
                            fov: o.fov});

/* ---- state ------------------------------------------------------------------------------ */

const S = {
  ws: null, seq: 0, authed: false, challenge: null, welcome: null, backoff: 250,
  pending: new Map(),        /* seq -> {kind, ...} of requests awaiting an answer */
  cloud: query.get('cloud') || '', info: null, opened: false,
  orbit: null, home: null,
  want: {}, applied: {},     /* parameter values wanted by the page / in force on the server */
  unavail: new Set(), pipeUnavail: new Set(),
  interacting: false, lastInput: 0, settleTimer: 0,
  dirty: false,              /* a request is due */
  inputT: null,              /* the time of the oldest input not yet sent; null: none */
  inflight: null,            /* the RENDER awaiting its FRAME: {seq, t} */
  decoding: false,           /* a frame is being decoded */
  waiting: null,             /* the newest frame that arrived meanwhile */
  frames: 0, spoiled: 0, lastSeq: 0, lastCamSeq: 0, fpsT: [], render: 0, encode: 0,
  lat: null,                 /* ms from the last input shown to its frame; null: no input yet */
  authError: '',             /* the server's text when it refused the token (asked again) */
  fw: 0, fh: 0, fpipe: '', lastCam: null, nsave: 0, status: '', closedByUser: false,
  stats: [], token: null,
  outstanding: 0, maxOutstanding: 0, inputs: 0, /* RENDERs without their FRAME; input events */
};
window.splatStats = () => S.stats.join('\n');
for (const k of Object.keys(PARAMS)) S.want[k] = S.applied[k] = PARAMS[k].def;
S.want.provisional = 1; /* a COPC file still preparing shows its top levels at once */
S.want.quality = REST_QUALITY;
if (PIPELINES.includes(query.get('pipeline')))
  S.want.pipeline = PIPELINES.indexOf(query.get('pipeline'));

function setStatus(s) { S.status = s; hud(); }
function nextSeq() { S.seq = (S.seq + 1) >>> 0; if (S.seq === 0) S.seq = 1; return S.seq; }
function send(type, payload, pend) {
  const seq = nextSeq();
  if (pend) S.pending.set(seq, pend);
  S.ws.send(message(type, seq, payload));
  return seq;
}

/* ---- connection ------------------------------------------------------------------------- */

function connect() {
  S.closedByUser = false;
  // wss when the page came over https (splatd with --tls-cert): a page on https may not open
  // a plaintext socket, and the daemon's TLS listener takes TLS only.
  const ws = new WebSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`);
  ws.binaryType = 'arraybuffer';
  S.ws = ws;
  ws.onopen = () => { S.backoff = 250; hello(null); };
  ws.onmessage = (ev) => {
    try { onMessage(ev.data); } catch (e) { setStatus('bad message: ' + e.message); }
  };
  ws.onclose = (ev) => {
    if (S.ws !== ws) return;
    S.ws = null; S.authed = false; S.opened = false; S.inflight = null; S.pending.clear();
    S.outstanding = 0;
    S.applied = {}; for (const k of Object.keys(PARAMS)) S.applied[k] = PARAMS[k].def;
    if (S.closedByUser) { setStatus('disconnected (reload to connect again)'); return; }
    const why = `${ev.code}${ev.reason ? ' ' + ev.reason : ''}`;
    /* A refused token closes the connection too: the reason to show is the token, and the
     * page connects again to ask for it (onWelcome). */
    if (S.authError) setStatus(`wrong token (${S.authError}); connecting again to ask for it`);
    else setStatus(`DISCONNECTED (${why}); retrying in ${S.backoff / 1000} s`);
    setTimeout(connect, S.backoff);
    S.backoff = Math.min(S.backoff * 2, 5000);
  };
}

function hello(proof) {
  const w = new Writer();
  w.u16(1); w.u16(1); w.str8('splat-web 0.1');
  if (proof) { w.u8(proof.length); w.bytes(proof); } else w.u8(0);
  send(P.HELLO, w.done(), {kind: 'hello'});
}

/* answerChallenge: HMAC-SHA256(key = token, message = challenge) with WebCrypto (PROTOCOL.md 4). */
async function answerChallenge(tokenText) {
  if (!window.crypto || !crypto.subtle) {
    setStatus('the server needs a token, and WebCrypto is only on https or localhost pages');
    return;
  }
  /* Kept in memory only (never stored), so a reconnection answers again by itself. */
  S.token = tokenText;
  const tok = new TextEncoder().encode(tokenText.replace(/[\r\n]+$/, ''));
  const key = await crypto.subtle.importKey('raw', tok, {name: 'HMAC', hash: 'SHA-256'}, false,
                                            ['sign']);
  const proof = new Uint8Array(await crypto.subtle.sign('HMAC', key, S.challenge));
  hello(proof);
}

function onMessage(buf) {
  if (buf.byteLength < 16) throw new Error('short message');
  const h = new DataView(buf, 0, 16);
  if (h.getUint32(0, true) !== P.MAGIC) throw new Error('bad magic');
  const type = h.getUint16(6, true), seq = h.getUint32(8, true), len = h.getUint32(12, true);
  if (16 + len !== buf.byteLength) throw new Error('length mismatch');
  const r = new Reader(buf, 16, len), pend = S.pending.get(seq);
  if (pend && type !== P.PROGRESS) S.pending.delete(seq);
  switch (type) {
  case P.WELCOME: onWelcome(r); break;
  case P.CLOUDS: onClouds(r); break;
  case P.PROGRESS: {
    const ph = r.u8(), f = r.f32(), tx = r.str8();
    setStatus(`preparing ${S.cloud}: ${tx || 'phase ' + ph} ${(f * 100).toFixed(0)}%`);
    break;
  }
  case P.INFO: onInfo(r); break;
  case P.FRAME: onFrame(r, seq, pend); break;
  case P.OK: break;
  case P.PONG: break;
  case P.ERROR: onError(r, seq, pend); break;
  default: break;
  }
}

function onWelcome(r) {
  const version = r.u16(), authRequired = r.u8(), authenticated = r.u8();
  S.challenge = r.bytes(32).slice();
  const maxReq = r.u32(), maxW = r.u32(), maxH = r.u32();
  S.welcome = {version, maxReq, maxW, maxH, server: r.str8(), backend: r.str8(),
               renderer: r.str8()};
  if (authRequired && !authenticated) {
    if (S.token) { answerChallenge(S.token); return; }
    $('token-box').hidden = false;
    setStatus(S.authError ? `wrong token (${S.authError}): enter the right one`
                          : 'this server needs its token');
    const go = () => answerChallenge($('token').value);
    $('token-go').onclick = go;
    $('token').onkeydown = (e) => { if (e.key === 'Enter') go(); e.stopPropagation(); };
    return;
  }
  $('token-box').hidden = true;
  S.authed = true;
  S.authError = '';
  setStatus(`connected to ${S.welcome.server} (${S.welcome.backend}: ${S.welcome.renderer})`);
  send(P.LIST, null, {kind: 'list'});
  if (S.cloud) openCloud(S.cloud);
}

function onClouds(r) {
  const n = r.u32(), sel = $('clouds');
  if (n * 21 > r.v.byteLength) throw new Error('CLOUDS count over its payload');
  sel.textContent = '';
  const none = document.createElement('option');
  none.value = ''; none.textContent = n ? '(choose a cloud)' : '(no clouds)';
  sel.appendChild(none);
  for (let i = 0; i < n; i++) {
    const name = r.str8(), bytes = r.u64(), points = r.u64(), flags = r.u32();
    const o = document.createElement('option');
    o.value = name;
    const extra = (points ? `, ${points} points` : '') + (flags & 2 ? ', loaded' : '');
    o.textContent = `${name} (${(bytes / 1048576).toFixed(1)} MiB${extra})`;
    sel.appendChild(o);
  }
  sel.value = S.cloud;
}

function openCloud(name) {
  if (!S.authed || !name) return;
  S.cloud = name; S.opened = false; S.info = null; S.inflight = null;
  sendParams(S.want); /* provisional=1 must come before the OPEN */
  const w = new Writer(); w.str8(name);
  send(P.OPEN, w.done(), {kind: 'open'});
  setStatus(`opening ${name}`);
}

function onInfo(r) {
  const name = r.str8(), points = r.u64(), dropped = r.u64();
  const bmin = [r.f64(), r.f64(), r.f64()], bmax = [r.f64(), r.f64(), r.f64()];
  r.f64(); r.f64(); r.f64(); /* offset */
  const provisional = (r.u32() & 0x80000000) !== 0; /* a second INFO follows (PROTOCOL.md) */
  r.f32(); r.u32(); r.str8(); /* sigma, k, format */
  const v3 = () => [r.f64(), r.f64(), r.f64()];
  const view = {up: v3(), dir: v3(), bmin: v3(), bmax: v3(), pts: []};
  for (let k = r.u8(); k > 0; k--) view.pts.push(v3());
  S.info = {name, points, dropped, bmin, bmax, view};
  S.opened = true;
  const [w, h] = fullSize();
  const keep = S.orbit && S.home && S.lastOpened === name; /* a reconnection keeps the view */
  S.home = frameFit(view, w, h, 45);
  if (!keep) S.orbit = cloneOrbit(S.home);
  S.lastOpened = name;
  $('clouds').value = name;
  setStatus(provisional ? `${name}: first image, ${points} points of its top levels ` +
            '(drawn with points); preparing the full cloud' : `${name}: ${points} points`);
  touchRequest(null);
}

function onError(r, seq, pend) {
  const code = r.u32(), text = r.str16();
  $('error').textContent = `${code} ${text}`;
  if (code === E_AUTH_FAILED) { /* ask again after the reconnection, saying why */
    S.token = null;
    S.authError = text;
  }
  if (pend && pend.kind === 'params' && (code === E_BAD_PARAM_NAME || code === E_BAD_PARAM_VALUE)) {
    /* A parameter this server lacks: marked n/a and put back, never an error loop. */
    for (const [k, v] of Object.entries(pend.values)) {
      if (k === 'pipeline') S.pipeUnavail.add(v);
      else if (code === E_BAD_PARAM_NAME) S.unavail.add(k);
      S.want[k] = S.applied[k] = pend.old[k];
    }
    syncControls();
  }
  if (pend && pend.kind === 'render') {
    S.outstanding--;
    if (S.inflight && S.inflight.seq === seq) S.inflight = null;
    pump();
  }
  setStatus(`error ${code}: ${text}`);
}

/* ---- requests: at most one frame in flight ------------------------------------------------ */

function fullSize() {
  const fixed = /^(\d+)x(\d+)$/.exec(query.get('size') || '');
  if (fixed) return [+fixed[1], +fixed[2]];
  const c = $('canvas'), dpr = Math.min(window.devicePixelRatio || 1, 2);
  return [Math.max(1, Math.round(c.clientWidth * dpr)),
          Math.max(1, Math.round(c.clientHeight * dpr))];
}

/* touchRequest: something the frame shows changed; t: when the input behind it happened, null
 * when no input did (a cloud opened, the full frame after a drag): latency is measured from an
 * input to the first frame that shows it, and only then. */
function touchRequest(t) {
  if (t !== null && S.inputT === null) S.inputT = t;
  S.dirty = true;
  hud();
  pump();
}

/* sendParams: one PARAMS with every parameter whose wanted value differs from the applied one. */
function sendParams(want) {
  const w = new Writer(), values = {}, old = {};
  let n = 0;
  for (const k of Object.keys(PARAMS)) if (want[k] !== S.applied[k] && !S.unavail.has(k)) n++;
  if (!n) return;
  w.u16(n);
  for (const [k, p] of Object.entries(PARAMS)) {
    if (want[k] === S.applied[k] || S.unavail.has(k)) continue;
    w.str8(k); w.u8(p.type);
    if (p.type === T_ENUM) w.i32(want[k]);
    else if (p.type === T_FLOAT) w.f32(want[k]);
    else w.i64(want[k]);
    values[k] = want[k]; old[k] = S.applied[k]; S.applied[k] = want[k];
  }
  send(P.PARAMS, w.done(), {kind: 'params', values, old});
}

function cameraPayload(o, w, h) {
  const c = new Writer();
  for (let i = 0; i < 3; i++) c.f64(o.target[i] + o.offset[i]);
  for (let i = 0; i < 3; i++) c.f64(o.target[i]);
  for (let i = 0; i < 3; i++) c.f64(o.up[i]);
  c.f32(o.fov); c.f32(0); c.f32(0); c.u32(w); c.u32(h);
  return c.done();
}

/* pump: sends the next request when one is due, none is in flight and no arrived frame waits
 * for the decoder. */
function pump() {
  if (!S.ws || !S.authed || !S.opened || !S.orbit || !S.dirty || S.inflight || S.waiting) return;
  const drag = S.interacting;
  const want = Object.assign({}, S.want);
  want.format = 0;
  want.quality = drag ? DRAG_QUALITY : REST_QUALITY;
  want.point_budget = drag && S.info && S.info.points > DRAG_BUDGET ? DRAG_BUDGET : 0;
  let [w, h] = fullSize();
  if (drag) { w = (w + 1) >> 1; h = (h + 1) >> 1; }
  sendParams(want);
  const cam = {eye: [0, 1, 2].map((i) => S.orbit.target[i] + S.orbit.offset[i]),
               target: S.orbit.target.slice(),
               up: S.orbit.up.slice(), fov: S.orbit.fov, width: w, height: h};
  const cseq = send(P.CAMERA, cameraPayload(S.orbit, w, h), null);
  const rseq = send(P.RENDER, null, {kind: 'render', cam, cseq, quality: want.quality,
                                     sent: performance.now()});
  S.inflight = {seq: rseq, t: S.inputT};
  S.inputT = null;
  S.outstanding++;
  S.maxOutstanding = Math.max(S.maxOutstanding, S.outstanding);
  S.dirty = false;
  hud();
}

function onFrame(r, seq, pend) {
  const camSeq = r.u32(), pipe = r.u8(), format = r.u8(); r.u16();
  const w = r.u32(), h = r.u32(), renderUs = r.u64(), readbackUs = r.u64();
  const encodeUs = r.u64(); r.u64();
  const data = r.rest();
  const type = format === 1 ? 'image/png' : 'image/jpeg';
  if (pend && pend.kind === 'save') { saveBlob(new Blob([data], {type}), pend.name); return; }
  const f = {seq, camSeq, pipe, w, h, renderUs, encodeUs, blob: new Blob([data], {type}),
             t: S.inflight && S.inflight.seq === seq ? S.inflight.t : null,
             cam: pend ? pend.cam : null, sent: pend ? pend.sent : 0, recv: performance.now(),
             work: (renderUs + readbackUs + encodeUs) / 1000, quality: pend ? pend.quality : 0};
  if (S.inflight && S.inflight.seq === seq) S.inflight = null;
  if (pend && pend.kind === 'render') S.outstanding--;
  if (S.decoding) {
    if (S.waiting) S.spoiled++;   /* a newer frame replaces one that was never shown */
    S.waiting = f;
    return;
  }
  show(f);
  pump();
}

/* show: decodes f off the main thread (createImageBitmap) and draws it. */
async function show(f) {
  S.decoding = true;
  try {
    const bmp = await createImageBitmap(f.blob);
    const c = $('canvas'), [fw, fh] = fullSize();
    if (c.width !== fw || c.height !== fh) { c.width = fw; c.height = fh; }
    c.getContext('2d').drawImage(bmp, 0, 0, c.width, c.height);
    bmp.close();
    const now = performance.now();
    S.frames++; S.lastSeq = f.seq; S.lastCamSeq = f.camSeq;
    S.fw = f.w; S.fh = f.h; S.fpipe = PIPELINES[f.pipe] || String(f.pipe);
    S.render = f.renderUs / 1000; S.encode = f.encodeUs / 1000;
    if (f.t !== null) S.lat = now - f.t; /* the frame shows an input: its latency */
    S.fpsT.push(now); while (S.fpsT.length && now - S.fpsT[0] > 1000) S.fpsT.shift();
    if (f.cam) S.lastCam = f.cam;
    if (f.cam && f.sent && S.stats.length < 4096) {
      /* One line per frame for the bench (window.splatStats): the camera, then camera sent ->
       * frame received and -> drawn, and the frame's own render + read-back + encode, in ms. */
      const c = f.cam;
      S.stats.push([c.width, c.height, ...c.eye, ...c.target, ...c.up, c.fov, f.quality,
                    (f.recv - f.sent).toFixed(3), (now - f.sent).toFixed(3),
                    f.work.toFixed(3)].join(' '));
    }
    $('nframes').textContent = String(S.frames);
    $('lastseq').textContent = String(f.seq);
    $('camseq').textContent = String(f.camSeq);
    $('fsize').textContent = `${f.w}x${f.h}`;
    if (f.cam) $('camera').textContent = JSON.stringify(f.cam);
    hud();
  } catch (e) {
    setStatus('frame decode failed: ' + e.message);
  }
  S.decoding = false;
  if (S.waiting) { const n = S.waiting; S.waiting = null; show(n); }
  pump();
  hud();
}

/* ---- save ------------------------------------------------------------------------------- */

function save() {
  if (!S.opened || !S.orbit) { setStatus('nothing to save yet'); return; }
  const name = `splat-view-${++S.nsave}.png`;
  const want = Object.assign({}, S.want, {format: 1, quality: REST_QUALITY, point_budget: 0});
  const [w, h] = fullSize();
  sendParams(want);
  send(P.CAMERA, cameraPayload(S.orbit, w, h), null);
  send(P.RENDER, null, {kind: 'save', name});
  setStatus(`saving ${name}`);
}

function saveBlob(blob, name) {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
  setStatus(`saved ${name} (${blob.size} bytes)`);
}

/* ---- input ------------------------------------------------------------------------------ */

function input(t) {
  S.inputs++;
  S.lastInput = t;
  if (!S.interacting) S.interacting = true;
  clearTimeout(S.settleTimer);
  S.settleTimer = setTimeout(settle, SETTLE_MS);
  touchRequest(t);
}

function settle() {
  if (performance.now() - S.lastInput < SETTLE_MS - 1) {
    S.settleTimer = setTimeout(settle, SETTLE_MS);
    return;
  }
  S.interacting = false;
  touchRequest(null); /* the full frame of what the drag's frames showed */
}

const pointers = new Map();
function onPointerDown(e) {
  $('canvas').focus();
  $('canvas').setPointerCapture(e.pointerId);
  pointers.set(e.pointerId, {x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey});
}
function onPointerMove(e) {
  const p = pointers.get(e.pointerId);
  if (!p || !S.orbit) return;
  const dx = e.clientX - p.x, dy = e.clientY - p.y;
  const dpr = fullSize()[1] / Math.max(1, $('canvas').clientHeight);
  if (pointers.size >= 2) {
    /* Two fingers: the pair's motion pans (half of it, each finger moves), its spread zooms. */
    const [a, b] = [...pointers.values()];
    const before = Math.hypot(a.x - b.x, a.y - b.y);
    p.x = e.clientX; p.y = e.clientY;
    const after = Math.hypot(a.x - b.x, a.y - b.y);
    orbitPan(S.orbit, dx * dpr / 2, dy * dpr / 2, fullSize()[1]);
    if (before > 0 && after > 0) orbitZoom(S.orbit, Math.log(after / before) / -Math.log(0.9));
  } else {
    p.x = e.clientX; p.y = e.clientY;
    if (p.pan) orbitPan(S.orbit, dx * dpr, dy * dpr, fullSize()[1]);
    else orbitDrag(S.orbit, dx, dy);
  }
  if (dx || dy) input(performance.now());
}
function onPointerUp(e) { pointers.delete(e.pointerId); }
function onWheel(e) {
  e.preventDefault();
  if (!S.orbit) return;
  const steps = e.deltaMode === 1 ? -e.deltaY / 3 : -e.deltaY / 100;
  orbitZoom(S.orbit, steps);
  input(performance.now());
}

function stepParam(name, dir) {
  if (S.unavail.has(name)) { setStatus(`${name}: not available on this server`); return; }
  const p = PARAMS[name];
  let x = S.want[name];
  if (p.min > 0) x = dir > 0 ? x * 1.25 : x * 0.8; else x += dir * (p.max - p.min) / 20;
  S.want[name] = Math.round(Math.min(p.max, Math.max(p.min, x)) * 1e6) / 1e6;
  paramChanged();
}

function paramChanged() { syncControls(); touchRequest(performance.now()); }

function setPipeline(i) {
  if (i >= PIPELINES.length) {
    setStatus(`no pipeline ${i + 1}: this viewer knows ${PIPELINES.length}`);
    return;
  }
  if (S.pipeUnavail.has(i)) {
    setStatus(`pipeline ${PIPELINES[i]}: not available on this server`);
    return;
  }
  S.want.pipeline = i;
  paramChanged();
}

function onKey(e) {
  const t = e.target;
  if (t.tagName === 'INPUT' && t.type !== 'range' && t.type !== 'checkbox') return;
  const k = e.key.toLowerCase();
  if (k >= '1' && k <= '9') { setPipeline(k.charCodeAt(0) - 49); return; }
  switch (k) {
  case 'u': stepParam('lambda', 1); break;
  case 'j': stepParam('lambda', -1); break;
  case 'i': stepParam('t', 1); break;
  case 'k': stepParam('t', -1); break;
  case 'o': stepParam('l_m', 1); break;
  case 'l': stepParam('l_m', -1); break;
  case 'f': S.want.field = (S.want.field + 1) % FIELDS.length; paramChanged(); break;
  case 'e': S.want.shading = S.want.shading ? 0 : 1; paramChanged(); break;
  case 'r': if (S.home) { S.orbit = cloneOrbit(S.home); touchRequest(performance.now()); } break;
  case 's': save(); break;
  case 'h': $('help').hidden = !$('help').hidden; break;
  case 'escape': case 'q':
    if (S.ws) { S.closedByUser = true; send(P.BYE, null, null); } break;
  default: return;
  }
  e.preventDefault();
}

/* ---- controls and heads-up line ---------------------------------------------------------- */

function syncControls() {
  const pipe = $('pipeline');
  for (let i = 0; i < pipe.options.length; i++) pipe.options[i].disabled = S.pipeUnavail.has(i);
  pipe.value = String(S.want.pipeline);
  for (const k of ['lambda', 't', 'l_m']) {
    $(k).value = String(S.want[k]);
    $(k).parentElement.classList.toggle('na', S.unavail.has(k));
  }
  $('field').value = String(S.want.field);
  $('field').parentElement.classList.toggle('na', S.unavail.has('field'));
  $('edl').checked = S.want.shading === 1;
  $('edl').parentElement.classList.toggle('na', S.unavail.has('shading'));
  hud();
}

function hud() {
  /* For tests: 1 when nothing is due, in flight, being decoded or interacting. */
  $('maxinflight').textContent = String(S.maxOutstanding);
  $('inputs').textContent = String(S.inputs);
  const rest = !S.dirty && !S.inflight && !S.decoding && !S.waiting && !S.interacting;
  $('idle').textContent = rest && S.frames ? '1' : '0';
  const fmt = (x) => (Math.round(x * 100) / 100).toString();
  const parts = [`${S.fpsT.length} fps`, `render ${S.render.toFixed(1)} ms`,
                 `encode ${S.encode.toFixed(1)} ms`,
                 S.lat === null ? '' : `latency ${S.lat.toFixed(0)} ms`,
                 S.fpipe || PIPELINES[S.want.pipeline], `${S.fw}x${S.fh}`,
                 `λ ${fmt(S.want.lambda)} t ${fmt(S.want.t)} l_m ${fmt(S.want.l_m)}`,
                 `field ${FIELDS[S.want.field]}`, S.want.shading ? 'EDL' : '',
                 `q${S.interacting ? DRAG_QUALITY : REST_QUALITY}`, `${S.frames} frames`];
  if (S.spoiled) parts.push(`${S.spoiled} spoiled`);
  $('hudline').textContent = parts.filter(Boolean).join(' · ');
  $('status').textContent = S.status;
}

function setup() {
  const pipe = $('pipeline');
  const option = (sel, value, text) => {
    const o = document.createElement('option');
    o.value = value; o.textContent = text;
    sel.appendChild(o);
  };
  PIPELINES.forEach((n, i) => option(pipe, String(i), `${i + 1} ${n}`));
  const field = $('field');
  FIELDS.forEach((n, i) => option(field, String(i), n));
  pipe.onchange = () => setPipeline(+pipe.value);
  field.onchange = () => { S.want.field = +field.value; paramChanged(); };
  for (const k of ['lambda', 't', 'l_m'])
    $(k).oninput = () => { S.want[k] = +$(k).value; paramChanged(); };
  $('edl').onchange = () => { S.want.shading = $('edl').checked ? 1 : 0; paramChanged(); };
  $('clouds').onchange = () => openCloud($('clouds').value);
  $('reset').onclick = () => onKey({key: 'r', target: document.body, preventDefault() {}});
  $('save').onclick = save;
  $('helpbtn').onclick = () => { $('help').hidden = !$('help').hidden; };
  const c = $('canvas');
  const fixed = /^(\d+)x(\d+)$/.exec(query.get('size') || '');
  if (fixed) { c.style.width = fixed[1] + 'px'; c.style.height = fixed[2] + 'px'; }
  c.addEventListener('pointerdown', onPointerDown);
  c.addEventListener('pointermove', onPointerMove);
  c.addEventListener('pointerup', onPointerUp);
  c.addEventListener('pointercancel', onPointerUp);
  c.addEventListener('wheel', onWheel, {passive: false});
  c.addEventListener('contextmenu', (e) => e.preventDefault());
  window.addEventListener('keydown', onKey);
  window.addEventListener('resize', () => { if (S.orbit) input(performance.now()); });
  /* A PING a minute keeps an idle tab inside --idle-timeout. */
  setInterval(() => {
    if (!S.ws || !S.authed) return;
    const w = new Writer();
    w.i64(Date.now());
    send(P.PING, w.done(), null);
  }, 60000);
  syncControls();
  connect();
}

setup();
