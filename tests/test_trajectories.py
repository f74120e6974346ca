"""Scripted vehicle motion: static, legged paths (hold, speed, duration, loop) and waypoints."""

import math

import pytest

from hilgate.sim.pose_sources import build_pose
from hilgate.scene import load_scene_text

EXACT = dict(abs=1e-12)


def vehicle(pose_yaml: str):
    scene = load_scene_text(f"channels: {{ac: {{speed_mps: 1500}}}}\nvehicles:\n  v:\n    pose:\n{pose_yaml}\nlinks: {{}}\n")
    return build_pose(scene.vehicles["v"])


def test_static_is_static():
    source = vehicle("      static: [1, 2, 3]")
    assert source.static and source.position(1e6) == (1.0, 2.0, 3.0)


def test_path_legs_hold_speed_and_duration():
    source = vehicle("""      path:
        start: [0.8, 0, 0]
        legs:
          - {hold_s: 11}
          - {to: [5.8, 0, 0], speed_mps: 0.25}
          - {to: [4.55, 0, 0], duration_s: 5}
          - {hold_s: 10}""")
    assert not source.static
    assert source.position(-1) == (0.8, 0.0, 0.0)
    assert source.position(11) == (0.8, 0.0, 0.0)
    assert source.position(21)[0] == pytest.approx(0.8 + 2.5, **EXACT)
    assert source.position(31)[0] == pytest.approx(5.8, **EXACT)
    assert source.position(33.5)[0] == pytest.approx(5.8 - 1.25 / 2, **EXACT)
    assert source.position(36)[0] == pytest.approx(4.55, **EXACT)
    assert source.position(1000)[0] == pytest.approx(4.55, **EXACT)


def test_path_speed_in_three_dimensions():
    source = vehicle("""      path:
        start: [0, 0, 0]
        legs: [{to: [3, 4, 12], speed_mps: 1.3}]""")  # 13 m at 1.3 m/s = 10 s
    assert source.position(5) == pytest.approx((1.5, 2.0, 6.0), **EXACT)
    assert source.position(10) == pytest.approx((3.0, 4.0, 12.0), **EXACT)


def test_looping_path_repeats_with_its_period():
    source = vehicle("""      path:
        start: [0, 0, 0]
        legs:
          - {to: [10, 0, 0], duration_s: 10}
          - {to: [0, 0, 0], duration_s: 10}
        loop: true""")
    for t, x in ((5, 5), (15, 5), (25, 5), (35, 5), (20, 0), (40, 0), (1005, 5)):
        assert source.position(t)[0] == pytest.approx(x, abs=1e-9), t


def test_waypoints_are_linear_in_between_and_held_outside():
    source = vehicle("""      waypoints:
        - [2, 0, 0, 0]
        - [4, 10, 0, 0]
        - [8, 10, 20, 0]""")
    assert source.position(0) == (0.0, 0.0, 0.0)
    assert source.position(3) == pytest.approx((5.0, 0.0, 0.0), **EXACT)
    assert source.position(6) == pytest.approx((10.0, 10.0, 0.0), **EXACT)
    assert source.position(9) == (10.0, 20.0, 0.0)


def test_a_path_that_never_moves_is_static():
    assert vehicle("      path: {start: [1, 1, 1], legs: [{hold_s: 5}]}").static
    assert vehicle("      waypoints: [[0, 1, 1, 1]]").static
    assert math.dist(vehicle("      waypoints: [[0, 1, 1, 1]]").position(3), (1, 1, 1)) == 0
