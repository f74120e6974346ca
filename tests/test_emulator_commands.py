"""The emulated EvoLogics modem answers its AT commands from one table (a real pty, pyserial on the
other end, as a driver would talk to it)."""

import serial

from daemon_kit import Daemon, unique


def test_the_emulated_modem_answers_settings_queries_and_unknown_commands(tmp_path, daemon_of):
    link = unique("em")
    pty = tmp_path / "ttyEVO"
    daemon = daemon_of(f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links: {{{link}: {{vehicle: v, address: 4, emulate: {{protocol: evologics, pty: {pty}}}}}}}
""", [link])
    port = serial.Serial(str(pty), 19200, timeout=10)

    def ask(command: str) -> str:
        port.write(command.encode() + b"\r\n")
        line = port.read_until(b"\r\n").decode().strip()
        return line

    assert ask("AT?AL") == "4"                      # a setting, from the link's address
    assert ask("AT!AL7") == "OK" and ask("AT?AL") == "7"
    assert ask("AT!AL") == "ERROR WRONG FORMAT"
    assert ask("AT?MODE") == "NET"                  # the network interpreter (issue 18: DUNE wants it)
    assert ask("AT?T") == "0"                       # no delivery yet
    assert ask("ATI7") == "EvoLogics GmbH"
    assert ask("AT?NOSUCH") == "ERROR UNKNOWN COMMAND"
    assert ask("ATH") == "OK"
    port.close()


def test_settings_are_range_checked_stored_and_restored_and_the_identity_comes_from_the_preset(tmp_path, daemon_of):
    """Issue 13 items 3, 4, 7: ranges of !AL (1..AM), !AR, !AM, !L, !G, !RI; &W / ATZ0 / &F; the polled
    queries; ATI and ?MODE from ``firmware:``; a malformed SENDIM answered at once, nothing swallowed."""
    link = unique("em")
    pty = tmp_path / "ttyEVO"
    daemon = daemon_of(f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links:
  {link}: {{vehicle: v, address: 4, model: evologics-s2cr-7-17, emulate: {{protocol: evologics, pty: {pty}}},
           firmware: {{version: "2.0", phy: "0.2.1", mac: "2.0.1", mode: "AT"}}}}
""", [link])
    port = serial.Serial(str(pty), 19200, timeout=10)

    def ask(command: str) -> str:
        port.write(command.encode() + b"\r")
        return port.read_until(b"\r\n").decode().strip()

    assert [ask("ATI0"), ask("ATI1"), ask("ATI7"), ask("AT?MODE")] == [
        "2.0", "phy: 0.2.1, mac: v2.0.1", "EvoLogics GmbH", "AT"]
    for command, answer in [
            ("AT!AL0", "ERROR OUT OF RANGE"), ("AT!AL255", "ERROR OUT OF RANGE"), ("AT!AM13", "ERROR OUT OF RANGE"),
            ("AT!AM14", "OK"), ("AT!AL15", "ERROR OUT OF RANGE"), ("AT!AL14", "OK"), ("AT!AR15", "ERROR OUT OF RANGE"),
            ("AT!AR0", "OK"), ("AT!L4", "ERROR OUT OF RANGE"), ("AT!L1", "OK"), ("AT!G2", "ERROR OUT OF RANGE"),
            ("AT!G1", "OK"), ("AT!RI256", "ERROR OUT OF RANGE"), ("AT!RI255", "OK"), ("AT!RI1.5", "ERROR WRONG FORMAT"),
            ("AT?AL", "14"), ("AT?AM", "14"), ("AT?L", "1"), ("AT?RI", "255")]:
        assert ask(command) == answer, command
    assert ask("AT&W") == "OK" and ask("AT!L2") == "OK" and ask("AT!AL3") == "OK"
    port.write(b"ATZ0\r")                            # a reboot: no answer, the stored profile runs again
    assert ask("AT?L") == "1" and ask("AT?AL") == "14"
    assert ask("AT&F") == "OK" and ask("AT?L") == "3" and ask("AT?AL") == "4" and ask("AT?AM") == "254"
    # polled queries
    assert ask("AT?CLOCK").isdigit() and ask("AT!UT1000000") == "OK" and int(ask("AT?UT")) >= 1000000
    assert ask("AT?BV") == "24.00" and ask("AT?BL") == "1900" and ask("AT?BR") == "1900"
    assert ask("AT?PC") == "0" and ask("AT?ZD") == "0" and ask("AT?ZO") == "0"
    assert ask("AT?S") == "ONLINE NORMAL 16384" and ask("AT?DI") == "EMPTY"
    port.write(b"AT?P\r")
    assert port.read_until(b"\r\n") == b"0 0\n" * 7 + b"0 0\r\n"   # 8 paths, bare LF between them
    # a SENDIM without its data: answered at once; the next commands are not swallowed
    assert ask("AT*SENDIM,5,1,ack") == "ERROR WRONG FORMAT"
    assert [ask("AT"), ask("AT"), ask("AT")] == ["OK", "OK", "OK"]
    port.close()


