// The top view and the depth strip: a chart with north up (the scene's x is north, y east: NED), a grid,
// a scale bar and a north arrow; zoom (wheel, + and −) and pan (drag) until "fit" gives the framing back
// to the vehicles. Range rings, vehicles with their trails and headings, stale poses flagged, and every
// frame: its wave from the sender, a dot to each receiver, its fate where it was judged.
//
// Two rules keep it fast and faithful. A ring that encloses the whole picture or misses it is not drawn,
// and a huge one is drawn solid: Chromium dashes a circle of 300 000 px dash by dash, about a second per
// redraw. A frame is drawn in flight at least once, whatever the speed: one whose flight is shorter
// than MIN_FLIGHT_MS of the viewer's time (an RF frame, any frame at 100×) flies in slow motion, so
// every frame is seen to fly and land; its fate then stays FATE_MS.
"use strict";

(function () {
  const view = window.hilgateView, W = window.hilgateWords;
  const SVG = "http://www.w3.org/2000/svg";
  const CHANNEL_COLOURS = ["#0b3954", "#087e8b", "#c1440e", "#6a4c93", "#3d5a80", "#bc4749"];
  const MIN_FLIGHT_MS = 600, FATE_MS = 1800, FRAMES_KEPT = 800;
  const MAX_DASHED_PX = 2500, MAX_DASHES = 2000;
  const TRAIL_S = 120, TRAIL_POINTS = 400, DETAILS_MAX = 20, STILL_HZ = 5;
  const $ = (id) => document.getElementById(id);

  const map = view.map = {
    auto: true, cam: null, dirty: true, urgent: true, stillAt: 0, width: 0, height: 0, trails: new Map(), lastT: null,
    pinned: null, hover: null, acks: false, drag: null, rings: { drawn: 0, dashed: 0, skipped: 0 },
    cost: { still: [0, 0], frames: [0, 0] },  // ms spent building each layer, and how often (the benchmark's)
  };
  view.frames = new Map();  // frame id -> {f, first, mode, shown, inState}

  function el(tag, attrs, text) {
    const node = document.createElementNS(SVG, tag);
    if (attrs) for (const key in attrs) node.setAttribute(key, attrs[key]);
    if (text !== undefined) node.textContent = text;
    return node;
  }
  map.el = el;

  function channelColour(name) {
    let h = 0;
    for (const c of String(name)) h = (h * 31 + c.charCodeAt(0)) >>> 0;
    return CHANNEL_COLOURS[h % CHANNEL_COLOURS.length];
  }
  map.channelColour = channelColour;

  function seen(frame, what) {
    let entry = view.seen.get(frame.id);
    if (!entry) {
      entry = { src: frame.src, dst: frame.dst, tx: frame.tx, states: [] };  // tx null: sent before the page looked
      view.seen.set(frame.id, entry);
      if (view.seen.size > 5000) view.seen.delete(view.seen.keys().next().value);
    }
    if (!entry.states.includes(what)) entry.states.push(what);
  }

  // -- text widths (for labels that must not print over each other) -------------------------------------
  const measure = document.createElement("canvas").getContext("2d");
  const widths = new Map();
  function textWidth(text, px) {
    const key = px + "|" + text;
    let w = widths.get(key);
    if (w === undefined) {
      measure.font = px + "px system-ui, sans-serif";
      w = Math.ceil(measure.measureText(text).width * 1.08) + 2;
      if (widths.size > 2000) widths.clear();
      widths.set(key, w);
    }
    return w;
  }
  map.textWidth = textWidth;

  // -- the camera ------------------------------------------------------------------------------------------
  function positions() {
    const out = {};
    for (const v of (view.state && view.state.vehicles) || []) if (v.position) out[v.name] = v.position;
    return out;
  }
  map.positions = positions;

  function fit(spots) {
    const points = Object.values(spots);
    if (!points.length || !map.width) return;
    let [n0, e0, n1, e1] = [Infinity, Infinity, -Infinity, -Infinity];
    for (const [n, e] of points) { n0 = Math.min(n0, n); n1 = Math.max(n1, n); e0 = Math.min(e0, e); e1 = Math.max(e1, e); }
    const b = map.bounds;
    if (b && n0 >= b[0] && n1 <= b[2] && e0 >= b[1] && e1 <= b[3] && map.cam) return;  // still inside: the view stays
    const span = Math.max(n1 - n0, e1 - e0, 10), pad = span * 0.2;
    map.bounds = [(n0 + n1) / 2 - span / 2 - pad, (e0 + e1) / 2 - span / 2 - pad, (n0 + n1) / 2 + span / 2 + pad, (e0 + e1) / 2 + span / 2 + pad];
    const [bn0, be0, bn1, be1] = map.bounds;
    map.cam = { n: (bn0 + bn1) / 2, e: (be0 + be1) / 2, s: Math.min(map.width / (be1 - be0), map.height / (bn1 - bn0)) };
    map.dirty = true;
  }

  function project(p) { const c = map.cam; return [map.width / 2 + (p[1] - c.e) * c.s, map.height / 2 - (p[0] - c.n) * c.s]; }
  function unproject(x, y) { const c = map.cam; return [c.n - (y - map.height / 2) / c.s, c.e + (x - map.width / 2) / c.s]; }
  map.project = project;

  map.zoom = function (factor, x, y) {
    if (!map.cam) return;
    if (x === undefined) { x = map.width / 2; y = map.height / 2; }
    const before = unproject(x, y);
    map.cam.s = Math.min(1e6, Math.max(1e-5, map.cam.s * factor));
    const after = unproject(x, y);
    map.cam.n += before[0] - after[0];
    map.cam.e += before[1] - after[1];
    map.auto = false;
    map.dirty = map.urgent = true;
    $("fit").disabled = false;
  };

  map.fit = function () { map.auto = true; map.bounds = null; map.cam = null; map.dirty = map.urgent = true; $("fit").disabled = true; };

  function niceStep(target) {
    const p = Math.pow(10, Math.floor(Math.log10(target)));
    for (const m of [1, 2, 5, 10]) if (m * p >= target) return m * p;
    return 10 * p;
  }
  function metres(v) {
    const a = Math.abs(v);
    if (a >= 1000) return +(v / 1000).toPrecision(4) + " km";
    return +v.toPrecision(4) + " m";
  }

  // -- the still part: grid, rings, trails, vehicles (redrawn when a picture comes or the camera moves) ----
  function drawGrid(layer) {
    const c = map.cam, step = niceStep(90 / c.s);
    const [nTop, eLeft] = unproject(0, 0), [nBottom, eRight] = unproject(map.width, map.height);
    let count = 0;
    for (let e = Math.ceil(eLeft / step) * step; e <= eRight && count < 80; e += step, count++) {
      const x = project([0, e])[0];
      layer.appendChild(el("line", { x1: x, y1: 0, x2: x, y2: map.height, class: "grid" }));
      layer.appendChild(el("text", { x: x + 2, y: map.height - 3, class: "grid-label" }, metres(e)));
    }
    for (let n = Math.ceil(nBottom / step) * step; n <= nTop && count < 160; n += step, count++) {
      const y = project([n, 0])[1];
      layer.appendChild(el("line", { x1: 0, y1: y, x2: map.width, y2: y, class: "grid" }));
      layer.appendChild(el("text", { x: 2, y: y - 2, class: "grid-label" }, metres(n)));
    }
  }

  function drawOverlay(layer) {
    const c = map.cam, length = niceStep(100 / c.s), px = length * c.s;
    const x0 = 14, y0 = map.height - 22;
    const bar = el("g", { id: "scale-bar", "data-metres": length, "data-px": px.toFixed(2) });
    bar.appendChild(el("rect", { x: x0 - 6, y: y0 - 16, width: px + 12, height: 24, class: "plate" }));
    bar.appendChild(el("path", { d: `M${x0},${y0 - 4}v4h${px}v-4`, class: "scale" }));
    bar.appendChild(el("text", { x: x0, y: y0 - 6, class: "scale-label" }, metres(length)));
    layer.appendChild(bar);
    const nx = map.width - 24, ny = 16;
    const north = el("g", { id: "north" });
    north.appendChild(el("path", { d: `M${nx},${ny}l7,20l-7,-5l-7,5z`, class: "north" }));
    north.appendChild(el("text", { x: nx - 4, y: ny + 33, class: "north-label" }, "N"));
    layer.appendChild(north);
  }

  function drawRings(layer, spots) {
    const scene = view.scene, stats = { drawn: 0, dashed: 0, skipped: 0 };
    const done = new Set(), rings = [];
    for (const [id, link] of Object.entries(scene.links)) {
      const p = spots[link.vehicle];
      if (!p || link.range_m[1] == null) continue;
      const [cx, cy] = project(p), r = link.range_m[1] * map.cam.s;
      const key = link.vehicle + "|" + link.range_m[1] + "|" + link.channel;  // two modems alike: one ring
      const far = Math.max(Math.hypot(cx, cy), Math.hypot(cx - map.width, cy), Math.hypot(cx, cy - map.height), Math.hypot(cx - map.width, cy - map.height));
      const nx = Math.max(0, Math.min(cx, map.width)), ny = Math.max(0, Math.min(cy, map.height));
      const near = Math.hypot(cx - nx, cy - ny);
      if (r >= far || r < near || done.has(key)) { stats.skipped++; continue; }  // encloses the picture, or misses it
      done.add(key);
      rings.push([id, link, cx, cy, r]);
    }
    // dashes are drawn one by one: only while they are few (a fleet's hundred rings are drawn solid)
    const dashes = rings.reduce((sum, [, , , , r]) => sum + (r <= MAX_DASHED_PX ? 2 * Math.PI * r / 8 : 0), 0);
    for (const [id, link, cx, cy, r] of rings) {
      const attrs = { cx, cy, r, class: "ring", stroke: channelColour(link.channel), "data-ring": id };
      if (r <= MAX_DASHED_PX && dashes <= MAX_DASHES) { attrs["stroke-dasharray"] = "4 4"; stats.dashed++; }
      layer.appendChild(el("circle", attrs));
      stats.drawn++;
    }
    map.rings = stats;
  }

  function noteTrails(state) {
    if (map.lastT !== null && state.t < map.lastT - 1e-9) map.trails.clear();  // a seek backwards
    map.lastT = state.t;
    for (const v of state.vehicles || []) {
      if (!v.position) continue;
      let trail = map.trails.get(v.name);
      if (!trail) map.trails.set(v.name, trail = []);
      const last = trail[trail.length - 1];
      if (!last || Math.hypot(v.position[0] - last[0], v.position[1] - last[1]) > 0.02) trail.push([v.position[0], v.position[1], state.t]);
      while (trail.length > TRAIL_POINTS || (trail.length > 2 && state.t - trail[0][2] > TRAIL_S)) trail.shift();
    }
  }
  map.onState = function (state) { noteTrails(state); map.dirty = true; };

  function heading(v) {
    if (v.heading != null) return v.heading;
    const trail = map.trails.get(v.name);
    if (!trail || trail.length < 2) return null;
    const a = trail[trail.length - 2], b = trail[trail.length - 1];
    if (Math.hypot(b[0] - a[0], b[1] - a[1]) < 1e-3) return null;
    return Math.atan2(b[1] - a[1], b[0] - a[0]);  // from north through east
  }

  function drawTrails(layer) {
    for (const [name, trail] of map.trails) {
      if (trail.length < 2) continue;
      layer.appendChild(el("polyline", { points: trail.map((p) => project(p).map((c) => c.toFixed(1)).join(",")).join(" "),
        class: "trail", "data-trail": name }));
    }
  }

  // greedy placement: the first spot around the marker where the label's box meets no other box
  function place(boxes, x, y, w, h) {
    const candidates = [[10, -h + 4], [10, 2], [-w - 10, -h + 4], [-w - 10, 2], [-w / 2, -h - 10], [-w / 2, 10]];
    for (let k = 1; k <= 12; k++) candidates.push([10, 2 + k * (h + 2)], [10, -h + 4 - k * (h + 2)], [-w - 10, 2 + k * (h + 2)]);
    for (const [dx, dy] of candidates) {
      const box = [x + dx, y + dy, x + dx + w, y + dy + h];
      if (!boxes.some((b) => box[0] < b[2] && box[2] > b[0] && box[1] < b[3] && box[3] > b[1])) { boxes.push(box); return [dx, dy]; }
    }
    const [dx, dy] = candidates[0];
    boxes.push([x + dx, y + dy, x + dx + w, y + dy + h]);
    return [dx, dy];
  }
  map.place = place;

  // Labels are kept from one picture to the next and only moved or reworded: laying out SVG text is the
  // costliest part of a redraw (a fleet's hundred labels made anew ten times a second halved the redraws).
  const labelNodes = new Map();  // vehicle -> {g, line, name, detail}
  function put(node, key, value) {
    const text = String(value);
    if (node.getAttribute(key) !== text) node.setAttribute(key, text);
  }
  function say(node, text) { if (node.textContent !== text) node.textContent = text; }

  function drawVehicles(layer, labels) {
    const scene = view.scene, boxes = [];
    const vehicles = (view.state.vehicles || []).filter((v) => v.position);
    const details = vehicles.length <= DETAILS_MAX;  // (a fleet: the source and age of the chosen, hovered and stale only)
    for (const v of vehicles) { const [x, y] = project(v.position); boxes.push([x - 7, y - 7, x + 7, y + 7]); }
    const kept = new Set();
    for (const v of vehicles) {
      const [x, y] = project(v.position);
      const kinds = Object.values(scene.links).filter((l) => l.vehicle === v.name).map((l) => l.kind);
      const colour = kinds.includes("real") ? "#c1440e" : kinds.includes("emulated") ? "#6a4c93" : "#0b3954";
      const g = el("g", { "data-vehicle": v.name, class: "vehicle" + (v.stale ? " stale" : "") + (map.pinned === v.name ? " pinned" : "") });
      if (v.stale) { g.dataset.stale = v.stale; g.appendChild(el("circle", { cx: x, cy: y, r: 11, class: "stale-halo" })); }
      const yaw = heading(v);
      if (yaw != null) {
        const dx = Math.sin(yaw), dy = -Math.cos(yaw);
        g.appendChild(el("path", { d: `M${x + dx * 12},${y + dy * 12}L${x - dy * 5},${y + dx * 5}L${x + dy * 5},${y - dx * 5}z`, fill: colour, class: "heading" }));
        g.dataset.heading = yaw.toFixed(3);
      }
      g.appendChild(el("circle", { cx: x, cy: y, r: 6, fill: colour }));
      layer.appendChild(g);
      const name = v.name + (v.stale ? (v.stale === "never" ? " · NO POSE" : " · STALE") : "");
      const showDetail = details || v.stale || map.pinned === v.name || map.hover === v.name;
      const detail = showDetail ? v.source + (v.age_s == null ? "" : " · " + v.age_s.toFixed(1) + " s") : "";
      const w = Math.max(textWidth(name, 11), detail ? textWidth(detail, 9) : 0), h = detail ? 24 : 13;
      const [dx, dy] = place(boxes, x, y, w, h);
      let node = labelNodes.get(v.name);
      if (!node) {
        node = { g: el("g", { class: "label", "data-label": v.name }), line: el("line", { class: "leader" }), name: el("text", {}), detail: el("text", { class: "small" }) };
        node.g.append(node.line, node.name, node.detail);
        labels.appendChild(node.g);
        labelNodes.set(v.name, node);
      }
      kept.add(v.name);
      const leader = Math.abs(dx) > 12 || dy > 6 || dy < -h;
      put(node.line, "visibility", leader ? "visible" : "hidden");
      if (leader) { put(node.line, "x1", x.toFixed(1)); put(node.line, "y1", y.toFixed(1)); put(node.line, "x2", (x + dx + (dx < 0 ? w : 0)).toFixed(1)); put(node.line, "y2", (y + dy + h / 2).toFixed(1)); }
      put(node.name, "x", (x + dx).toFixed(1));
      put(node.name, "y", (y + dy + 10).toFixed(1));
      put(node.name, "class", v.stale ? "stale-name" : "");
      say(node.name, name);
      put(node.detail, "x", (x + dx).toFixed(1));
      put(node.detail, "y", (y + dy + 21).toFixed(1));
      say(node.detail, detail);
    }
    for (const [name, node] of labelNodes) if (!kept.has(name)) { node.g.remove(); labelNodes.delete(name); }
  }

  function drawPair(layer) {
    const a = map.pinned, b = map.hover;
    const spots = positions();
    if (!a || !b || a === b || !spots[a] || !spots[b]) { $("pair").hidden = true; return; }
    const [x0, y0] = project(spots[a]), [x1, y1] = project(spots[b]);
    layer.appendChild(el("line", { x1: x0, y1: y0, x2: x1, y2: y1, class: "pair" }));
    window.hilgatePair.show(a, b, spots, (x0 + x1) / 2, (y0 + y1) / 2);
  }

  function drawStill() {
    const spots = positions();
    const svg = $("top");
    const still = $("still");
    const grid = el("g"), rings = el("g"), trails = el("g"), vehicles = el("g"), overlay = el("g");
    if (!map.layers) {  // the vehicles, their labels (kept: drawVehicles) and the overlay, in this order for good
      map.layers = { vehicles: el("g"), labels: el("g"), overlay: el("g") };
      $("above").replaceChildren(map.layers.vehicles, map.layers.labels, map.layers.overlay);
    }
    drawGrid(grid);
    drawRings(rings, spots);
    drawTrails(trails);
    drawVehicles(vehicles, map.layers.labels);
    drawPair(overlay);
    drawOverlay(overlay);
    still.replaceChildren(grid, rings, trails);
    map.layers.vehicles.replaceChildren(...vehicles.childNodes);
    map.layers.overlay.replaceChildren(...overlay.childNodes);
    svg.setAttribute("viewBox", `0 0 ${map.width} ${map.height}`);
    drawDepth(view.state.vehicles || []);
    map.dirty = false;
  }

  // -- frames --------------------------------------------------------------------------------------------
  // ``before``: the model time of the picture before this one. A frame sent since then is new, and flies
  // even when this picture is a paused one (the last of a trace played at 100×); one sent before it is
  // part of a still picture while the player is paused.
  map.onFrames = function (state, before) {
    const ids = new Set(), now = performance.now();
    for (const f of state.frames || []) {
      ids.add(f.id);
      const e = view.frames.get(f.id);
      if (e) e.f = f;
      else view.frames.set(f.id, { f, first: null, mode: null, shown: new Map(), inState: true, born: now,
        fresh: f.tx != null && before != null && f.tx > before });
    }
    for (const [id, e] of view.frames) e.inState = ids.has(id);
    while (view.frames.size > FRAMES_KEPT) view.frames.delete(view.frames.keys().next().value);
  };
  map.clearFrames = function () { view.frames.clear(); };

  function dist(a, b) { return Math.hypot(a[0] - b[0], a[1] - b[1], (a[2] || 0) - (b[2] || 0)); }

  function drawFrames(layer, spots, now, wall, rate) {
    const scene = view.scene;
    for (const [id, e] of view.frames) {
      const f = e.f;
      if (f.kind && !map.acks) { if (!e.inState) view.frames.delete(id); continue; }
      const link = scene.links[f.src];
      const from = link && spots[link.vehicle];
      const targets = new Map();  // link -> distance from the sender
      if (f.dst && f.dst !== "*" && scene.links[f.dst]) targets.set(f.dst, null);
      for (const [where] of f.out || []) targets.set(where, null);
      let farthest = 0;
      for (const target of targets.keys()) {
        const at = spots[(scene.links[target] || {}).vehicle];
        const d = at && from ? dist(from, at) : 0;
        targets.set(target, d);
        farthest = Math.max(farthest, d);
      }
      const reach = link && link.range_m[1] != null ? link.range_m[1] : Infinity;
      if (e.first === null) {
        e.first = wall;
        const spread = farthest || Math.min(reach, 50);
        const flight = link ? (link.min_delay_s || 0) + spread / link.speed_mps : 0;
        const age = f.tx == null ? Infinity : now - f.tx;
        e.mode = rate > 0 && flight / rate * 1000 >= MIN_FLIGHT_MS && age < flight / 2 ? "real"
          : rate > 0 || view.state.playing !== false || e.fresh ? "slow" : "still";
        e.spread = spread;
      }
      const group = el("g", { "data-frame": f.id, class: "frame" + (f.kind ? " control" : "") + (view.inspect.what && view.inspect.what.id === f.id ? " chosen" : "") });
      let radius = -1, flying = false, p = 1;
      if (f.tx != null && from && link) {
        if (e.mode === "slow") {
          p = Math.min(1, (wall - e.first) / MIN_FLIGHT_MS);
          radius = p * e.spread;
          flying = p < 1;
        } else {
          const age = now - f.tx;
          radius = Math.max(0, age - (link.min_delay_s || 0)) * link.speed_mps;
          flying = age >= 0 && age <= f.reach_s && radius <= reach;
        }
        if (flying) {
          seen(f, "flight");
          group.appendChild(el("circle", { cx: project(from)[0], cy: project(from)[1], r: Math.max(1, radius * map.cam.s),
            class: "wave", stroke: channelColour(link.channel) }));
        }
      }
      let live = flying;
      const marks = new Map();  // (fate, fading step) -> one path of rings (and crosses) and where: few elements a frame
      for (const [where, t, ev, cause] of f.out || []) {
        const key = where + "|" + t;
        const d = targets.get(where) || 0;
        const due = f.tx == null || !from ? true : e.mode === "slow" ? p >= 1 || radius >= d - 1e-9 : now >= t;
        if (!due) { live = true; continue; }
        if (!e.shown.has(key)) e.shown.set(key, wall);
        const age = e.mode === "still" ? (now - t) / Math.max(view.state.linger_s || 2, 1e-9) * FATE_MS : wall - e.shown.get(key);
        if (age > FATE_MS) continue;
        live = true;
        const at = spots[(scene.links[where] || {}).vehicle];
        if (!at) continue;
        const code = ev === "rx" ? "rx" : (cause || "?");
        const [x, y] = project(at), opacity = Math.max(0.2, Math.round(10 * (1 - age / FATE_MS)) / 10);
        const mark = code + "|" + opacity;
        let m = marks.get(mark);
        if (!m) marks.set(mark, m = { code, opacity, d: "", at: [] });
        m.d += `M${(x + 9).toFixed(1)},${y.toFixed(1)}a9,9 0 1,0 -18,0a9,9 0 1,0 18,0`;
        if (code !== "rx") m.d += `M${(x - 5).toFixed(1)},${(y - 5).toFixed(1)}l10,10m0,-10l-10,10`;
        m.at.push(where);
        seen(f, code);
      }
      for (const m of marks.values()) {
        group.appendChild(el("path", { d: m.d, stroke: W.colour(m.code), "stroke-opacity": m.opacity, class: "fate", "data-fate": m.code, "data-at": m.at.join(" ") }));
      }
      if (flying && from) {  // one path of dots, one towards each receiver not judged yet
        const judged = new Set([...e.shown.keys()].map((k) => k.slice(0, k.lastIndexOf("|"))));
        let d = "";
        const to = [];
        for (const [target, distance] of targets) {
          if (target === f.src || judged.has(target)) continue;
          const at = spots[(scene.links[target] || {}).vehicle];
          if (!at) continue;
          const w = Math.min(1, radius / (distance || 1));
          const [x, y] = project([from[0] + (at[0] - from[0]) * w, from[1] + (at[1] - from[1]) * w]);
          d += `M${(x + 4).toFixed(1)},${y.toFixed(1)}a4,4 0 1,0 -8,0a4,4 0 1,0 8,0z`;
          to.push(target);
        }
        if (d) group.appendChild(el("path", { d, fill: channelColour(link.channel), class: "flight", "data-to": to.join(" ") }));
      }
      if (group.childNodes.length) layer.appendChild(group);
      if (!live && !e.inState && e.first !== null) view.frames.delete(id);
    }
  }

  // -- the depth strip: one label per vehicle, pushed down where they would overlap ------------------------
  function drawDepth(vehicles) {
    const svg = $("depth");
    const [width, height] = map.sizes.depth;
    const placed = vehicles.filter((v) => v.position).map((v) => ({ v, z: v.position[2] }));
    const depths = placed.map((p) => p.z);
    const bottom = Math.max(5, ...depths) * 1.15, top = Math.min(0, ...depths);
    const Y = (z) => 18 + (height - 30) * (z - top) / (bottom - top || 1);
    const key = width + "|" + height + "|" + placed.map((p) => p.v.name + ":" + Math.round(Y(p.z)) + (p.v.stale ? "!" : "")).join(",");
    if (key === map.depthKey) return;  // nothing moved by a pixel: its labels stay as they are
    map.depthKey = key;
    const layer = el("g");
    layer.appendChild(el("text", { x: 3, y: 11, class: "small" }, "depth (m)"));
    layer.appendChild(el("line", { x1: 12, y1: Y(0), x2: width, y2: Y(0), class: "surface" }));
    layer.appendChild(el("text", { x: 2, y: height - 4, class: "small" }, bottom.toFixed(0)));
    placed.sort((a, b) => a.z - b.z || (a.v.name < b.v.name ? -1 : 1));
    let next = -Infinity;
    for (const { v, z } of placed) {
      const y = Y(z), ly = Math.max(y + 4, next);
      next = ly + 12;
      layer.appendChild(el("circle", { cx: 17, cy: y, r: 4, class: v.stale ? "depth-dot stale" : "depth-dot", "data-vehicle": v.name }));
      if (Math.abs(ly - (y + 4)) > 1) layer.appendChild(el("line", { x1: 21, y1: y, x2: 26, y2: ly - 4, class: "leader" }));
      layer.appendChild(el("text", { x: 27, y: ly, class: "small depth-label", "data-label": v.name }, v.name));
    }
    svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
    svg.replaceChildren(layer);
  }

  // -- every animation frame ---------------------------------------------------------------------------------
  map.draw = function (now) {
    const scene = view.scene, state = view.state;
    if (!scene || !state) return;
    const [width, height] = map.sizes.top;  // (read by a ResizeObserver: reading them here forced a layout per redraw)
    if (width !== map.width || height !== map.height) { map.width = width; map.height = height; map.dirty = map.urgent = true; if (map.auto) map.cam = null; }
    const spots = positions();
    if (map.auto) fit(spots);
    if (!map.cam) return;
    const t0 = performance.now();
    // a fleet's chart follows its pictures at most STILL_HZ times a second (its frames, every redraw);
    // what the operator does (zoom, pan, hover, a click) is drawn at once
    const many = (state.vehicles || []).length > DETAILS_MAX;
    if (map.dirty && (map.urgent || !many || t0 - map.stillAt >= 1000 / STILL_HZ)) {
      drawStill();
      map.urgent = false;
      map.stillAt = t0;
      map.cost.still[0] += performance.now() - t0;
      map.cost.still[1]++;
    }
    const t1 = performance.now();
    const layer = el("g");
    drawFrames(layer, spots, now, t1, state.rate || 0);
    $("frames").replaceChildren(layer);
    if (map.flightBox !== map.width + " " + map.height) {
      map.flightBox = map.width + " " + map.height;
      $("flight").setAttribute("viewBox", `0 0 ${map.width} ${map.height}`);
    }
    map.cost.frames[0] += performance.now() - t1;
    map.cost.frames[1]++;
  };

  // -- the pointer: drag to pan, wheel to zoom, click to inspect, hover a second vehicle for the pair -------
  function hit(target) {
    const frame = target.closest && target.closest("[data-frame]");
    if (frame) return { frame: frame.dataset.frame };
    const vehicle = target.closest && target.closest("[data-vehicle]");
    if (vehicle) return { vehicle: vehicle.dataset.vehicle };
    const ring = target.closest && target.closest("[data-ring]");
    if (ring) return { link: ring.dataset.ring };
    return {};
  }

  map.sizes = { top: [600, 400], depth: [78, 400] };
  function watchSize(id, key) {
    const node = $(id);
    const take = () => { map.sizes[key] = [node.clientWidth || map.sizes[key][0], node.clientHeight || map.sizes[key][1]]; map.dirty = true; };
    take();
    if (window.ResizeObserver) new ResizeObserver(take).observe(node);
    else window.addEventListener("resize", take);
  }

  map.setUp = function () {
    watchSize("top", "top");
    watchSize("depth", "depth");
    const svg = $("map-box");  // the chart and the frames' layer above it
    const panel = (event) => event.target.closest && event.target.closest("#tools, #inspect, #pair");
    svg.addEventListener("wheel", (event) => {
      if (panel(event)) return;  // (the inspector scrolls)
      event.preventDefault();
      const box = svg.getBoundingClientRect();
      map.zoom(Math.pow(1.0015, -event.deltaY), event.clientX - box.left, event.clientY - box.top);
    }, { passive: false });
    svg.addEventListener("pointerdown", (event) => {
      if (panel(event)) return;
      map.drag = { x: event.clientX, y: event.clientY, moved: false, hit: hit(event.target), cam: map.cam && Object.assign({}, map.cam) };
      svg.setPointerCapture && svg.setPointerCapture(event.pointerId);
    });
    svg.addEventListener("pointermove", (event) => {
      const drag = map.drag;
      if (drag && drag.cam) {
        const dx = event.clientX - drag.x, dy = event.clientY - drag.y;
        if (Math.abs(dx) + Math.abs(dy) > 4) drag.moved = true;
        if (drag.moved) {
          map.cam.e = drag.cam.e - dx / map.cam.s;
          map.cam.n = drag.cam.n + dy / map.cam.s;
          map.auto = false;
          $("fit").disabled = false;
          map.dirty = map.urgent = true;
        }
        return;
      }
      const over = hit(event.target).vehicle || null;
      if (over !== map.hover) { map.hover = over; map.dirty = map.urgent = true; }
    });
    svg.addEventListener("pointerup", (event) => {
      const drag = map.drag;
      map.drag = null;
      if (!drag || drag.moved) return;
      map.choose(drag.hit);  // what was under the pointer when it went down (the frames' layer is redrawn meanwhile)
    });
    svg.addEventListener("pointerleave", () => { if (map.hover) { map.hover = null; map.dirty = map.urgent = true; } });
    svg.addEventListener("dblclick", () => map.fit());
    $("zoom-in").addEventListener("click", () => map.zoom(1.5));
    $("zoom-out").addEventListener("click", () => map.zoom(1 / 1.5));
    $("fit").addEventListener("click", () => map.fit());
    $("acks").addEventListener("change", () => { map.acks = $("acks").checked; });
  };

  map.choose = function (what) {
    if (what.frame) {
      const e = view.frames.get(what.frame);
      if (e) view.inspect.frame(e.f);
    } else if (what.link) {
      view.inspect.link(what.link);
    } else if (what.vehicle) {  // chosen: hover another for the pair (its links are inspected by their rows)
      map.pinned = map.pinned === what.vehicle ? null : what.vehicle;
    } else {
      map.pinned = null;
    }
    map.dirty = map.urgent = true;
  };
})();
