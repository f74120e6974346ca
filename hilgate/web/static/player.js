// The trace player: play and pause, a speed from 0.1× to 100×, a slider that seeks anywhere, a time axis
// with the trace's events marked (click one to go there), and steps to the next or previous event. It
// takes the keyboard: space plays or pauses, ← → step a second (with shift ten), n and p (or ] and [)
// go to the next and previous event, + and − change the speed, Home and End go to the ends.
"use strict";

(function () {
  const view = window.hilgateView;
  const SPEEDS = [0.1, 0.25, 0.5, 1, 2, 5, 10, 25, 50, 100];
  const $ = (id) => document.getElementById(id);
  const player = view.player = { events: [], dragging: false, axisKey: "", asked: null };

  function seek(t) {
    const state = view.state;
    if (!state || state.end === undefined) return;
    t = Math.min(Math.max(t, state.start), state.end);
    view.seekTo(t);
  }
  player.seek = seek;

  function setSpeed(speed) { view.send({ class: "SPEED", speed }); $("speed").value = speed; player.asked = speed; }

  player.step = function (direction) {
    const t = view.state ? view.state.t : 0;
    const events = player.events;
    if (direction > 0) {
      const next = events.find((e) => e.t > t + 1e-6);
      if (next) seek(next.t);
    } else {
      let prev = null;
      for (const e of events) if (e.t < t - 1e-6) prev = e;
      if (prev) seek(prev.t);
    }
  };

  player.setUp = function () {
    const speed = $("speed");
    for (const s of SPEEDS) {
      const option = document.createElement("option");
      option.value = s;
      option.textContent = s + "×";
      if (s === 1) option.selected = true;
      speed.appendChild(option);
    }
    speed.addEventListener("change", () => view.send({ class: "SPEED", speed: Number(speed.value) }));
    $("play").addEventListener("click", () => view.send({ class: view.state && view.state.playing ? "PAUSE" : "PLAY" }));
    $("prev-event").addEventListener("click", () => player.step(-1));
    $("next-event").addEventListener("click", () => player.step(1));
    const slider = $("slider");
    slider.addEventListener("input", () => { player.dragging = true; seek(Number(slider.value)); });
    slider.addEventListener("change", () => { player.dragging = false; });
    $("axis").addEventListener("click", (event) => {
      const mark = event.target.closest("[data-event]");
      if (mark) { seek(Number(mark.dataset.t)); return; }
      const box = $("axis").getBoundingClientRect(), state = view.state;
      if (state && state.end > state.start) seek(state.start + (state.end - state.start) * (event.clientX - box.left) / box.width);
    });
    document.addEventListener("keydown", (event) => {
      if (view.mode !== "replay" || event.ctrlKey || event.metaKey || event.altKey) return;
      const tag = (event.target && event.target.tagName) || "";
      if (tag === "INPUT" && event.target.type !== "range" || tag === "TEXTAREA") return;
      const state = view.state;
      if (!state) return;
      const index = SPEEDS.indexOf(Number($("speed").value));  // the speed asked for last (the picture's may lag)
      let done = true;
      switch (event.key) {
        case " ": view.send({ class: state.playing ? "PAUSE" : "PLAY" }); break;
        case "ArrowRight": seek(state.t + (event.shiftKey ? 10 : 1)); break;
        case "ArrowLeft": seek(state.t - (event.shiftKey ? 10 : 1)); break;
        case "n": case "]": player.step(1); break;
        case "p": case "[": player.step(-1); break;
        case "+": case "=": if (index < SPEEDS.length - 1) setSpeed(SPEEDS[index + 1]); break;
        case "-": case "_": if (index > 0) setSpeed(SPEEDS[index - 1]); break;
        case "Home": seek(state.start); break;
        case "End": seek(state.end); break;
        case "Escape": view.inspect.close(); break;
        default: done = false;
      }
      if (done) event.preventDefault();
    });
  };

  player.setEvents = function (message) {
    player.events = message.events || [];
    player.axisKey = "";
  };

  function drawAxis(state) {
    const svg = $("axis");
    const width = svg.clientWidth || 600, height = svg.clientHeight || 22;
    const key = width + "|" + state.start + "|" + state.end + "|" + player.events.length;
    const X = (t) => 6 + (width - 12) * (t - state.start) / ((state.end - state.start) || 1);
    if (key !== player.axisKey) {
      player.axisKey = key;
      const el = view.map.el, layer = el("g");
      layer.appendChild(el("line", { x1: 6, y1: 8, x2: width - 6, y2: 8, class: "axis-line" }));
      const span = state.end - state.start;
      const step = span > 0 ? Math.pow(10, Math.floor(Math.log10(span / 5))) * ([1, 2, 5].find((m) => span / (m * Math.pow(10, Math.floor(Math.log10(span / 5)))) <= 10) || 10) : 1;
      for (let t = Math.ceil(state.start / step) * step; t <= state.end + 1e-9 && span > 0; t += step) {
        layer.appendChild(el("line", { x1: X(t), y1: 8, x2: X(t), y2: 12, class: "axis-line" }));
        layer.appendChild(el("text", { x: X(t) + 2, y: 21, class: "small" }, +t.toFixed(3) + " s"));
      }
      for (const e of player.events) {
        const mark = el("rect", { x: X(e.t) - 1.5, y: 1, width: 3, height: 12, class: "mark " + e.level, "data-event": e.kind, "data-t": e.t });
        const title = el("title", {}, e.t.toFixed(1) + " s: " + view.log.text(e));
        mark.appendChild(title);
        layer.appendChild(mark);
      }
      layer.appendChild(el("line", { x1: 0, y1: 0, x2: 0, y2: 16, class: "playhead", id: "playhead" }));
      svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
      svg.replaceChildren(layer);
    }
    const head = document.getElementById("playhead");
    if (head) { head.setAttribute("x1", X(state.t)); head.setAttribute("x2", X(state.t)); }
  }

  player.onState = function (state) {
    if (state.end === undefined) return;
    $("play").textContent = state.playing ? "▮▮ pause" : "▶ play";
    const slider = $("slider");
    slider.min = state.start;
    slider.max = state.end;
    if (!player.dragging) slider.value = state.t;
    $("position").textContent = state.t.toFixed(1) + " / " + Number(state.end).toFixed(1) + " s";
    const speed = $("speed");
    if (player.asked === state.speed) player.asked = null;  // (until the player has it, keys count from the asked)
    if (player.asked == null && Number(speed.value) !== state.speed && document.activeElement !== speed) speed.value = state.speed;
    $("prev-event").disabled = !player.events.some((e) => e.t < state.t - 1e-6);
    $("next-event").disabled = !player.events.some((e) => e.t > state.t + 1e-6);
    drawAxis(state);
  };
})();
