"""The per-frame path's shortcuts (issue 31) are taken only where they change nothing: each is checked
to be taken when its conditions hold and not otherwise, and the slow path is run on the same scene to
show the very same trace, byte for byte.

- ``mac: none`` itself: the modem does NoMac's steps (``SimModem.direct``); a subclass of NoMac, which
  could do anything, gets the MAC's calls as before."""

from __future__ import annotations

import io
import os

import pytest

from hilgate.scene import load_scene_text
from hilgate.sim.simulate import Simulation

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")

PLAIN_MAC = '''\
from hilgate.models.mac import NoMac


class PlainNoMac(NoMac):
    """NoMac, unchanged, under another name: the modem cannot know that, so it calls it."""

    name = "plain-none"
    calls = 0  # (per instance once counted)

    def on_enqueue(self):
        self.calls += 1
        super().on_enqueue()

    def on_tx_done(self, frame):
        self.calls += 1
        super().on_tx_done(frame)

    def on_frame(self, frame, cause, addressed):
        self.calls += 1
        super().on_frame(frame, cause, addressed)
'''

# Every step of a modem under ``mac: none``: a FIFO that fills (a flow faster than the air), tx and rx
# delays with jitter, half-duplex collisions, losses on the path, the modem's own acknowledgements
# (retries and give-ups), broadcast, a frame to an address nobody has.
BUSY_SCENE = """\
seed: 5
duration_s: 40
channels: {ac: {speed_mps: 1500}}
vehicles:
  a: {pose: {static: [0, 0, 0]}}
  b: {pose: {static: [300, 0, 0]}}
  c: {pose: {static: [0, 400, 0]}}
links:
  la: {vehicle: a, address: 1, bitrate_bps: 2000, fifo_bytes: 600, tx_delay_s: 0.01, tx_jitter_s: 0.004,
       range_m: [0, 1000], error: {unit: bit, expr: "2e-4"}}
  lb: {vehicle: b, address: 2, bitrate_bps: 2000, rx_delay_s: 0.02, rx_jitter_s: 0.005, ack_turnaround_s: 0.05,
       range_m: [0, 1000]}
  lc: {vehicle: c, address: 3, bitrate_bps: 2000, range_m: [0, 350]}
flows:
  - {from: la, to: lb, size_bytes: 120, rate_hz: 12, poisson: true}
  - {from: lb, to: la, size_bytes: 40, rate_hz: 3, poisson: true, ack_retries: 2}
  - {from: lc, to: "*", size_bytes: 30, interval_s: 0.7}
  - {from: lc, to: lb, size_bytes: 30, interval_s: 1.3, start_s: 0.2}
"""


def run(text: str, *overrides: str, plugins: tuple[str, ...] = ()) -> tuple[Simulation, str]:
    out = io.StringIO()
    simulation = Simulation(load_scene_text(text, os.path.join(SCENES, "scene.yaml"), overrides, plugins=plugins),
                            None, None, out)
    simulation.run()
    return simulation, out.getvalue()


@pytest.fixture
def plain_mac(tmp_path):
    path = tmp_path / "plain_mac.py"
    path.write_text(PLAIN_MAC)
    return str(path)


def test_the_modem_does_the_macs_steps_itself_only_under_mac_none_itself(plain_mac):
    text = BUSY_SCENE
    direct, _ = run(text)
    assert all(modem.direct for modem in direct.world.modems.values())
    for protocol in ("plain-none", "aloha", "cs-aloha", "s-fama"):
        other, _ = run(text, f"links.*.mac.protocol={protocol}", plugins=(plain_mac,))
        assert not any(modem.direct for modem in other.world.modems.values()), protocol


@pytest.mark.parametrize("scene", ["busy", "demo.yaml"])
def test_mac_none_writes_the_trace_its_macs_calls_wrote(scene, plain_mac):
    text = BUSY_SCENE if scene == "busy" else open(os.path.join(SCENES, scene)).read()
    direct, fast = run(text, "links.*.mac.protocol=none")
    slow_run, slow = run(text, "links.*.mac.protocol=plain-none", plugins=(plain_mac,))
    assert all(modem.direct for modem in direct.world.modems.values())
    assert not any(modem.direct for modem in slow_run.world.modems.values())
    assert sum(modem.mac.calls for modem in slow_run.world.modems.values()) > 0  # the slow path was taken
    assert fast.count("\n") > 100 and fast == slow


# -- no BUSY announcement after a queue application's own frame (issue 31) ---------------------------------
#
# After a frame the link's endpoints are told its state at the end of the instant.  When the frame came
# through the link's only endpoint, a queue endpoint whose application took the link as BUSY as it sent,
# and the simulated modem is on air (so READY can only come when its transmission ends, which tells the
# link), that announcement would tell nobody anything: the link skips it.

