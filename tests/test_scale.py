"""A thousand simulated modems: wide addresses, the medium's neighbour index, exact outcomes.

The ring has 1 000 modems 100 m apart (radius 100 000 / 2π m) with ``range_m: [0, 250]``: each hears
exactly the two modems either side of it.  Addresses are 1..1001 without 255 (the broadcast address),
so 746 of them are wider than 8 bits.  A few periodic flows make a sub-case whose outcomes are
known exactly: delivery times from the chord length, arrivals from the four neighbours in range,
range errors for a frame addressed beyond range, and a collision between two senders either side
of one receiver.
"""

import io
import json
import math
import random
import subprocess
import sys

import pytest

from hilgate.scene import SceneError, load_scene_text
from hilgate.sim.simulate import Simulation

N = 1000
SPACING = 100.0
RADIUS = SPACING * N / (2 * math.pi)
AIRTIME = 35 * 8 / 1000.0


def address(i: int) -> int:
    return i + 1 if i + 1 < 255 else i + 2


def ring(flows: list[str], duration: float = 20.0, extra: str = "") -> str:
    lines = ["name: ring-1000", "seed: 3", f"duration_s: {duration}", "channels: {ac: {speed_mps: 1500}}", "vehicles:"]
    for i in range(N):
        angle = 2 * math.pi * i / N
        lines.append(f"  v{i}: {{pose: {{static: [{RADIUS * math.cos(angle)!r}, {RADIUS * math.sin(angle)!r}, 0]}}}}")
    lines.append("links:")
    for i in range(N):
        lines.append(f"  m{i}: {{vehicle: v{i}, address: {address(i)}, bitrate_bps: 1000, range_m: [0, 250]{extra}}}")
    lines.append("flows:")
    lines.extend(f"  - {flow}" for flow in flows)
    return "\n".join(lines) + "\n"


def periodic(src: int, dst: int, start: float = 0.0) -> str:
    return f"{{from: m{src}, to: m{dst}, size_bytes: 35, interval_s: 1, start_s: {start}, stop_s: 10}}"


def test_a_thousand_modems_load_and_run_with_exact_outcomes():
    scene = load_scene_text(ring([
        periodic(0, 1),                  # 8-bit addresses, across the seam of the ring (m0 hears m998, m999)
        periodic(600, 601, 0.25),        # both wide
        periodic(300, 700, 0.5),         # 400 modems away: out of range, never visited
        periodic(100, 101, 0.75), periodic(102, 101, 0.75),  # m101 hears both at once: collisions
    ]))
    assert len(scene.links) == N
    assert sorted(link.params.address for link in scene.links.values()) == [address(i) for i in range(N)]
    trace = io.StringIO()
    simulation = Simulation(scene, trace=trace)
    summary = simulation.run()
    flows = {(f["from"], f["to"]): f for f in summary["flows"]}

    chord = 2 * RADIUS * math.sin(math.pi / N)  # neighbours one apart
    for key in (("m0", "m1"), ("m600", "m601")):
        f = flows[key]
        assert (f["offered"], f["tx_packets"], f["rx_packets"]) == (10, 10, 10)
        assert f["lost"] == {"prop": 0, "col": 0, "mult": 0, "range": 0}
        assert f["delay_mean_s"] == pytest.approx(AIRTIME + chord / 1500, abs=1e-9)
    far = flows[("m300", "m700")]
    assert (far["tx_packets"], far["rx_packets"], far["lost"]["range"]) == (10, 0, 10)
    for key in (("m100", "m101"), ("m102", "m101")):
        f = flows[key]
        assert (f["tx_packets"], f["rx_packets"], f["lost"]["col"]) == (10, 0, 10)
    # every transmission reaches exactly its four neighbours in range
    assert simulation.world.medium.arrivals == 5 * 10 * 4

    events = [json.loads(line) for line in trace.getvalue().splitlines()]
    rx = [e for e in events if e["ev"] == "rx" and e["link"] == "m601"]
    assert [e["t"] for e in rx] == pytest.approx([0.25 + k + AIRTIME + chord / 1500 for k in range(10)], abs=1e-9)
    assert {e["src"] for e in rx} == {"m600"}
    ranges = [e for e in events if e["ev"] == "err" and e.get("cause") == "range"]
    assert [(e["link"], e["t"]) for e in ranges] == [("m700", 0.5 + k) for k in range(10)]


