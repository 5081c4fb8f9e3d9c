// eskin-bus web console: the session, the live connection and the shared helpers.
// Plain JavaScript, no framework, no build step.
"use strict";

const Console = {
  info: null,        // /api/info: the nodes and the session
  session: null,
  ws: null,
  watch: null,       // the node this page shows in full (its frames and trends)
  handlers: [],      // called with every message
  seen: {},          // page timestamps of what appeared (tests and the status line read them)
  errors: [],
};

function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") e.className = v; else if (k === "text") e.textContent = v; else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c);
  return e;
}

function fmt(x, digits = 2) {
  return x === null || x === undefined || Number.isNaN(x) ? "-" : Number(x).toFixed(digits);
}

function nowMs() { return performance.timeOrigin + performance.now(); }

async function api(path, body) {
  const opts = body === undefined ? { credentials: "same-origin" } : {
    method: "POST", credentials: "same-origin",
    headers: Object.assign({ "Content-Type": "application/json" },
                           Console.session && Console.session.csrf ? { "X-CSRF-Token": Console.session.csrf } : {}),
    body: JSON.stringify(body),
  };
  const r = await fetch(path, opts);
  let data = {};
  try { data = await r.json(); } catch (e) { data = {}; }
  return { status: r.status, ok: r.ok, data };
}

function say(text) {
  const m = document.getElementById("message");
  if (m) m.textContent = text;
}

function renderLogin() {
  const box = document.getElementById("login");
  if (!box) return;
  box.replaceChildren();
  const s = Console.session;
  if (!s || !s.login) { box.append(el("span", { class: "dim", text: "read-only (no users)" })); return; }
  if (s.user) {
    box.append(el("span", { id: "whoami", text: `${s.user} (${s.role})` }));
    const out = el("button", { id: "logout", text: "log out" });
    out.onclick = async () => { await api("/api/logout", {}); location.reload(); };
    box.append(out);
    return;
  }
  const user = el("input", { id: "user", placeholder: "user", autocomplete: "username" });
  const pass = el("input", { id: "password", type: "password", placeholder: "password",
                             autocomplete: "current-password" });
  const go = el("button", { id: "login-button", text: "log in" });
  const submit = async () => {
    const r = await api("/api/login", { user: user.value, password: pass.value });
    if (!r.ok) { say(r.data.error || `login refused (${r.status})`); return; }
    location.reload();
  };
  go.onclick = submit;
  pass.addEventListener("keydown", (e) => { if (e.key === "Enter") submit(); });
  box.append(user, pass, go);
}

function stateClass(snap) {
  if (!snap || snap.state_label === null || snap.state_label === undefined) return "unknown";
  return snap.state_label;
}

function stateText(snap) {
  if (!snap) return "NO DATA";
  if (snap.offline) return "OFFLINE";
  if (snap.state_label === null) return snap.stale ? "STALE" : (snap.enabled ? "UNKNOWN" : "DISABLED");
  return snap.state_label.replace("_", " ").toUpperCase();
}

// The health flags every page shows beside a state: [name, on, bad].
function healthFlags(snap) {
  if (!snap) return [];
  return [
    ["valid", snap.valid, false], ["enabled", snap.enabled, false], ["slip latched", snap.slip_latched, true],
    ["stale", snap.stale, true], ["bus fault", snap.bus_fault, true], ["sensor fault", snap.sensor_fault !== 0, true],
    ["turn unseen", snap.turn_unseen, false], ["offline", snap.offline, true],
  ];
}

function flagsElement(snap) {
  const span = el("span", { class: "flags" });
  for (const [name, on, bad] of healthFlags(snap)) {
    span.append(el("span", { class: `flag${on ? " on" : ""}${bad ? " bad" : ""}`, "data-flag": name, text: name }));
  }
  return span;
}

// A node page's message (outputs/web/wire.py): u32 LE n, n bytes of JSON (padded to a
// multiple of 4), then the frame's forces as float32 LE when the JSON names a frame.
const utf8Decoder = new TextDecoder();
function decodeMessage(buffer) {
  const n = new DataView(buffer).getUint32(0, true);
  const msg = JSON.parse(utf8Decoder.decode(new Uint8Array(buffer, 4, n)));
  if (msg.frame) {
    const forces = new Float32Array(buffer, 4 + n, msg.frame.n);
    msg.frame.forces = Array.from(forces, (x) => (Number.isFinite(x) ? x : null));
  }
  return msg;
}

function connect() {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const ws = new WebSocket(`${scheme}//${location.host}/ws`);
  Console.ws = ws;
  const status = document.getElementById("status");
  ws.onopen = () => {
    if (status) status.textContent = "live";
    if (Console.watch !== null) ws.send(JSON.stringify({ watch: Console.watch }));
  };
  ws.binaryType = "arraybuffer";
  ws.onmessage = (ev) => {
    const msg = typeof ev.data === "string" ? JSON.parse(ev.data) : decodeMessage(ev.data);
    msg.received = nowMs();
    for (const h of Console.handlers) h(msg);
    ws.send('{"ack":1}');  // drawn: the server may send the next (a slow page is sent fewer, newer ones)
  };
  ws.onclose = () => {
    if (status) status.textContent = "disconnected: reconnecting";
    setTimeout(connect, 1000);
  };
}

async function start(onInfo) {
  const r = await api("/api/info");
  Console.info = r.data;
  Console.session = r.data.session;
  renderLogin();
  if (!r.data.nodes) { say("log in to see the cell"); return; }
  onInfo(r.data);
  connect();
}

async function command(node, name) {
  const r = await api(`/api/nodes/${node}/command`, { command: name });
  const text = r.ok ? `${name}: queued` : `${name}: refused (${r.data.error || r.status})`;
  say(text);
  Console.seen.lastCommand = { name, status: r.status, error: r.data.error || null };
  return r;
}

window.Console = Console;
