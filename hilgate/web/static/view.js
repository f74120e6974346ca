// The operator's view: draws what the daemon (or the trace player) pushes over the WebSocket.
// No framework and no build step; every name from the scene goes into the page as text, never as HTML.
"use strict";

const SVG = "http://www.w3.org/2000/svg";
// The words and colours of frames' fates come with the SCENE (hilgate/report/causes.py, the report's table):
// the page keeps none of its own, so a cause reads the same here as in the report's figures and tables.
const LEGEND_FATES = ["rx", "col", "mult", "prop", "range", "fifo", "band", "modulation"];
const OTHER = "#8c564b";
const CHANNEL_COLOURS = ["#0b3954", "#087e8b", "#c1440e", "#6a4c93", "#3d5a80", "#bc4749"];
const SPEEDS = [0.1, 0.25, 0.5, 1, 2, 5, 10, 25, 50, 100];
const SEEN_KEPT = 5000;

const view = window.hilgateView = {
  scene: null, state: null, received: 0, connected: false, authed: false, mode: null, error: null,
  seen: new Map(),     // frame id -> {src, dst, states}: what it was drawn as, in order ("flight", then fates)
  bounds: null, drawn: 0, ws: null,
};

const $ = (id) => document.getElementById(id);

function el(tag, attrs, text) {
  const node = document.createElementNS(SVG, tag);
  for (const [key, value] of Object.entries(attrs || {})) node.setAttribute(key, value);
  if (text !== undefined) node.textContent = text;
  return node;
}

function cell(row, name, text) {
  let td = row.querySelector("td." + name);
  if (!td) { td = document.createElement("td"); td.className = name; row.appendChild(td); }
  if (text !== undefined && td.textContent !== String(text)) td.textContent = text;
  return td;
}

function fates() {
  return (view.scene && view.scene.fates) || {};
}

function fate(ev, cause) {
  const key = ev === "rx" ? "rx" : (cause || "?");
  return [key, (fates()[key] || [key, OTHER])[1]];
}

function said(cause) {  // a cause in words (a link's "modem" error and unknown codes as they are)
  const known = fates()[cause];
  return known ? known[0] : cause;
}

function channelColour(name) {
  let h = 0;
  for (const c of String(name)) h = (h * 31 + c.charCodeAt(0)) >>> 0;
  return CHANNEL_COLOURS[h % CHANNEL_COLOURS.length];
}

function seen(frame, what) {
  let entry = view.seen.get(frame.id);
  if (!entry) {
    entry = { src: frame.src, dst: frame.dst, states: [] };
    view.seen.set(frame.id, entry);
    if (view.seen.size > SEEN_KEPT) view.seen.delete(view.seen.keys().next().value);
  }
  if (!entry.states.includes(what)) entry.states.push(what);
}

// -- the connection --------------------------------------------------------------------------------

