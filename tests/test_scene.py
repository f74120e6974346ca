"""Scene loading and validation: every error names file, line and key; unknown keys are errors."""

import math
import os
import subprocess
import sys
import textwrap

import pytest

from hilgate.scene import SceneError, load_scene, load_scene_text, preset_names

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

GOOD = """\
name: two-rovs
seed: 3
duration_s: 30
channels:
  rf: {speed_mps: 2.25e7, min_delay_s: 0}
  acoustic: {speed_mps: 1500}
vehicles:
  rov0: {pose: {static: [0, 0, 0]}}
  rov1:
    pose:
      path:
        start: [0.8, 0, 0]
        legs: [{hold_s: 11}, {to: [5.8, 0, 0], speed_mps: 0.25}]
links:
  rov0_rf:
    vehicle: rov0
    model: s100
    address: 1
    channel: rf
    tx_delay_s: 0.001
  rov1_rf: {vehicle: rov1, model: s100, channel: rf}
  rov0_ac: {vehicle: rov0, channel: acoustic, bitrate_bps: 1900}
flows:
  - {from: rov0_rf, to: rov1_rf, size_bytes: 20, interval_s: 0.1}
  - {from: rov1_rf, to: "*", size_bytes: 20, rate_hz: 5, poisson: true, start_s: 2, stop_s: 20}
trace: {file: trace.jsonl}
"""


def error_of(text: str, *overrides: str) -> SceneError:
    with pytest.raises(SceneError) as info:
        load_scene_text(textwrap.dedent(text), "scene.yaml", overrides)
    return info.value


def test_good_scene_with_presets_and_overrides():
    scene = load_scene_text(GOOD, "good.yaml")
    assert scene.name == "two-rovs" and scene.seed == 3 and scene.duration_s == 30
    assert scene.channels["rf"].speed_mps == 2.25e7
    rf0 = scene.links["rov0_rf"].params
    assert rf0.bitrate_bps == 1800 and rf0.range_m == (0.5, 6.0) and rf0.duplex == "half"
    assert rf0.error.unit == "bit" and rf0.error.expression.text == "6e-13 * d^13.7"
    assert rf0.tx_delay_s == 0.001  # the link's own key overrides the preset's default
    assert scene.links["rov1_rf"].params.address == 2  # auto-assigned, the smallest free one
    assert scene.links["rov0_ac"].params.bitrate_bps == 1900
    assert scene.links["rov0_ac"].params.range_m == (0.0, math.inf)
    poisson = scene.flows[1]
    assert poisson.poisson and poisson.interval_s == pytest.approx(0.2) and poisson.dst == "*"
    assert scene.trace_file == os.path.join(os.getcwd(), "trace.jsonl")  # relative to the scene's directory


def test_presets_exist_with_the_numbers_of_the_design_card():
    assert {"s100", "evologics-s2cr-7-17"} <= set(preset_names())
    scene = load_scene_text("""\
channels: {ac: {speed_mps: 1500}}
vehicles: {a: {pose: {static: [0, 0, 0]}}}
links: {x: {vehicle: a, model: evologics-s2cr-7-17}}
""")
    p = scene.links["x"].params
    assert p.bitrate_bps == 1900 and p.tx_delay_s == 0.001


ONE = "channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0,0,0]}}}\n"
"""The first two lines of most scenes below: a link's errors are on line 3 and after."""
XY = ONE + "links:\n  x: {vehicle: a}\n  y: {vehicle: a}\nflows:\n"
"""Two links and the start of a flow: a flow's errors are on line 7 and after."""