def test_the_neighbour_lists_match_a_brute_force_scan():
    """The grid by max range lists, in attachment order, exactly the radios a full scan would keep:
    static pairs in range and every pair with a moving vehicle; a frame addressed beyond range finds
    its radio through the same scan."""
    rng = random.Random(15)
    lines = ["seed: 1", "duration_s: 10", "channels: {ac: {speed_mps: 1500}, rf: {speed_mps: 2e8}}", "vehicles:"]
    n = 160
    for i in range(n):
        p = [round(rng.uniform(-3000, 3000), 1), round(rng.uniform(-3000, 3000), 1), round(rng.uniform(0, 900), 1)]
        if i % 20 == 7:
            q = [p[0] + 2000, p[1] - 500, p[2]]
            lines.append(f"  v{i}: {{pose: {{path: {{start: {p}, legs: [{{to: {q}, speed_mps: 2}}]}}}}}}")
        else:
            lines.append(f"  v{i}: {{pose: {{static: {p}}}}}")
    lines.append("links:")
    for i in range(n):
        rmax = rng.choice(["300", "750", "1000", ".inf"])
        rmin = rng.choice([0, 0, 100])
        channel = "rf" if i % 31 == 5 else "ac"
        lines.append(f"  l{i}: {{vehicle: v{i}, address: {address(i) + 300}, channel: {channel}, "
                     f"range_m: [{rmin}, {rmax}]}}")
    simulation = Simulation(load_scene_text("\n".join(lines) + "\n"))
    medium = simulation.world.medium
    medium._rebuild()
    radios = medium.radios
    assert len(radios) == n
    pruned = 0
    for sender in radios:
        expected, beyond = [], []
        for receiver in radios:
            if receiver is sender or receiver.rx_channel != sender.tx_channel or not receiver.listens:
                continue
            if sender.pose.static and receiver.pose.static:
                d = math.dist(sender.pose.position(0.0), receiver.pose.position(0.0))
                if not sender.range_m[0] <= d <= sender.range_m[1]:
                    beyond.append(receiver)
                    continue
            expected.append(receiver)
        roaming = medium._roam.get(sender)  # a moving sender finds everyone through the moving grid
        listed = [nb.radio for nb in (medium._all(roaming) if roaming is not None else medium._neighbours[sender])]
        # a static sender's quiet receivers (models/air.py) are counted, not listed: together, the same radios
        quiet = [radio for radio in radios if medium._quiet.tau(sender, radio) is not None]
        assert len(quiet) == medium._quiet_count.get(sender, 0) and not set(quiet) & set(listed)
        assert sorted(listed + quiet, key=radios.index) == expected
        pruned += len(beyond)
        for receiver in beyond:
            assert medium._beyond(sender, receiver.address) == (receiver,)
        for receiver in expected:
            assert medium._beyond(sender, receiver.address) == ()
    assert pruned > n * n // 2  # the grid did leave most pairs out
    assert medium._quiet_count  # and the senders that hear many static radios took the quiet path


