"""Water that contradicts itself, or modems outside it, is one ``FILE:LINE: key: what is wrong`` (issue 38).

Before: a bathymetry starting shallower than ``depth_m`` put BELLHOP's sources in the sediment (every cell
of ``hilgate check`` 250 dB / PER 1), a modem under the bottom or above the surface was looked up as if
clamped into the water, and a profile that stopped short was extended with its last speed, all without a
word; Munk's profile, built in, was refused as a scene value.  No BELLHOP runs here: loading only.
"""

from __future__ import annotations

import textwrap

import pytest

from hilgate.models.environment import munk_speed
from hilgate.scene import SceneError, load_scene_text


def scene(water: str, vehicle: str = "{static: [0, 0, 10]}", extra: str = "") -> str:
    """A scene with channel ``ac`` holding ``water`` (YAML lines) and vehicle ``a`` with link ``la`` on it."""
    lines = ["channels:", "  ac:", "    speed_mps: 1500", "    water:"]
    lines += ["      " + line for line in textwrap.dedent(water).splitlines()]
    lines += ["vehicles:", "  a:", f"    pose: {vehicle}"] + ([extra] if extra else [])
    lines += ["links:", "  la: {vehicle: a, address: 1, channel: ac}"]
    return "\n".join(lines) + "\n"


def error_of(text: str) -> str:
    with pytest.raises(SceneError) as info:
        load_scene_text(text, "w.yaml")
    message = str(info.value)
    assert "\n" not in message
    return message


def line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


# -- the bottom under the sender -------------------------------------------------------------------------


def test_a_bathymetry_shallower_than_depth_m_at_the_sender_is_refused():
    text = scene("""\
    depth_m: 100
    sound_speed: [[0, 1500], [100, 1500]]
    bathymetry: [[0, 40], [2000, 30]]
    """)
    message = error_of(text)
    assert message.startswith(f"w.yaml:{line_of(text, 'bathymetry')}: channels.ac.water.bathymetry[0][1]: "), message
    assert "40" in message and "depth_m" in message and "100" in message


def test_a_bathymetry_that_starts_beyond_the_sender_is_read_from_its_first_row():
    """BELLHOP extends the first row back to range 0: that depth is the water under the sender."""
    text = scene("""\
    depth_m: 100
    sound_speed: [[0, 1500], [100, 1500]]
    bathymetry: [[500, 80], [2000, 60]]
    """)
    assert "channels.ac.water.bathymetry[0][1]: " in error_of(text)


def test_depth_m_may_be_left_to_the_bathymetry():
    text = scene("""\
    sound_speed: [[0, 1500], [100, 1500]]
    bathymetry: [[0, 100], [2000, 60]]
    """)
    water = load_scene_text(text, "w.yaml").channels["ac"].water
    assert water.depth_m == 100.0


def test_a_consistent_bathymetry_loads():
    text = scene("""\
    depth_m: 100
    sound_speed: [[0, 1500], [120, 1490]]
    bathymetry: [[0, 100], [1000, 120], [2000, 60]]
    """)
    water = load_scene_text(text, "w.yaml").channels["ac"].water
    assert water.deepest_m == 120.0 and water.sound_speed[-1] == (120.0, 1490.0)


# -- the profile reaches the bottom ------------------------------------------------------------------------


@pytest.mark.parametrize("water, key, words", [
    ("depth_m: 100\nsound_speed: [[0, 1500], [40, 1490]]\n", "channels.ac.water.sound_speed", ["40", "100"]),
    ("depth_m: 100\nsound_speed: [[0, 1500]]\n", "channels.ac.water.sound_speed", ["0 m", "100", "sound_speed: 1500"]),
    ("depth_m: 100\ntemperature_c: [[0, 12], [60, 8]]\n", "channels.ac.water.temperature_c", ["60", "100"]),
    # the profile must reach the deepest water the bathymetry has, not only depth_m
    ("depth_m: 100\nsound_speed: [[0, 1500], [100, 1490]]\nbathymetry: [[0, 100], [900, 150]]\n",
     "channels.ac.water.sound_speed", ["100", "150"]),
])
def test_a_profile_that_stops_above_the_bottom_is_refused(water, key, words):
    text = scene(water)
    message = error_of(text)
    where = "temperature_c" if "temperature_c" in water else "sound_speed"
    assert message.startswith(f"w.yaml:{line_of(text, where)}: {key}: "), message
    assert all(word in message for word in words), message


