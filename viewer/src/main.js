// The page: token, sessions, run controls, electrode drag/power/on-off, display, readouts.
// Everything goes through the documented REST API (api.js) and the session stream (stream.js).
import { Api } from "./api.js";
import {
  applyFrames as paint,
  drawFps as fps,
  fineRegionText,
  leftOutText,
  onMessage as receive,
  updatePanel as panel,
  voltageText,
} from "./frames.js";
import { View } from "./render.js";
import { Stream } from "./stream.js";

const $ = (id) => document.getElementById(id);
const view = new View($("view"));

const stats = {
  framesReceived: { surface: 0, volume: 0 },
  framesDrawn: 0,
  drawnAt: [], // performance.now() of recent drawn frames
  stepsAt: [], // [time, step] of recent frames
  applyMs: 0, // mean decode + geometry time of a drawn frame, ms
  renderMs: 0,
  bytes: 0,
  reconnects: 0,
};

const st = {
  api: null,
  session: null,
  electrodes: [],
  streams: null,
  wantRunning: false,
  raw: { surface: null, volume: null }, // newest undrawn messages
  last: { surface: null, volume: null }, // newest drawn messages (kept for re-colouring)
  dragging: false,
  lastPoll: 0,
  tag: 0,
  pending: new Map(), // electrode name -> changes not sent yet
  inflightTag: null, // tag of the electrode control awaiting its ack
  exaggeration: 1,
};

function setStatus(text, isError = false) {
  const el = $("status");
  el.textContent = text;
  el.className = isError ? "error" : "";
}

async function guarded(what, fn) {
  try {
    return await fn();
  } catch (err) {
    setStatus(`${what}: ${err.message}`, true);
    return undefined;
  }
}

// ------------------------------------------------------------------ sessions
async function connect() {
  const token = $("token").value.trim();
  localStorage.setItem("diathermy.token", token);
  st.api = new Api(window.location.origin, token);
  await guarded("connect", async () => {
    const scenes = await st.api.scenes();
    const sel = $("scene");
    sel.innerHTML = "";
    for (const [name, scene] of Object.entries(scenes)) {
      const opt = document.createElement("option");
      opt.value = name;
      opt.textContent = `${name} (${scene.grid.join("x")})`;
      opt.title = scene.description || "";
      sel.appendChild(opt);
    }
    await refreshSessions();
    setStatus("connected");
  });
}

async function refreshSessions() {
  const list = await st.api.sessions();
  const sel = $("sessions");
  sel.innerHTML = '<option value="">(none)</option>';
  for (const s of list) {
    const opt = document.createElement("option");
    opt.value = s.id;
    opt.textContent = `${s.scene_name} ${s.grid.shape.join("x")} step ${s.step}`;
    sel.appendChild(opt);
  }
  if (st.session) sel.value = st.session.id;
}

function createBody() {
  const text = $("scene-json").value.trim();
  let body;
  if (text) {
    let scene;
    try {
      scene = JSON.parse(text);
    } catch (err) {
      throw new Error(`scene JSON: ${err.message}`);
    }
    body = { scene };
  } else {
    body = { builtin: $("scene").value || "default" };
  }
  const grid = ["grid-z", "grid-y", "grid-x"].map((id) => $(id).value.trim());
  if (grid.some((v) => v !== "")) {
    if (grid.some((v) => v === "")) throw new Error("grid: give all three of nz, ny, nx");
    body.grid = grid.map(Number);
  }
  return body;
}

async function createSession() {
  if (!st.api) await connect();
  await guarded("create", async () => {
    setStatus("creating session…");
    const info = await st.api.createSession(createBody());
    await openSession(info);
    await refreshSessions();
  });
}

async function deleteSession() {
  if (!st.session) return;
  const id = st.session.id;
  closeSession();
  await guarded("delete", async () => {
    await st.api.deleteSession(id);
    await refreshSessions();
    setStatus(`deleted session ${id}`);
  });
}

function closeSession() {
  if (st.streams) {
    st.streams.surface.close();
    st.streams.volume.close();
  }
  st.streams = null;
  st.session = null;
  st.wantRunning = false;
  st.pending.clear();
  st.inflightTag = null;
  st.raw = { surface: null, volume: null };
  st.last = { surface: null, volume: null };
  view.clear();
}

function subscriptions() {
  const colour = $("colour").value;
  return {
    surface: { fields: [colour, "displacement"], region: "surface", dtype: "float32", every: 1 },
    // the tissue's top face only (1/nz of the volume's bytes), float16: enough to draw
    volume: { fields: [colour, "displacement", "level_set"], region: "top", dtype: "float16", every: 1 },
  };
}

