"""The USB adapter pulled and plugged back, 20 times, while another link carries traffic.

The test plays the modem: it makes a pseudo-terminal, links its slave at the path the scene names,
and answers AT commands with OK.  To unplug, it closes the master and removes the link; to plug
back, it makes a new pty at the same path.  The driver must go down, reopen with backoff, come back
up with no restart, keep (bounded) what was queued meanwhile, and the other link must not notice.
"""

import time

from daemon_kit import Daemon, PluggablePty, unique
from hilgate.client import Link
from hilgate.drivers.evologics_codec import Command, ModemCodec


class FakeModem(PluggablePty):
    """An EvoLogics modem that says OK to everything, on a pty at ``path``; records SENDIMs."""

    def __init__(self, path: str):
        self.sent: list[bytes] = []
        super().__init__(path)

    def plugged(self) -> None:
        self.codec = ModemCodec()

    def answer(self, data: bytes) -> bytes:
        reply = b""
        for event in self.codec.receive_data(data):
            if isinstance(event, Command):
                if event.name == "*SENDIM":
                    self.sent.append(event.payload)
                reply += self.codec.reply(event, "OK")
        return reply


def test_unplug_and_replug_twenty_times_while_another_link_carries_traffic(tmp_path):
    r, x, y = unique("r"), unique("x"), unique("y")
    path = str(tmp_path / "ttyUSB0")
    modem = FakeModem(path)
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  v0: {{pose: {{static: [0, 0, 0]}}}}
  v1: {{pose: {{static: [15, 0, 0]}}}}
links:
  {r}: {{vehicle: v0, backend: evologics, port: {path}, address: 5, ack: false, queue_frames: 3,
        packet: vl2b}}
  {x}: {{vehicle: v0, address: 1, bitrate_bps: 10000}}
  {y}: {{vehicle: v1, address: 2, bitrate_bps: 10000}}
"""
    daemon = Daemon(tmp_path, scene, [r, x, y])

    def state() -> str:
        return next(l["state"] for l in daemon.status()["links"] if l["id"] == r)

    def wait_state(wanted: str, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while state() != wanted:
            assert time.monotonic() < deadline, f"{r} never became {wanted}"
            time.sleep(0.02)

    try:
        daemon.wait_for("READY=1")
        wait_state("up")
        with Link.open(x, runtime_dir=daemon.runtime) as lx, Link.open(y, runtime_dir=daemon.runtime) as ly, \
                Link.open(r, runtime_dir=daemon.runtime) as lr:
            exchanged = 0
            for cycle in range(20):
                modem.unplug()
                wait_state("down")
                if cycle == 0:
                    for i in range(5):  # queued while down: 3 kept, 2 dropped and counted
                        lr.send(b"while down %d" % i, dst=7)
                lx.send(b"cycle %d" % cycle, dst=2)  # the other link carries on
                assert ly.recv(timeout=30).data == b"cycle %d" % cycle
                exchanged += 1
                modem.plug()
                wait_state("up")
                if cycle == 0:  # the kept frames reach the modem before the next unplug: one caught on
                    deadline = time.monotonic() + 60  # the wire then is sent again (the driver's rule)
                    while len(modem.sent) < 3 and time.monotonic() < deadline:
                        time.sleep(0.02)
            lr.send(b"after", dst=7)
            deadline = time.monotonic() + 60
            while len(modem.sent) < 4 and time.monotonic() < deadline:
                time.sleep(0.05)
        assert [p[3:-2] for p in modem.sent] == [b"while down 0", b"while down 1", b"while down 2", b"after"]
        status = {l["id"]: l for l in daemon.status()["links"]}
        assert status[r]["drops"] == 2 and status[x]["drops"] == 0 and exchanged == 20
        assert daemon.process.poll() is None
        daemon.stop()
        events = daemon.trace_events()
        states = [e["state"] for e in events if e.get("ev") == "link" and e["link"] == r]
        assert states.count("down") == 20 and states.count("up") >= 21
        # every frame on the simulated link took exactly its model time: its bytes at 10 kbit/s + 10 ms
        enq = {e["pkt"]: (e["t"], e["size"]) for e in events if e.get("ev") == "enq" and e["link"] == x}
        rx = {e["pkt"]: e["t"] for e in events if e.get("ev") == "rx" and e["link"] == y}
        assert len(rx) == 20
        assert all(abs(rx[p] - enq[p][0] - (enq[p][1] * 8 / 10000 + 0.01)) < 1e-6 for p in rx)
        assert sorted(e["cause"] for e in events if e.get("ev") == "drop" and e["link"] == r) == ["down", "down"]
    finally:
        daemon.close()
        modem.close()
