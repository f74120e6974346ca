"""The M64 and Micro-Modem drivers ride out an adapter pulled and plugged back, and garbage on the line.

The test plays the modem on a pty it makes at the path the scene names (as tests/test_unplug.py does for
the EvoLogics driver): between its answers it writes noise (bytes that are no sentence, half sentences,
bad checksums, a refusal).  Unplugged three times, the driver goes down, reopens, configures the modem
again (``wcs`` / ``$CCCFG,SRC``) and comes back up; frames sent while it is down wait and go after; a
frame the modem sends amid the noise reaches the application whole.
"""

import time

import pytest

from daemon_kit import Daemon, PluggablePty, unique, wait_until
from hilgate.client import Link
from hilgate.drivers import m64_codec, micromodem_codec
from hilgate.drivers.micromodem_codec import sentence

NOISE = b"\x00\xff\xfe garbage \x1b[0m\r\n\r\n"


class FakeModem(PluggablePty):
    """A modem on a pty at ``path``, answering with ``answer(bytes) -> bytes`` after some noise."""

    def __init__(self, path: str, answer):
        self.heard: list[bytes] = []
        self._answer = answer
        super().__init__(path)

    def answer(self, data: bytes) -> bytes:
        self.heard.append(data)
        reply = self._answer(data)
        return NOISE + reply if reply else b""


def m64_answers():
    codec = m64_codec.ModemCodec()
    queued: list[bytes] = []

    def answer(data: bytes) -> bytes:
        out = b""
        for event in codec.receive_data(data):
            if isinstance(event, m64_codec.Command):
                letter = event.letter
                options = {"v": ("1", "0", "1"), "n": ("8",), "s": ("a",), "l": ("0",), "q": ("a",), "d": ("y", "1", "0", "0.0")}
                if letter == "q":
                    queued.append(event.payload)
                out += b"wc\n" + m64_codec.ModemCodec.response(letter, *options.get(letter, ("a",)))
        return out

    return answer, queued


def micromodem_answers(address: int):
    codec = micromodem_codec.ModemCodec()
    packets: list[bytes] = []
    cycle = {}

    def answer(data: bytes) -> bytes:
        out = b""
        for event in codec.receive_data(data):
            if not isinstance(event, micromodem_codec.Sentence):
                continue
            out += b"$CAERR,000000,NMEA,2*00\r\n$CA"  # a bad checksum and half a sentence, ended by the next line's CR LF
            if event.kind == "CCCFG":
                out += b"\r\n" + sentence("CACFG", *event.fields)
            elif event.kind == "CCCYC":
                cycle["n"] = int(event.fields[5])
                cycle["frames"] = []
                out += b"\r\n" + sentence("CACYC", *event.fields) + sentence("CADRQ", "000000", address, event.fields[2], 0, 64, 1)
            elif event.kind == "CCTXD":
                cycle["frames"].append(bytes.fromhex(event.fields[3]))
                if len(cycle["frames"]) < cycle["n"]:
                    out += b"\r\n" + sentence("CADRQ", "000000", address, event.fields[1], 0, 64, len(cycle["frames"]) + 1)
                else:
                    packets.append(b"".join(cycle["frames"]))
                    out += b"\r\n" + sentence("CATXF", len(packets[-1]))
            else:
                out += b"\r\n"
        return out

    return answer, packets


def datagrams(packets: list[bytes]) -> list[bytes]:
    """The datagrams that the M64 packets a modem queued carry, in order."""
    deframer = m64_codec.Deframer()
    return [e.data for packet in list(packets) for e in deframer.receive_packet(packet)
            if isinstance(e, m64_codec.Datagram)]


def wait_state(daemon, link, wanted, timeout=60):
    deadline = time.monotonic() + timeout
    while daemon.link_status(link)["state"] != wanted:
        assert time.monotonic() < deadline, f"{link} never {wanted}\n{daemon.output()}"
        time.sleep(0.02)


@pytest.mark.parametrize("modem", ["m64", "micromodem"])
def test_unplugged_three_times_with_garbage_on_the_line_the_driver_comes_back_and_loses_nothing(tmp_path, modem):
    link = unique("r")
    path = str(tmp_path / "ttyUSB0")
    if modem == "m64":
        answer, sent = m64_answers()
        options = "backend: m64, role: a, modem_channel: 2, poll_s: 0.05, packet: raw"
    else:
        answer, sent = micromodem_answers(5)
        options = "backend: micromodem, rate: 1, packet: raw"
    fake = FakeModem(path, answer)
    scene = f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  v0: {{pose: {{static: [0, 0, 0]}}}}
links:
  {link}: {{vehicle: v0, {options}, port: {path}, address: 5, queue_frames: 3, gli: [socket]}}
"""
    daemon = Daemon(tmp_path, scene, [link])
    try:
        daemon.wait_for("READY=1")
        wait_state(daemon, link, "up")
        with Link.open(link, runtime_dir=daemon.runtime) as lr:
            for cycle in range(3):
                fake.unplug()
                wait_state(daemon, link, "down")
                lr.send(b"while down %d" % cycle, dst=7)
                fake.plug()
                wait_state(daemon, link, "up")
                # the frame has gone (the modem's report read) before the next pull: a pull amid its cycle
                # leaves the driver not knowing whether it went, and it sends it again (at least once)
                wait_until(lambda: daemon.link_status(link)["tx_packets"] == cycle + 1,
                           lambda: f"the frame sent while down\n{daemon.output()}")
            # a frame from the far modem, amid the noise
            if modem == "m64":
                fake.write(NOISE + b"".join(m64_codec.ModemCodec.packet(p)
                                            for p in m64_codec.packets(m64_codec.frame(b"from the far modem"))))
            else:
                fake.write(NOISE + sentence("CACYC", 0, 7, 5, 1, 0, 1) + b"$CA\r\n"
                           + sentence("CARXD", 7, 5, 0, 1, b"from the far modem".hex().upper()))
            message = lr.recv(timeout=60)
            assert message is not None and message.data == b"from the far modem"
            # until the modem has all three frames (an M64 datagram is as many packets as its length needs)
            wait_until(lambda: len(datagrams(sent) if modem == "m64" else sent) >= 3,
                       lambda: f"the three frames at the modem, got {sent}\n{daemon.output()}")
        if modem == "m64":
            assert datagrams(sent) == [b"while down %d" % i for i in range(3)]
            heard = b"".join(fake.heard)
            assert heard.count(b"wcs,a,2") == 4  # configured at start and after each replug
        else:
            assert sent == [b"while down %d" % i for i in range(3)]
            assert b"".join(fake.heard).count(b"$CCCFG,SRC,5") >= 4
        assert daemon.process.poll() is None
        daemon.stop()
        states = [e["state"] for e in daemon.trace_events() if e.get("ev") == "link" and e["link"] == link]
        assert states.count("down") == 3 and states.count("up") == 4
    finally:
        daemon.close()
        fake.close()
