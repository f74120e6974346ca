"""The channel that knows the water (issue 28), checked against the BELLHOP program itself and against
physics it must reproduce.  BELLHOP is pelagic run as a separate program from ``.venv-bellhop``
(``bellhop_kit``), on small grids so that every run takes a second or two.

- Our ``.shd``/``.arr`` readers give back, value for value, what the program reports it computed.
- Deep isovelocity water: the looked-up TL is spherical spreading plus Thorp's absorption, and the first
  arrival's delay is the distance over the sound speed.
- The Munk profile: the first arrival's delay equals that of the earliest eigenray our own ray
  integration (RK4 on the ray equations, below) finds.
- A simulated link through the lookup loses frames at the PER of the looked-up SNR (a z-test).
"""

from __future__ import annotations

import json
import math
import os
import textwrap

import numpy as np
import pytest

from bellhop_kit import ensure_program, run_with_report
from hilgate.channel.arrfile import first_and_spread, read_arr
from hilgate.channel.envfile import ARRIVALS_RUN, TL_RUN, env_text
from hilgate.channel.prepare import ready_channels
from hilgate.channel.runner import BellhopError, Program, prepare_fields
from hilgate.channel.shdfile import FieldFileError, read_shd
from hilgate.models.acoustics import thorp_db_per_km
from hilgate.models.environment import SEDIMENTS, Water, munk_speed
from hilgate.scene import SceneError, load_scene_text


@pytest.fixture(scope="session")
def program() -> Program:
    return ensure_program()


@pytest.fixture(scope="session")
def cache(tmp_path_factory) -> str:
    """A cache of fields for the whole run, laid out as ``$HILGATE_CACHE/bellhop``."""
    path = tmp_path_factory.mktemp("cache") / "bellhop"
    path.mkdir()
    return str(path)


DEEP = Water(depth_m=10000.0, sound_speed=((0.0, 1500.0), (10000.0, 1500.0)), bottom=SEDIMENTS["clay"],
             range_m=2000.0, ranges=40, depths=100, source_depths=1, arrival_ranges=20, arrival_depths=100)
"""10 km of 1500 m/s water: the source at 5 000 m (one bin), receivers every 100 m from 50 m, ranges
50 m to 2 km.  The surface- and bottom-reflected paths travel 10 km more than the direct one: at 2 km
they are 28 dB below it (0.01 dB in an incoherent sum), so the field is the direct path's."""


# -- the readers against the program's own values -------------------------------------------------


def test_shd_reader_gives_the_programs_field(program, tmp_path):
    root = str(tmp_path / "tl")
    (tmp_path / "tl.env").write_text(env_text(DEEP, 12000.0, TL_RUN))
    report = json.loads(open(run_with_report(root), encoding="utf-8").read())
    shade = read_shd((tmp_path / "tl.shd").read_bytes())
    assert shade.frequency_hz == report["frequency_hz"] == 12000.0
    assert shade.plot_type == "rectilin"
    np.testing.assert_allclose(shade.source_depths, report["sources"])
    np.testing.assert_allclose(shade.receiver_depths, report["depths"], rtol=1e-6)
    np.testing.assert_allclose(shade.ranges, report["ranges"])
    ours = shade.transmission_loss_db()
    theirs = np.array([[[np.inf if v is None else v for v in row] for row in plane] for plane in report["tl_db"]])
    assert ours.shape == theirs.shape == (1, 100, 40)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-4)  # float32 pressure, −20·log10 of it


def test_arr_reader_gives_the_programs_arrivals(program, tmp_path):
    root = str(tmp_path / "arr")
    (tmp_path / "arr.env").write_text(env_text(DEEP, 12000.0, ARRIVALS_RUN))
    report = json.loads(open(run_with_report(root), encoding="utf-8").read())
    arrivals = read_arr((tmp_path / "arr.arr").read_text())
    assert arrivals.shape == (1, 100, 20)
    assert len(arrivals.amplitude) == len(report["amplitude"]) > 1000
    # pelagic lists receivers range by range, the file depth by depth: match them by their place
    depth_index = {round(z, 3): i for i, z in enumerate(arrivals.receiver_depths)}
    range_index = {round(r, 3): i for i, r in enumerate(arrivals.ranges)}
    per_source = report["receiver_offset"]
    offsets = report["arrival_offset"]
    compared = 0
    for isz in range(1):
        for k in range(per_source[isz], per_source[isz + 1]):
            a, b = offsets[k], offsets[k + 1]
            rows = arrivals.at(isz, depth_index[round(report["receiver_depths"][k], 3)],
                               range_index[round(report["receiver_ranges"][k], 3)])
            assert rows.stop - rows.start == b - a
            np.testing.assert_allclose(arrivals.amplitude[rows], report["amplitude"][a:b], rtol=1e-8)
            np.testing.assert_allclose(arrivals.delay_s[rows], report["travel_time_s"][a:b], rtol=1e-8)
            np.testing.assert_allclose(np.radians(arrivals.phase_deg[rows]), report["phase_radians"][a:b], atol=1e-8)
            np.testing.assert_array_equal(arrivals.bottom_bounces[rows], report["bottom_bounces"][a:b])
            compared += b - a
    assert compared == len(arrivals.amplitude)


