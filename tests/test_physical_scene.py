"""``error: {kind: physical}`` in a scene: with the EvoLogics presets, overrides, bad input (one line
naming file, line and key), and what ``hilgate check`` prints about it."""

import subprocess
import sys
import textwrap

import pytest

from hilgate.models.errormodel import ErrorModel
from hilgate.models.physical import PhysicalErrorModel
from hilgate.scene import SceneError, load_scene_text, preset_names
from hilgate.sim.budget import crossing, link_budget

SCENE = """\
name: phys
channels: {ac: {speed_mps: 1500}}
vehicles:
  a: {pose: {static: [0, 0, 0]}}
  b: {pose: {static: [1500, 0, 0]}}
links:
  la: {vehicle: a, model: evologics-s2cr-18-34, error: {kind: physical, spreading: 1.5, shipping: 0.5}}
  lb: {vehicle: b, model: evologics-s2cr-18-34, error: {kind: physical}, acoustic: {level: 1}}
  lc: {vehicle: b, model: evologics-s2cr-7-17}
flows:
  - {from: la, to: lb, size_bytes: 48, interval_s: 1}
"""


def load(text):
    return load_scene_text(textwrap.dedent(text), "scene.yaml")


def error_of(text) -> SceneError:
    with pytest.raises(SceneError) as info:
        load(text)
    return info.value


def test_presets_for_the_three_evologics_bands():
    assert {"evologics-s2cr-7-17", "evologics-s2cr-18-34", "evologics-s2cr-48-78"} <= set(preset_names())


def test_physical_error_with_a_preset_and_overrides():
    scene = load(SCENE)
    la, lb, lc = (scene.links[k].params for k in ("la", "lb", "lc"))
    assert isinstance(la.error, PhysicalErrorModel)
    assert la.error.acoustic.band_khz == (18.0, 34.0) and la.error.bitrate_bps == 13900
    assert la.error.acoustic.source_level_db == 148 and la.error.source_db == 148
    assert lb.error.acoustic.level == 1 and lb.error.source_db == 142  # AT!L1: −6 dB, the rest from the preset
    assert isinstance(lc.error, ErrorModel) and lc.error.constant_zero  # the preset's own error stays


@pytest.mark.parametrize("preset,range_m", [("evologics-s2cr-7-17", 8000), ("evologics-s2cr-18-34", 3500),
                                            ("evologics-s2cr-48-78", 1000)])
def test_preset_source_levels_put_per_near_0_1_at_the_datasheet_range(preset, range_m):
    scene = load(f"""\
    channels: {{ac: {{speed_mps: 1500}}}}
    vehicles: {{a: {{pose: {{static: [0, 0, 0]}}}}}}
    links: {{la: {{vehicle: a, model: {preset}, error: {{kind: physical}}}}}}
    """)
    link = scene.links["la"].params
    assert link.range_m == (0.0, range_m)
    assert 0.04 < link.error.per(range_m, 64) < 0.2  # calibrated to 0.1, rounded to a whole dB


@pytest.mark.parametrize("bad,where,message", [
    ("error: {kind: physical}", "links.la.error", "needs the link's acoustic"),
    ("error: {kind: physical, expr: '0.1'}, acoustic: {band_khz: [7, 17], source_level_db: 150}",
     "links.la.error.expr", "only for kind: expr"),
    ("error: {kind: waves}", "links.la.error.kind", "must be one of expr, physical"),
    ("error: {unit: bit, expr: '0', spreading: 2}", "links.la.error.spreading", "only for kind: physical"),
    ("error: {kind: physical, spreading: 3}, acoustic: {band_khz: [7, 17], source_level_db: 150}",
     "links.la.error.spreading", "at most 2"),
    ("error: {kind: physical}, acoustic: {band_khz: [17, 7], source_level_db: 150}",
     "links.la.acoustic.band_khz", "must be above low"),
    ("error: {kind: physical}, acoustic: {band_khz: [7, 17]}", "links.la.acoustic", "missing required key"),
    ("error: {kind: physical}, acoustic: {band_khz: [7, 17], source_level_db: 150, modulation: ofdm}",
     "links.la.acoustic.modulation", "must be one of"),
    ("error: {kind: physical, colisions: sinr}, acoustic: {band_khz: [7, 17], source_level_db: 150}",
     "links.la.error.colisions", "did you mean 'collisions'"),
    ("acoustic: {band_khz: [7, 17], source_level_db: 150, levle: 2}", "links.la.acoustic.levle",
     "did you mean 'level'"),
    ("acoustic: {band_khz: [7, 17], source_level_db: 150, decodes: [bfsk, ofdm]}", "links.la.acoustic.decodes[1]",
     "must be one of"),
    ("acoustic: {band_khz: [7, 17], source_level_db: 150, decodes: bfsk}", "links.la.acoustic.decodes",
     "must be a list"),
    ("acoustic: {band_khz: [7, 17], source_level_db: 150, decodes: [qpsk, qpsk]}", "links.la.acoustic.decodes[1]",
     "given twice"),
    ("model: evologics-s2cr-7-17, acoustic: {band_khz: [7]}", "links.la.acoustic.band_khz", "must be [low, high]"),
])
def test_bad_physical_keys_are_one_line_errors(bad, where, message):
    error = error_of(f"""\
    channels: {{ac: {{speed_mps: 1500}}}}
    vehicles: {{a: {{pose: {{static: [0, 0, 0]}}}}}}
    links:
      la: {{vehicle: a, {bad}}}
    """)
    assert error.file == "scene.yaml" and error.line == 4, str(error)
    assert error.path == where and message in error.message, str(error)
    assert "\n" not in str(error)


