// The operator's view: the connection, the messages and the tables. The map (map.js), the event log
// (log.js), the inspector (inspect.js), the rates (rates.js), the pair of modems (pair.js) and the
// player (player.js) hang on window.hilgateView. No framework and no build step; every name from the
// scene goes into the page as text, never as HTML.
"use strict";

const view = window.hilgateView = {
  scene: null, state: null, received: 0, connected: false, authed: false, mode: null, error: null,
  seen: new Map(),     // frame id -> {src, dst, states}: what it was drawn as, in order ("flight", then fates)
  drawn: 0, ws: null,
  cost: { state: [0, 0] },  // ms spent taking pictures in, and how many (the benchmark's)
};

(function () {
  const W = window.hilgateWords;
  const $ = (id) => document.getElementById(id);

  function cell(row, name, text) {
    const cells = row.hgCells || (row.hgCells = {});  // (a lookup per cell, not a query: 100 links × 11 cells)
    let td = cells[name];
    if (!td) { td = cells[name] = document.createElement("td"); td.className = name; row.appendChild(td); }
    if (text !== undefined && td.textContent !== String(text)) td.textContent = text;
    return td;
  }

  function title(node, text) { if (node.title !== text) node.title = text; return node; }

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
        document.body.dataset.mode = msg.mode;
        $("player").hidden = msg.mode !== "replay";
      } else if (msg.class === "SCENE") {
        onScene(msg);
      } else if (msg.class === "EVENTS") {
        view.player.setEvents(msg);
        view.log.setReplay(msg.events || []);
      } else if (msg.class === "STATE") {
        const t0 = performance.now();
        onState(msg);
        view.cost.state[0] += performance.now() - t0;
        view.cost.state[1] += 1;
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

  view.send = function (obj) {
    if (view.ws && view.ws.readyState === WebSocket.OPEN) view.ws.send(JSON.stringify(obj));
  };

  view.seekTo = function (t) {
    view.map.clearFrames();
    view.send({ class: "SEEK", t });
  };

  // -- messages --------------------------------------------------------------------------------------

  function onScene(scene) {
    const before = view.scene;
    view.scene = scene;
    view.map.dirty = true;
    tablesAt = 0;  // a reload's badges in the next picture's tables
    $("scene-name").textContent = "scene " + scene.name;
    W.load(scene.fates);  // the report's words and colours (one vocabulary: hilgate/report/causes.py)
    const legend = $("legend");
    legend.textContent = "";
    for (const key of W.LEGEND) {
      if (!(key in W.FATES)) continue;
      const [label, colour] = W.FATES[key];
      const item = document.createElement("span");
      item.textContent = label;
      item.dataset.fate = key;
      item.style.setProperty("--c", colour);
      legend.appendChild(item);
    }
    const channels = new Set(Object.values(scene.links).map((l) => l.channel));
    for (const channel of channels) {
      const item = document.createElement("span");
      item.textContent = "channel " + channel;
      item.title = "its frames' waves and its modems' range rings";
      item.style.setProperty("--c", view.map.channelColour(channel));
      legend.appendChild(item);
    }
    if (view.mode === "live") view.log.onScene(scene, before);
  }

  const TABLES_HZ = 4;
  let tablesAt = 0, lastAlarms = "";

  function onState(state) {
    const before = view.state;
    if (before && state.t < before.t - 1e-9) view.map.clearFrames();  // a seek backwards
    view.state = state;
    view.received = performance.now();
    view.map.onFrames(state, before && state.t >= before.t ? before.t : null);
    view.map.onState(state);
    const sampled = view.rates.onState(state);
    const wall = performance.now();
    // the tables at most TABLES_HZ times a second (nobody reads faster; a fleet's hundred rows cost the chart
    // its redraws), and always when the rates were sampled or the player moved by hand
    const alarms = (state.vehicles || []).map((v) => v.stale || "").join() + "|" + (state.links || []).map((l) => l.state).join()
      + "|" + (state.hosts || []).map((h) => h.state).join();  // a stale pose, a link or host down: at once
    if (sampled || !tablesAt || wall - tablesAt >= 1000 / TABLES_HZ || state.rate === 0 || alarms !== lastAlarms) {
      lastAlarms = alarms;
      tablesAt = wall;
      if (state.links) updateLinks(state.links, sampled);
      updateHosts(state.hosts || []);
      updateFlows(state.flows || []);
      updateVehicles(state.vehicles || []);
    }
    view.log.onState(state);
    view.player.onState(state);
    if (view.inspect.what && (view.inspect.what.type === "link" || sampled)) view.inspect.refresh();
  }

  const rows = {};  // table -> Map key -> row
  function rowFor(table, key, attribute) {
    const known = rows[table] || (rows[table] = new Map());
    let row = known.get(key);
    if (row) return row;
    row = document.createElement("tr");
    row.dataset[attribute] = key;
    $(table).tBodies[0].appendChild(row);
    known.set(key, row);
    return row;
  }

  function prune(table, attribute, keys) {
    const known = rows[table] || new Map();
    for (const [key, row] of known) if (!keys.has(key)) { row.remove(); known.delete(key); }
  }

  function count(row, name, n) {  // a count; a loss only in red when there is one
    const td = cell(row, name, n === undefined ? "–" : n);
    if (td.classList.contains("zero") === !!n) td.classList.toggle("zero", !n);
    return td;
  }

  function updateLinks(links, sampled) {
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
      cell(row, "tx", link.tx === undefined ? "–" : link.tx);
      cell(row, "rx", link.rx === undefined ? "–" : link.rx);
      const causes = W.causes(link.causes) || "";
      title(count(row, "drops", link.drops), causes);
      title(count(row, "lost", link.lost), causes);
      const chart = cell(row, "rate");
      if (sampled) {
        let svg = chart.querySelector("svg");
        if (!svg) { svg = document.createElementNS("http://www.w3.org/2000/svg", "svg"); chart.appendChild(svg); }
        view.rates.draw(svg, link.id, 64, 16);
        const last = view.rates.summary(link.id, 60);
        title(chart, last ? "last " + Math.round(last.span) + " s: " + last.rx.toFixed(2) + " received/s, " + last.lost.toFixed(2) + " lost/s" : "");
      }
      const errors = (link.errors || []).map((e) => Number(e[0]).toFixed(1) + " s " + W.word(e[1]) + (e[2] ? " " + e[2] : ""));
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
      const td = cell(row, "lost", W.causes(flow.lost) || "none");
      td.classList.toggle("zero", !Object.values(flow.lost || {}).some((n) => n > 0));
      td.dataset.lost = JSON.stringify(flow.lost || {});
    }
    prune("flows", "flow", keys);
  }

  function updateVehicles(vehicles) {
    for (const v of vehicles) {
      const row = rowFor("vehicles", v.name, "vehicle");
      row.classList.toggle("stale", !!v.stale);
      row.dataset.stale = v.stale || "";
      cell(row, "name", v.name);
      cell(row, "source", v.source);
      cell(row, "position", v.position ? v.position.map((c) => c.toFixed(1)).join(", ") : "unknown");
      cell(row, "age", v.age_s == null ? "–" : v.age_s.toFixed(1) + " s");
      cell(row, "pose", v.stale === "stale" ? "STALE" : v.stale === "never" ? "NO POSE" : "fresh");
    }
    prune("vehicles", "vehicle", new Set(vehicles.map((v) => v.name)));
  }

  // -- every animation frame ---------------------------------------------------------------------------

  function modelNow() {
    const state = view.state;
    if (!state) return 0;
    const ahead = Math.min((performance.now() - view.received) / 1000, 0.5) * (state.rate || 0);
    const t = state.t + ahead;
    return state.end !== undefined ? Math.min(t, state.end) : t;
  }
  view.modelNow = modelNow;

  function draw() {
    requestAnimationFrame(draw);
    if (!view.scene || !view.state) return;
    const now = modelNow();
    view.map.draw(now);
    $("clock").textContent = "t = " + now.toFixed(2) + " s";
    view.drawn += 1;
  }

  document.addEventListener("DOMContentLoaded", () => {
    view.player.setUp();
    view.map.setUp();
    $("inspect-close").addEventListener("click", () => view.inspect.close());
    $("links").addEventListener("click", (event) => {
      const row = event.target.closest("tr[data-link]");
      if (row) view.inspect.link(row.dataset.link);
    });
    $("alarms").addEventListener("click", () => $("log-box").scrollIntoView({ block: "nearest" }));
    document.addEventListener("keydown", (event) => { if (event.key === "Escape") view.inspect.close(); });
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
})();
