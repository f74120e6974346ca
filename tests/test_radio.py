"""The radio on its own: collisions, interference, half duplex, the error draw and carrier sense,
decided without a medium or a modem (a host that records what it is told, a loss model that says
how likely a frame is lost)."""

import random

import pytest

from hilgate.core.scheduler import VirtualScheduler
from hilgate.models.errormodel import NO_ERRORS, ErrorModel
from hilgate.models.frame import BROADCAST, Frame
from hilgate.models.radio import NOISE_MIN, Arrival, Radio

ME, OTHER = 1, 2


class Host:
    def __init__(self, clock):
        self.clock = clock
        self.outcomes: list[tuple[float, int, str | None]] = []
        self.unreachable_frames: list[int] = []

    def heard(self, frame, cause):
        self.outcomes.append((self.clock.now(), frame.id, cause))

    def unreachable(self, frame, cause):
        self.unreachable_frames.append((frame.id, cause))


class Loss:
    def __init__(self, per: float):
        self.value = per
        self.asked = 0

    def per(self, d, size):
        self.asked += 1
        return self.value


class Medium:
    def __init__(self):
        self.sent = []

    def transmit(self, radio, frame, t, duration):
        self.sent.append((frame.id, t, duration))


def make(half_duplex=True, judges_all=False, error_free=True, seed=1):
    clock = VirtualScheduler()
    host = Host(clock)
    radio = Radio(host, Medium(), clock, random.Random(seed))
    error = NO_ERRORS if error_free else ErrorModel("packet", "0.5")  # the loss model handed says how much
    radio.configure(ME, "ac", "ac", (0.0, float("inf")), error, half_duplex)
    radio.judges_all = judges_all
    return radio, host, clock


def frame(id, dst=ME, size=10):
    return Frame(id, "a", "b", dst, size, 0.0)


NO_LOSS = Loss(0.0)


def test_overlapping_judged_arrivals_both_collide_back_to_back_ones_do_not():
    radio, host, clock = make()
    radio.arrive(frame(1), 0.0, 1.0, 2.0, 10.0, NO_LOSS)
    radio.arrive(frame(2), 0.0, 1.5, 2.5, 10.0, NO_LOSS)
    radio.arrive(frame(3), 0.0, 2.5 - 1e-10, 3.5, 10.0, NO_LOSS)  # touches frame 2 within a nanosecond
    clock.run()
    assert host.outcomes == [(2.0, 1, "col"), (2.5, 2, "col"), (3.5, 3, None)]


def test_interference_spoils_what_is_judged_and_has_no_outcome_of_its_own():
    radio, host, clock = make()
    radio.arrive(frame(1), 0.0, 1.0, 2.0, 10.0, NO_LOSS)
    radio.arrive(frame(2, dst=OTHER), 0.0, 1.9, 2.9, 10.0, NO_LOSS)  # spoils frame 1, already judged
    radio.arrive(frame(3, dst=OTHER), 0.0, 3.0, 4.0, 10.0, NO_LOSS)
    radio.arrive(frame(4), 0.0, 3.5, 4.5, 10.0, NO_LOSS)  # spoiled by frame 3, judged later
    radio.arrive(frame(5, dst=BROADCAST), 0.0, 5.0, 6.0, 10.0, NO_LOSS)
    clock.run()
    assert host.outcomes == [(2.0, 1, "col"), (4.5, 4, "col"), (6.0, 5, None)]


def test_a_radio_that_judges_all_reports_frames_for_others_too():
    radio, host, clock = make(judges_all=True)
    radio.arrive(frame(1, dst=OTHER), 0.0, 1.0, 2.0, 10.0, NO_LOSS)
    clock.run()
    assert host.outcomes == [(2.0, 1, None)]


@pytest.mark.parametrize("half_duplex, expected", [(True, "col"), (False, None)])
def test_own_transmission_spoils_an_arrival_when_half_duplex(half_duplex, expected):
    # the transmission starts during an arrival ...
    radio, host, clock = make(half_duplex)
    radio.arrive(frame(1), 0.0, 1.0, 2.0, 10.0, NO_LOSS)
    radio.transmit(frame(9), 1.5, 1.0)
    clock.run()
    assert host.outcomes == [(2.0, 1, expected)]
    assert radio.medium.sent == [(9, 1.5, 1.0)]
    # ... or an arrival starts during the transmission; ending exactly as it starts is no overlap
    radio, host, clock = make(half_duplex)
    radio.transmit(frame(9), 0.0, 1.0)
    radio.arrive(frame(1), 0.0, 0.5, 0.9, 10.0, NO_LOSS)
    radio.arrive(frame(2), 0.0, 1.0, 2.0, 10.0, NO_LOSS)
    clock.run()
    assert host.outcomes == [(0.9, 1, expected), (2.0, 2, None)]


