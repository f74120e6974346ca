// Hover a second vehicle while one is chosen (click it): the distance between them, the delay of each
// channel they share, and for each pair of their simulated modems the SNR and PER of the link budget
// (`hilgate check`'s, sent with the live scene as tables over distance; a trace's player has none).
"use strict";

(function () {
  const view = window.hilgateView;
  const $ = (id) => document.getElementById(id);

  function lookup(table, d) {  // linear in log-distance between the table's points
    const ds = table.d;
    if (!ds.length) return [null, null];
    const at = (k, i) => (table[k] ? table[k][i] : null);
    if (d <= ds[0]) return [at("per", 0), at("snr", 0)];
    for (let i = 1; i < ds.length; i++) {
      if (d <= ds[i]) {
        const w = (Math.log(d) - Math.log(ds[i - 1])) / (Math.log(ds[i]) - Math.log(ds[i - 1]));
        const mix = (k) => (table[k] && table[k][i] != null && table[k][i - 1] != null ? table[k][i - 1] + (table[k][i] - table[k][i - 1]) * w : null);
        return [mix("per"), mix("snr")];
      }
    }
    return [at("per", ds.length - 1), at("snr", ds.length - 1)];
  }

  function show(a, b, spots, x, y) {
    const box = $("pair"), scene = view.scene;
    const pa = spots[a], pb = spots[b];
    const d = Math.hypot(pa[0] - pb[0], pa[1] - pb[1], pa[2] - pb[2]);
    const lines = [a + " ↔ " + b + ": " + (d >= 1000 ? (d / 1000).toFixed(3) + " km" : d.toFixed(1) + " m")];
    const budget = scene.budget || { pairs: {}, tables: [] };
    const linksA = Object.entries(scene.links).filter(([, l]) => l.vehicle === a);
    const linksB = Object.entries(scene.links).filter(([, l]) => l.vehicle === b);
    const pairs = [];
    const directed = [];
    for (const [ia, la] of linksA) for (const [ib, lb] of linksB) directed.push([ia, la, ib, lb], [ib, lb, ia, la]);
    {
      for (const [ia, la, ib, lb] of directed) {
        if (la.channel !== lb.channel) continue;
        const delay = (la.min_delay_s || 0) + d / la.speed_mps;
        const outOfRange = la.range_m[1] != null && (d > la.range_m[1] || d < la.range_m[0]);
        let per = null, snr = null;
        const index = budget.pairs[ia + ">" + ib];
        if (index !== undefined) [per, snr] = lookup(budget.tables[index], d);
        if (outOfRange) per = 1;
        pairs.push({ src: ia, dst: ib, delay_ms: 1000 * delay, per, snr_db: snr, out_of_range: outOfRange, budget: index !== undefined });
        lines.push(ia + " → " + ib + ": delay " + (1000 * delay).toFixed(delay < 0.01 ? 4 : 1) + " ms" +
          (snr != null ? ", SNR " + snr.toFixed(1) + " dB" : "") +
          (per != null ? ", PER " + (per < 0.001 && per > 0 ? per.toExponential(1) : per.toFixed(3)) : index === undefined && la.kind === "sim" && lb.kind === "sim" ? ", error-free" : "") +
          (outOfRange ? " (out of range)" : ""));
      }
    }
    if (!pairs.length) lines.push("no channel in common");
    box.replaceChildren(...lines.map((line) => { const div = document.createElement("div"); div.textContent = line; return div; }));
    box.dataset.pair = a + "|" + b;
    box.dataset.distance = d.toFixed(3);
    view.pair = { a, b, distance_m: d, pairs };
    box.hidden = false;
    const map = $("top").getBoundingClientRect(), width = box.offsetWidth || 240;
    box.style.left = Math.max(4, Math.min(map.width - width - 4, x + 12)) + "px";
    box.style.top = Math.max(4, Math.min(map.height - 60, y + 12)) + "px";
  }

  window.hilgatePair = { show, lookup };
})();
