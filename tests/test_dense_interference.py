"""Interference gathered lazily (``models/air.py``, issue 31) gives the traces the eager hand-out gave.

The dense scene of ``dense_scene.py`` (static modems that all hear each other, moving ones, one in
another band, a promiscuous one, ALOHA, CS-ALOHA's carrier sense and acknowledgements, unicast and
broadcast) is simulated with ``collisions: overlap`` and ``sinr``; its traces must be byte for byte
the ones recorded by the eager medium before the change (``dense_traces.json``), and the ones the
medium gives with the lazy path switched off (``Medium.lazy = False``, the old algorithm kept as the
oracle)."""

import hashlib
import io
import json
import os
import random

import pytest

from dense_scene import dense_scene
from hilgate.core.scheduler import VirtualScheduler
from hilgate.models.errormodel import NO_ERRORS
from hilgate.models.frame import BROADCAST, Frame
from hilgate.models.medium import Channel, Medium
from hilgate.models.radio import Radio
from hilgate.models.trajectories import Piecewise, Segment, Static
from hilgate.scene import load_scene_text
from hilgate.sim.simulate import Simulation

HERE = os.path.dirname(os.path.abspath(__file__))
with open(os.path.join(HERE, "dense_traces.json"), encoding="utf-8") as _handle:
    RECORDED = json.load(_handle)["sha256"]


def trace_of(collisions: str, lazy: bool) -> tuple[str, Simulation]:
    scene = load_scene_text(dense_scene(collisions), f"dense-{collisions}.yaml")
    out = io.StringIO()
    simulation = Simulation(scene, trace=out)
    simulation.world.medium.lazy = lazy
    simulation.world.medium.quiet_min = 1  # every sender's static pairs quiet, however few (the default: 32)
    simulation.run()
    return out.getvalue(), simulation


@pytest.mark.parametrize("collisions", ["overlap", "sinr"])
def test_dense_trace_is_the_one_the_eager_medium_recorded(collisions):
    lazy, simulation = trace_of(collisions, lazy=True)
    assert hashlib.sha256(lazy.encode()).hexdigest() == RECORDED[collisions]
    medium = simulation.world.medium
    assert medium._quiet_count, "the scene's static pairs took the lazy path"
    eager, oracle = trace_of(collisions, lazy=False)
    assert not oracle.world.medium._quiet_count
    assert eager == lazy
    assert oracle.world.medium.arrivals == medium.arrivals  # the same arrivals counted either way
    causes = {json.loads(line).get("cause") for line in lazy.splitlines()}
    assert {"col", "band", "range", "busy"} <= causes  # collisions, another band, out of range, carrier sense


class Host:
    on_phy = None

    def __init__(self, name, clock):
        self.id = name
        self.clock = clock
        self.heard_frames: list[tuple[float, int, str | None]] = []

    def heard(self, frame, cause):
        self.heard_frames.append((self.clock.now(), frame.id, cause))

    def unreachable(self, frame, cause="range"):
        self.heard_frames.append((self.clock.now(), frame.id, cause))


def _medium(positions, lazy=True, moving=(), judges_all=(), range_m=(0.0, float("inf")), quiet_min=1):
    """Radios on one 1500 m/s channel at ``positions`` (addresses 1..n); those in ``moving`` on a path."""
    clock = VirtualScheduler()
    medium = Medium(clock, [Channel("ac", 1500.0)])
    medium.lazy = lazy
    medium.quiet_min = quiet_min
    radios = []
    for i, position in enumerate(positions):
        radio = Radio(Host(f"m{i + 1}", clock), medium, clock, random.Random(i))
        radio.configure(i + 1, "ac", "ac", range_m, NO_ERRORS, True)
        radio.pose = Piecewise([Segment(0.0, 100.0, position, tuple(p + 10.0 for p in position))]) if i in moving \
            else Static(position)
        radio.judges_all = i in judges_all
        medium.attach(radio)
        radios.append(radio)
    return clock, medium, radios


def _send(clock, medium, radio, frame_id, dst, at, duration=0.2):
    frame = Frame(frame_id, radio.host.id, "x", dst, 20, at)
    clock.at(at, lambda: radio.transmit(frame, clock.now(), duration))


def _outcomes(lazy, **kwargs):
    positions = [(0.0, 0.0, 0.0), (150.0, 0.0, 0.0), (300.0, 0.0, 0.0), (0.0, 300.0, 0.0), (600.0, 0.0, 0.0)]
    clock, medium, radios = _medium(positions, lazy=lazy, **kwargs)
    _send(clock, medium, radios[1], 1, 1, 0.0)      # to radio 1
    _send(clock, medium, radios[2], 2, 4, 0.05)     # to radio 4: quiet at 1, overlaps frame 1 there
    _send(clock, medium, radios[3], 3, BROADCAST, 1.0)
    _send(clock, medium, radios[4], 4, 1, 2.0)      # to radio 1, alone: heard
    busy = []
    clock.at(0.2, lambda: busy.append(radios[0].busy(clock.now())))  # frame 2 is on air at radio 1
    clock.at(1.9, lambda: busy.append(radios[0].busy(clock.now())))  # nothing is
    clock.run(10.0)
    return [r.host.heard_frames for r in radios], busy, medium