async function openSession(info) {
  closeSession();
  st.session = info;
  st.electrodes = await st.api.electrodes(info.id);
  const sel = $("electrode");
  sel.innerHTML = "";
  for (const e of st.electrodes) {
    const opt = document.createElement("option");
    opt.value = e.name;
    opt.textContent = e.name;
    sel.appendChild(opt);
  }
  const first = st.electrodes[0];
  view.setGrid(info.grid, first ? first.radius_m : 0);
  showElectrode();
  const subs = subscriptions();
  const url = st.api.streamUrl(info.id);
  const handlers = (kind) => ({
    onMessage: (msg, bytes) => onMessage(kind, msg, bytes),
    onStatus: setStatus,
    onOpen: (again) => {
      if (again) stats.reconnects += 1;
      setStatus(again ? "reconnected" : `session ${info.id} (${info.scene_name})`);
      if (kind === "surface") {
        st.inflightTag = null; // an unanswered control died with the old connection
        if (st.wantRunning) sendRun();
        flushElectrode();
      }
    },
  });
  st.streams = {
    surface: new Stream(url, subs.surface, handlers("surface")),
    volume: new Stream(url, subs.volume, handlers("volume")),
  };
  st.streams.surface.connect();
  st.streams.volume.connect();
  $("sessions").value = info.id;
  window.location.hash = info.id;
}

// ------------------------------------------------------------------ electrodes
function currentElectrode() {
  const name = $("electrode").value;
  return st.electrodes.find((e) => e.name === name) || st.electrodes[0] || null;
}

function showElectrode() {
  const e = currentElectrode();
  if (!e) return;
  if (!st.dragging) view.setElectrode(e.position_m[0], e.position_m[1], e.active);
  if (document.activeElement !== $("power")) {
    $("power").value = String(Math.round(e.power_w));
    $("power-out").textContent = `${Math.round(e.power_w)} W`;
  }
  $("active").checked = e.active;
}

async function pollElectrodes(force = false) {
  const now = performance.now();
  if (!st.session || st.dragging || (!force && now - st.lastPoll < 400)) return;
  st.lastPoll = now;
  const id = st.session.id;
  const list = await st.api.electrodes(id).catch(() => null);
  // while a control is unanswered the server may still hold the old values: keep the local ones
  const settled = st.inflightTag === null && st.pending.size === 0;
  if (list && st.session && st.session.id === id && !st.dragging && settled) {
    st.electrodes = list;
    showElectrode();
  }
}

// One electrode control in flight at a time; later changes merge into the next one, so while a
// long step holds the session no backlog of stale positions queues up ahead of run or pause.
function sendElectrode(change) {
  const e = currentElectrode();
  if (!e || !st.session) return;
  Object.assign(e, change);
  st.pending.set(e.name, { ...(st.pending.get(e.name) || {}), ...change });
  flushElectrode();
}

function flushElectrode() {
  if (st.inflightTag !== null || st.pending.size === 0 || !st.session) return;
  const [name, change] = st.pending.entries().next().value;
  st.pending.delete(name);
  const tag = ++st.tag;
  if (st.streams && st.streams.surface.send({ type: "electrode", name, tag, ...change })) {
    st.inflightTag = tag;
  } else {
    const path = `/v1/sessions/${st.session.id}/electrodes/${encodeURIComponent(name)}`;
    guarded("electrode", () => st.api.request("PATCH", path, change));
  }
}

let lastDragSend = 0;
function dragTo(ev, final) {
  const p = view.topPoint(ev.clientX, ev.clientY);
  if (!p) return;
  const e = currentElectrode();
  view.setElectrode(p[0], p[1], e ? e.active : true);
  const now = performance.now();
  if (final || now - lastDragSend > 50) {
    lastDragSend = now;
    sendElectrode({ position_m: p });
  }
}

// capture phase on the stage: decide before the orbit controls see the pointer
$("stage").addEventListener("pointerdown", (ev) => {
  if (ev.button !== 0 || ev.target !== view.canvas || !view.hitsElectrode(ev.clientX, ev.clientY)) return;
  st.dragging = true;
  view.controls.enabled = false;
  view.canvas.setPointerCapture(ev.pointerId);
  ev.preventDefault();
}, true);
view.canvas.addEventListener("pointermove", (ev) => { if (st.dragging) dragTo(ev, false); });
view.canvas.addEventListener("pointerup", (ev) => {
  if (!st.dragging) return;
  dragTo(ev, true);
  st.dragging = false;
  view.controls.enabled = true;
  st.lastPoll = performance.now(); // let the control reach the server before reading back
});

function onMessage(kind, msg, bytes) {
  receive(st, stats, setStatus, kind, msg, bytes);
  const answered = (msg.type === "ack" && msg.of === "electrode" && msg.tag === st.inflightTag) || msg.type === "error";
  if (kind === "surface" && answered) {
    st.inflightTag = null;
    flushElectrode();
  }
}
const applyFrames = () => paint(st, view);
const updatePanel = () => panel(st, stats);
const drawFps = () => fps(stats);

