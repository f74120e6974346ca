// One vocabulary for the whole page: the legend, the tables, the event log and the inspector say a
// frame's fate with the same words and colours (hilgate report's colours). A code the page does not
// know is shown as itself, spaced, never dropped.
"use strict";

(function () {
  const FATES = {
    rx: ["delivered", "#2ca02c"], col: ["collided", "#d62728"], mult: ["collided (several)", "#9467bd"],
    prop: ["lost to errors", "#e69f00"], range: ["out of range", "#1f77b4"], fifo: ["dropped from a FIFO", "#222222"],
    closed: ["link closed", "#7f7f7f"], no_pose: ["no pose", "#7f7f7f"], band: ["outside the band", "#17becf"],
    modulation: ["modulation not decoded", "#bcbd22"],
  };
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

  function word(code) {
    if (code in FATES) return FATES[code][0];
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

  window.hilgateWords = { FATES, OTHER, word, colour, causes, kind, seconds };
})();
