"""``hilgate report`` and ``hilgate fit`` on damaged traces (issue 24): every trace gets a result or one
line naming what is wrong (the line number, when a line is), never a traceback; both tools follow one
rule for NaN and infinities; and matching real links' frames costs bounded work per line however the
times repeat.

The damaged traces are made from a good one (a simulated run, a daemon's run and reload lines with
real links, their drivers' lines): truncated, wrong types in every field the tools read, huge
numbers, deep nesting, repeated times, binary, shuffled, non-objects; then seeded random mutations.
"""

from __future__ import annotations

import io
import json
import random
from collections import Counter

import pytest

from fuzzkit import examples
from hilgate.cli import main
from hilgate.report import observations as obs
from hilgate.scene import load_scene_text
from hilgate.scene.view import scene_view
from hilgate.sim.simulate import simulate

SCENE = """\
name: fuzzed
seed: 4
duration_s: 12
channels: {ac: {speed_mps: 1500}}
vehicles:
  a: {pose: {static: [0, 0, 0]}}
  b: {pose: {path: {start: [100, 0, 0], legs: [{to: [160, 0, 0], speed_mps: 5}]}}}
links:
  la: {vehicle: a, address: 1, bitrate_bps: 2000, error: {unit: packet, expr: "d / 300"}}
  lb: {vehicle: b, address: 2, bitrate_bps: 2000, error: {unit: packet, expr: "d / 300"}}
  ra: {vehicle: a, address: 3, bitrate_bps: 2000}
  rb: {vehicle: b, address: 4, bitrate_bps: 2000}
flows:
  - {from: la, to: lb, size_bytes: 20, interval_s: 0.5}
"""


def good_lines() -> list[str]:
    """A daemon-like trace: a run line whose scene has ra and rb on real modems, the simulated links'
    events and poses, the drivers' tx/rx between ra and rb (two thirds heard), then a reload that
    makes them simulated."""
    scene = load_scene_text(SCENE, "fuzzed.yaml")
    buffer = io.StringIO()
    simulate(scene, trace=buffer)
    view = scene_view(scene)
    for link in ("ra", "rb"):
        view["links"][link]["backend"] = "evologics"
    events = [json.loads(line) for line in buffer.getvalue().splitlines()]
    for i in range(24):
        t = 0.25 + i * 0.45
        events.append({"t": t, "ev": "tx", "link": "ra", "dst": 4, "size": 30})
        if i % 3:
            events.append({"t": t + 0.1, "ev": "rx", "link": "rb", "src": 3, "dst": 4, "size": 30,
                           "kind": "recvim", "rssi": -60 - i, "integrity": 200})
    events.append({"t": 3.05, "ev": "drop", "link": "ra", "dst": 4, "size": 30, "cause": "queue_full"})
    events.sort(key=lambda e: e["t"])
    run = {"t": 0.0, "ev": "run", "run": "fuzzrun", "start": "2026-11-26T00:00:00+00:00", "scene": "fuzzed",
           "path": "/nonexistent/fuzzed.yaml", "version": "x", "speed": 1.0, "scene_hash": "0", "scene_view": view}
    after = json.loads(json.dumps(view))
    for link in ("ra", "rb"):
        after["links"][link]["backend"] = "sim"
    reload = {"t": 11.5, "ev": "reload", "scene": "fuzzed", "scene_hash": "1",
              "changes": {"ra": {"backend": ["evologics", "sim"]}}, "scene_view": after}
    return [json.dumps(e) for e in [run, *events, reload]]


@pytest.fixture(scope="module")
def good():
    return good_lines()


def run_tools(tmp_path, capsys, name: str, data: bytes):
    """Both tools on ``data``; each must answer with a result or one error line, never a traceback."""
    path = tmp_path / f"{name}.jsonl"
    path.write_bytes(data)
    outcomes = {}
    for tool, args, codes in (("report", ["--out", str(tmp_path / f"{name}-report")], (0, 1)),
                              ("fit", [], (0, 2)), ("fit", ["--model", "logistic"], (0, 2))):
        code = main([tool, str(path), *args])  # an exception here is the failure this test looks for
        out, err = capsys.readouterr()
        assert code in codes, (tool, name, code, err)
        if code:
            lines = err.strip().splitlines()
            assert lines and lines[-1].startswith("hilgate: ") and "Traceback" not in err, (tool, name, err)
            assert len([line for line in lines if line.startswith("hilgate: ")]) == 1, (tool, name, err)
        outcomes[" ".join([tool, *args[:2]]) if tool == "fit" else tool] = (code, err.strip().splitlines()[-1]
                                                                          if code else out)
    return outcomes


