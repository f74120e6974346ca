"""Issue 18: LSTS DUNE's ``Transports.Evologics`` task, unmodified, against two emulated modems.

No DUNE here (CI has no build of it): an independent AT client (:mod:`at_client`) replays the task's
exact start-up and polling sequence, read from DUNE's source (``Task.cpp``: ``onResourceAcquisition``,
``onResourceInitialization``, ``keepAlive``, ``handleMessageDelivered``, ``handleInstantMessage``,
``handleBurstMessage``, ``handleSendEnd``; ``Driver.hpp``: ``sendReset``, ``sendInitialization`` and the
parsers), over TCP with ``\\n`` line ends as DUNE sends them, and checks that every answer parses the
way DUNE parses it.  The two modems are 150 m apart on a 1500 m/s channel: one-way τ = 100 000 µs.
"""

from __future__ import annotations

from at_client import DUNE_DELIVERED, DUNE_I1, DUNE_RECV, DUNE_RECVIM, AtClient, multipath, unsigned
from daemon_kit import free_port, unique

TAU_US = 100_000          # 150 m at 1500 m/s
BITRATE = 1900            # models/evologics-s2cr-7-17.yaml
OK = ("OK", "[*]OK")      # DUNE's expectOK


def scene(la: str, lb: str, pa: int, pb: int) -> str:
    # the scene gives the links addresses 5 and 6; DUNE's configuration says 1 and 2 and sends AT!AL
    return f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{a: {{pose: {{static: [0, 0, 0]}}}}, b: {{pose: {{static: [150, 0, 0]}}}}}}
links:
  {la}: {{vehicle: a, model: evologics-s2cr-7-17, channel: ac, address: 5, emulate: {{protocol: evologics, tcp: {pa}}}}}
  {lb}: {{vehicle: b, model: evologics-s2cr-7-17, channel: ac, address: 6, emulate: {{protocol: evologics, tcp: {pb}}}}}
"""


def dune_start(port: int, address: int) -> AtClient:
    """What DUNE's task does from onResourceAcquisition to the end of onResourceInitialization."""
    first = AtClient(port)
    first.send(b"ATZ0\n")                       # a reboot on a connection of its own ...
    assert first.closed_by_peer(), "ATZ0 must drop the TCP connection"
    first.close()
    modem = AtClient(port)                      # ... then the connection it keeps
    for reset in (b"ATZ1\n", b"ATZ3\n", b"ATZ4\n"):  # sendReset: no answer read, input flushed after 2 s
        modem.send(reset)
    assert [modem.reply() for _ in range(3)] == ["OK", "OK", "OK"]
    assert modem.command("?MODE") == "NET"      # else "invalid mode for Evologics": task deactivated
    version = modem.command("I0")
    assert version not in ("1.6",)              # 1.6 would make DUNE parse RECVIM with the old fields
    assert DUNE_I1.match(modem.command("I1")), "DUNE cannot read the PHY and MAC versions from ATI1"
    if version not in ("1.6", "1.7"):
        assert modem.command("@CTRL") in OK
    for setting in (f"!AL{address}", "!L3", "!G0", "!RC3", "!RT2000", "!RI0", "!ZI0", "!AM14", "@ZU1", "!RP1",
                    "!C2", "@ZX1"):
        assert modem.command(setting) in OK, setting
    unsigned(modem.command("?CLOCK"))           # the keep-alive, every 5 s while idle
    return modem


def fields(message) -> list[str]:
    return message.text.split(",")[1:]


def test_dune_start_up_polling_and_a_message_exchange_parse_as_dune_parses_them(daemon_of):
    la, lb = unique("da"), unique("db")
    pa, pb = free_port(), free_port()
    daemon = daemon_of(scene(la, lb, pa, pb), [la, lb], queue_budget_unlimited=True)
    a = b = None
    try:
        a = dune_start(pa, 1)
        b = dune_start(pb, 2)
        assert a.command("?AL") == "1" and b.command("?AL") == "2"

        # 1. an IM with ack from 1 to 2 (a payload with a comma and CR LF: framed by its length)
        payload = b"hi,\r\nthere"
        assert a.command(b"*SENDIM,10,2,ack," + payload) in OK
        received = b.wait_message("RECVIM")
        match = DUNE_RECVIM.match(received.line)
        assert match, received
        size, src, dst, flag = int(match[1]), int(match[2]), int(match[3]), match[4].decode()
        assert (size, src, dst, flag, received.payload) == (10, 1, 2, "ack", payload)
        assert int(match[7]) > 100                           # integrity: good
        multipath(b.command("?P"))                           # handleInstantMessage asks ?P
        start = a.wait_message("SENDSTART")
        end = a.wait_message("SENDEND")
        duration_us = round(10 * 8 / BITRATE * 1e6)
        assert fields(start)[:3] == ["2", "im", str(duration_us)]
        assert fields(end)[0:2] == ["2", "im"] and int(fields(end)[3]) == duration_us
        b.wait_message("RECVSTART")
        recv_end = b.wait_message("RECVEND")
        assert abs(int(fields(recv_end)[1]) - duration_us) <= 1
        # the model's exact times: the reception ends one propagation time after the transmission
        assert abs(int(fields(recv_end)[0]) - int(fields(end)[2]) - TAU_US) <= 1
        delivered = a.wait_message("DELIVEREDIM")
        assert int(DUNE_DELIVERED.match(delivered.text)[1]) == 2
        ptime = unsigned(a.command("?T"))                    # handleMessageDelivered: ?T, then ?P
        assert ptime == TAU_US and f"{ptime * 1500 / 1e6:.2f}" == "150.00"
        multipath(a.command("?P"))

        # 2. an IM without ack from 2 to 1: DUNE frees the modem on SENDEND
        assert b.command(b"*SENDIM,3,1,noack,abc") in OK
        b.wait_message("SENDSTART")
        send_end = b.wait_message("SENDEND")
        assert fields(send_end)[:2] == ["1", "im"]
        received = a.wait_message("RECVIM")
        match = DUNE_RECVIM.match(received.line)
        assert match and (int(match[2]), int(match[3]), match[4], received.payload) == (2, 1, b"noack", b"abc")
        multipath(a.command("?P"))

        # 3. a burst (DUNE sends more than 64 bytes so): DELIVERED,<pc>,<dst>
        data = bytes(range(100))
        assert a.command(b"*SEND,100,2," + data) in OK
        pc = unsigned(a.command("?PC"))
        received = b.wait_message("RECV")
        match = DUNE_RECV.match(received.line)
        assert match, received
        assert (int(match[1]), int(match[2]), int(match[3]), int(match[4]), received.payload) == (100, 1, 2, BITRATE,
                                                                                                   data)
        assert int(match[7]) == TAU_US                       # the propagation time field
        multipath(b.command("?P"))                           # handleBurstMessage asks ?P
        delivered = a.wait_message("DELIVERED")
        assert fields(delivered) == [str(pc), "2"]
        assert DUNE_DELIVERED.match(delivered.text)          # (DUNE reads the pc there, and finds no name)
        assert unsigned(a.command("?T")) == TAU_US
        multipath(a.command("?P"))

        # keep-alive while idle
        for modem in (a, b):
            unsigned(modem.command("?CLOCK"))
        # nothing DUNE would misread: no blank line, no answer nobody asked for, no ERROR
        for modem in (a, b):
            assert modem.blank_lines == 0 and modem.replies == []
            assert not any(m.name in ("FAILEDIM", "FAILED") for m in modem.messages)
    finally:
        for modem in (a, b):
            if modem is not None:
                modem.close()