def test_error_draw_from_the_radios_own_stream_and_the_causes():
    radio, host, clock = make(error_free=False)
    certain = Loss(1.0)
    radio.arrive(frame(1), 0.0, 1.0, 2.0, 10.0, certain)
    radio.arrive(frame(2), 0.0, 3.0, 4.0, 10.0, certain)
    radio.arrive(frame(3), 0.0, 3.5, 4.5, 10.0, NO_LOSS)
    clock.run()
    assert host.outcomes == [(2.0, 1, "prop"), (4.0, 2, "mult"), (4.5, 3, "col")]
    # a certain or impossible loss needs no draw; a likely one takes exactly one per arrival
    state = radio.rng.getstate()
    radio.arrive(frame(4), 5.0, 6.0, 7.0, 10.0, Loss(0.5))
    expected = random.Random()
    expected.setstate(state)
    expected.random()
    assert radio.rng.getstate() == expected.getstate()


def test_an_error_free_radio_neither_asks_for_the_loss_nor_draws():
    radio, host, clock = make(error_free=True)
    loss = Loss(1.0)
    state = radio.rng.getstate()
    radio.arrive(frame(1), 0.0, 1.0, 2.0, 10.0, loss)
    clock.run()
    assert host.outcomes == [(2.0, 1, None)] and loss.asked == 0 and radio.rng.getstate() == state


def test_carrier_sense():
    radio, host, clock = make()
    radio.transmit(frame(9), 0.0, 1.0)
    radio.arrive(frame(1), 0.0, 2.0, 3.0, 10.0, NO_LOSS)
    radio.arrive(frame(2, dst=OTHER), 0.0, 4.0, 5.0, 10.0, NO_LOSS)
    busy = {t: radio.busy(t) for t in (0.0, 0.5, 1.0, 1.5, 2.0, 2.9, 3.0, 4.5, 5.0)}
    assert busy == {0.0: True, 0.5: True, 1.0: False, 1.5: False, 2.0: True, 2.9: True, 3.0: False,
                    4.5: True, 5.0: False}


def test_unreachable_goes_to_the_host():
    radio, host, clock = make()
    radio.unreachable(frame(7))
    radio.unreachable(frame(8), "band")
    radio.unreachable(frame(9), "no_pose")
    assert host.unreachable_frames == [(7, "range"), (8, "band"), (9, "no_pose")]


def test_an_arrival_it_cannot_decode_interferes_and_ends_lost_with_its_cause():
    """A refused arrival (another modulation) spoils the good one it overlaps, keeps the channel busy,
    and ends lost with its own cause even on an error-free radio, collided or not."""
    radio, host, clock = make(error_free=True)
    radio.arrive(frame(1), 0.0, 1.0, 2.0, 10.0, NO_LOSS)
    radio.arrive_refused(frame(2), 0.0, 1.5, 2.5, 10.0, Loss(1.0), "modulation")
    radio.arrive_refused(frame(3), 0.0, 3.0, 4.0, 10.0, Loss(1.0), "modulation")
    radio.arrive_refused(frame(4, dst=OTHER), 0.0, 5.0, 6.0, 10.0, Loss(1.0), "modulation")  # for another radio
    radio.arrive(frame(5), 0.0, 5.5, 6.5, 10.0, NO_LOSS)
    assert radio.busy(3.5)
    clock.run()
    assert host.outcomes == [(2.0, 1, "col"), (2.5, 2, "modulation"), (4.0, 3, "modulation"), (6.5, 5, "col")]


def test_interference_kept_stays_as_short_as_what_is_on_air():
    radio, host, clock = make()
    for k in range(10_000):
        t = k * 0.25
        radio.arrive(frame(k, dst=OTHER), t, t + 0.5, t + 1.0, 10.0, NO_LOSS)  # four on air at most
        assert len(radio.noise) <= NOISE_MIN + 2 * 4 + 1


def test_hot_objects_have_slots():
    radio, host, clock = make()
    for obj in (radio, Arrival(frame(1), 0.0, 1.0, 1.0)):
        assert not hasattr(obj, "__dict__")
