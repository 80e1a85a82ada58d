// cpm monitor's page: draws /api/world once, then every snapshot of /api/stream (server-sent
// events) as cars on the map, a panel per car, plots, topics and log lines. Nothing is fetched
// from anywhere but the monitor that served this page.
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const PLOT_WINDOW_S = 30;
const COLOURS = ["#1e88e5", "#e53935", "#43a047", "#fb8c00", "#8e24aa", "#00acc1", "#6d4c41", "#3949ab", "#c0ca33", "#d81b60"];

// What tests and curious people can read from the console.
window.cpmMonitor = { received: 0, updates: 0, connected: false, last: null, world: null };

const $ = (id) => document.getElementById(id);
const colour = (id) => COLOURS[id % COLOURS.length];
const fixed = (v, digits) => (v === null || v === undefined ? "–" : Number(v).toFixed(digits));
const deg = (rad) => (rad * 180) / Math.PI;

function el(name, attrs, parent) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

// An HTML element with attributes and children; a child that is not a node becomes text.
function html(name, attrs, ...children) {
  const e = document.createElement(name);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  for (const c of children) e.append(c instanceof Node ? c : String(c ?? ""));
  return e;
}

// ---- the map ----------------------------------------------------------------------------------
const bounds = { minx: Infinity, miny: Infinity, maxx: -Infinity, maxy: -Infinity };
function include(x, y) {
  if (!Number.isFinite(x) || !Number.isFinite(y)) return false;
  const grew = x < bounds.minx || y < bounds.miny || x > bounds.maxx || y > bounds.maxy;
  bounds.minx = Math.min(bounds.minx, x); bounds.maxx = Math.max(bounds.maxx, x);
  bounds.miny = Math.min(bounds.miny, y); bounds.maxy = Math.max(bounds.maxy, y);
  return grew;
}
function fitView() {
  if (!Number.isFinite(bounds.minx)) return;
  const pad = 0.3;
  const w = bounds.maxx - bounds.minx + 2 * pad, h = bounds.maxy - bounds.miny + 2 * pad;
  // The world group flips y (scale(1,-1)): world y runs from -maxy to -miny in the view.
  $("map").setAttribute("viewBox", `${bounds.minx - pad} ${-bounds.maxy - pad} ${w} ${h}`);
}

function drawWorld(world) {
  window.cpmMonitor.world = world;
  for (const pts of world.lanes) {
    el("polyline", { class: "lane", points: pts.map((p) => p.join(",")).join(" "), "stroke-width": world.lane_width || 0.1 }, $("lanes"));
    for (const p of pts) include(p[0], p[1]);
  }
  for (const w of world.walls) {
    el("line", { class: "wall", x1: w[0], y1: w[1], x2: w[2], y2: w[3] }, $("walls"));
    include(w[0], w[1]); include(w[2], w[3]);
  }
  const byId = {};
  for (const m of world.markers) {
    byId[m.id] = m;
    const g = el("g", { transform: `translate(${m.x} ${m.y}) rotate(${deg(m.yaw)})` }, $("markers"));
    el("rect", { class: "marker", "data-id": m.id, x: -0.01, y: -m.size / 2, width: 0.02, height: m.size }, g);
    const t = el("text", { class: "label", transform: `translate(${m.x + 0.03} ${m.y}) scale(1,-1)` }, $("labels"));
    t.textContent = `#${m.id}`;
    include(m.x, m.y);
  }
  for (const gate of world.gates) {
    const a = byId[gate.left], b = byId[gate.right];
    if (a && b) el("line", { class: "gate", x1: a.x, y1: a.y, x2: b.x, y2: b.y }, $("gates"));
  }
  fitView();
}

const cars = new Map();  // id → {g, body, label, panel}

function carOnMap(v) {
  let c = cars.get(v.id);
  if (!c) {
    const g = el("g", { class: "car", "data-id": v.id }, $("cars"));
    el("rect", { class: "body", x: -0.04, y: -0.05, width: 0.22, height: 0.1, rx: 0.015, fill: colour(v.id) }, g);
    el("path", { d: "M 0.18 0 L 0.12 -0.035 L 0.12 0.035 Z", fill: "#fff" }, g);
    el("circle", { r: 0.012, fill: "#222" }, g);  // the car's reference point: its pose
    const label = el("text", { class: "label" }, $("labels"));
    c = { g, label };
    cars.set(v.id, c);
  }
  c.g.setAttribute("transform", `translate(${v.x} ${v.y}) rotate(${deg(v.yaw)})`);
  c.g.setAttribute("data-x", v.x);
  c.g.setAttribute("data-y", v.y);
  c.g.classList.toggle("stale", v.stale);
  c.label.setAttribute("transform", `translate(${v.x - 0.05} ${v.y + 0.09}) scale(1,-1)`);
  c.label.textContent = `${v.id}${v.fsm_state ? " " + v.fsm_state : ""}${v.stale ? " (stale)" : ""}`;
  if (include(v.x, v.y)) fitView();
}

