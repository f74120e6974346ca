// Click a frame, a link (its row, its ring) or a vehicle to inspect it: a frame's size, source,
// destination, times, fates and causes; a link's modem, counters, losses by cause and its throughput and
// loss over the last minutes. The panel follows the live counters until it is closed (Esc or ×).
"use strict";

(function () {
  const view = window.hilgateView, W = window.hilgateWords;
  const ins = view.inspect = { what: null };
  const $ = (id) => document.getElementById(id);

  function rows(pairs) {
    const body = $("inspect-body");
    const nodes = [];
    for (const [key, label, value] of pairs) {
      const dt = document.createElement("dt");
      dt.textContent = label;
      const dd = document.createElement("dd");
      dd.dataset.key = key;
      dd.textContent = value;
      nodes.push(dt, dd);
    }
    body.replaceChildren(...nodes);
  }

  function show(type, id, title) {
    const box = $("inspect");
    box.hidden = false;
    box.dataset.type = type;
    box.dataset.id = id;
    $("inspect-title").textContent = title;
  }

  ins.close = function () { ins.what = null; $("inspect").hidden = true; };

  ins.frame = function (frame) {
    ins.what = { type: "frame", id: frame.id, frame: JSON.parse(JSON.stringify(frame)) };
    ins.refresh();
  };

  ins.link = function (id) { ins.what = { type: "link", id }; ins.refresh(); };

  function linkName(id) {
    const link = view.scene && view.scene.links[id];
    return link ? id + " (" + link.vehicle + ")" : id;
  }

  function frameRows(frame) {
    const out = [["kind", "kind", frame.kind ? W.kind(frame.kind) : "data"], ["size", "size", frame.size + " bytes"],
      ["src", "source", linkName(frame.src)],
      ["dst", "destination", !frame.dst || frame.dst === "*" ? "everyone in range" : linkName(frame.dst)],
      ["tx", "sent at", frame.tx == null ? "not sent (dropped at the sender)" : W.seconds(frame.tx)]];
    const scene = view.scene || { links: {} };
    const from = scene.links[frame.src];
    if (from && from.bitrate_bps) out.push(["airtime", "time on air", (1000 * frame.size * 8 / from.bitrate_bps).toFixed(1) + " ms"]);
    (frame.out || []).forEach(([where, t, ev, cause], i) => {
      const code = ev === "rx" ? "rx" : (cause || "?");
      const delay = frame.tx == null ? "" : ", " + (1000 * (t - frame.tx)).toFixed(1) + " ms after it was sent";
      out.push(["fate-" + i, "at " + linkName(where), W.word(code) + " at " + W.seconds(t) + delay]);
    });
    if (!(frame.out || []).length) out.push(["fate", "fate", "not judged yet"]);
    return out;
  }

  function linkRows(id) {
    const info = (view.scene && view.scene.links[id]) || {};
    const live = ((view.state && view.state.links) || []).find((l) => l.id === id) || {};
    const out = [["vehicle", "vehicle", info.vehicle || "–"],
      ["backend", "backend", live.remote ? "on " + live.host : info.kind === "sim" ? "simulated" : (info.kind || "") + " " + (live.backend || info.backend || "")],
      ["channel", "channel", (info.channel || "–") + (info.speed_mps ? " (" + info.speed_mps.toPrecision(3) + " m/s)" : "")],
      ["address", "address", info.address == null ? "–" : info.address],
      ["bitrate", "bit rate", info.bitrate_bps ? info.bitrate_bps + " bit/s" : "–"],
      ["range", "range", info.range_m && info.range_m[1] != null ? info.range_m[0] + "–" + info.range_m[1] + " m" : "unbounded"],
      ["state", "state", (live.state || "–") + (live.ready === true ? ", READY" : live.ready === false ? ", BUSY" : "")],
      ["fifo", "FIFO", (live.fifo_bytes || 0) + " of " + (info.fifo_bytes || "?") + " bytes"],
      ["counts", "tx / rx / drops / lost", [live.tx, live.rx, live.drops, live.lost].map((n) => (n === undefined ? "–" : n)).join(" / ")],
      ["causes", "losses by cause", W.causes(live.causes) || "none"]];
    const minute = view.rates.summary(id, 60);
    if (minute) {
      out.push(["rate", "last " + Math.round(minute.span) + " s", minute.tx.toFixed(2) + " sent/s, " + minute.rx.toFixed(2) +
        " received/s, " + minute.lost.toFixed(2) + " lost/s"]);
    }
    return out;
  }

  ins.refresh = function () {
    const what = ins.what;
    if (!what) return;
    const chart = $("inspect-chart");
    if (what.type === "frame") {
      const fresh = view.frames && view.frames.get(what.id);
      if (fresh) what.frame = fresh.f;
      show("frame", what.id, (what.frame.kind ? W.kind(what.frame.kind) : "frame") + " " + what.id);
      rows(frameRows(what.frame));
      chart.hidden = true;
    } else {
      show("link", what.id, "link " + what.id);
      rows(linkRows(what.id));
      chart.hidden = false;
      view.rates.draw(chart, what.id, 300, 60);
    }
  };
})();