@pytest.mark.parametrize("data, message", [
    (b"", "fewer than 4 bytes"),
    (b"\x29\x00\x00\x00" + b" " * 400, "truncated shade file"),
    (b"\xff\xff\xff\x7f" + b" " * 100, "record length"),
])
def test_shd_reader_refuses_what_is_not_a_shade_file(data, message):
    with pytest.raises(FieldFileError, match=message):
        read_shd(data)


@pytest.mark.parametrize("text, message", [
    ("", "ends before its kind"),
    ("'3D'\n", "not a 2-D ASCII arrivals file"),
    ("'2D'\n12000\n1 10\n1 10\n1 100\n1\n1\n0.1 0 0.06", "ends within an arrival"),
    ("'2D'\n12000\n1 10\n1 10\n1 100\n1\n5\n", "a number of arrivals 5"),
    ("'2D'\n12000\n1 10\n1 nan\n", "not finite"),
])
def test_arr_reader_refuses_what_is_not_an_arrivals_file(text, message):
    with pytest.raises(FieldFileError, match=message):
        read_arr(text)


def test_shd_reader_survives_random_bytes():
    rng = np.random.default_rng(28)
    for _ in range(200):
        data = rng.integers(0, 256, int(rng.integers(0, 3000)), dtype=np.uint8).tobytes()
        try:
            read_shd(data)
        except FieldFileError:
            pass


# -- physics ---------------------------------------------------------------------------------------------


def test_deep_isovelocity_tl_is_spherical_spreading_plus_absorption(program, cache):
    """Direct path only: TL = 20·log10(R) + α·R/1000 (R the slant distance, α Thorp's at 12 kHz).  The
    tolerance, 0.5 dB, covers the beams' discretisation (BELLHOP's incoherent sum of Gaussian beams is
    smooth to a few hundredths of a dB here) and the bilinear lookup between grid points 50 m and
    100 m apart, where 20·log10 R bends by at most 0.3 dB at the nearest range the test uses."""
    fields = prepare_fields(DEEP, [12000.0], program=program, cache=cache)[0]
    alpha = thorp_db_per_km(12.0)
    worst = 0.0
    for r in (300.0, 500.0, 777.0, 1000.0, 1500.0, 2000.0):
        for zr in (4850.0, 5000.0, 5120.0, 5300.0):
            slant = math.hypot(r, zr - 5000.0)
            expected = 20.0 * math.log10(slant) + alpha * slant / 1000.0
            worst = max(worst, abs(fields.tl_db(r, 5000.0, zr) - expected))
    assert worst < 0.5


def test_first_arrival_is_distance_over_speed_in_isovelocity_water(program, cache):
    """The delay a frame takes is the direct path's, d / 1500 m/s, within 0.2 ms (the lookup between
    grid points 100 m apart on a curve whose bend there is < 0.1 ms; BELLHOP's own delays are exact)."""
    fields = prepare_fields(DEEP, [12000.0], program=program, cache=cache)[0]
    for r in (300.0, 600.0, 1000.0, 1450.0, 2000.0):
        for zr in (4650.0, 5000.0, 5350.0):
            assert fields.delay_s(r, 5000.0, zr) == pytest.approx(math.hypot(r, zr - 5000.0) / 1500.0, abs=2e-4)


MUNK_DEPTHS = [float(z) for z in range(0, 5001, 250)]
MUNK = Water(depth_m=5000.0, sound_speed=tuple((z, munk_speed(z)) for z in MUNK_DEPTHS), bottom=SEDIMENTS["sand"],
             range_m=10000.0, ranges=10, depths=50, source_depths=5, arrival_ranges=10, arrival_depths=50, beams=2001)
