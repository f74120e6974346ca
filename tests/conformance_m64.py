"""The Water Linked Modem-M64's conformance rows (``conformance_kit``): Water Linked's public "Modem-M64 serial
protocol" (version 1.0.x, waterlinked.github.io/modem-m64/modem-m64-protocol) and the modem's page (LED,
channels, "64 bit per second … latency 1.5 – 2.5 sec"); the outside library is Water Linked's ``wlmodem``
1.3.0 (tests/test_m64.py, tests/test_fuzz_bytes_m64.py).  The probes go to an emulated M64 of role a on
channel 1."""

from conformance_kit import Row

CK = rb"\*[0-9a-f]{2}\n"  # the modem always sends its checksum

ROWS = [
    Row("`wcv`", "`wrv,<major>,<minor>,<patch>` (`wrv,1,0,1`); a host checks major 1",
        "`wrv,1,0,1`", "at start: protocol 1.x or it retries in 2 s", ("WlModem.connect", "WlModem.cmd_get_version"),
        probe=b"wcv\n", answer=rb"wrv,1,0,1\*44\n", keys=("v",), driver_code='command("v"'),
    Row("`wcn`", "`wrn,<size>`: the payload size, 8 on the M64", "`wrn,8`",
        "at start: the size it cuts datagrams into", ("WlModem.connect",),
        probe=b"wcn\n", answer=rb"wrn,8\*ba\n", keys=("n",), driver_code='command("n"'),
    Row("`wcc`", "`wrc,<role>,<channel>`", "the role and channel in force", "—", ("WlModem.request",),
        probe=b"wcc\n", answer=rb"wrc,a,1" + CK, keys=("c",)),
    Row("`wcs,<role>,<channel>`", "`wrs,a` / `wrs,n`; roles a and b on the same channel 1–7 make a pair",
        "`wrs,a`, the link moves to the channel's band (a `band` trace line); `wrs,n` for another role or channel",
        "at start and after every reconnection: the link's `role`, `modem_channel`", ("WlModem.cmd_configure",),
        probe=b"wcs,a,1\nwcs,c,9\n", answer=rb"wrs,a" + CK + rb"wrs,n" + CK, keys=("s",), driver_code='command("s"'),
    Row("`wcl`", "`wrl,<packets queued>`", "the emulator's queue (at most 1024 packets: the real bound is not published)",
        "every `poll_s`, to keep `queued_packets` in the modem, as WlUDPSocket", ("WlModem.cmd_get_queue_length",
                                                                                 "WlUDPSocket.send"),
        probe=b"wcl\n", answer=rb"wrl,0" + CK, keys=("l",), driver_code='command("l"'),
    Row("`wcf`", "`wrf,a` / `wrf,n`: the transmit queue flushed", "`wrf,a`; each packet flushed traced `drop`, cause `flushed`",
        "after start-up: what a reconnection cut short does not go (the frame goes again whole)",
        ("WlModem.cmd_flush_queue",), probe=b"wcf\n", answer=rb"wrf,a" + CK, keys=("f",), driver_code='command("f"'),
    Row("`wcd`", "`wrd,<link y|n>,<packet_count>,<packet_loss_count>,<bit_error_rate>`; an undecodable packet, data "
        "or sync, counts as lost", "link = in sync; packets from the other role; those the model lost and those "
        "missed in sync; BER `0.0` (the model loses packets whole)", "every `diagnostic_s` into the trace "
        "(`modem_stats`)", ("WlModem.cmd_get_diagnostic",), probe=b"wcd\n", answer=rb"wrd,n,0,0,0\.0" + CK,
        keys=("d",), driver_code='command("d"'),
    Row("`wcq,<size>,<payload>`", "`wrq,a` (queued; no acoustic acknowledgement) / `wrq,n`; the payload binary, "
        "exactly `size` bytes, a checksum optional", "`wrq,a`; `wrq,n` for another size or a full queue (`drop`, "
        "`queue_full`); the payload framed by its length (a last byte CR is the payload's)",
        "a GLI frame as one WlUDPSocket datagram: CRC-8, COBS/R, a zero byte, in 8-byte packets",
        ("WlModem.cmd_queue_packet", "WlUDPSocket.send"), probe=b"wcq,8,1234567\r\nwcq,3,abc\nwcf\n",
        answer=rb"wrq,a" + CK + rb"wrq,n" + CK + rb"wrf,a" + CK, keys=("q",), driver_code='command("q"'),
    Row("`wrp,<size>,<payload>`", "a packet from the other modem", "when the model delivers it, with its checksum; "
        "never the all-zero sync packet", "joined into datagrams; one with a lost packet fails its CRC "
        "(`err`, `crc`/`cobs`)", ("WlModem.get_data_packet", "WlUDPSocket.receive"),
        tested=("test_fuzz_bytes_m64.py", "get_data_packet"), driver_code="case Packet(payload=payload)"),
    Row("`wr?`", "malformed request", "the same, for bytes that make no sentence", "fails the command in flight",
        probe=b"hello\n", answer=rb"wr\?\*[0-9a-f]{2}\n", driver_code="case Refused("),
    Row("`wr!`", "the checksum does not match", "the same", "fails the command in flight",
        probe=b"wcv*00\n", answer=rb"wr!\*1e\n", driver_code="case Refused("),
    Row("checksum `*xx`", "CRC-8 (0x07), optional from the host, always sent by the modem",
        "taken with or without; always sent", "sends it", ("WlModem.request",), probe=b"wcv*fe\n",
        answer=rb"wrv,1,0,1\*44\n"),
    Row("line end", "LF or CR LF", "either, and empty lines (wlmodem sends one to start afresh)",
        "an empty line at start", ("WlModem.connect",), probe=b"\r\n\nwcv\r\n", answer=rb"wrv,1,0,1\*44\n",
        driver_code='self.port.write(b"\\n")'),
    Row("the all-zero payload", "reserved: the sync packet, sent when nothing is queued, filtered by the receiver",
        "role A sends it when its queue is empty (B once in sync), never printed", "its datagram framing never "
        "makes one", tested=("test_fuzz_bytes_m64.py", "zero_free=True")),
    Row("roles and sync", "A always transmits; B listens until it hears an A, then answers; B goes back to listen "
        "mode after several undecodable packets (signal lost)", "A every second; B 50 ms after A's packet ends; "
        "in sync after a good packet, a slot without one is missed (`err`, `missed`), out of sync after three",
        "—", ("WlModem.cmd_get_diagnostic",), tested=("test_m64.py", "falls_silent")),
    Row("channels 1–7", "bands 31.25–62.25 … 218–250 kHz (the channel table)", "the link's band in the "
        "simulation, at power-on (`emulate: {channel}`) and after `wcs`: other channels never meet",
        "`modem_channel`", ("WlModem.cmd_configure",), tested=("test_m64.py", "power_on_channel")),
    Row("rate and latency", "64 bit/s each way, latency 1.5–2.5 s", "a packet a second each way; 0.32 s on air "
        "(the `m64` preset's 200 bit/s) + decoding 1.1 s: 1.42–2.55 s from queueing over 0–200 m", "—",
        ("WlModem.get_data_packet",), tested=("test_m64.py", "RX_DELAY")),
    Row("LED", "flashing: pairing; fixed: in sync, a blink per packet", "not emulated (no LED): `wcd`'s link flag "
        "says the sync", "—"),
    Row("serial line", "115200 8N1, no flow control", "not paced (a `wcq` takes 1.2 ms on the real line)",
        "`baud` 115200", tested=("test_m64.py", "WlModem(str(p))")),
]
