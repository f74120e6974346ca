// One vocabulary for the whole page, and the same as the report's: the legend, the tables, the event log
// and the inspector say a frame's fate with the words and colours of hilgate/report/causes.py, which the
// daemon sends with each SCENE (load). Until then, and for a code that table does not name, the words
// below; a code nobody knows is shown as itself, spaced, never dropped.
"use strict";

(function () {
  const FATES = {
    rx: ["received", "#2ca02c"], col: ["collision", "#d62728"], mult: ["collision + errors", "#9467bd"],
    prop: ["channel errors", "#e69f00"], range: ["out of range", "#1f77b4"], fifo: ["FIFO full", "#222222"],
    closed: ["link closed", "#7f7f7f"], no_pose: ["position unknown", "#7f7f7f"], band: ["outside the band", "#17becf"],
    modulation: ["modulation not decoded", "#bcbd22"],
  };
  // the frame's fates the legend shows (the report's order); the report's other causes are words only
  const LEGEND = ["rx", "col", "mult", "prop", "range", "fifo", "band", "modulation"];
  const ALSO = {};  // the report's words for every other cause, once a SCENE has brought them
  const OTHER_CAUSES = {  // the GLI's and the drivers' causes: no colour of their own
    no_reader: "no application reading", not_a_frame: "not a frame", bad_frame: "bad frame",
    stale: "stale in the queues", size: "too large", queue_full: "queue full", overflow: "overflow",
    no_remote_address: "no remote address", no_receiver: "no receiver", no_backend: "no modem",
    host_down: "host down", flushed: "flushed", buffer_full: "buffer full", app_full: "application's queue full",
    no_ack: "not acknowledged", crc: "bad CRC", bad_crc: "bad CRC", busy: "modem busy", net_gap: "network gap",
    modem: "modem error", "?": "unknown cause",
  };
  const OTHER = "#8c564b";
  const KINDS = { ack: "acknowledgement", rts: "RTS", cts: "CTS", modem_ack: "modem's acknowledgement" };

  // The report's table (hilgate.web.picture.fates): the legend's fates take its words and colours, every
  // other cause its words.
  function load(table) {
    for (const [code, [words, colour]] of Object.entries(table || {})) {
      if (LEGEND.includes(code) || code in FATES) FATES[code] = [words, colour];
      else ALSO[code] = words;
    }
  }

  function word(code) {
    if (code in FATES) return FATES[code][0];
    if (code in ALSO) return ALSO[code];
    if (code in OTHER_CAUSES) return OTHER_CAUSES[code];
    return String(code).replace(/_/g, " ");
  }

  function colour(code) { return code in FATES ? FATES[code][1] : OTHER; }

  // "lost to errors 3, collided 1" from {prop: 3, col: 1}: largest first, zeros left out
  function causes(counts) {
    return Object.entries(counts || {}).filter(([, n]) => n > 0).sort((a, b) => b[1] - a[1] || (a[0] < b[0] ? -1 : 1))
      .map(([code, n]) => word(code) + " " + n).join(", ");
  }

  function kind(code) { return KINDS[code] || String(code); }

  function seconds(t) { return t == null ? "–" : Number(t).toFixed(t < 100 ? 3 : 2) + " s"; }

  window.hilgateWords = { FATES, LEGEND, OTHER, load, word, colour, causes, kind, seconds };
})();
