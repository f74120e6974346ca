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
