"""Every byte value crosses the Water Linked Modem-M64 family end to end, both ways (issue 38 item 3).

Three pairs of emulated M64s in one daemon, each pair on a modem channel of its own (bands that never
meet), 10 m apart, the model at ``--speed`` 40 (a slot of a second is 25 ms here; times are the model's):

- **packets**: Water Linked's ``WlModem`` at both ends, ``cmd_queue_packet`` → ``get_data_packet``: every
  8-byte payload but the all-zero sync packet (the modem reserves it), CR and LF last among them (a
  payload that ended in CR was refused, ``wrq,n``);
- **datagrams**: ``WlUDPSocket`` at both ends, datagrams of 1 to 300 bytes (each a few seconds of the
  model: a packet a second each way);
- **driver**: hilgate's driver (``packet: raw``: a GLI frame is one datagram) on one modem, ``WlUDPSocket``
  on the other: 1 to 4000 bytes, the driver's bound (``limits``), the largest once each way.
"""

import pytest
from hypothesis import example, given

from bytes_kit import edges, many, payloads, running
from daemon_kit import HANG_GUARD_S, unique, wait_until
from hilgate.client import Link

wlmodem = pytest.importorskip("wlmodem")
from wlmodem import WlModem, WlUDPSocket  # noqa: E402

SPEED = 40
DATAGRAM, DRIVER_MOST = 300, 4000
CHANNELS = {"packets": 2, "datagrams": 4, "driver": 6}


def scene(tmp_path, ids):
    lines = []
    for pair, channel in CHANNELS.items():
        for role, vehicle, address in (("a", "va", 1), ("b", "vb", 2)):
            pty = tmp_path / f"{pair}_{role}"
            lines.append(f"  {ids[pair, role]}: {{vehicle: {vehicle}, model: m64, address: {address + 2 * channel}, "
                         f"packet: raw, gli: [socket], emulate: {{protocol: m64, pty: {pty}, role: {role}, "
                         f"channel: {channel}}}}}\n")
    lines.append(f"  {ids['driver']}: {{vehicle: va, backend: m64, port: {tmp_path / 'driver_a'}, role: a, "
                 f"modem_channel: {CHANNELS['driver']}, address: 1, packet: raw, gli: [socket], poll_s: 0.01, "
                 f"queued_packets: 8, diagnostic_s: 0}}\n")
    return ("channels: {ac: {speed_mps: 1500}}\n"
            "vehicles:\n  va: {pose: {static: [0, 0, 0]}}\n  vb: {pose: {static: [10, 0, 0]}}\n"
            "links:\n" + "".join(lines))


def modem(path, role, channel):
    device = WlModem(str(path))
    assert device.connect() and device.cmd_configure(role, channel)
    return device


@pytest.fixture(scope="module")
def ends(tmp_path_factory):
    ids = {(pair, role): unique("m") for pair in CHANNELS for role in "ab"}
    ids["driver"] = unique("d")
    tmp = tmp_path_factory.mktemp("ptys")
    sockets, devices = [], []
    with running(tmp_path_factory, scene(tmp, ids), list(ids.values()), "--speed", str(SPEED)) as daemon:
        try:
            daemon.wait_up(ids["driver"])
            devices = [modem(tmp / "packets_a", "a", 2), modem(tmp / "packets_b", "b", 2)]
            datagram_a, datagram_b, far = (modem(tmp / "datagrams_a", "a", 4), modem(tmp / "datagrams_b", "b", 4),
                                           modem(tmp / "driver_b", "b", 6))
            devices += [datagram_a, datagram_b, far]
            sockets = [WlUDPSocket(m, sleep_time=0.005, desired_queue_length=8) for m in (datagram_a, datagram_b, far)]
            with Link.open(ids["driver"], runtime_dir=daemon.runtime) as driver:
                yield {"packets": devices[:2], "datagrams": sockets[:2], "driver": (driver, sockets[2])}
        finally:
            for socket_ in sockets:
                socket_.stop()
            for device in devices:
                device._serial.close()


def through(sender, receiver, data):
    """A datagram by one WlUDPSocket, as the other receives it (the next one it has)."""
    assert sender.send(data)
    return wait_until(receiver.receive, "a datagram")


@many(20)
@given(packet=payloads(8, least=8, zero_free=True))
@example(packet=b"1234567\r").via("a CR at the end (was wrq,n)")
@example(packet=b"\r\n\r\n\r\n\r\n").via("line ends only")
@example(packet=b"wcq,8,\r\n").via("a command inside")
@example(packet=b"\x00" * 7 + b"\x01").via("nearly the sync packet")
def test_fuzz_every_byte_crosses_in_an_m64_packet_both_ways(ends, packet):
    a, b = ends["packets"]
    assert a.cmd_queue_packet(packet) and b.get_data_packet(timeout=60) == packet
    assert b.cmd_queue_packet(packet) and a.get_data_packet(timeout=60) == packet


@many(10)
@given(data=payloads(DATAGRAM))
@example(data=edges(DATAGRAM)[1]).via("300 bytes of every value")
@example(data=b"\x00").via("a zero byte, the frame end")
def test_fuzz_every_byte_crosses_in_a_wlmodem_datagram_both_ways(ends, data):
    a, b = ends["datagrams"]
    assert through(a, b, data) == data
    assert through(b, a, data) == data


@many(6)
@given(data=payloads(DRIVER_MOST))
@example(data=edges(DRIVER_MOST)[1]).via("4000 bytes, the driver's largest")
@example(data=b"\r").via("a lone CR")
def test_fuzz_every_byte_crosses_between_hilgates_driver_and_wlmodem_both_ways(ends, data):
    driver, far = ends["driver"]
    # both ways at once: A and B send in slots of their own, so neither waits for the other's datagram
    driver.send(data, dst=2)
    assert far.send(data)
    # (4000 bytes are 504 slots of the model each way: a hang guard for a slow host)
    assert wait_until(far.receive, "the driver's datagram", timeout=3 * HANG_GUARD_S) == data
    message = driver.recv(timeout=3 * HANG_GUARD_S)
    assert message is not None and message.data == data