def test_the_good_trace_gives_figures_and_a_fit(tmp_path, capsys, good):
    outcomes = run_tools(tmp_path, capsys, "good", ("\n".join(good) + "\n").encode())
    assert outcomes["report"][0] == 0 and outcomes["fit"][0] == outcomes["fit --model logistic"][0] == 0
    assert "24 frames (8 lost) heard or missed by rb; left out: queue_full 1" in outcomes["fit"][1]


def _replace(lines: list[str], ev: str, key: str, raw: str) -> bytes:
    """The first ``ev`` line with ``key``'s value replaced by the JSON text ``raw``."""
    out = list(lines)
    for i, line in enumerate(out):
        event = json.loads(line)
        if event.get("ev") == ev and key in event:
            event[key] = "@@"
            out[i] = json.dumps(event).replace('"@@"', raw)
            break
    else:
        raise AssertionError(f"no {ev} line with {key}")
    return ("\n".join(out) + "\n").encode()


BAD_VALUES = ['null', 'true', '"x"', '{}', '[1, 2]', '1e308', '-1e308', '1e999', 'NaN', '-Infinity', '1' * 5000,
              str(2 ** 70), '"' + "é" * 50 + '"']
FIELDS = [("pose", "t"), ("pose", "position"), ("pose", "vehicle"), ("tx", "t"), ("tx", "size"), ("tx", "pkt"),
          ("tx", "src"), ("tx", "dst"), ("tx", "link"), ("rx", "t"), ("rx", "src"), ("rx", "size"), ("rx", "pkt"),
          ("rx", "rssi"), ("enq", "fifo_bytes"), ("err", "cause"), ("run", "scene_view"), ("run", "t"),
          ("run", "run"), ("run", "path"), ("reload", "scene_view"), ("reload", "t"), ("drop", "cause")]