@pytest.mark.parametrize("text,where,key,words", [
    (ONE + "links: {x: {vehicle: a, bitrate_bsp: 10}}\n", 3, "links.x.bitrate_bsp", "did you mean 'bitrate_bps'"),
    (ONE + "links:\n  x:\n    vehicle: a\n    bitrate_bps: fast\n", 6, "links.x.bitrate_bps", "must be a number"),
    (ONE + "links:\n  x:\n    vehicle: b\n", 5, "links.x.vehicle", "no vehicle 'b'"),
    (ONE + "links:\n  x: {vehicle: a, model: s200}\n", 4, "links.x.model", "unknown modem model 's200'"),
    (ONE + "links:\n  x:\n    vehicle: a\n    error: {unit: bit, expr: \"__import__('os')\"}\n",
     6, "links.x.error.expr", "bad error-rate expression"),
    (ONE + "links:\n  x:\n    vehicle: a\n    error: {unit: bits, expr: \"0\"}\n",
     6, "links.x.error.unit", "bit, byte, packet"),
    ("channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0,0]}}}\nlinks: {}\n",
     2, "vehicles.a.pose.static", "list of 3 numbers"),
    ("channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {statik: [0,0,0]}}}\nlinks: {}\n",
     2, "vehicles.a.pose.statik", "did you mean 'static'"),
    ("channels: {ac: {speed_mps: 1500}}\nvehicles:\n  a: {pose: {static: [0,0,0]}}\n  a: {pose: {static: [1,0,0]}}\n"
     "links: {}\n", 4, "vehicles.a", "duplicate key (first given on line 3)"),
    ("channels: {ac: {speed_mps: 1500}, rf: {speed_mps: 2e7}}\nvehicles: {a: {pose: {static: [0,0,0]}}}\n"
     "links:\n  x: {vehicle: a}\n", 4, "links.x", "missing 'channel'"),
    (ONE + "links:\n  x: {vehicle: a, channel: rf}\n", 4, "links.x.channel", "no channel 'rf'"),
    (ONE + "links:\n  x: {vehicle: a, address: 1}\n  y: {vehicle: a, address: 1}\n",
     5, "links.y.address", "already used"),
    (ONE + "links:\n  x: {vehicle: a, address: 255}\n", 4, "links.x.address", "broadcast address"),
    (ONE + "links:\n  x: {vehicle: a, address: 65535}\n", 4, "links.x.address", "at most 65534"),
    (ONE + "links:\n  x:\n    vehicle: a\n    packet: dlf16\n    address: 300\n", 7, "links.x.address",
     "packet class dlf16 carries a one-byte address on air"),
    (ONE + "links:\n  x: {vehicle: a, range_m: [6, 0.5]}\n", 4, "links.x.range_m", "below min"),
    (ONE + "links:\n  x: {vehicle: a, mac: {protocol: tdma}}\n", 4, "links.x.mac.protocol", "unknown MAC protocol"),
    (ONE + "links:\n  x: {vehicle: a, packet: vl3b}\n", 4, "links.x.packet", "simple:N"),
    (XY + "  - {from: x, to: z, size_bytes: 20, interval_s: 1}\n",
     7, "flows[0].to", "no link 'z'"),
    (XY + "  - {from: x, to: y, size_bytes: 20}\n",
     7, "flows[0]", "exactly one of interval_s or rate_hz"),
    (XY + "  - {from: x, to: y, size_bytes: 0, interval_s: 1}\n",
     7, "flows[0].size_bytes", "at least 1"),
    (XY + "  - {from: x, to: y, size_bytes: 2, interval_s: 1,\n"
     "     start_s: 5, stop_s: 5}\n", 8, "flows[0].stop_s", "after start_s"),
    ("channels: {a: {speed_mps: 1}, b: {speed_mps: 1}}\nvehicles: {v: {pose: {static: [0,0,0]}}}\n"
     "links:\n  x: {vehicle: v, channel: a}\n  y: {vehicle: v, channel: b}\nflows:\n"
     "  - {from: x, to: y, size_bytes: 2, interval_s: 1}\n", 7, "flows[0].to", "can never hear"),
    ("chanels: {}\n", 1, "chanels", "did you mean 'channels'"),
    ("channels: {ac: {speed_mps: 1500}}\nvehicles:\n  a:\n    pose:\n      path:\n        start: [0,0,0]\n"
     "        legs: [{to: [1,0,0]}]\nlinks: {}\n", 7, "vehicles.a.pose.path.legs[0]", "exactly one of speed_mps"),
    ("channels: {ac: {speed_mps: 1500}}\nvehicles:\n  a:\n    pose:\n      path:\n        start: [0,0,0]\n"
     "        legs: [{to: [1,0,0], speed_mps: 1}]\n        loop: true\nlinks: {}\n",
     5, "vehicles.a.pose.path", "must end where it starts"),
    ("channels: {ac: {speed_mps: 1500}}\nvehicles:\n  a:\n    pose:\n      waypoints:\n        - [0, 0, 0, 0]\n"
     "        - [0, 1, 0, 0]\nlinks: {}\n", 7, "vehicles.a.pose.waypoints[1]", "times must increase"),
    ("channels: {ac: {speed_mps: 1500}\nvehicles: {}\n", 2, "", "not valid YAML"),
    ("channels: {ac: {speed_mps: -1}}\nvehicles: {}\nlinks: {}\n", 1, "channels.ac.speed_mps", "greater than 0"),
    ("seed: -1\nchannels: {ac: {speed_mps: 1}}\nvehicles: {}\nlinks: {}\n", 1, "seed", "at least 0"),
    (ONE + "links:\n  bad/id: {vehicle: a}\n", 4, "links.bad/id", "POSIX queues"),
    (ONE + "links:\n  x: {vehicle: a, emulate: {protocol: evologics, tcp: 9200},\n"
     "      firmware: {version: 1.10}}\n", 5, "links.x.firmware.version", "in quotes"),
    (ONE + "links:\n  x: {vehicle: a, firmware: {phi: \"0.1\"}}\n", 4, "links.x.firmware.phi", "did you mean 'phy'"),
])
def test_errors_name_file_line_and_key(text, where, key, words):
    error = error_of(text)
    assert error.file == "scene.yaml"
    assert error.line == where, str(error)
    assert error.path == key, str(error)
    assert words in error.message, str(error)
    assert str(error).startswith(f"scene.yaml:{where}: ")