def test_one_speed_is_the_same_speed_at_every_depth():
    text = scene("depth_m: 100\nsound_speed: 1490\nbathymetry: [[0, 100], [900, 150]]\n")
    water = load_scene_text(text, "w.yaml").channels["ac"].water
    assert water.sound_speed == ((0.0, 1490.0), (150.0, 1490.0))
    text = scene("depth_m: 100\ntemperature_c: 10\n")
    water = load_scene_text(text, "w.yaml").channels["ac"].water
    assert water.sound_speed[0][0] == 0.0 and water.sound_speed[-1][0] == 100.0


# -- Munk's profile ----------------------------------------------------------------------------------------


def test_munk_is_a_scene_value():
    text = scene("depth_m: 5000\nsound_speed: munk\n", "{static: [0, 0, 1000]}")
    water = load_scene_text(text, "w.yaml").channels["ac"].water
    depths = [z for z, _ in water.sound_speed]
    assert depths[0] == 0.0 and depths[-1] == 5000.0 and max(b - a for a, b in zip(depths, depths[1:])) <= 50.0
    assert all(c == pytest.approx(munk_speed(z)) for z, c in water.sound_speed)
    assert min(water.sound_speed, key=lambda p: p[1])[0] == pytest.approx(1300.0, abs=50.0)  # the axis


def test_a_misspelt_munk_says_what_it_could_be():
    text = scene("depth_m: 5000\nsound_speed: mnuk\n")
    message = error_of(text)
    assert message.startswith(f"w.yaml:{line_of(text, 'sound_speed')}: channels.ac.water.sound_speed: "), message
    assert "did you mean 'munk'" in message


# -- modems in the water -----------------------------------------------------------------------------------


WATER = "depth_m: 100\nsound_speed: [[0, 1500], [100, 1500]]\nsurface_z_m: -5\n"


@pytest.mark.parametrize("pose, key, words", [
    ("{static: [0, 0, 120]}", "vehicles.a.pose.static[2]", ["125 m deep", "bottom", "100 m", "la"]),
    ("{static: [0, 0, -8]}", "vehicles.a.pose.static[2]", ["3 m above the surface", "la"]),
    ("{path: {start: [0, 0, 10], legs: [{to: [100, 0, 50], speed_mps: 1}, {to: [200, 0, 101], speed_mps: 1}]}}",
     "vehicles.a.pose.path.legs[1].to[2]", ["106 m deep", "bottom"]),
    ("{waypoints: [[0, 0, 0, 10], [10, 5, 0, -6]]}", "vehicles.a.pose.waypoints[1][3]", ["above the surface"]),
    ("{controlled: {start: [0, 0, 200], max_speed_mps: 1}}", "vehicles.a.pose.controlled.start[2]", ["bottom"]),
])
def test_a_modem_outside_the_water_is_refused(pose, key, words):
    text = scene(WATER, pose)
    message = error_of(text)
    assert message.startswith(f"w.yaml:{line_of(text, 'pose:')}: {key}: "), message
    assert all(word in message for word in words), message


def test_modems_at_the_surface_and_on_the_bottom_are_in_the_water():
    for z in (-5, 95, 47.5):
        load_scene_text(scene(WATER, f"{{static: [0, 0, {z}]}}"), "w.yaml")


def test_a_vehicle_whose_links_are_not_on_the_water_channel_may_be_anywhere():
    text = scene(WATER, "{static: [0, 0, 10]}", "  b: {pose: {static: [0, 0, 500]}}").replace(
        "links:\n", "links:\n  lb: {vehicle: b, address: 2, channel: air}\n").replace(
        "channels:\n", "channels:\n  air: {speed_mps: 3.0e8}\n")
    load_scene_text(text, "w.yaml")