function tick() {
  const fresh = (st.raw.surface ? 1 : 0) + (st.raw.volume ? 1 : 0);
  if (fresh) {
    const t0 = performance.now();
    if (st.raw.surface) st.last.surface = st.raw.surface;
    if (st.raw.volume) st.last.volume = st.raw.volume;
    st.raw = { surface: null, volume: null };
    applyFrames();
    const t1 = performance.now();
    view.render();
    const t2 = performance.now();
    stats.applyMs = 0.8 * stats.applyMs + 0.2 * (t1 - t0);
    stats.renderMs = 0.8 * stats.renderMs + 0.2 * (t2 - t1);
    stats.framesDrawn += fresh;
    for (let i = 0; i < fresh; i++) stats.drawnAt.push(t2);
    updatePanel();
    pollElectrodes();
  } else if (view.dirty) {
    view.render();
  }
  $("p-fps").textContent = drawFps().toFixed(1);
  requestAnimationFrame(tick);
}

// ------------------------------------------------------------------ controls
function sendRun() {
  const rate = Number($("rate").value) || 10;
  if (st.streams) st.streams.surface.send({ type: "run", rate_hz: rate });
}

$("connect").addEventListener("click", connect);
$("create").addEventListener("click", createSession);
$("delete").addEventListener("click", deleteSession);
$("sessions").addEventListener("change", async () => {
  const id = $("sessions").value;
  if (!id) return closeSession();
  await guarded("open", async () => openSession(await st.api.session(id)));
});
$("run").addEventListener("click", () => { st.wantRunning = true; sendRun(); });
$("pause").addEventListener("click", () => {
  st.wantRunning = false;
  if (st.streams) st.streams.surface.send({ type: "pause" });
});
$("step").addEventListener("click", () => { if (st.streams) st.streams.surface.send({ type: "step", n: 1 }); });
$("rate").addEventListener("change", () => { if (st.wantRunning) sendRun(); });
$("electrode").addEventListener("change", showElectrode);
$("power").addEventListener("input", () => { $("power-out").textContent = `${$("power").value} W`; });
$("power").addEventListener("change", () => sendElectrode({ power_w: Number($("power").value) }));
$("active").addEventListener("change", () => sendElectrode({ active: $("active").checked }));
$("colour").addEventListener("change", () => {
  if (!st.streams) return;
  const subs = subscriptions();
  st.streams.surface.resubscribe(subs.surface);
  st.streams.volume.resubscribe(subs.volume);
});
$("focus").addEventListener("click", () => {
  const e = currentElectrode();
  if (e && view.grid) view.look(e.position_m[0], e.position_m[1], Math.min(0.8, Math.max(0.25, (40 * e.radius_m) / view.grid.L)));
});
$("overview").addEventListener("click", () => view.overview());
$("exag").addEventListener("input", () => {
  st.exaggeration = 10 ** Number($("exag").value);
  $("exag-out").textContent = st.exaggeration < 10 ? st.exaggeration.toFixed(1) : st.exaggeration.toFixed(0);
  if (st.last.surface || st.last.volume) applyFrames();
});

// ------------------------------------------------------------------ hooks for tests and benchmarks
window.viewer = {
  view,
  stats,
  state: st,
  panel() {
    const out = {};
    for (const row of document.querySelectorAll("#panel tr")) out[row.cells[0].textContent] = row.cells[1].textContent;
    return out;
  },
  report() { return st.last.surface ? st.last.surface.report : null; },
  cutFaces() { return view.cutFaces || 0; },
  electrodeScreenPosition() {
    const e = currentElectrode();
    return e && view.grid ? view.screenOf(e.position_m[0], e.position_m[1]) : null;
  },
  screenOf(x, y) { return view.screenOf(x, y); },
  fineRegionText,
  leftOutText,
  voltageText,
  drawFps,
  // Re-draws the newest frames n times (decode, geometry, colours, render, GPU sync): the
  // viewer's own frames per second, independent of how fast the server steps.
  redrawBenchmark(n) {
    const gl = view.renderer.getContext();
    const px = new Uint8Array(4);
    let apply = 0;
    const t0 = performance.now();
    for (let i = 0; i < n; i++) {
      const a0 = performance.now();
      applyFrames();
      apply += performance.now() - a0;
      view.render();
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    }
    const ms = performance.now() - t0;
    return { frames: n, fps: (1000 * n) / ms, applyMs: apply / n, renderMs: (ms - apply) / n };
  },
};

$("token").value = new URLSearchParams(window.location.search).get("token") || localStorage.getItem("diathermy.token") || "";
requestAnimationFrame(tick);
if ($("token").value) {
  connect().then(async () => {
    const id = window.location.hash.slice(1);
    if (id && st.api) await guarded("open", async () => openSession(await st.api.session(id)));
  });
}