"""Munk's profile (tabulated every 250 m, c-linear between, as the Toolbox's MunkB cases), sources at
500, 1 500, … m, receivers every 100 m, ranges every km to 10 km."""


def _munk_speed_and_slope(z: np.ndarray, table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """c(z) and dc/dz of the tabulated profile, linear in between: the profile BELLHOP was given."""
    zs, cs = table[:, 0], table[:, 1]
    i = np.clip(np.searchsorted(zs, z, side="right") - 1, 0, len(zs) - 2)
    slope = (cs[i + 1] - cs[i]) / (zs[i + 1] - zs[i])
    return cs[i] + slope * (z - zs[i]), slope


def munk_eigenray_times(r_target: float, zs: float, zr: float, table: np.ndarray) -> list[float]:
    """The travel times of the eigenrays from (0, zs) to (r_target, zr) that touch neither boundary:
    a fan of 4 001 rays within ±25° integrated with RK4 on dr/ds = cξ, dz/ds = cζ, dζ/ds = −c_z/c²,
    dt/ds = 1/c (ξ constant: range-independent), in steps of 2 m; two neighbouring rays that bracket
    zr at r_target hold an eigenray, whose time is interpolated between them."""
    angles = np.radians(np.linspace(-25.0, 25.0, 4001))
    c0, _ = _munk_speed_and_slope(np.array([zs]), table)
    xi = np.cos(angles) / c0[0]
    state = np.stack([np.zeros_like(angles), np.full_like(angles, zs), np.sin(angles) / c0[0],
                      np.zeros_like(angles)])  # r, z, ζ, t
    alive = np.ones(len(angles), dtype=bool)
    ds = 2.0

    def slope(s: np.ndarray) -> np.ndarray:
        c, cz = _munk_speed_and_slope(s[1], table)
        return np.stack([c * xi, c * s[2], -cz / (c * c), 1.0 / c])

    done = np.zeros(len(angles), dtype=bool)
    z_at = np.zeros(len(angles))
    t_at = np.zeros(len(angles))
    while not np.all(done | ~alive):
        before = state.copy()
        k1 = slope(state)
        k2 = slope(state + ds / 2 * k1)
        k3 = slope(state + ds / 2 * k2)
        k4 = slope(state + ds * k3)
        state = state + ds / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        alive &= (state[1] > 0.0) & (state[1] < 5000.0)
        crossing = ~done & (state[0] >= r_target)
        f = (r_target - before[0][crossing]) / (state[0][crossing] - before[0][crossing])
        z_at[crossing] = before[1][crossing] + f * (state[1][crossing] - before[1][crossing])
        t_at[crossing] = before[3][crossing] + f * (state[3][crossing] - before[3][crossing])
        done |= crossing
    times = []
    ok = alive & done
    for i in range(len(angles) - 1):
        if ok[i] and ok[i + 1] and (z_at[i] - zr) * (z_at[i + 1] - zr) <= 0.0 and z_at[i] != z_at[i + 1]:
            f = (zr - z_at[i]) / (z_at[i + 1] - z_at[i])
            times.append(t_at[i] + f * (t_at[i + 1] - t_at[i]))
    return times


def test_munk_first_arrival_matches_an_independent_ray_integration(program, cache):
    """A classic case: Munk's deep-water profile, source at 1 500 m (just under the sound channel's
    axis at 1 300 m), receiver at 1 000 m.  The first arrival the lookup gives at 5 and 10 km is the
    earliest eigenray of our own ray integration, within 0.5 ms (0.1 ms seen: the lookup interpolates
    the delay's residual over 100 m of receiver depth; the reference's step error is < 0.1 ms)."""
    fields = prepare_fields(MUNK, [50.0], program=program, cache=cache)[0]
    table = np.array(MUNK.sound_speed)
    for r in (5000.0, 8000.0, 10000.0):
        times = munk_eigenray_times(r, 1500.0, 1000.0, table)
        assert times
        assert fields.delay_s(r, 1500.0, 1000.0) == pytest.approx(min(times), abs=5e-4)
        # while the straight line at the mean sound speed (the lookup's fallback) is tens of ms off
        assert abs(min(times) - math.hypot(r, 500.0) / MUNK.mean_speed_mps) > 0.02


# -- the scene, the medium, the PER ------------------------------------------------------------------------


SCENE = """\
name: bellhop
seed: 5
duration_s: 160
channels:
  ac:
    speed_mps: 1500
    water:
      depth_m: 200
      sound_speed: [[0, 1500], [200, 1500]]
      bottom: clay
      grid: {{range_m: 1000, ranges: 20, depths: 20, source_depths: 4, arrival_ranges: 20, arrival_depths: 20}}
vehicles:
  a: {{pose: {{static: [0, 0, 75]}}}}
  b: {{pose: {{static: [{r}, 0, 75]}}}}
  c:
    pose:
      path: {{start: [100, 0, 25], legs: [{{to: [900, 0, 175], duration_s: 160}}]}}
links:
  la: {{vehicle: a, address: 1, bitrate_bps: 10000, range_m: [0, 5000],
        acoustic: {{band_khz: [10, 14], source_level_db: {sl}}}, error: {{kind: physical}}}}
  lb: {{vehicle: b, address: 2, bitrate_bps: 10000, range_m: [0, 5000],
        acoustic: {{band_khz: [10, 14], source_level_db: {sl}}}, error: {{kind: physical}}}}
  lc: {{vehicle: c, address: 3, bitrate_bps: 10000, range_m: [0, 5000],
        acoustic: {{band_khz: [10, 14], source_level_db: {sl}}}, error: {{kind: physical}}}}
flows:
  - {{from: la, to: lb, size_bytes: 16, interval_s: 0.04, stop_s: 159.99}}
"""


def _scene(r: float = 600.0, sl: float = 120.0):
    return load_scene_text(SCENE.format(r=r, sl=sl), "bellhop.yaml")


def _ready(scene, program, cache):
    return ready_channels(scene.channels, scene.links, program=program, cache=cache)


def test_a_static_pair_is_looked_up_once_and_a_moving_one_per_arrival(program, cache, monkeypatch):
    from hilgate.core.scheduler import VirtualScheduler
    from hilgate.models.bellhop_fields import ArrivalLoss, BellhopPath
    from hilgate.models.observer import NullObserver
    from hilgate.sim.world import World

    monkeypatch.setenv("HILGATE_CACHE", os.path.dirname(cache))
    world = World(_scene(), VirtualScheduler(), NullObserver())
    medium = world.medium
    medium._rebuild()
    sender = world.modems["la"].radio
    by_link = {nb.radio.host.id: nb for nb in medium._neighbours[sender]}
    static, moving = by_link["lb"], by_link["lc"]
    assert isinstance(static.model, ArrivalLoss) and not static.positional
    fields = static.model.path.fields
    assert static.model.tl_db == pytest.approx(fields.tl_db(600.0, 75.0, 75.0))
    assert static.tau == pytest.approx(fields.delay_s(600.0, 75.0, 75.0))
    assert static.tau == pytest.approx(600.0 / 1500.0, abs=2e-4)
    assert isinstance(moving.model, BellhopPath) and moving.positional
    at = moving.model.at((0.0, 0.0, 75.0), (500.0, 0.0, 100.0))
    assert at.delay == pytest.approx(math.hypot(500.0, 25.0) / 1500.0, abs=2e-4)


def test_simulated_per_through_the_lookup_is_the_analytic_per_at_the_looked_up_snr(program, cache, monkeypatch):
    """The source level is set so the PER at the pair's looked-up SNR is near 0.5; 4 000 frames are then
    lost binomially with that p: z = (k − np)/√(np(1 − p)) within ±3.5 (P = 4.7e-4 for a correct model;
    an SNR off by 0.3 dB moves p by ~0.05 and z by ~6)."""
    from hilgate.sim.simulate import simulate

    scene = _scene()
    path = _ready(scene, program, cache)["ac"].propagation
    bound = path.bind(scene.links["la"].params, scene.links["lb"].params).model
    reception = bound.at((0.0, 0.0, 75.0), (600.0, 0.0, 75.0))
    model = bound.model
    # SNR where PER(16 bytes) = 0.5, by bisection on the model's own curve
    low, high = -20.0, 40.0
    for _ in range(80):
        mid = (low + high) / 2
        low, high = (mid, high) if model.per_at_snr(mid, 16) > 0.5 else (low, mid)
    sl = 120.0 + (low - reception.snr_db())
    scene = _scene(sl=sl)
    bound = _ready(scene, program, cache)["ac"].propagation.bind(scene.links["la"].params, scene.links["lb"].params).model
    p = bound.at((0.0, 0.0, 75.0), (600.0, 0.0, 75.0)).per(600.0, 16)
    assert 0.45 < p < 0.55
    monkeypatch.setenv("HILGATE_CACHE", os.path.dirname(cache))
    summary = simulate(scene, until=162.0)
    flow = summary["flows"][0]
    n = flow["tx_packets"]
    k = flow["lost"]["prop"]
    assert n == 4000 and flow["rx_packets"] + k == n
    z = (k - n * p) / math.sqrt(n * p * (1 - p))
    assert abs(z) < 3.5, (k, n, p, z)


@pytest.mark.parametrize("water, where, message", [
    ("{depth_m: 100}", "channels.ac.water", "missing 'sound_speed'"),
    ("{depth_m: 100, sound_speed: [[5, 1500]]}", "channels.ac.water.sound_speed", "must start at the surface"),
    ("{depth_m: 100, sound_speed: [[0, 1500], [200, 1490]]}", "channels.ac.water.sound_speed", "below the bottom"),
    ("{depth_m: 100, sound_speed: [[0, 1500], [0, 1490]]}", "channels.ac.water.sound_speed[1]", "rows go outwards"),
    ("{depth_m: 100, sound_speed: [[0, 900]]}", "channels.ac.water.sound_speed[0][1]", "at least 1300"),
    ("{depth_m: 100, sound_speed: 1500, bottom: mud}", "channels.ac.water.bottom", "must be one of clay"),
    ("{depth_m: 100, sound_speed: 1500, botom: sand}", "channels.ac.water.botom", "did you mean 'bottom'"),
    ("{depth_m: 100, sound_speed: 1500, grid: {ranges: 100000, depths: 10000}}", "channels.ac.water.grid.ranges",
     "more than"),
    ("{depth_m: 100, temperature_c: [[0, 12]], sound_speed: [[0, 1500]]}", "channels.ac.water.temperature_c",
     "not both"),
])
def test_bad_water_is_a_one_line_error_with_its_line(water, where, message):
    text = textwrap.dedent(f"""\
    channels:
      ac:
        speed_mps: 1500
        water: {water}
    vehicles: {{a: {{pose: {{static: [0, 0, 0]}}}}}}
    links: {{la: {{vehicle: a, address: 1}}}}
    """)
    with pytest.raises(SceneError) as info:
        load_scene_text(text, "w.yaml")
    line = str(info.value)
    assert line.startswith("w.yaml:4: ") and where in line and message in line, line


def test_temperature_profile_becomes_mackenzie_sound_speed():
    text = textwrap.dedent("""\
    channels: {ac: {speed_mps: 1500, water: {depth_m: 100, temperature_c: [[0, 20], [100, 10]], salinity_ppt: 35}}}
    vehicles: {a: {pose: {static: [0, 0, 0]}}}
    links: {la: {vehicle: a, address: 1}}
    """)
    water = load_scene_text(text, "w.yaml").channels["ac"].water
    assert water.sound_speed[0] == (0.0, pytest.approx(1521.5, abs=0.1))  # Mackenzie at 20 °C, 35 ‰, 0 m
    assert water.sound_speed[1][1] == pytest.approx(1491.6, abs=0.2)


def test_a_missing_program_is_one_clear_error(tmp_path):
    water = Water(depth_m=50.0, sound_speed=((0.0, 1500.0),), ranges=5, depths=5, source_depths=1,
                  arrival_ranges=5, arrival_depths=5)
    with pytest.raises(BellhopError, match="cannot start BELLHOP .*no such program"):
        prepare_fields(water, [10000.0], program=Program(("/nonexistent/bellhop.exe",), "bellhop.exe"),
                       cache=str(tmp_path))


def test_the_cache_is_keyed_by_what_the_fields_depend_on(program, tmp_path):
    from hilgate.channel.runner import cache_file, field_key
    water = Water(depth_m=50.0, sound_speed=((0.0, 1500.0),), ranges=5, depths=5, source_depths=1,
                  arrival_ranges=5, arrival_depths=5, beams=500)  # a fan given: two runs, not a search of five
    prepare_fields(water, [10000.0], program=program, cache=str(tmp_path))
    assert [str(tmp_path / name) for name in os.listdir(tmp_path)] == [cache_file(str(tmp_path), water, 10000.0)]
    # from the cache: a program that cannot run is not asked
    prepare_fields(water, [10000.0], program=Program(("/nonexistent",), "x"), cache=str(tmp_path))
    changed = Water(depth_m=50.0, sound_speed=((0.0, 1490.0),), ranges=5, depths=5, source_depths=1,
                    arrival_ranges=5, arrival_depths=5, beams=500)
    assert field_key(changed, 10000.0) != field_key(water, 10000.0)
    assert field_key(water, 12000.0) != field_key(water, 10000.0)
    with pytest.raises(BellhopError):
        prepare_fields(changed, [10000.0], program=Program(("/nonexistent",), "x"), cache=str(tmp_path))


def test_first_and_spread_of_known_arrivals():
    text = "'2D'\n12000\n1 10\n1 10\n2 100 200\n3\n3\n1.0 0 0.10 0 0 0 0 0\n0.5 0 0.12 0 0 0 0 1\n0.001 0 0.05 0 0 0 1 1\n0\n"
    first, spread = first_and_spread(read_arr(text), 20.0)
    assert first[0, 0, 0] == pytest.approx(0.10)  # the 0.05 s arrival is 60 dB down: it does not count
    w1, w2 = 1.0, 0.25
    mean = (w1 * 0.10 + w2 * 0.12) / (w1 + w2)
    assert spread[0, 0, 0] == pytest.approx(math.sqrt((w1 * (0.10 - mean) ** 2 + w2 * (0.12 - mean) ** 2) / (w1 + w2)))
    assert math.isnan(first[0, 0, 1]) and math.isnan(spread[0, 0, 1])


# -- the commands ------------------------------------------------------------------------------------------


def test_channel_prepare_check_and_report_draw_the_water(program, cache, tmp_path, monkeypatch, capsys):
    """``hilgate channel prepare`` fills the cache (a progress bar on stderr), ``hilgate check`` prints the
    link budget from the fields and a TL / PER table per pair, ``hilgate report --water`` draws the field
    with the tracks; a scene without water says there is nothing to prepare."""
    from hilgate.cli import main

    monkeypatch.setenv("HILGATE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("HILGATE_BELLHOP", " ".join(program.argv))
    scene = tmp_path / "w.yaml"
    scene.write_text(SCENE.format(r=600.0, sl=120.0))
    assert main(["channel", "prepare", str(scene)]) == 0
    out, err = capsys.readouterr()
    assert "channel ac: BELLHOP fields at 12 kHz ready in" in out
    assert "BELLHOP [" in err and "done" in err
    assert main(["check", str(scene)]) == 0
    out, _ = capsys.readouterr()
    assert "the water (BELLHOP):" in out
    assert "la -> lb on ac: 12 kHz, source at 75 m, 16 bytes" in out
    table = out[out.index("la -> lb on ac"):].splitlines()
    assert table[1].split() == ["depth", "m", "100", "m", "250", "m", "500", "m", "1", "km"]
    assert [row.split()[0] for row in table[2:5]] == ["20", "100", "180"]
    trace = tmp_path / "t.jsonl"
    assert main(["sim", str(scene), "--until", "20", "--trace", str(trace)]) == 0
    assert main(["report", str(trace), "--out", str(tmp_path / "rep"), "--water", str(scene)]) == 0
    assert (tmp_path / "rep" / "water-ac.png").stat().st_size > 10_000
    plain = tmp_path / "plain.yaml"
    plain.write_text("channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0, 0, 0]}}}\n"
                     "links: {la: {vehicle: a, address: 1}}\n")
    capsys.readouterr()
    assert main(["channel", "prepare", str(plain)]) == 0
    assert "no channel has water" in capsys.readouterr().out


def test_a_failing_program_is_one_line_from_the_command(tmp_path, monkeypatch, capsys):
    from hilgate.cli import main

    monkeypatch.setenv("HILGATE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("HILGATE_BELLHOP", "/bin/false")
    scene = tmp_path / "w.yaml"
    scene.write_text(SCENE.format(r=600.0, sl=120.0))
    assert main(["channel", "prepare", str(scene)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("hilgate: BELLHOP (/bin/false) failed on tl: exit status 1"), err


def test_a_cached_field_that_does_not_fit_is_computed_again(program, tmp_path):
    from hilgate.channel.fieldcache import encode
    from hilgate.channel.runner import cache_file
    water = Water(depth_m=50.0, sound_speed=((0.0, 1500.0),), ranges=5, depths=5, source_depths=1,
                  arrival_ranges=5, arrival_depths=5, beams=500)  # a fan given: two runs, not a search of five
    path = tmp_path / os.path.basename(cache_file(str(tmp_path), water, 10000.0))
    path.write_bytes(encode({"tl": np.full((1, 2, 2), np.nan)}))  # wrong keys and shapes: another version's
    fields = prepare_fields(water, [10000.0], program=program, cache=str(tmp_path))[0]
    assert fields.tl_db(50.0, 25.0, 25.0) > 0.0
    path.write_bytes(b"not a zip")
    assert prepare_fields(water, [10000.0], program=program, cache=str(tmp_path))[0].frequency_hz == 10000.0


def test_an_arrivals_lookup_agrees_with_the_separate_ones(program, cache):
    """``tl_and_delay`` (what an arrival asks: the grid located once, the delay resampled onto the TL
    grid) gives tl_db's TL exactly and delay_s's delay within 0.1 ms, in the Munk field where the delay
    bends most, at random places inside and beyond the grid."""
    fields = prepare_fields(MUNK, [50.0], program=program, cache=cache)[0]
    rng = np.random.default_rng(3)
    for _ in range(300):
        r, zs, zr = rng.uniform(0, 12000), rng.uniform(0, 5000), rng.uniform(0, 5000)
        tl, delay = fields.tl_and_delay(r, zs, zr)
        assert tl == pytest.approx(fields.tl_db(r, zs, zr), abs=1e-9)
        assert delay == pytest.approx(fields.delay_s(r, zs, zr), abs=1e-4)


def test_a_sloping_bottom_reaches_the_field(program, cache):
    """``bathymetry`` (depth against range from the sender, BELLHOP's .bty): where the bottom has risen
    from 100 m to 70 m (1 km) and 43 m (1.9 km), a receiver at 80 m is in the sediment (tens of dB more
    loss, or none of the sound), while at 30 m the field stays within 1 dB of the flat bottom's.  Both with
    the fan that convergence finds for either (8001 beams): the same fields without its ten runs each."""
    sloping = Water(depth_m=100.0, sound_speed=((0.0, 1500.0), (100.0, 1500.0)), bathymetry=((0.0, 100.0), (2000.0, 40.0)),
                    range_m=2000.0, ranges=20, depths=20, source_depths=2, arrival_ranges=10, arrival_depths=10,
                    beams=8001)
    flat = Water(**{**sloping.__dict__, "bathymetry": ()})
    slope, level = (prepare_fields(w, [12000.0], program=program, cache=cache)[0] for w in (sloping, flat))
    for r in (1000.0, 1900.0):
        assert slope.tl_db(r, 25.0, 80.0) > level.tl_db(r, 25.0, 80.0) + 20.0
        assert slope.tl_db(r, 25.0, 30.0) == pytest.approx(level.tl_db(r, 25.0, 30.0), abs=1.0)
    assert slope.tl_db(200.0, 25.0, 80.0) == pytest.approx(level.tl_db(200.0, 25.0, 80.0), abs=1.0)


def test_a_receiver_that_tolerates_less_delay_spread_loses_the_frame(program, cache):
    """``acoustic: delay_spread_s`` on the receiver: where the looked-up RMS spread (surface and bottom
    echoes in 200 m of water, 600 m apart) exceeds it, every frame is lost; below it, the SNR decides."""
    import dataclasses

    scene = _scene()
    paths = _ready(scene, program, cache)["ac"].propagation
    sender, receiver = scene.links["la"].params, scene.links["lb"].params
    spread = paths.bind(sender, receiver).model.fields.spread_s(600.0, 75.0, 75.0)
    assert spread > 1e-4
    for limit, lost in ((spread / 2, True), (spread * 2, False)):
        strict = dataclasses.replace(receiver, acoustic=dataclasses.replace(receiver.acoustic, delay_spread_s=limit))
        reception = paths.bind(sender, strict).model.at((0.0, 0.0, 75.0), (600.0, 0.0, 75.0))
        assert reception.spread == pytest.approx(spread)
        assert (reception.per(600.0, 16) == 1.0) is lost