def three_modems(tmp_path, bitrate: int = 400) -> tuple[Daemon, list[str], list[int]]:
    """Links a (address 1), b (2), c (3, every frame to it lost by its error model), 150 m apart in a row."""
    from daemon_kit import free_port

    links = [unique("ea"), unique("eb"), unique("ec")]
    ports = [free_port() for _ in links]
    daemon = Daemon(tmp_path, f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{a: {{pose: {{static: [0, 0, 0]}}}}, b: {{pose: {{static: [150, 0, 0]}}}}, c: {{pose: {{static: [0, 150, 0]}}}}}}
links:
  {links[0]}: {{vehicle: a, address: 1, bitrate_bps: {bitrate}, emulate: {{protocol: evologics, tcp: {ports[0]}}}}}
  {links[1]}: {{vehicle: b, address: 2, bitrate_bps: {bitrate}, emulate: {{protocol: evologics, tcp: {ports[1]}}}}}
  {links[2]}: {{vehicle: c, address: 3, bitrate_bps: {bitrate}, error: {{unit: packet, expr: "1"}},
               emulate: {{protocol: evologics, tcp: {ports[2]}}}}}
""", links, queue_budget_unlimited=True)
    daemon.wait_for("READY=1")
    return daemon, links, ports


def test_at_al_moves_the_modem_in_the_simulation(tmp_path):
    """Issue 13 item 3: after AT!AL the peers see the new source and IMs to the new address arrive;
    the old address reaches nobody."""
    from at_client import AtClient, DUNE_RECVIM

    daemon, links, ports = three_modems(tmp_path, bitrate=4000)
    a, b = AtClient(ports[0]), AtClient(ports[1])
    try:
        assert b.command("!AL9") == "OK" and a.command("!AL7") == "OK"
        assert a.command(b"*SENDIM,2,9,ack,hi") == "OK"
        received = b.wait_message("RECVIM")
        match = DUNE_RECVIM.match(received.line)
        assert (int(match[2]), int(match[3]), received.payload) == (7, 9, b"hi")
        assert a.wait_message("DELIVEREDIM").text == "DELIVEREDIM,9"
        assert a.command(b"*SENDIM,2,2,ack,hi") == "OK"   # the old address: nobody answers to it now
        assert a.wait_message("FAILEDIM").text == "FAILEDIM,2"
        assert not any(m.name == "RECVIM" for m in b.messages)
        daemon.stop()                                       # the trace is complete once the daemon stops
        trace = daemon.trace_events()
        # the trace names the new address's link, and the old one as an address nobody has
        sent = [e for e in trace if e["ev"] == "tx" and e["link"] == links[0]]  # (b's ACK aside)
        assert [e["dst"] for e in sent] == [links[1]] + ["addr:2"] * 4   # the first try and !RI 3 retries
        assert not any(e["ev"] == "rx" and e["pkt"] == sent[1]["pkt"] for e in trace)
    finally:
        a.close()
        b.close()
        daemon.close()


def test_atz_clears_the_transmit_buffer_and_the_pool_refuses_beyond_its_size(tmp_path):
    """Issue 13 items 4 and 6: ATZ4 with an IM awaiting its acknowledgement and two IMs queued behind
    it: ?DI is EMPTY, the two queued IMs never go (traced as drops, cause cleared; ?ZD 2) and no
    report comes for the first.  The transmit pool (@ZL) refuses what does not fit: BUFFER FULL, ?ZO."""
    from at_client import AtClient

    daemon, links, ports = three_modems(tmp_path, bitrate=100)  # a 64-byte IM is on air 5.12 s
    a, b = AtClient(ports[0]), AtClient(ports[1])
    try:
        payload = bytes(64)
        assert a.command(b"*SENDIM,64,2,ack," + payload) == "OK"
        assert a.command(b"*SENDIM,64,2,noack," + payload) == "OK"
        assert a.command(b"*SENDIM,64,2,noack," + payload) == "OK"
        assert a.command("?DI") == "DELIVERING" and a.command("?S") == f"ONLINE DELIVERING {16384 - 192}"
        assert a.command("Z4") == "OK"
        assert a.command("?DI") == "EMPTY" and a.command("?ZD") == "2"
        b.wait_message("RECVIM")                          # the one already on air
        assert a.command("?S") == "ONLINE NORMAL 16384"   # the pool is empty again
        assert a.command("@ZL50") == "OK"                 # a pool of 50 bytes
        assert a.command(b"*SENDIM,64,2,noack," + payload) == "ERROR BUFFER FULL" and a.command("?ZO") == "1"
        assert a.command("@ZO") == "OK" and a.command("?ZO") == "0"
        assert a.command("@ZL0") == "ERROR OUT OF RANGE"
        daemon.stop()                                       # the trace is complete once the daemon stops
        cleared = [e for e in daemon.trace_events() if e.get("cause") == "cleared"]
        assert len(cleared) == 2 and all(e["ev"] == "drop" for e in cleared)
        assert not any(m.name in ("DELIVEREDIM", "FAILEDIM") for m in a.messages)
        assert [m.name for m in b.messages].count("RECVIM") == 0
    finally:
        a.close()
        b.close()
        daemon.close()


def test_bursts_count_packets_and_report_delivered_and_failed_and_ar0_cannot_send(tmp_path):
    """Issue 13 item 6: AT?PC, DELIVERED,<pc>,<dst> / FAILED,<pc>,<dst>; in data mode raw data goes to
    AR, and with AR 0 it cannot be sent (dropped, counted in ?ZD)."""
    from at_client import AtClient

    daemon, links, ports = three_modems(tmp_path, bitrate=4000)
    a, b = AtClient(ports[0]), AtClient(ports[1])
    try:
        assert a.command(b"*SEND,5,2,hello") == "OK" and a.command("?PC") == "1"
        assert b.wait_message("RECV").payload == b"hello"
        assert a.wait_message("DELIVERED").text == "DELIVERED,1,2"
        assert a.command(b"*SEND,5,3,hello") == "OK" and a.command("?PC") == "2"  # c loses every frame
        assert a.wait_message("FAILED").text == "FAILED,2,3"
        # data mode: AR 0 cannot send; AR 2 can, and the reports come framed as +++AT:<n>:
        a.send(b"ATO\n")
        a.send(b"raw data")
        a.send(b"+++AT?ZD\n")
        # (in data mode every line is an escape frame; the client files them with the answers)
        a.wait(lambda: "+++AT?ZD:1:1" in a.replies, "the ?ZD answer in data mode")
        a.send(b"+++AT!AR2\n")
        a.wait(lambda: "+++AT!AR:2:OK" in a.replies, "the !AR answer")
        a.send(b"raw data")
        assert b.wait_message("RECV").payload == b"raw data"
        a.wait(lambda: "+++AT:13:DELIVERED,3,2" in a.replies, "DELIVERED in data mode")
        daemon.stop()                                       # the trace is complete once the daemon stops
        assert any(e.get("cause") == "no_remote_address" for e in daemon.trace_events())
    finally:
        a.close()
        b.close()
        daemon.close()


def test_extended_notifications_follow_the_model(tmp_path):
    """Issue 13 item 5: with @ZX1, SENDSTART/SENDEND at the sender and RECVSTART/RECVEND at the
    receiver with the model's durations and times; RECVFAILED for a frame the receiver's error model
    loses; SRCLEVEL when the source level changes; nothing of it with @ZX0."""
    from at_client import AtClient

    daemon, links, ports = three_modems(tmp_path, bitrate=4000)
    a, b, c = (AtClient(port) for port in ports)
    try:
        assert a.command(b"*SENDIM,5,2,noack,quiet") == "OK"   # @ZX0: no extended notification
        assert b.wait_message("RECVIM").payload == b"quiet"
        for modem in (a, b, c):
            assert modem.command("@ZX1") == "OK"
        assert a.command("!L1") == "OK"
        assert a.wait_message("SRCLEVEL").text == "SRCLEVEL,1"
        assert a.command(b"*SENDIM,5,2,ack,hello") == "OK"
        start, end = a.wait_message("SENDSTART"), a.wait_message("SENDEND")
        duration_us = round(5 * 8 / 4000 * 1e6)                  # 10 000 µs
        assert start.text.split(",")[1:4] == ["2", "im", str(duration_us)]
        assert end.text.split(",")[1:3] == ["2", "im"] and int(end.text.split(",")[4]) == duration_us
        b.wait_message("RECVSTART")
        recv_end = b.wait_message("RECVEND").text.split(",")
        assert int(recv_end[2]) == duration_us and abs(int(recv_end[1]) - int(end.text.split(",")[3]) - 100_000) <= 1
        received = b.wait_message("RECVIM")
        assert received.payload == b"hello" and recv_end[4] == received.text.split(",")[7]  # same integrity
        a.wait_message("DELIVEREDIM")
        assert a.command(b"*SENDIM,4,3,noack,lost") == "OK"    # c's error model loses every frame
        c.wait_message("RECVSTART")
        failed = c.wait_message("RECVFAILED").text.split(",")
        assert failed[1] == "0.00" and int(failed[2]) < 0
        assert not any(m.name == "RECVIM" for m in c.messages) and not any(m.name.startswith("SEND") for m in b.messages)
        for modem in (a, b, c):
            assert modem.blank_lines == 0
    finally:
        for modem in (a, b, c):
            modem.close()
        daemon.close()
