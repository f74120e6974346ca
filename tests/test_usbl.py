"""USBL fixes and the reception figures, as pure arithmetic (models/usbl.py, models/link_budget.py)."""

import math
import random
import statistics

import pytest

from hilgate.models.link_budget import SimpleLinkBudget, radial_speed, reception
from hilgate.models.trajectories import Piecewise, Static, path_segments
from hilgate.models.usbl import UsblParams, fix

EXACT = dict(abs=1e-12)
Z = 5.0  # the bound of the seeded statistical checks, in standard errors


def test_without_noise_the_fix_is_the_geometry():
    f = fix((1, 2, 3), (31, 42, 13), UsblParams())
    assert f.local == pytest.approx((30, 40, 10), **EXACT)
    assert f.enu == pytest.approx((40, 30, -10), **EXACT)  # east, north, up
    assert f.range_m == pytest.approx(math.sqrt(30 ** 2 + 40 ** 2 + 10 ** 2), **EXACT)
    assert f.bearing == pytest.approx(math.atan2(40, 30), **EXACT) == f.local_bearing
    assert f.elevation == pytest.approx(-math.asin(10 / f.range_m), **EXACT)  # below: negative
    assert f.accuracy_m == 0.0


def test_the_mounting_orientation_turns_the_local_frame_only():
    yaw = fix((0, 0, 0), (30, 40, 10), UsblParams((0.0, 0.0, math.pi / 2)))
    assert yaw.local == pytest.approx((40, -30, 10), abs=1e-9)  # x along east, y along south
    assert yaw.enu == pytest.approx((40, 30, -10), abs=1e-9)
    assert yaw.bearing == pytest.approx(math.atan2(40, 30), abs=1e-12)
    assert yaw.local_bearing == pytest.approx(math.atan2(-30, 40), abs=1e-12)
    flipped = fix((0, 0, 0), (30, 40, 10), UsblParams((math.pi, 0.0, 0.0)))  # mounted upside down
    assert flipped.local == pytest.approx((30, -40, -10), abs=1e-9)
    pitched = fix((0, 0, 0), (0, 0, 10), UsblParams((0.0, math.pi / 2, 0.0)))  # pitched up: x points up
    assert pitched.local == pytest.approx((-10, 0, 0), abs=1e-9)


def test_with_noise_range_and_angles_have_the_configured_sigma():
    n, sigma_r, sigma_b = 4000, 0.5, math.radians(2.0)
    params = UsblParams((0.1, -0.2, 1.0), sigma_b, sigma_r)
    rng = random.Random(11)
    own, remote = (0, 0, 0), (300, -200, 50)
    truth = fix(own, remote, params)
    fixes = [fix(own, remote, params, rng) for _ in range(n)]
    range_errors = [f.range_m - truth.range_m for f in fixes]
    bearing_errors = [math.remainder(f.local_bearing - truth.local_bearing, math.tau) for f in fixes]
    for errors, sigma in ((range_errors, sigma_r), (bearing_errors, sigma_b)):
        assert abs(statistics.fmean(errors)) < Z * sigma / math.sqrt(n)
        assert abs(statistics.stdev(errors) - sigma) < Z * sigma / math.sqrt(2 * (n - 1))
    for f in fixes[:50]:  # the position is the measured range along the measured direction
        assert math.dist((0, 0, 0), f.local) == pytest.approx(f.range_m, abs=1e-9)
        assert math.dist((0, 0, 0), f.enu) == pytest.approx(f.range_m, abs=1e-9)
    assert fixes[0].accuracy_m == pytest.approx(math.sqrt(sigma_r ** 2 + 2 * (fixes[0].range_m * sigma_b) ** 2))


def test_without_noise_nothing_is_drawn():
    rng = random.Random(3)
    state = rng.getstate()
    fix((0, 0, 0), (1, 1, 1), UsblParams(), rng)
    assert rng.getstate() == state


def test_reception_figures_from_distance_and_radial_speed():
    budget = SimpleLinkBudget(8000.0)
    assert round(budget.rssi_db(1000)) == round(-20 - 60 - 1)
    assert budget.integrity(0) == 250 and budget.integrity(8000) == 50 and budget.integrity(4000) == 150
    assert SimpleLinkBudget().integrity(1e6) == 250
    towards = Piecewise(path_segments([100, 0, 0], [{"to": [0, 0, 0], "speed_mps": 1.5}]))
    assert radial_speed(towards, Static((0, 0, 0)), 10.0) == pytest.approx(1.5, abs=1e-9)
    sideways = Piecewise(path_segments([0, 100, 0], [{"to": [100, 100, 0], "speed_mps": 1.0}]))
    assert radial_speed(sideways, Static((0, 0, 0)), 0.0) == pytest.approx(0.0, abs=1e-3)
    heard = reception(towards, Static((0, 0, 0)), 20.0, budget)
    assert heard.distance_m == pytest.approx(70.0) and heard.velocity_mps == pytest.approx(1.5)
    assert heard.sender == pytest.approx((70, 0, 0)) and heard.receiver == (0, 0, 0)


def scene_text(link_extra: str) -> str:
    return ("channels: {ac: {speed_mps: 1500}}\n"
            "vehicles: {v: {pose: {static: [0, 0, 0]}}}\n"
            f"links:\n  l: {{vehicle: v, model: evologics-s2cr-7-17{link_extra}}}\n")


def test_the_scene_reads_usbl_and_ack_keys_and_refuses_them_where_they_mean_nothing():
    from hilgate.scene import SceneError, load_scene_text

    link = load_scene_text(scene_text(", emulate: {protocol: evologics, tcp: 9300}, usbl: "
                                      "{orientation_deg: [0, 180, 90], bearing_sigma_deg: 1, range_sigma_m: 0.2}"),
                           "s.yaml").links["l"]
    assert link.usbl.orientation == pytest.approx((0, math.pi, math.pi / 2))
    assert link.usbl.bearing_sigma == pytest.approx(math.radians(1)) and link.usbl.range_sigma_m == 0.2
    assert link.params.ack_bytes == 6 and link.params.ack_turnaround_s == 0.27  # from the preset
    assert load_scene_text(scene_text(", emulate: {protocol: evologics, tcp: 9300}, usbl: true"),
                           "s.yaml").links["l"].usbl == UsblParams()
    for extra, key, words in [
        (", usbl: true", "links.l.usbl", "only an emulated EvoLogics modem"),
        (", emulate: {protocol: evologics, tcp: 9300}, usbl: {bearing_sigma: 1}", "links.l.usbl", "bearing_sigma"),
        (", emulate: {protocol: evologics, tcp: 9300}, usbl: {orientation_deg: [0, 0]}",
         "links.l.usbl.orientation_deg", "[roll, pitch, yaw]"),
        (", ack_turnaround_s: -1", "links.l.ack_turnaround_s", ""),
        (", ack_bytes: 0", "links.l.ack_bytes", ""),
    ]:
        with pytest.raises(SceneError) as info:
            load_scene_text(scene_text(extra), "s.yaml")
        message = str(info.value)
        assert message.startswith("s.yaml:4:") and key in message and words in message, message
