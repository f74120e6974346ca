"""The swap holds for the Modem-M64 and the Micro-Modem: a link moves between a simulated modem and a
real one (hilgate's driver on the pty of an emulated modem: the whole chain of a bench) by a reload, and
the application, connected all along, does not change.

Phase 1: both links simulated with the modem's preset.  Phase 2: the application's link is the real
modem's driver; the far link is an emulated modem whose applications get what the modem received (the
receiving bridge joins the M64's packets into datagrams, a Micro-Modem packet's frames into a frame).
Phase 3: simulated again.  The emulated modem the driver talks to exists only in phase 2 (the bench is
plugged in): an M64 of role A transmits every second, and would share the channel with the simulated links.
"""

import pytest

from daemon_kit import unique, wait_until
from hilgate.client import Link

SPEED = 4


def scene(tmp_path, ap, far, ea, modem, real):
    pa, pb = tmp_path / "a", tmp_path / "b"
    if modem == "m64":
        driver = f"backend: m64, port: {pa}, role: a, modem_channel: 1"
        far_emulated = f"emulate: {{protocol: m64, pty: {pb}, role: b}}"
        mine = f"emulate: {{protocol: m64, pty: {pa}}}"
    else:
        driver = f"backend: micromodem, port: {pa}, rate: 1"
        far_emulated = f"emulate: {{protocol: micromodem, pty: {pb}}}"
        mine = f"emulate: {{protocol: micromodem, pty: {pa}}}"
    app_link = f"{{vehicle: va, {driver}, address: 1, gli: [socket]}}" if real else \
        f"{{vehicle: va, model: {modem}, address: 1, gli: [socket]}}"
    far_link = f"{{vehicle: vb, model: {modem}, address: 2, gli: [socket], {far_emulated}}}" if real else \
        f"{{vehicle: vb, model: {modem}, address: 2, gli: [socket]}}"
    return f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {{static: [150, 0, 0]}}}}
links:
  {ap}: {app_link}
  {far}: {far_link}
""" + (f"  {ea}: {{vehicle: va, model: {modem}, address: 3, gli: [socket], {mine}}}\n" if real else "")


@pytest.mark.parametrize("modem", ["m64", "micromodem"])
def test_a_link_moves_between_simulated_and_real_modem_with_the_application_untouched(tmp_path, modem, daemon_of):
    ap, far, ea = unique("ap"), unique("far"), unique("ea")
    daemon = daemon_of(scene(tmp_path, ap, far, ea, modem, real=False), [ap, far, ea], "--speed", str(SPEED))
    with Link.open(ap, runtime_dir=daemon.runtime) as la, Link.open(far, runtime_dir=daemon.runtime) as lf:
        la.send(b"simulated", dst=2)
        message = lf.recv(timeout=60)
        assert message is not None and message.data == b"simulated"
        daemon.reload(scene(tmp_path, ap, far, ea, modem, real=True))
        daemon.wait_up(ap)  # the driver has configured the emulated modem on the pty
        la.send(b"through the real modem's driver", dst=2)
        message = lf.recv(timeout=60)
        assert message is not None and message.data == b"through the real modem's driver"
        daemon.reload(scene(tmp_path, ap, far, ea, modem, real=False))
        # what the removed emulated modem had on the air finishes as the physics says: wait (in model time,
        # from the live trace: the pose samples go on) until it has, or the next frame meets it
        # (the trace is flushed every half second: wait for the second reload's own line, not the first's)
        reloads = wait_until(lambda: (lambda r: r if len(r) >= 2 else None)(
            [e["t"] for e in daemon.trace_so_far() if e["ev"] == "reload"]), "the second reload in the trace")
        wait_until(lambda: any(e["t"] > reloads[-1] + 3 for e in daemon.trace_so_far()), "the model's clock")
        la.send(b"simulated again", dst=2)
        message = lf.recv(timeout=60)
        assert message is not None and message.data == b"simulated again"
    daemon.stop()
    events = daemon.trace_events()
    kinds = [e["state"] for e in events if e["ev"] == "link" and e.get("link") == ap]
    assert "up" in kinds  # the driver's own link state, in phase 2
    assert [e["size"] for e in events if e["ev"] == "tx" and e.get("link") == ap and "pkt" not in e] == [
        1 + 2 + len(b"through the real modem's driver") + 2]  # vl2b on air, sent by the driver
