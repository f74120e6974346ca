"""A modem's limits (issue 24 item 4): a simulated link with an EvoLogics preset refuses what the real
modem refuses, with the words of hilgate's driver in front of an emulated modem, when the application
sends; a frame at the limit crosses both.  Real parts: the driver opens the emulator's pty, the
applications speak the socket GLI."""

import io
import json
import subprocess
import sys

import pytest

from at_pty_client import AtClient
from daemon_kit import SCENE_HEAD, unique
from hilgate.client import GliError, Link
from hilgate.core.packets import PacketError
from hilgate.drivers.table import EVOLOGICS_LIMITS
from hilgate.scene import load_scene_text
from hilgate.sim.apps import _VirtualLink
from hilgate.sim.simulate import Simulation

VL2B = 5  # preamble, two length bytes, CRC-16: the bytes vl2b adds to a payload on air


def refusal(link, payload, dst):
    """The error the daemon answers a frame with (None: the frame was taken)."""
    link.send(payload, dst=dst)
    try:
        link.command({"class": "STATUS"})  # hilgate answers in order: an ERROR for the frame comes first
    except GliError as exc:
        return str(exc)
    return None


@pytest.mark.parametrize("mode,modes,most", [
    ("im", "", 64),                      # the preset's IM, as the driver's default im: true
    ("burst", "", 1024),                 # im: false on the driver, send_as: burst on the simulated link
    ("im", "modes: {im: 32}", 32),       # a link's own figure binds driver, emulator and simulated link alike
])
def test_the_simulated_link_refuses_what_the_driver_refuses_with_the_same_words(tmp_path, mode, modes, most, daemon_of):
    d, e, s = unique("drv"), unique("emu"), unique("sim")
    pty = tmp_path / "evo"
    im = "true" if mode == "im" else "false"
    preset = "model: evologics-s2cr-7-17, packet: vl2b" + (f", limits: {{{modes}}}" if modes else "")
    sim_limits = ", ".join(filter(None, [f"send_as: {mode}", modes]))
    daemon = daemon_of(f"""\
{SCENE_HEAD}links:
  {d}: {{vehicle: va, backend: evologics, port: {pty}, address: 1, im: {im}, {preset}}}
  {e}: {{vehicle: va, address: 1, emulate: {{protocol: evologics, pty: {pty}}}, {preset}}}
  {s}: {{vehicle: vb, address: 2, model: evologics-s2cr-7-17, packet: vl2b, limits: {{{sim_limits}}}}}
""", [d, e, s])
    daemon.wait_up(d)
    too_large = b"x" * (most - VL2B + 1)
    fits = b"y" * (most - VL2B)
    with Link.open(d, runtime_dir=daemon.runtime) as ld, Link.open(s, runtime_dir=daemon.runtime) as ls:
        by_driver = refusal(ld, too_large, 2)
        by_sim = refusal(ls, too_large, 1)
        what = "an instant message" if mode == "im" else "a burst"
        hint = "; use a smaller packet class" + (" or bursts (at most 1024)" if mode == "im" else "")
        assert by_driver == by_sim == \
            f"size: {most + 1} bytes on air do not fit {what} of the EvoLogics modem (at most {most}){hint}"
        # a frame at the limit crosses: driver -> emulated modem -> channel -> simulated link, and back
        assert refusal(ld, fits, 2) is None
        message = ls.recv(timeout=60)
        assert message is not None and message.data == fits
        assert refusal(ls, fits, 1) is None
        message = ld.recv(timeout=60)
        assert message is not None and message.data == fits
        for link in (d, s):  # counted as a refused frame of the application's, on both
            assert daemon.link_status(link)["drop_causes"] == {"size": 1}
    daemon.stop()
    events = daemon.trace_events()
    for link in (d, s):
        [drop] = [ev for ev in events if ev.get("link") == link and ev["ev"] == "drop"]
        assert (drop["cause"], drop["src"], drop["size"]) == ("size", "app", len(too_large))
    # refused when sent: it never reached a modem's queue, the emulator's nor the simulated one's
    assert [ev["size"] for ev in events if ev["ev"] == "enq" and ev.get("link") in (e, s)] == [most, most]


