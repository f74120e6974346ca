"""Every byte value crosses the WHOI Micro-Modem family end to end, both ways (issue 38 item 3).

Two pairs of emulated Micro-Modems in one daemon, each on a channel of its own, 10 m apart, the model at
``--speed`` 8 (times are the model's):

- **acomms**: WHOI's ``acomms`` at both ends (``send_packet_data`` → the packet-received queue), a packet
  of any rate 0 to 5 and of any size its frames hold (1 to 32 bytes at rate 0, 192 at rates 1-2, 512 at
  3-4, 2048 at 5), the largest of each rate among them;
- **driver**: hilgate's driver (``packet: raw``, rate 5) on one modem, ``acomms`` on the other: 1 to 2048
  bytes from the driver; any rate from ``acomms`` to the driver.

``acomms`` runs in a process of its own (tests/peers/acomms_peer.py ``serve``: its serial threads never
end), driven a JSON line at a time; hypothesis draws the payloads here.  The data travel as hex on the
line, so what is checked is that no byte is changed, dropped or padded on the way.
"""

import json
import subprocess
import sys

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from bytes_kit import edges, many, payloads, running
from daemon_kit import HANG_GUARD_S, HERE, unique
from hilgate.client import Link
from hilgate.drivers.micromodem_codec import RATES

pytest.importorskip("acomms")

SPEED = 8
PEER = f"{HERE}/peers/acomms_peer.py"
ADDRESSES = {"a": 1, "b": 2, "x": 3, "y": 4}  # x: the driver's modem; y: acomms' modem facing it


def scene(tmp_path, ids):
    lines = [f"  {ids[name]}: {{vehicle: {'va' if name in 'ax' else 'vb'}, channel: {'c1' if name in 'ab' else 'c2'}, "
             f"model: micromodem, address: {address}, packet: raw, gli: [socket], "
             f"emulate: {{protocol: micromodem, pty: {tmp_path / name}}}}}\n" for name, address in ADDRESSES.items()]
    lines.append(f"  {ids['driver']}: {{vehicle: va, channel: c2, backend: micromodem, port: {tmp_path / 'x'}, "
                 f"address: {ADDRESSES['x']}, rate: 5, packet: raw, gli: [socket]}}\n")
    return ("channels: {c1: {speed_mps: 1500}, c2: {speed_mps: 1500}}\n"
            "vehicles:\n  va: {pose: {static: [0, 0, 0]}}\n  vb: {pose: {static: [10, 0, 0]}}\n"
            "links:\n" + "".join(lines))


class Peer:
    """The acomms process: one command a line in, one answer a line out."""

    def __init__(self, tmp_path, names):
        self.process = subprocess.Popen([sys.executable, PEER, "serve", str(tmp_path / "acomms_logs"),
                                         *(f"{name}={tmp_path / name}" for name in names)],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.ids = self._answer()["ids"]

    def _answer(self) -> dict:
        while True:
            line = self.process.stdout.readline()
            assert line, f"the acomms peer ended ({self.process.poll()})"
            if line.startswith("{"):
                return json.loads(line)

    def ask(self, **command) -> dict:
        self.process.stdin.write(json.dumps(command) + "\n")
        self.process.stdin.flush()
        return self._answer()

    def send(self, name: str, dest: int, rate: int, data: bytes) -> None:
        self.ask(op="send", dest=dest, rate=rate, data=data.hex(), **{"from": name})

    def receive(self, name: str) -> bytes | None:
        answer = self.ask(op="receive", at=name, timeout=HANG_GUARD_S)
        return None if answer["frames"] is None else b"".join(bytes.fromhex(frame) for frame in answer["frames"])

    def close(self) -> None:
        self.process.kill()
        self.process.wait()


@pytest.fixture(scope="module")
def ends(tmp_path_factory):
    ids = {name: unique("u") for name in ADDRESSES}
    ids["driver"] = unique("d")
    tmp = tmp_path_factory.mktemp("ptys")
    with running(tmp_path_factory, scene(tmp, ids), list(ids.values()), "--speed", str(SPEED)) as daemon:
        daemon.wait_up(ids["driver"])
        peer = Peer(tmp, ["a", "b", "y"])
        try:
            assert peer.ids == {"a": 1, "b": 2, "y": 4}
            with Link.open(ids["driver"], runtime_dir=daemon.runtime) as driver:
                yield peer, driver
        finally:
            peer.close()


def a_packet():
    """(rate, data): any rate, any size its packet holds."""
    return st.sampled_from(sorted(r for r in RATES if r <= 5)).flatmap(
        lambda rate: st.tuples(st.just(rate), payloads(RATES[rate].packet_bytes)))


@many(12)
@given(packet=a_packet())
@example(packet=(0, edges(32)[1])).via("rate 0, 32 bytes")
@example(packet=(1, edges(192)[0])).via("rate 1, every special")
@example(packet=(5, edges(2048)[1])).via("rate 5, 2048 bytes")
@example(packet=(3, b"\x00" * 300)).via("zeros: a real modem's padding would not show")
def test_fuzz_every_byte_crosses_between_two_acomms_modems_both_ways(ends, packet):
    peer, _ = ends
    rate, data = packet
    peer.send("a", ADDRESSES["b"], rate, data)
    assert peer.receive("b") == data
    peer.send("b", ADDRESSES["a"], rate, data)
    assert peer.receive("a") == data


@many(8)
@given(data=payloads(RATES[5].packet_bytes), rate=st.sampled_from([0, 1, 2, 3, 4, 5]))
@example(data=edges(2048)[1], rate=5).via("2048 bytes each way")
@example(data=b"\r\n", rate=0).via("a line end at rate 0")
def test_fuzz_every_byte_crosses_between_hilgates_driver_and_acomms_both_ways(ends, data, rate):
    peer, driver = ends
    driver.send(data, dst=ADDRESSES["y"])
    assert peer.receive("y") == data
    back = data[:RATES[rate].packet_bytes]
    peer.send("y", ADDRESSES["x"], rate, back)
    message = driver.recv(timeout=HANG_GUARD_S)
    assert message is not None and message.data == back