from framepath import SCENE as TWO_LINKS  # noqa: E402
from framepath import run_frames  # noqa: E402

from hilgate.core.endpoint import ABSENT  # noqa: E402

BUSY_MESSAGE, READY_MESSAGE = b"\x02\x00", b"\x02\x01"


class Listening:
    """An endpoint of link a beside its queues, that only listens to READY/BUSY (as a socket client does)."""

    kind = "listening"
    busy = False
    phy = None

    def __init__(self) -> None:
        self.states: list[bool] = []

    def deliver(self, frame, t):
        return ABSENT

    def state(self, ready: bool) -> None:
        self.states.append(ready)

    def close(self) -> None:
        pass


def announcements(router, link_id: str) -> list[int]:
    """Count link ``link_id``'s announcements (in a list, so the count is read after the run)."""
    link = router.links[link_id]
    counted = [0]
    announce = link._announce_state

    def counting() -> None:
        counted[0] += 1
        announce()

    link._announce_state = counting  # (the bound method the link defers is looked up per call)
    return counted


def slow_path(router, link_id: str) -> None:
    """The link's queue endpoint no longer says its application assumes BUSY: every frame is announced."""
    link = router.links[link_id]
    for endpoint in link.endpoints:
        endpoint.assumes_busy = False
    link._endpoints_changed()


PASSES = 5


def test_no_busy_announcement_after_the_only_endpoints_own_frame_and_the_same_messages_and_trace(tmp_path):
    counted: dict[str, list[int]] = {}

    def fast(router, a, b):
        counted["fast"] = announcements(router, a)

    def slow(router, a, b):
        slow_path(router, a)
        counted["slow"] = announcements(router, a)

    (tmp_path / "fast").mkdir()
    (tmp_path / "slow").mkdir()
    taken = run_frames(str(tmp_path / "fast"), PASSES, fast)
    anew = run_frames(str(tmp_path / "slow"), PASSES, slow)
    # taken when its conditions hold: one announcement per frame (READY, when the modem is done), not two
    assert counted["fast"][0] == PASSES  # (REQ_STATE is answered at once, not announced)
    assert counted["slow"][0] == 2 * PASSES
    # and nobody is told anything else: the applications read the same messages, the trace is the same
    assert taken.to_a == anew.to_a
    assert taken.to_a[1:] == [[READY_MESSAGE]] * PASSES
    assert taken.to_b == anew.to_b and all(len(got) == 1 and got[0][0] == 0 for got in taken.to_b[1:])
    assert taken.trace.count('"ev": "tx"') == PASSES
    assert strip_names(taken.trace) == strip_names(anew.trace)


def strip_names(trace: str) -> str:
    """The trace's events (not its first line: the run's id, wall-clock start and directory) with the links'
    random names made alike (``fra…``/``frb…``)."""
    import re

    first, events = trace.split("\n", 1)
    assert '"ev": "run"' in first
    return re.sub(r"fr([ab])[0-9a-f]{8}", r"fr\1", events)


def test_busy_is_announced_when_another_endpoint_listens(tmp_path):
    listening = Listening()
    counted = {}

    def prepare(router, a, b):
        router.links[a].attach(listening)
        counted["n"] = announcements(router, a)

    got = run_frames(str(tmp_path), PASSES, prepare)
    assert counted["n"][0] == 2 * PASSES  # not taken: the listener must hear BUSY
    assert listening.states == [True] + [False, True] * PASSES  # (READY as the link came up, then each frame)
    assert got.to_a[1:] == [[READY_MESSAGE]] * PASSES


def test_busy_is_announced_when_the_frame_did_not_come_through_the_queue(tmp_path):
    counted = {}

    def prepare(router, a, b):
        counted["n"] = announcements(router, a)

    def send(router, a):
        router.links[a].send_payload(b"from elsewhere", 2)  # a frame from no endpoint (as a command sends)

    got = run_frames(str(tmp_path), PASSES, prepare, send=send)
    assert counted["n"][0] == 2 * PASSES  # not taken: a's application, told READY, must hear BUSY
    assert got.to_a[1:] == [[BUSY_MESSAGE, READY_MESSAGE]] * PASSES


def test_busy_is_announced_when_the_modem_is_not_on_air_after_the_send(tmp_path):
    # under S-FAMA the frame waits for its slot: the PHY is free after the send, so the link announces
    scene = TWO_LINKS.replace("packet: vl2b}}", "packet: vl2b, mac: {{protocol: s-fama, max_range_m: 100}}}}")
    assert scene.count("s-fama") == 2
    counted = {}

    def prepare(router, a, b):
        counted["n"] = announcements(router, a)

    run_frames(str(tmp_path), 1, prepare, scene_text=scene)
    assert counted["n"][0] == 2  # BUSY after the frame (told nobody anything), READY once it was sent