def test_the_emulated_modem_refuses_each_mode_beyond_its_link_limits(tmp_path, daemon_of):
    a, b = unique("ea"), unique("eb")
    pa = tmp_path / "evo_a"
    daemon = daemon_of(f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {{static: [100, 0, 0]}}}}
links:
  {a}: {{vehicle: va, model: evologics-s2cr-7-17, address: 1, emulate: {{protocol: evologics, pty: {pa}}},
        limits: {{modes: {{im: 10, ims: 11, pbm: 12, burst: 13}}}}}}
  {b}: {{vehicle: vb, model: evologics-s2cr-7-17, address: 2}}
""", [a, b])
    ca = AtClient(pa)
    for command, most in ((b"*SENDIM", 10), (b"*SENDIMS", 11), (b"*SENDPBM", 12), (b"*SEND", 13)):
        extra = {b"*SENDIM": b"noack,", b"*SENDIMS": b",", b"*SENDPBM": b"", b"*SEND": b""}[command]
        for size, answer in ((most + 1, b"ERROR OUT OF RANGE"), (most, b"OK")):
            assert ca.ask(b"AT%s,%d,2,%s%s" % (command, size, extra, b"z" * size)) == answer, (command, size)
    ca.close()


def test_the_presets_state_their_modems_limits_and_check_prints_them(tmp_path):
    scene = load_scene_text("""\
channels: {ac: {speed_mps: 1500}, rf: {speed_mps: 2.25e7}}
vehicles: {v: {pose: {static: [0, 0, 0]}}}
links:
  a: {vehicle: v, channel: ac, model: evologics-s2cr-18-34}
  b: {vehicle: v, channel: rf, model: s100}
  c: {vehicle: v, channel: ac}
""", str(tmp_path / "scene.yaml"))
    assert scene.links["a"].limits == EVOLOGICS_LIMITS
    assert scene.links["b"].limits.piece_bytes == 45 and scene.links["b"].limits.flow_control == "rtscts"
    assert scene.links["c"].limits is None  # a simulated link without a preset refuses nothing by size
    (tmp_path / "scene.yaml").write_text("""\
channels: {ac: {speed_mps: 1500}}
vehicles: {v: {pose: {static: [0, 0, 0]}}}
links:
  a: {vehicle: v, model: evologics-s2cr-7-17, limits: {send_as: burst}}
  b: {vehicle: v, backend: evologics, port: /dev/null, im: false}
""")
    result = subprocess.run([sys.executable, "-m", "hilgate", "check", str(tmp_path / "scene.yaml")],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert ("    limits (preset evologics-s2cr-7-17): im 64 B, ims 64 B, pbm 64 B, burst 1024 B; serial 19200 baud; "
            "GLI frames go as burst (send_as), larger ones are refused; transmit FIFO 16384 B") in result.stdout
    assert ("    limits (the evologics driver's own): im 64 B, ims 64 B, pbm 64 B, burst 1024 B; serial 19200 baud; "
            "GLI frames go as burst (im: false); the driver queues 50 frames") in result.stdout


def test_hilgate_sims_applications_are_refused_alike():
    """In virtual time (``hilgate sim``) an application's link refuses the same frame with the same words."""
    trace = io.StringIO()
    simulation = Simulation(load_scene_text("""\
channels: {ac: {speed_mps: 1500}}
vehicles: {v: {pose: {static: [0, 0, 0]}}, w: {pose: {static: [100, 0, 0]}}}
links:
  a: {vehicle: v, model: evologics-s2cr-7-17, address: 1}
  b: {vehicle: w, model: evologics-s2cr-7-17, address: 2}
"""), trace=trace)
    link = _VirtualLink(simulation.world, "a")
    with pytest.raises(PacketError) as refused:
        link.send(b"x" * 60, dst=2)
    assert str(refused.value) == ("size: 65 bytes on air do not fit an instant message of the EvoLogics modem "
                                  "(at most 64); use a smaller packet class or bursts (at most 1024)")
    link.send(b"x" * 59, dst=2)  # 64 bytes on air: taken
    assert [(e["ev"], e["size"]) for e in map(json.loads, trace.getvalue().splitlines())] == [("enq", 64)]