function takeToken() {
  const match = /(?:^#|&)token=([^&]*)/.exec(location.hash);
  if (match) {
    sessionStorage.setItem("hilgate-token", decodeURIComponent(match[1]));
    history.replaceState(null, "", location.pathname + location.search);  // not in the history, nor on screen
  }
  return sessionStorage.getItem("hilgate-token");
}

function showLogin(why) {
  $("login").hidden = false;
  if (why) $("login-why").textContent = why;
  $("token").focus();
}

function setConnection(text, ok) {
  const node = $("connection");
  node.textContent = text;
  node.classList.toggle("off", !ok);
}

function connect() {
  const token = takeToken();
  if (!token) { showLogin(); return; }
  $("login").hidden = true;
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws");
  view.ws = ws;
  let refused = false;
  ws.onopen = () => { view.connected = true; setConnection("proving the token", false); };
  ws.onmessage = (event) => {
    let msg;
    try { msg = JSON.parse(event.data); } catch (e) { return; }
    if (msg.class === "HELLO") {
      view.mode = msg.mode;
      ws.send(JSON.stringify({ class: "AUTH", proof: window.hilgateProof(token, msg.nonce) }));
    } else if (msg.class === "WELCOME") {
      view.authed = true;
      setConnection(msg.mode === "live" ? "connected" : "trace loaded", true);
      $("mode").textContent = msg.mode;
      $("player").hidden = msg.mode !== "replay";
    } else if (msg.class === "SCENE") {
      onScene(msg);
    } else if (msg.class === "STATE") {
      onState(msg);
    } else if (msg.class === "ERROR") {
      view.error = msg.error;
      $("message").textContent = msg.error;
      if (!view.authed) refused = true;
    }
  };
  ws.onclose = (event) => {
    view.connected = false;
    view.authed = false;
    setConnection("not connected", false);
    if (refused || event.code === 1008) {
      sessionStorage.removeItem("hilgate-token");
      showLogin(view.error || "The token was refused.");
    } else {
      setTimeout(connect, 2000);  // the daemon restarts, the network hiccups: try again
    }
  };
}

function send(obj) {
  if (view.ws && view.ws.readyState === WebSocket.OPEN) view.ws.send(JSON.stringify(obj));
}

// -- messages --------------------------------------------------------------------------------------

function onScene(scene) {
  view.scene = scene;
  $("scene-name").textContent = "scene " + scene.name;
  const legend = $("legend");
  legend.textContent = "";
  for (const key of LEGEND_FATES) {
    if (!fates()[key]) continue;
    const [label, colour] = fates()[key];
    const item = document.createElement("span");
    item.textContent = label;
    item.dataset.fate = key;
    item.style.setProperty("--c", colour);
    legend.appendChild(item);
  }
  const channels = new Set(Object.values(scene.links).map((l) => l.channel));
  for (const channel of channels) {
    const item = document.createElement("span");
    item.textContent = "channel " + channel + " (wave, ring: range)";
    item.style.setProperty("--c", channelColour(channel));
    legend.appendChild(item);
  }
}

function onState(state) {
  view.state = state;
  view.received = performance.now();
  if (state.links) updateLinks(state.links);
  updateHosts(state.hosts || []);
  updateFlows(state.flows || []);
  updateVehicles(state.vehicles || []);
  updatePlayer(state);
}

function rowFor(table, key, attribute) {
  const body = $(table).tBodies[0];
  for (const row of body.rows) if (row.dataset[attribute] === key) return row;
  const row = document.createElement("tr");
  row.dataset[attribute] = key;
  body.appendChild(row);
  return row;
}

function prune(table, attribute, keys) {
  for (const row of Array.from($(table).tBodies[0].rows)) if (!keys.has(row.dataset[attribute])) row.remove();
}

function updateLinks(links) {
  const scene = view.scene || { links: {} };
  for (const link of links) {
    const info = scene.links[link.id] || {};
    const row = rowFor("links", link.id, "link");
    cell(row, "id", link.id);
    const backend = cell(row, "backend");
    let badge = backend.querySelector(".badge");
    if (!badge) { badge = document.createElement("span"); badge.className = "badge"; backend.appendChild(badge); }
    const kind = link.remote ? "remote" : (info.kind || (link.backend === "sim" ? "sim" : "real"));
    const label = link.remote ? "on " + link.host : kind === "sim" ? "sim"
      : kind === "emulated" ? "emulated " + (info.emulate || "modem") : "real · " + (link.backend || info.backend);
    if (badge.dataset.kind !== kind) badge.dataset.kind = kind;
    if (badge.textContent !== label) badge.textContent = label;
    const state = cell(row, "state", link.state || "–");
    state.className = "state " + (link.state === "up" ? "up" : link.state === "down" ? "down" : "");
    cell(row, "ready", link.ready === true ? "READY" : link.ready === false ? "BUSY" : "–");
    const fifo = cell(row, "fifo");
    let bar = fifo.querySelector(".bar");
    if (!bar) { bar = document.createElement("span"); bar.className = "bar"; bar.appendChild(document.createElement("div")); fifo.appendChild(bar); }
    const capacity = info.fifo_bytes || 0;
    const fill = capacity ? Math.min(1, (link.fifo_bytes || 0) / capacity) : 0;
    bar.firstChild.style.width = (100 * fill).toFixed(1) + "%";
    bar.title = (link.fifo_bytes || 0) + " of " + (capacity || "?") + " bytes";
    fifo.dataset.bytes = link.fifo_bytes || 0;
    for (const key of ["tx", "rx", "drops", "lost"]) cell(row, key, link[key] === undefined ? "–" : link[key]);
    const errors = (link.errors || []).map((e) => Number(e[0]).toFixed(1) + " s " + said(e[1]) + (e[2] ? " " + e[2] : ""));
    if (link.reason) errors.push(link.reason);
    const box = cell(row, "errors");
    const text = errors.slice(-2).join("\n");
    if (box.dataset.text !== text) {
      box.dataset.text = text;
      box.replaceChildren(...errors.slice(-2).map((line) => {
        const div = document.createElement("div");
        div.textContent = line;
        div.title = line;
        return div;
      }));
    }
  }
  prune("links", "link", new Set(links.map((l) => l.id)));
}

function updateHosts(hosts) {
  $("hosts-box").hidden = hosts.length === 0;
  for (const host of hosts) {
    const row = rowFor("hosts", host.host, "host");
    cell(row, "name", host.host);
    cell(row, "state", host.state).className = "state " + host.state;
    cell(row, "late", host.late === undefined ? "–" : host.late);
    cell(row, "worst", host.late_max_ms === undefined ? "–" : host.late_max_ms + " ms");
    cell(row, "delay", host.net_delay_mean_ms == null ? "–" : host.net_delay_mean_ms + " ms");
  }
  prune("hosts", "host", new Set(hosts.map((h) => h.host)));
}

function updateFlows(flows) {
  $("flows-box").hidden = flows.length === 0;
  const keys = new Set();
  for (const flow of flows) {
    const key = flow.src + " → " + flow.dst;
    keys.add(key);
    const row = rowFor("flows", key, "flow");
    cell(row, "name", key);
    cell(row, "sent", flow.sent);
    cell(row, "received", flow.received);
    const lost = Object.entries(flow.lost || {}).sort().map(([cause, n]) => said(cause) + " " + n).join(", ");
    const td = cell(row, "lost", lost || "0");
    td.dataset.lost = JSON.stringify(flow.lost || {});
  }
  prune("flows", "flow", keys);
}

function updateVehicles(vehicles) {
  for (const v of vehicles) {
    const row = rowFor("vehicles", v.name, "vehicle");
    cell(row, "name", v.name);
    cell(row, "source", v.source);
    cell(row, "position", v.position ? v.position.map((c) => c.toFixed(1)).join(", ") : "unknown");
    cell(row, "age", v.age_s == null ? "–" : v.age_s.toFixed(1) + " s");
  }
  prune("vehicles", "vehicle", new Set(vehicles.map((v) => v.name)));
}

// -- the player (a trace) ----------------------------------------------------------------------------

let dragging = false;

function setUpPlayer() {
  const speed = $("speed");
  for (const s of SPEEDS) {
    const option = document.createElement("option");
    option.value = s;
    option.textContent = s + "×";
    if (s === 1) option.selected = true;
    speed.appendChild(option);
  }
  speed.addEventListener("change", () => send({ class: "SPEED", speed: Number(speed.value) }));
  $("play").addEventListener("click", () => send({ class: view.state && view.state.playing ? "PAUSE" : "PLAY" }));
  const slider = $("slider");
  slider.addEventListener("input", () => { dragging = true; send({ class: "SEEK", t: Number(slider.value) }); });
  slider.addEventListener("change", () => { dragging = false; });
}

function updatePlayer(state) {
  if (state.end === undefined) return;
  $("play").textContent = state.playing ? "▮▮ pause" : "▶ play";
  const slider = $("slider");
  slider.min = state.start;
  slider.max = state.end;
  if (!dragging) slider.value = state.t;
  $("position").textContent = state.t.toFixed(1) + " / " + Number(state.end).toFixed(1) + " s";
  const speed = $("speed");
  if (Number(speed.value) !== state.speed && document.activeElement !== speed) speed.value = state.speed;
}

// -- the picture -------------------------------------------------------------------------------------

function modelNow() {
  const state = view.state;
  if (!state) return 0;
  const ahead = Math.min((performance.now() - view.received) / 1000, 0.5) * (state.rate || 0);
  const t = state.t + ahead;
  return state.end !== undefined ? Math.min(t, state.end) : t;
}

function positions() {
  const out = {};
  for (const v of (view.state && view.state.vehicles) || []) if (v.position) out[v.name] = v.position;
  return out;
}

function fitBounds(spots) {
  const points = Object.values(spots);
  if (!points.length) return;
  let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
  for (const [x, y] of points) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
  const b = view.bounds;
  if (b && x0 >= b[0] && x1 <= b[2] && y0 >= b[1] && y1 <= b[3]) return;  // still inside: the view stays put
  const span = Math.max(x1 - x0, y1 - y0, 10);
  const pad = span * 0.2;
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2, half = span / 2 + pad;
  view.bounds = [cx - half, cy - half, cx + half, cy + half];
}

function draw() {
  requestAnimationFrame(draw);
  const scene = view.scene, state = view.state;
  if (!scene || !state) return;
  const svg = $("top");
  const width = svg.clientWidth || 600, height = svg.clientHeight || 560;
  const spots = positions();
  fitBounds(spots);
  if (!view.bounds) return;
  const [bx0, by0, bx1, by1] = view.bounds;
  const scale = Math.min(width / (bx1 - bx0), height / (by1 - by0));
  const ox = width / 2 - scale * (bx0 + bx1) / 2, oy = height / 2 + scale * (by0 + by1) / 2;
  const X = (x) => ox + scale * x, Y = (y) => oy - scale * y;
  const now = modelNow();
  svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
  const layer = el("g");
  // a scale bar
  const metres = Math.pow(10, Math.floor(Math.log10((bx1 - bx0) / 4)));
  layer.appendChild(el("line", { x1: 12, y1: height - 14, x2: 12 + metres * scale, y2: height - 14, stroke: "#57606a", "stroke-width": 2 }));
  layer.appendChild(el("text", { x: 12, y: height - 20, class: "small" }, metres + " m"));
  // range rings of each link's modem
  for (const [id, link] of Object.entries(scene.links)) {
    const p = spots[link.vehicle];
    if (!p || link.range_m[1] == null) continue;
    layer.appendChild(el("circle", { cx: X(p[0]), cy: Y(p[1]), r: link.range_m[1] * scale, fill: "none",
      stroke: channelColour(link.channel), "stroke-dasharray": "4 4", "stroke-opacity": 0.45, "data-ring": id }));
  }
  // frames: the wave from the sender, a dot towards each receiver, the fate where it was judged
  const linger = state.linger_s || 2;
  for (const frame of state.frames || []) {
    const link = scene.links[frame.src];
    const from = link && spots[link.vehicle];
    const group = el("g", { "data-frame": frame.id, class: "frame" });
    let radius = -1;
    if (link && from && frame.tx != null) {
      const age = now - frame.tx;
      if (age >= 0 && age <= frame.reach_s) {
        radius = Math.max(0, age - link.min_delay_s) * link.speed_mps;
        const reach = link.range_m[1] == null ? Infinity : link.range_m[1];
        if (radius <= reach) {
          group.appendChild(el("circle", { cx: X(from[0]), cy: Y(from[1]), r: Math.max(1, radius * scale), fill: "none",
            stroke: channelColour(link.channel), "stroke-width": 2, "stroke-opacity": 0.7, class: "wave" }));
        }
      }
    }
    const judged = new Set();
    for (const [where, t, ev, cause] of frame.out || []) {
      if (t > now) continue;
      judged.add(where);
      const age = now - t;
      if (age > linger) continue;
      const target = scene.links[where];
      const at = target && spots[target.vehicle];
      if (!at) continue;
      const [key, colour] = fate(ev, cause);
      const opacity = Math.max(0.15, 1 - age / linger);
      group.appendChild(el("circle", { cx: X(at[0]), cy: Y(at[1]), r: 9, fill: "none", stroke: colour, "stroke-width": 3,
        "stroke-opacity": opacity, "data-fate": key, "data-at": where, class: "fate" }));
      if (key !== "rx") {
        group.appendChild(el("path", { d: `M${X(at[0]) - 5},${Y(at[1]) - 5}l10,10m0,-10l-10,10`, stroke: colour,
          "stroke-width": 2, "stroke-opacity": opacity }));
      }
      seen(frame, key);
    }
    if (radius >= 0 && from) {  // still on its way to the receivers not judged yet
      const targets = new Set();
      if (frame.dst && frame.dst !== "*" && scene.links[frame.dst]) targets.add(frame.dst);
      for (const [where] of frame.out || []) targets.add(where);
      for (const target of targets) {
        if (judged.has(target) || target === frame.src) continue;
        const at = spots[(scene.links[target] || {}).vehicle];
        if (!at) continue;
        const d = Math.hypot(at[0] - from[0], at[1] - from[1], (at[2] || 0) - (from[2] || 0)) || 1;
        const w = Math.min(1, radius / d);
        group.appendChild(el("circle", { cx: X(from[0] + (at[0] - from[0]) * w), cy: Y(from[1] + (at[1] - from[1]) * w),
          r: 4, fill: channelColour(link.channel), class: "flight", "data-to": target }));
      }
      seen(frame, "flight");
    }
    if (group.childNodes.length) layer.appendChild(group);
  }
  // vehicles on top
  for (const v of state.vehicles || []) {
    const p = v.position;
    if (!p) continue;
    const kinds = Object.values(scene.links).filter((l) => l.vehicle === v.name).map((l) => l.kind);
    const colour = kinds.includes("real") ? "#c1440e" : kinds.includes("emulated") ? "#6a4c93" : "#0b3954";
    layer.appendChild(el("circle", { cx: X(p[0]), cy: Y(p[1]), r: 6, fill: colour, "data-vehicle": v.name }));
    layer.appendChild(el("text", { x: X(p[0]) + 9, y: Y(p[1]) - 4 }, v.name));
    const age = v.age_s == null ? "" : " · " + v.age_s.toFixed(1) + " s";
    layer.appendChild(el("text", { x: X(p[0]) + 9, y: Y(p[1]) + 9, class: "small" }, v.source + age));
  }
  svg.replaceChildren(layer);
  drawDepth(state.vehicles || []);
  $("clock").textContent = "t = " + now.toFixed(2) + " s";
  view.drawn += 1;
}

function drawDepth(vehicles) {
  const svg = $("depth");
  const width = svg.clientWidth || 90, height = svg.clientHeight || 560;
  const depths = vehicles.filter((v) => v.position).map((v) => v.position[2]);
  const bottom = Math.max(5, ...depths) * 1.15;
  const top = Math.min(0, ...depths);
  const Y = (z) => 16 + (height - 28) * (z - top) / (bottom - top || 1);
  const layer = el("g");
  layer.appendChild(el("text", { x: 4, y: 11, class: "small" }, "depth (m)"));
  layer.appendChild(el("line", { x1: 14, y1: Y(0), x2: width, y2: Y(0), stroke: "#3d5a80", "stroke-dasharray": "3 3" }));
  layer.appendChild(el("text", { x: 2, y: height - 4, class: "small" }, bottom.toFixed(0)));
  for (const v of vehicles) {
    if (!v.position) continue;
    const y = Y(v.position[2]);
    layer.appendChild(el("circle", { cx: 20, cy: y, r: 4, fill: "#0b3954", "data-vehicle": v.name }));
    layer.appendChild(el("text", { x: 27, y: y + 4, class: "small" }, v.name));
  }
  svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
  svg.replaceChildren(layer);
}

document.addEventListener("DOMContentLoaded", () => {
  setUpPlayer();
  $("login-form").addEventListener("submit", (event) => {
    event.preventDefault();
    const token = $("token").value.trim();
    if (!token) return;
    sessionStorage.setItem("hilgate-token", token);
    $("token").value = "";
    connect();
  });
  connect();
  requestAnimationFrame(draw);
});