def test_budget_of_a_physical_pair():
    scene = load(SCENE)
    rows = {(r.src, r.dst): r for r in link_budget(scene)}
    # lc (7-17 kHz) and la, lb (18-34 kHz) do not share a band: whatever their error models, none hears
    # the other (PER 1, cause band); la <-> lb are the physical pairs
    assert set(rows) == {("la", "lb"), ("lb", "la"), ("la", "lc"), ("lb", "lc"), ("lc", "la"), ("lc", "lb")}
    for pair in (("la", "lc"), ("lb", "lc"), ("lc", "la"), ("lc", "lb")):
        assert (rows[pair].refused, rows[pair].per, rows[pair].snr_db, rows[pair].d_per_01) == ("band", 1.0, None, None)
    ab = rows[("la", "lb")]
    la, lb = scene.links["la"].params, scene.links["lb"].params
    model = lb.error.path_from(la.acoustic, la.bitrate_bps)
    assert model.source_db == 148 and ab.refused is None
    assert ab.size == 48 and ab.d == 1500.0
    assert ab.snr_db == pytest.approx(model.snr_db(1500.0)) and ab.per == pytest.approx(model.per(1500.0, 48))
    assert ab.d_per_01 is None and model.per(3500.0, 48) < 0.1  # la's range (3500 m) ends before PER 0.1
    ba = rows[("lb", "la")]  # lb sends 6 dB quieter (AT!L1): it crosses within la's range
    back = la.error.path_from(lb.acoustic, lb.bitrate_bps)
    assert back.source_db == 142 and ba.size == 64
    assert back.per(ba.d_per_01, 64) == pytest.approx(0.1, abs=1e-6)
    assert back.per(ba.d_per_09, 64) == pytest.approx(0.9, abs=1e-6)
    assert ba.d_per_01 < ba.d_per_09 < 3500


def test_crossing_of_a_known_curve():
    assert crossing(lambda d: d / 100.0, 0.5, 0.0, 100.0) == pytest.approx(50.0)
    assert crossing(lambda d: d / 100.0, 0.5, 60.0, 100.0) == 60.0
    assert crossing(lambda d: d / 1000.0, 0.5, 0.0, 100.0) is None


def test_check_prints_the_link_budget(tmp_path):
    path = tmp_path / "phys.yaml"
    path.write_text(SCENE)
    result = subprocess.run([sys.executable, "-m", "hilgate", "check", str(path)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("pair"))
    assert lines[header].split("  ")[0] == "pair" and "SNR dB" in lines[header] and "PER 0.9 at m" in lines[header]
    row = lines[header + 1].split()
    assert row[:5] == ["la", "->", "lb", "48", "1500.0"]
    assert lines[-1] == "ok"


SINR = """\
name: sinr
channels: {ac: {speed_mps: 1500}}
vehicles:
  r: {pose: {static: [0, 0, 0]}}
  near: {pose: {static: [100, 0, 0]}}
  far: {pose: {static: [0, 1000, 0]}}
x-m: &m {model: evologics-s2cr-18-34, error: {kind: physical, collisions: sinr, capture_db: 10}}
links:
  lr: {<<: *m, vehicle: r, address: 1}
  ln: {<<: *m, vehicle: near}
  lf: {<<: *m, vehicle: far}
flows:
  - {from: ln, to: lr, size_bytes: 200, interval_s: 1, start_s: 0.5}
  - {from: lf, to: lr, size_bytes: 200, interval_s: 1, start_s: 0.0}
"""


def test_sinr_in_a_scene_captures_the_near_sender(tmp_path):
    """Both senders' frames overlap at lr every second (the far one leaves 0.5 s earlier and travels
    0.6 s longer): with capture at 10 dB the near sender's frames all arrive, the far one's collide;
    with the default strict overlap both would be lost.  The same seed gives the same trace."""
    from hilgate.sim.simulate import simulate

    scene = load(SINR)
    error = scene.links["lr"].params.error
    assert error.sinr and error.capture == pytest.approx(10.0)
    traces = []
    for _ in range(2):
        path = tmp_path / f"t{len(traces)}.jsonl"
        with open(path, "w", encoding="utf-8") as trace:
            summary = simulate(scene, until=20, trace=trace)
        traces.append(path.read_text())
    assert traces[0] == traces[1]
    near, far = summary["flows"]
    assert near["rx_packets"] == near["tx_packets"] == 20 and near["lost"]["col"] == 0
    assert far["rx_packets"] == 0 and far["lost"]["col"] + far["lost"]["mult"] == far["tx_packets"] == 20
    strict = load(SINR.replace("collisions: sinr", "collisions: overlap"))
    summary = simulate(strict, until=20)
    assert summary["flows"][0]["rx_packets"] == 0 and summary["flows"][1]["rx_packets"] == 0


def test_budget_rows_are_limited():
    scene = load(SCENE)
    assert len(link_budget(scene, limit=1)) == 2  # one more than the limit: the caller says "more"
    assert len(link_budget(scene, limit=10)) == 6