@pytest.mark.parametrize("kwargs", [{}, {"moving": (2,)}, {"judges_all": (0,)}])
def test_quiet_path_is_taken_only_for_static_pairs_whose_receiver_does_not_judge(kwargs):
    """Radio 1 is judging frame 1 when frame 2 (to radio 4) arrives: static, not addressed to it, so
    quiet, and it still spoils frame 1 and keeps radio 1 busy.  A moving sender's pairs, and every pair
    of a radio that judges everything, are handed at once instead; the outcomes are the same."""
    lazy, busy, medium = _outcomes(True, **kwargs)
    eager, busy_eager, oracle = _outcomes(False, **kwargs)
    assert lazy == eager and busy == busy_eager == [True, False]
    assert lazy[0][:1] == [(pytest.approx(0.3), 1, "col")] and lazy[0][-1] == (pytest.approx(2.6), 4, None)
    quiet = medium._quiet
    sender, receiver = medium.radios[2], medium.radios[0]
    if kwargs.get("moving"):
        assert sender not in quiet.senders and quiet.tau(sender, receiver) is None
    elif kwargs.get("judges_all"):
        assert receiver not in quiet.receivers and quiet.tau(sender, receiver) is None
    else:
        assert quiet.tau(sender, receiver) == pytest.approx(300.0 / 1500.0)
    assert not oracle._quiet_count and medium.arrivals == oracle.arrivals == 16


def test_quiet_pairs_keep_no_path_until_asked():
    """A dense static scene lists no path for its quiet pairs: only the pairs a judged arrival needed."""
    positions = [(100.0 * i, 0.0, 0.0) for i in range(40)]
    clock, medium, radios = _medium(positions)
    for i in range(1, 40):
        _send(clock, medium, radios[i], i, 1, 0.5 * i)
    clock.run(40.0)
    assert sum(len(nbs) for nbs in medium._neighbours.values()) == 0
    assert sum(medium._quiet_count.values()) == 40 * 39
    assert len(medium._quiet.pairs) == 39  # every sender to radio 1, the one that judged
    assert medium.arrivals == 39 * 39
    # dead records dropped: one lives while an arrival of it may still overlap one to be judged, the
    # farthest pair's τ (2.6 s) plus twice the duration (0.2 s): the last 7 of one every 0.5 s
    assert [len(records) for records in medium.air.records.values()] == [7]


def _long_frame(lazy):
    """A 5 s frame from a moving sender (handed at once) to radio 1, whose start a short quiet frame
    overlaps; then, every second while it lasts, a quiet frame between two radios out of radio 1's
    range (200 m): records of the same channel, so each one prunes."""
    positions = [(0.0, 0.0, 0.0), (150.0, 0.0, 0.0), (0.0, 150.0, 0.0), (150.0, 100.0, 0.0),
                 (1000.0, 0.0, 0.0), (1100.0, 0.0, 0.0)]
    clock, medium, radios = _medium(positions, lazy=lazy, moving=(2,), range_m=(0.0, 200.0))
    _send(clock, medium, radios[2], 1, 1, 0.0, duration=5.0)
    _send(clock, medium, radios[1], 2, 4, 0.05, duration=0.1)
    for i in range(1, 5):
        _send(clock, medium, radios[4], 2 + i, 6, float(i), duration=0.1)
    clock.run(10.0)
    return radios[0].host.heard_frames, medium


def test_records_outlive_the_longest_arrival_still_to_be_judged():
    """A record is kept while an arrival it overlaps may still be judged, however long that arrival
    and whoever sent it: frame 1 (not quiet) is judged at its end, 5.1 s, spoilt by a quiet frame that
    overlapped its start, though four shorter ones were recorded since."""
    lazy, medium = _long_frame(True)
    eager, _ = _long_frame(False)
    assert lazy == eager == [(pytest.approx(5.1), 1, "col")]
    assert medium.air.longest == 5.0


def test_a_sparse_sender_hands_its_arrivals_at_once():
    """Below ``quiet_min`` quiet pairs a sender's pairs are listed as before: in a ring of 40 modems
    100 m apart hearing 250 m (four each) nobody is quiet with the default, all are with 4."""
    positions = [(100.0 * i, 0.0, 0.0) for i in range(40)]
    _, sparse, _ = _medium(positions, range_m=(0.0, 250.0), quiet_min=32)
    _, dense, _ = _medium(positions, range_m=(0.0, 250.0), quiet_min=4)
    for medium in (sparse, dense):
        medium._rebuild()
    assert not sparse._quiet_count and not sparse._quiet.senders
    assert sum(len(nbs) for nbs in sparse._neighbours.values()) == 2 * (1 + 2 + 37 * 2)  # as before
    assert set(dense._quiet_count.values()) == {4} and len(dense._quiet_count) == 36  # the ends hear 2 or 3
    assert sparse._quiet.tau(sparse.radios[0], sparse.radios[1]) is None
    assert dense._quiet.tau(dense.radios[5], dense.radios[6]) == pytest.approx(100.0 / 1500.0)
