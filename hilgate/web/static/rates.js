// Per-link throughput and loss over the last minutes: the links' counters sampled once a model second
// (the page keeps them; the daemon keeps nothing more for it), drawn as a small chart in each link's row
// and a larger one in the inspector. Frames per second: received (green) and lost or dropped (red).
"use strict";

(function () {
  const view = window.hilgateView;
  const SVG = "http://www.w3.org/2000/svg";
  const KEPT_S = 300, EVERY_S = 1;

  const rates = view.rates = { samples: new Map(), lastT: null };

  rates.onState = function (state) {
    const t = state.t;
    if (rates.lastT !== null && t < rates.lastT - 1e-9) rates.samples.clear();  // a seek backwards
    if (rates.lastT !== null && t - rates.lastT < EVERY_S && rates.samples.size) return false;
    rates.lastT = t;
    for (const link of state.links || []) {
      if (link.tx === undefined) continue;
      let list = rates.samples.get(link.id);
      if (!list) rates.samples.set(link.id, list = []);
      list.push([t, link.tx, link.rx, (link.lost || 0) + (link.drops || 0)]);
      while (list.length > 2 && t - list[0][0] > KEPT_S) list.shift();
    }
    return true;
  };

  // [[t, tx/s, rx/s, lost/s], …] between successive samples
  rates.of = function (id) {
    const list = rates.samples.get(id) || [];
    const out = [];
    for (let i = 1; i < list.length; i++) {
      const dt = list[i][0] - list[i - 1][0];
      if (dt <= 0) continue;
      out.push([list[i][0], (list[i][1] - list[i - 1][1]) / dt, (list[i][2] - list[i - 1][2]) / dt, (list[i][3] - list[i - 1][3]) / dt]);
    }
    return out;
  };

  rates.summary = function (id, window) {
    const list = rates.samples.get(id) || [];
    if (list.length < 2) return null;
    const last = list[list.length - 1];
    let first = list[0];
    for (const s of list) if (last[0] - s[0] <= window) { first = s; break; }
    const dt = last[0] - first[0];
    if (dt <= 0) return null;
    return { span: dt, tx: (last[1] - first[1]) / dt, rx: (last[2] - first[2]) / dt, lost: (last[3] - first[3]) / dt };
  };

  function el(tag, attrs) {
    const node = document.createElementNS(SVG, tag);
    for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
    return node;
  }

  // a chart of rx and lost frames per second into an <svg> of width × height
  rates.draw = function (svg, id, width, height) {
    const points = rates.of(id);
    if (svg.getAttribute("width") !== String(width)) {  // (once: a size set again lays the table out again)
      svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
      svg.setAttribute("width", width);
      svg.setAttribute("height", height);
    }
    if (!points.length) { svg.replaceChildren(); svg.dataset.points = 0; return; }
    const t1 = points[points.length - 1][0], t0 = Math.min(points[0][0], t1 - 60);
    const top = Math.max(0.1, ...points.map((p) => Math.max(p[2], p[3])));
    const X = (t) => ((t - t0) / (t1 - t0 || 1)) * (width - 1), Y = (r) => height - 1 - (r / top) * (height - 3);
    const line = (k) => points.map((p) => X(p[0]).toFixed(1) + "," + Y(p[k]).toFixed(1)).join(" ");
    svg.replaceChildren(el("polyline", { points: line(2), fill: "none", stroke: "#2ca02c", "stroke-width": 1.2, class: "rx" }),
      el("polyline", { points: line(3), fill: "none", stroke: "#d62728", "stroke-width": 1.2, class: "lost" }));
    svg.dataset.points = points.length;
  };
})();