def test_empty_scene_is_an_error():
    assert "empty" in str(error_of(""))


def test_an_error_inside_a_user_preset_names_the_preset_file(tmp_path):
    preset = tmp_path / "mymodem.yaml"
    preset.write_text("bitrate_bps: 1900\ntx_delay_s: soon\n")
    scene_file = tmp_path / "scene.yaml"
    scene_file.write_text("channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0,0,0]}}}\n"
                          "links:\n  x: {vehicle: a, model: mymodem.yaml}\n")
    with pytest.raises(SceneError) as info:
        load_scene(str(scene_file))
    assert info.value.file == str(preset) and info.value.line == 2 and info.value.path == "links.x.tx_delay_s"


def test_preset_refuses_keys_that_are_not_modem_keys(tmp_path):
    (tmp_path / "p.yaml").write_text("bitrate_bps: 1900\nvehicle: a\n")
    (tmp_path / "s.yaml").write_text("channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0,0,0]}}}\n"
                                     "links:\n  x: {vehicle: a, model: p.yaml}\n")
    with pytest.raises(SceneError) as info:
        load_scene(str(tmp_path / "s.yaml"))
    assert info.value.line == 2 and info.value.path == "vehicle"


def test_nested_override_merges_key_by_key():
    scene = load_scene_text("channels: {rf: {speed_mps: 2.25e7}}\nvehicles: {a: {pose: {static: [0,0,0]}}}\n"
                            "links: {x: {vehicle: a, model: s100, error: {expr: '0'}}}\n")
    error = scene.links["x"].params.error
    assert error.unit == "bit" and error.expression.text == "0"


def test_set_overrides_with_wildcards():
    scene = load_scene_text(GOOD, "good.yaml", ["links.*.bitrate_bps=900", "seed=42"])
    assert {l.params.bitrate_bps for l in scene.links.values()} == {900.0}
    assert scene.seed == 42
    error = error_of(GOOD, "links.*.bitrate_bsp=900")
    assert error.path == "links.rov0_rf.bitrate_bsp" and error.file == "--set"
    assert "matched nothing" in str(error_of(GOOD, "links.nothing.*=1"))


def test_yaml_1_2_floats_are_numbers():
    scene = load_scene_text("channels: {rf: {speed_mps: 2.25e7, min_delay_s: 1e-3}}\nvehicles: {}\nlinks: {}\n")
    assert scene.channels["rf"].speed_mps == 2.25e7 and scene.channels["rf"].min_delay_s == 0.001


def test_shipped_scenes_are_valid():
    folder = os.path.join(REPO, "scenes")
    names = [n for n in os.listdir(folder) if n.endswith(".yaml")]
    assert "demo.yaml" in names
    for name in names:
        load_scene(os.path.join(folder, name))


def test_check_exits_2_with_one_line_and_no_traceback(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0,0,0]}}}\n"
                   "links:\n  x: {vehicle: a, fifo_byte: 10}\n")
    result = subprocess.run([sys.executable, "-m", "hilgate", "check", str(bad)], capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr.strip() == f"hilgate: {bad}:4: links.x.fifo_byte: unknown key (did you mean 'fifo_bytes'?)"
    assert "Traceback" not in result.stderr
    missing = subprocess.run([sys.executable, "-m", "hilgate", "sim", str(tmp_path / "nope.yaml")],
                             capture_output=True, text=True)
    assert missing.returncode == 2 and "cannot read" in missing.stderr and "Traceback" not in missing.stderr