def damaged(good: list[str]) -> dict[str, bytes]:
    text = "\n".join(good) + "\n"
    data = text.encode()
    rng = random.Random(24)
    cases = {
        "empty": b"",
        "newlines": b"\n\n\n",
        "a list": b"[1,2,3]\n",
        "a string": b'"text"\n',
        "a number": b"3\n" * 3,
        "null": b"null\n",
        "binary": bytes(rng.randrange(256) for _ in range(4000)),
        "binary line in the middle": ("\n".join(good[:40]) + "\n").encode() + b"\xff\xfe\x00\x80garbage\n"
                                     + ("\n".join(good[40:]) + "\n").encode(),
        "not JSON in the middle": ("\n".join(good[:40] + ["{\"t\": 1, "] + good[40:]) + "\n").encode(),
        "deep nesting": b'{"t": 1, "ev": "pose", "vehicle": "a", "position": ' + b"[" * 100000 + b"]" * 100000 + b"}\n",
        "deep nesting alone": b"[" * 200000 + b"\n",
        "repeated times": "\n".join(json.dumps({**json.loads(line), "t": 5.0}) for line in good).encode() + b"\n",
        "shuffled": ("\n".join(rng.sample(good, len(good))) + "\n").encode(),
        "duplicated": (text * 3).encode(),
        "no newline at all": text.replace("\n", " ").encode(),
        "a line too long": b'{"t": 0, "ev": "x", "pad": "' + b"a" * (33 << 20) + b'"}\n',
        "windows line ends": text.replace("\n", "\r\n").encode(),
        "nul bytes": data.replace(b"}", b"}\x00", 5),
        "only a run line": (good[0] + "\n").encode(),
        "run line without links": _replace(good, "run", "scene_view", '{"links": 3}'),
        "a link that is a list": _replace(good, "run", "scene_view", '{"links": {"ra": [1]}}'),
    }
    for cut in (1, len(data) // 3, len(data) // 2 + 7, len(data) - 2):
        cases[f"truncated at {cut}"] = data[:cut]
    for ev, key in FIELDS:
        for value in BAD_VALUES:
            cases[f"{ev}.{key} = {value[:12]}"] = _replace(good, ev, key, value)
    return cases


def test_fuzz_named_damage_gets_a_result_or_one_line(tmp_path, capsys, good, monkeypatch):
    """Every field either tool reads, with values of every wrong kind.  What passes the checks is
    drawn by the same code as the good trace (the drawing is left out here, for time; the next test
    draws the values that pass the checks but stretch the figures)."""
    from hilgate.report import figures

    monkeypatch.setattr(figures, "figures", lambda *args, **kwargs: [])
    for name, data in damaged(good).items():
        outcomes = run_tools(tmp_path, capsys, "case", data)
        for tool, (code, said) in outcomes.items():
            if code and any(value in name for value in ("NaN", "Infinity", "1e999")):
                # one rule in both tools: the line is named, and the number is refused
                assert ":" in said and ("not a number" in said or "too large" in said), (tool, name, said)


def stretched(good: list[str]) -> dict[str, bytes]:
    """Values the checks let through and the figures must still draw: all at one instant, at the
    largest times a trace may hold, negative times, huge sizes and FIFOs, far positions, shuffled."""
    def each(change) -> bytes:
        out = []
        for line in good:
            event = json.loads(line)
            change(event)
            out.append(json.dumps(event))
        return ("\n".join(out) + "\n").encode()

    def scale(factor):
        return lambda event: event.update(t=event["t"] * factor) if "t" in event else None

    rng = random.Random(7)
    return {
        "one instant": each(lambda event: event.update(t=5.0)),
        "largest times": each(lambda event: event.update(t=1e15 - event["t"])),
        "negative times": each(scale(-1.0)),
        "tiny span": each(scale(1e-12)),
        "huge sizes": each(lambda event: event.update(size=10 ** 15, fifo_bytes=10 ** 15)
                           if "size" in event and "fifo_bytes" in event else None),
        "far positions": each(lambda event: event.update(position=[1e15, -1e15, 0.0]) if event.get("ev") == "pose"
                              else None),
        "shuffled": ("\n".join(rng.sample(good, len(good))) + "\n").encode(),
        "zero delays": each(lambda event: event.update(t=round(event["t"], 0))),
    }


def test_fuzz_stretched_values_are_drawn_or_refused_in_one_line(tmp_path, capsys, good):
    for name, data in stretched(good).items():
        run_tools(tmp_path, capsys, "stretched", data)


def mutate(lines: list[str], rng: random.Random) -> bytes:
    out = list(lines)
    for _ in range(rng.randint(1, 4)):
        i = rng.randrange(len(out))
        kind = rng.randrange(7)
        if kind == 0:  # cut a line short
            out[i] = out[i][: rng.randrange(len(out[i]) + 1)]
        elif kind == 1:  # a value of another type
            try:
                event = json.loads(out[i])
            except ValueError:
                continue
            if isinstance(event, dict) and event:
                key = rng.choice(sorted(event))
                event[key] = rng.choice([None, True, "x", [], {}, [1, [2]], 1e300, -7, 2 ** 80, "*", 3.5])
                out[i] = json.dumps(event)
        elif kind == 2:  # a key removed
            try:
                event = json.loads(out[i])
            except ValueError:
                continue
            if isinstance(event, dict) and event:
                del event[rng.choice(sorted(event))]
                out[i] = json.dumps(event)
        elif kind == 3:  # bytes overwritten
            raw = bytearray(out[i].encode())
            if raw:
                raw[rng.randrange(len(raw))] = rng.randrange(256)
            out[i] = raw.decode("utf-8", "replace")
        elif kind == 4:
            out.insert(i, out[rng.randrange(len(out))])
        elif kind == 5:
            j = rng.randrange(len(out))
            out[i], out[j] = out[j], out[i]
        else:
            out[i] = json.dumps(rng.choice([[1, 2], "s", 7, None, {"ev": "tx"}, {"ev": "pose", "t": 1}]))
    return ("\n".join(out) + "\n").encode()


def test_fuzz_random_damage_gets_a_result_or_one_line(tmp_path, capsys, good):
    rng = random.Random(2024)
    for n in range(examples(15)):
        run_tools(tmp_path, capsys, f"random{n % 3}", mutate(good, rng))


def test_matching_real_frames_costs_bounded_work_whatever_the_times(monkeypatch):
    """50 000 frames sent and 50 000 heard, all at the same instant: each rx looks at no more than
    ``SCAN`` frames (the quadratic matching took over a minute on a million such events)."""
    looked = 0
    original = obs._Real._match

    def counting(self, candidates, t, rx):
        nonlocal looked
        looked += min(len(candidates), obs.SCAN)
        return original(self, candidates, t, rx)

    monkeypatch.setattr(obs._Real, "_match", counting)
    links = {"ra": obs.LinkInfo("a", "evologics", 3, "ac", "ac"), "rb": obs.LinkInfo("b", "evologics", 4, "ac", "ac")}
    events = [{"t": 0.0, "ev": "pose", "vehicle": v, "position": [0.0, 0.0, 0.0]} for v in "ab"]
    n = 50_000
    for i in range(n):
        events.append({"t": 1.0, "ev": "tx", "link": "ra", "dst": 4, "size": 10 + i % 7})
    for i in range(n):
        events.append({"t": 1.0, "ev": "rx", "link": "rb", "src": 3, "size": 10 + i % 5})
    data = obs.observations(events, links)
    assert len(data.frames) == n and looked <= obs.SCAN * n
    sent, heard = Counter(10 + i % 7 for i in range(n)), Counter(10 + i % 5 for i in range(n))
    assert sum(o.delivered for o in data.frames) == sum(min(sent[size], heard[size]) for size in heard)