function sightLines(vehicles) {
  const sight = $("sight");
  sight.replaceChildren();
  document.querySelectorAll(".marker.seen").forEach((m) => m.classList.remove("seen"));
  for (const v of vehicles) {
    for (const m of v.markers || []) {
      if (m.x === null || m.y === null) continue;
      const c = Math.cos(v.yaw), s = Math.sin(v.yaw);
      el("line", { class: "sight", x1: v.x, y1: v.y, x2: v.x + c * m.x - s * m.y, y2: v.y + s * m.x + c * m.y }, sight);
      const drawn = document.querySelector(`.marker[data-id="${CSS.escape(String(m.id))}"]`);
      if (drawn) drawn.classList.add("seen");
    }
  }
}

// ---- the panels -------------------------------------------------------------------------------
function panelFor(v, allowStop) {
  let c = cars.get(v.id);
  if (!c.panel) {
    const p = document.createElement("div");
    p.className = "panel";
    p.dataset.id = v.id;
    p.style.setProperty("--car", colour(v.id));
    const button = html("button", { class: "stop", "data-id": v.id }, "Stop");
    p.append(html("h3", {}, html("span", {}, `car ${v.id}`), html("span", { class: "stale-tag" }), button), html("dl"));
    p.querySelector("button").addEventListener("click", () => stop(v.id));
    $("panels").appendChild(p);
    c.panel = p;
  }
  const p = c.panel;
  p.classList.toggle("stale", v.stale);
  p.querySelector(".stale-tag").textContent = v.stale ? `stale ${fixed(v.age_ms / 1000, 1)} s` : "";
  const button = p.querySelector("button");
  button.disabled = !allowStop;
  button.title = allowStop ? `send a StopRequest to car ${v.id}` : "start cpm monitor with --allow-stop to stop cars from here";
  const r = v.ranges;
  const rows = [
    ["state", v.fsm_state ? `${v.fsm_state}${v.fsm_for_s !== undefined ? ` for ${fixed(v.fsm_for_s, 1)} s` : ""}` : "–"],
    ["speed", `${fixed(v.speed, 2)} m/s`],
    ["steering", fixed(v.steering, 2)],
    ["pose", `${fixed(v.x, 2)}, ${fixed(v.y, 2)} m, ${fixed(deg(v.yaw), 0)}°`],
    ["placed by", v.pose_source || "–"],
    ["ranges", r ? `F ${fixed(r.front, 2)} L ${fixed(r.left, 2)} R ${fixed(r.right, 2)} m` : "–"],
    ["battery", v.battery_voltage !== undefined ? `${fixed(v.battery_voltage, 2)} V` : "–"],
    ["nearest", v.clearance_m !== null && v.clearance_m !== undefined ? `${fixed(v.clearance_m, 2)} m (${v.clearance_to})` : "–"],
    ["markers", (v.markers || []).length ? v.markers.map((m) => `#${m.id} ${fixed(m.distance, 2)} m`).join(", ") : "none seen"],
    ["newest", `${fixed(v.age_ms, 0)} ms ago`],
  ];
  p.querySelector("dl").replaceChildren(...rows.flatMap(([k, val]) => [html("dt", {}, k), html("dd", { "data-field": k }, val)]));
}

async function stop(id) {
  const who = id === 0 ? "every car" : `car ${id}`;
  try {
    const res = await fetch("/api/stop", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ vehicle_id: id }) });
    const body = await res.json();
    $("stop-result").textContent = res.ok ? body.message : `stop ${who} refused: ${body.error}`;
  } catch (e) {
    $("stop-result").textContent = `stop ${who} failed: ${e}`;
  }
}
$("stop-all").addEventListener("click", () => stop(0));

// A bookmark of this moment (cpm lab mark from the page).
$("mark-form").addEventListener("submit", async (event) => {
  event.preventDefault();
  const text = $("mark-text").value;
  try {
    const res = await fetch("/api/mark", { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ text }) });
    const body = await res.json();
    $("stop-result").textContent = res.ok ? body.message : `mark refused: ${body.error}`;
    if (res.ok) $("mark-text").value = "";
  } catch (e) {
    $("stop-result").textContent = `mark failed: ${e}`;
  }
});