def test_wide_addresses_are_refused_where_8_bits_are_carried(tmp_path):
    base = ("channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0,0,0]}}}\nlinks:\n"
            "  x:\n    vehicle: a\n")
    with pytest.raises(SceneError) as info:
        load_scene_text(base + "    emulate: {protocol: evologics, tcp: 40123}\n    address: 256\n", "s.yaml")
    assert str(info.value).startswith("s.yaml:7: links.x.address: 256 is wider than 8 bits")
    assert "emulated modem" in str(info.value)
    scene = load_scene_text(base + "    address: 4000\n", "s.yaml")
    assert scene.links["x"].params.address == 4000
    # hilgate run attaches dccomms queues and the socket GLI to every link: refused before anything opens
    path = tmp_path / "wide.yaml"
    path.write_text(base + "    address: 4000\n")
    result = subprocess.run([sys.executable, "-m", "hilgate", "run", str(path), "--runtime-dir", str(tmp_path / "rt"),
                             "--until", "1"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"hilgate: {path}:6: links.x.address: 4000 is wider than 8 bits (0..254): hilgate run attaches dccomms "
        f"queues and the socket GLI (8-bit addresses) to every link; wide addresses are for hilgate sim"]
    assert not (tmp_path / "rt").exists()


def moving_scene(seed: int) -> str:
    """48 vehicles crossing a 4 km square at 1-3 m/s, 8 static ones, one that jumps (no top speed);
    600 m range: every sender has more moving neighbours than the neighbour index's ROAMING_MIN."""
    rng = random.Random(seed)
    lines = [f"seed: {seed}", "duration_s: 300", "channels: {ac: {speed_mps: 1500}}", "vehicles:"]
    n = 57
    for i in range(n):
        p = [round(rng.uniform(-2000, 2000), 1), round(rng.uniform(-2000, 2000), 1), round(rng.uniform(0, 200), 1)]
        if i < 48:
            q = [round(rng.uniform(-2000, 2000), 1), round(rng.uniform(-2000, 2000), 1), p[2]]
            legs = f"[{{to: {q}, speed_mps: {rng.uniform(1, 3):.2f}}}, {{to: {p}, speed_mps: 2}}]"
            lines.append(f"  v{i}: {{pose: {{path: {{start: {p}, legs: {legs}, loop: true}}}}}}")
        elif i < 56:
            lines.append(f"  v{i}: {{pose: {{static: {p}}}}}")
        else:
            lines.append(f"  v{i}: {{pose: {{path: {{start: {p}, legs: [{{hold_s: 100}}, {{to: [0, 0, 0], duration_s: 0}}]}}}}}}")
    lines.append("links:")
    for i in range(n):
        lines.append(f"  l{i}: {{vehicle: v{i}, address: {i + 400}, bitrate_bps: 2000, range_m: [0, 600]}}")
    lines.append("flows:")
    for i in range(n):
        dst = rng.choice([f"l{j}" for j in range(n) if j != i] + ['"*"'])
        lines.append(f"  - {{from: l{i}, to: {dst}, size_bytes: {rng.randint(10, 60)}, rate_hz: 0.2, poisson: true}}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("seed", [1, 2])
def test_the_moving_grid_gives_the_trace_of_a_full_scan(seed, monkeypatch):
    """Senders with many moving neighbours visit only those the moving grid puts near them; the
    trace (every arrival, collision, loss and range error) is byte-identical to visiting all."""
    import hilgate.models.neighbours as neighbours_module  # (the neighbour index decides who roams)

    def run() -> tuple[str, int, int]:
        trace = io.StringIO()
        simulation = Simulation(load_scene_text(moving_scene(seed)), trace=trace)
        simulation.run()
        medium = simulation.world.medium
        return trace.getvalue(), medium.arrivals, len(medium._roam)

    indexed, arrivals, roaming = run()
    assert roaming == 57
    monkeypatch.setattr(neighbours_module, "ROAMING_MIN", 10**9)
    scanned, arrivals_scanned, roaming_scanned = run()
    assert roaming_scanned == 0
    assert indexed == scanned and arrivals == arrivals_scanned
    events = [json.loads(line) for line in indexed.splitlines()]
    assert sum(e["ev"] == "rx" for e in events) > 100
    assert sum(e["ev"] == "err" and e.get("cause") == "range" for e in events) > 20


def test_the_moving_grid_holds_every_radio_in_range():
    """At many instants, what the grid visits includes every radio a sender reaches (a full scan)."""
    simulation = Simulation(load_scene_text(moving_scene(3)))
    medium = simulation.world.medium
    medium._rebuild()
    rng = random.Random(4)
    from hilgate.models.frame import BROADCAST, Frame

    visited_total = listed_total = 0
    for _ in range(60):
        t = rng.uniform(0, 1000)
        for sender in medium.radios:
            here = sender.pose.position(t)
            frame = Frame(1, "x", "y", BROADCAST, 10, t)
            visit = medium._visit(medium._roam[sender], here, t, frame)
            listed = medium._all(medium._roam[sender])
            assert visit == [nb for nb in listed if nb in visit]  # list order kept
            in_range = [nb for nb in listed if math.dist(here, nb.radio.pose.position(t)) <= 600]
            assert set(in_range) <= set(visit)
            visited_total += len(visit)
            listed_total += len(listed)
    assert visited_total < listed_total / 2  # and it does leave most out
