// The event log: what happened, with a severity, newest first. Live, the page derives it from one
// picture to the next (links down and up, hosts, reloads and the links they swapped, bursts of losses
// by cause, stale poses); a trace's events come from the player (hilgate/web/events.py, the same rules)
// and are shown up to the playhead.
"use strict";

(function () {
  const view = window.hilgateView, W = window.hilgateWords;
  const BURST_N = 3, BURST_GAP_S = 5;  // as hilgate/web/events.py
  const SHOWN = 300;                   // lines on the page (the oldest go)

  const log = view.log = {
    entries: [], replay: null, shownUpTo: -1, prevLinks: new Map(), prevHosts: new Map(), prevStale: new Map(),
    clusters: new Map(), counts: { info: 0, warning: 0, error: 0 }, started: false,
  };

  function text(e) {
    switch (e.kind) {
      case "link": return "link " + e.link + (e.state === "down" ? " down" + (e.reason ? ": " + e.reason : "") : " up");
      case "host": return "host " + e.host + (e.state === "down" ? " lost: its links are gone" : " back");
      case "burst": return e.link + ": " + e.n + " frames " + W.word(e.cause) +
        (e.until != null && e.until > e.t ? " in " + (e.until - e.t).toFixed(1) + " s" : "");
      case "pose": return "vehicle " + e.vehicle + (e.state === "fresh" ? ": pose fresh again"
        : e.state === "never" ? ": no pose yet from " + (e.source || "its source")
        : ": pose stale" + (e.source ? " (" + e.source + (e.age != null ? ", " + e.age.toFixed(1) + " s old" : "") + ")" : ""));
      case "reload": {
        const parts = ["reload: scene " + e.scene];
        for (const [link, before, after] of e.swaps || []) parts.push(link + " " + before + " → " + after);
        if ((e.added || []).length) parts.push("added " + e.added.join(", "));
        if ((e.removed || []).length) parts.push("removed " + e.removed.join(", "));
        return parts.join("; ");
      }
      case "page": return e.text;
      default: return e.text || e.kind;
    }
  }
  log.text = text;

  function render(e) {
    let li = e.node;
    if (!li) {
      li = e.node = document.createElement("li");
      li.appendChild(document.createElement("span")).className = "t";
      li.appendChild(document.createElement("span")).className = "level";
      li.appendChild(document.createElement("span")).className = "what";
    }
    li.dataset.level = e.level;
    li.dataset.kind = e.kind;
    li.children[0].textContent = Number(e.t).toFixed(1) + " s";
    li.children[1].textContent = e.level;
    const words = text(e);
    if (li.children[2].textContent !== words) li.children[2].textContent = words;
    li.title = words;
    return li;
  }

  function counters() {
    const box = document.getElementById("alarms");
    const parts = [];
    if (log.counts.error) parts.push(log.counts.error + (log.counts.error === 1 ? " error" : " errors"));
    if (log.counts.warning) parts.push(log.counts.warning + (log.counts.warning === 1 ? " warning" : " warnings"));
    box.textContent = parts.join(", ");
    box.hidden = parts.length === 0;
    box.dataset.level = log.counts.error ? "error" : "warning";
  }

  function add(e) {
    log.entries.push(e);
    log.counts[e.level] = (log.counts[e.level] || 0) + 1;
    const list = document.getElementById("log-list");
    list.insertBefore(render(e), list.firstChild);
    while (list.childNodes.length > SHOWN) list.removeChild(list.lastChild);
    counters();
    return e;
  }

  // -- live: from one picture to the next --------------------------------------------------------------

  log.onScene = function (scene, before) {
    if (log.replay) return;
    if (!before) { add({ t: 0, level: "info", kind: "page", text: "page opened: scene " + scene.name }); return; }
    const swaps = [], old = before.links || {}, now = scene.links || {};
    const backend = (l) => (l.kind === "sim" ? "sim" : l.kind + " " + l.backend);
    for (const id of Object.keys(now).sort()) if (old[id] && backend(old[id]) !== backend(now[id])) swaps.push([id, backend(old[id]), backend(now[id])]);
    add({ t: view.state ? view.state.t : 0, level: swaps.length ? "warning" : "info", kind: "reload", scene: scene.name, swaps,
      added: Object.keys(now).filter((id) => !old[id]).sort(), removed: Object.keys(old).filter((id) => !now[id]).sort() });
  };

  function burst(t, link, cause, added) {
    const key = link + "\u0000" + cause;
    let c = log.clusters.get(key);
    if (!c || t - c.last > BURST_GAP_S) { c = { start: t, last: t, n: 0, entry: null }; log.clusters.set(key, c); }
    c.n += added;
    c.last = t;
    if (c.entry) { c.entry.n = c.n; c.entry.until = t; render(c.entry); }
    else if (c.n >= BURST_N) c.entry = add({ t: c.start, level: "warning", kind: "burst", link, cause, n: c.n, until: t });
  }

  log.onState = function (state) {
    if (log.replay) { showReplay(state.t); return; }
    const t = state.t;
    for (const link of state.links || []) {
      const before = log.prevLinks.get(link.id);
      if (before && link.state && before.state !== link.state && (link.state === "down" || before.state === "down")) {
        add({ t, level: link.state === "down" ? "error" : "info", kind: "link", link: link.id, state: link.state, reason: link.reason });
      }
      if (before && link.causes) {
        for (const [cause, n] of Object.entries(link.causes)) {
          const added = n - ((before.causes || {})[cause] || 0);
          if (added > 0) burst(t, link.id, cause, added);
        }
      }
      log.prevLinks.set(link.id, { state: link.state, causes: link.causes });
    }
    for (const host of state.hosts || []) {
      const before = log.prevHosts.get(host.host);
      if (before !== undefined && before !== host.state) add({ t, level: host.state === "down" ? "error" : "info", kind: "host", host: host.host, state: host.state });
      else if (before === undefined && host.state === "down") add({ t, level: "error", kind: "host", host: host.host, state: "down" });
      log.prevHosts.set(host.host, host.state);
    }
    for (const v of state.vehicles || []) {
      const before = log.prevStale.get(v.name) || null, now = v.stale || null;
      if (before !== now) {
        add({ t, level: now ? "warning" : "info", kind: "pose", vehicle: v.name, state: now || "fresh", source: v.source, age: v.age_s });
      }
      log.prevStale.set(v.name, now);
    }
  };

  // -- a trace: the player's events, up to the playhead ------------------------------------------------

  log.setReplay = function (events) {
    log.replay = events.map((e) => Object.assign({}, e));
    log.shownUpTo = -1;
    if (view.state) showReplay(view.state.t);
  };

  function showReplay(t) {
    const events = log.replay;
    let n = 0;
    while (n < events.length && events[n].t <= t + 1e-9) n++;
    if (n === log.shownUpTo) return;
    log.shownUpTo = n;
    log.entries = events.slice(0, n);
    log.counts = { info: 0, warning: 0, error: 0 };
    for (const e of log.entries) log.counts[e.level] = (log.counts[e.level] || 0) + 1;
    const list = document.getElementById("log-list");
    list.replaceChildren(...log.entries.slice(-SHOWN).reverse().map(render));
    counters();
  }
})();