// ---- topics and log ---------------------------------------------------------------------------
// Every string here comes from the DDS domain, where any participant may write: rows are built
// as nodes with their text set, never parsed as HTML.
function topicsTable(topics) {
  $("topics").tBodies[0].replaceChildren(...topics.map((t) =>
    html("tr", {}, html("td", {}, t.name), html("td", {}, fixed(t.rate_hz, 1)), html("td", { class: "muted" }, t.from))));
}
function logTable(lines) {
  $("log").tBodies[0].replaceChildren(...lines.slice().reverse().map((l) =>
    html("tr", { class: l.level }, html("td", {}, l.level), html("td", {}, l.id), html("td", {}, l.text))));
}

// ---- plots ------------------------------------------------------------------------------------
const series = new Map();  // id → [[t_ms (page clock), speed, clearance], ...]
function addPoint(id, t, speed, clearance) {
  let s = series.get(id);
  if (!s) series.set(id, (s = []));
  if (s.length && t - s[s.length - 1][0] < 100) return;
  s.push([t, speed, clearance]);
  while (s.length && s[0][0] < t - PLOT_WINDOW_S * 1000) s.shift();
}
function drawPlot(canvas, index) {
  const ctx = canvas.getContext("2d"), w = canvas.width, h = canvas.height, left = 36, bottom = 18;
  ctx.clearRect(0, 0, w, h);
  const now = performance.now();
  let max = 0.1;
  for (const s of series.values()) for (const p of s) if (p[index] !== null && Number.isFinite(p[index])) max = Math.max(max, p[index]);
  max *= 1.1;
  ctx.strokeStyle = "#ccc"; ctx.fillStyle = "#777"; ctx.font = "11px sans-serif"; ctx.lineWidth = 1;
  for (let i = 0; i <= 4; ++i) {
    const y = h - bottom - ((h - bottom - 6) * i) / 4;
    ctx.beginPath(); ctx.moveTo(left, y); ctx.lineTo(w, y); ctx.stroke();
    ctx.fillText(((max * i) / 4).toFixed(2), 2, y + 4);
  }
  for (let s = 0; s <= PLOT_WINDOW_S; s += 10) ctx.fillText(s === PLOT_WINDOW_S ? "now" : `-${PLOT_WINDOW_S - s} s`, left + ((w - left - 24) * s) / PLOT_WINDOW_S, h - 4);
  for (const [id, s] of series) {
    ctx.strokeStyle = colour(id); ctx.lineWidth = 2; ctx.beginPath();
    let pen = false;
    for (const p of s) {
      if (p[index] === null || !Number.isFinite(p[index])) { pen = false; continue; }
      const x = left + (w - left) * (1 - (now - p[0]) / (PLOT_WINDOW_S * 1000));
      const y = h - bottom - ((h - bottom - 6) * p[index]) / max;
      if (pen) ctx.lineTo(x, y); else ctx.moveTo(x, y);
      pen = true;
    }
    ctx.stroke();
  }
}
setInterval(() => { drawPlot($("plot-speed"), 1); drawPlot($("plot-clearance"), 2); }, 200);

// ---- the stream -------------------------------------------------------------------------------
function show(snapshot) {
  const m = window.cpmMonitor;
  m.updates += 1;
  m.last = snapshot;
  const badge = $("source");
  badge.textContent = snapshot.source === "replay" ? "replay (cpm play)" : "live";
  badge.className = `badge ${snapshot.source}`;
  $("stop-all").disabled = !snapshot.allow_stop;
  $("stop-all").title = snapshot.allow_stop ? "send a StopRequest to every car" : "start cpm monitor with --allow-stop to stop cars from here";
  const now = performance.now();
  for (const v of snapshot.vehicles) {
    carOnMap(v);
    panelFor(v, snapshot.allow_stop);
    if (!v.stale) addPoint(v.id, now, v.speed, v.clearance_m);
  }
  sightLines(snapshot.vehicles);
  topicsTable(snapshot.topics);
  logTable(snapshot.log);
}

async function start() {
  try {
    drawWorld(await (await fetch("/api/world")).json());
    const plots = await (await fetch("/api/plots")).json();
    const now = performance.now();
    for (const v of plots.vehicles) for (const p of v.points) addPoint(v.id, now + p[0] * 1000, p[1], p[2]);
  } catch (e) {
    $("connection").textContent = `cannot read the map: ${e}`;
  }
  const stream = new EventSource("/api/stream");
  let pending = null;
  stream.onmessage = (e) => {
    // Draw at most once per frame: the newest snapshot wins.
    window.cpmMonitor.received += 1;
    const first = pending === null;
    pending = JSON.parse(e.data);
    if (first) requestAnimationFrame(() => { const s = pending; pending = null; show(s); });
  };
  stream.onopen = () => { window.cpmMonitor.connected = true; $("connection").textContent = ""; };
  stream.onerror = () => {
    window.cpmMonitor.connected = false;
    $("connection").textContent = "lost the monitor; trying again…";
  };
}
start();
