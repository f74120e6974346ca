"""WHOI's own ``acomms`` library (unmodified) driving Micro-Modems, for tests/test_micromodem.py and
tests/test_fuzz_bytes_micromodem.py.

Run as ``acomms_peer.py SCENARIO PTY_A PTY_B LOG_DIR``; prints one JSON line per result; or as
``acomms_peer.py serve LOG_DIR NAME=PTY…``, a server of commands on stdin (:func:`serve`).  A process of
its own, because ``acomms``' serial thread never ends (it reopens the port for ever once closed): the
process's end ends it.  Every wait is a hang guard: it returns as soon as the modem answers.
"""

import json
import sys
import time
from datetime import datetime, timezone
from queue import Empty, Queue

from acomms.micromodem import Micromodem


def say(**fields):
    print(json.dumps(fields), flush=True)


def frames_of(packet):
    return [bytes(f.data).hex() for f in packet.frames]


def serve(logs: str, ptys: list[str]) -> None:
    """``serve LOG_DIR NAME=PTY…``: a Micromodem on each pty, then one JSON command a line on stdin, one
    JSON answer a line on stdout (tests/test_fuzz_bytes_micromodem.py drives it with hypothesis):
    ``{"op": "send", "from": NAME, "dest": ADDRESS, "rate": R, "data": HEX}`` once the modem is idle;
    ``{"op": "receive", "at": NAME, "timeout": S}`` → the next packet's frames (hex) or null."""
    modems, received = {}, {}
    for entry in ptys:
        name, path = entry.split("=", 1)
        modems[name] = Micromodem(name=name, log_path=logs)
        modems[name].connect_serial(path, 19200)
        received[name] = Queue()
        modems[name].attach_packetrx_queue(received[name])
    say(ids={name: m.id for name, m in modems.items()})
    for line in sys.stdin:
        command = json.loads(line)
        if command["op"] == "send":
            sender = modems[command["from"]]
            for _ in range(6000):  # the previous cycle's end (a hang guard of 60 s)
                if str(sender.state) == "Idle":
                    break
                time.sleep(0.01)
            sender.send_packet_data(command["dest"], bytes.fromhex(command["data"]), rate_num=command["rate"])
            say(sent=str(sender.state))
        elif command["op"] == "receive":
            try:
                packet = received[command["at"]].get(timeout=command["timeout"])
            except Empty:
                say(frames=None)
            else:
                say(frames=frames_of(packet), src=packet.cycleinfo.src, rate=packet.cycleinfo.rate_num)


def main() -> None:
    if sys.argv[1] == "serve":
        serve(sys.argv[2], sys.argv[3:])
        return
    scenario, pty_a, pty_b, logs = sys.argv[1:5]
    a = Micromodem(name="a", log_path=logs)
    b = Micromodem(name="b", log_path=logs)
    a.connect_serial(pty_a, 19200)
    b.connect_serial(pty_b, 19200)
    say(event="ids", a=a.id, b=b.id)
    packets, csts, acks, results = Queue(), Queue(), Queue(), Queue()
    b.attach_packetrx_queue(packets)
    b.attach_incoming_cst_queue(csts)
    a.ack_listeners.append(lambda ack, msg: acks.put((ack.src, ack.dest, ack.frame_num, ack.ack)))
    if scenario == "exchange":
        for rate, data in ((1, b"three frames at rate one: " * 7), (5, bytes(range(256)) * 3 + b"tail")):
            a.send_packet_data(b.id, data, rate_num=rate)
            packet = packets.get(timeout=60)
            cst = csts.get(timeout=30)
            say(event="packet", rate=rate, frames=frames_of(packet), src=packet.cycleinfo.src,
                dest=packet.cycleinfo.dest, cst={k: cst[k] for k in ("mode", "rate_num", "num_frames", "bad_frames_num",
                                                                    "mfd_pow", "snr_in", "dqf", "src", "dest")})
        a.send_packet_data(b.id, b"acknowledge these two frames please" * 3, rate_num=2, ack=True)
        packet = packets.get(timeout=60)
        got = [acks.get(timeout=30) for _ in range(2)]
        say(event="acked", frames=frames_of(packet), acks=got)
        a.send_ping(b.id)
        say(event="ping", owtt=a.wait_for_ping_reply(b.id, timeout=60))
        a.send_packet_data(b.id, b"FH-FSK, rate 0", rate_num=0)
        say(event="packet", rate=0, frames=frames_of(packets.get(timeout=60)))
    elif scenario == "lost":
        a.send_packet_data(b.id, b"lost on the way " * 12, rate_num=1, ack=True)
        cst = csts.get(timeout=60)
        say(event="cst", mode=cst["mode"], num_frames=cst["num_frames"], bad_frames_num=cst["bad_frames_num"])
        try:
            packets.get(timeout=0.5)
            say(event="packet")
        except Empty:
            pass
        say(event="acks", count=acks.qsize())
    elif scenario == "wait":
        # Micromodem.wait_for_data_packet: $CARXP (a packet detected), then the frames, then its $CACST
        # (at rate 0, fsk=True: the cycle init's $CACST first); every sentence's type and the raw $CACST
        seen = {"a": [], "b": []}
        a.nmea_listeners.append(lambda msg: seen["a"].append(msg["type"]))
        b.nmea_listeners.append(lambda msg: seen["b"].append(msg["type"]))
        csts = []
        b.nmea_listeners.append(lambda msg: msg["type"] == "CACST" and csts.append(msg["raw"].strip()))
        for rate, data, fsk in ((1, b"waited for, at rate one; " * 7, False), (0, b"an FSK packet, waited for", True)):
            a.send_packet_data(b.id, data, rate_num=rate)
            got = b.wait_for_data_packet(fsk=fsk, timeout=60)
            say(event="waited", rate=rate, data=None if got is None else bytes(got).hex())
        say(event="sentences", a=seen["a"], b=seen["b"], cst=csts)
    elif scenario == "calls":
        # the rest of Micromodem's public calls that a modem answers, one by one
        say(event="api", level=a.query_nmea_api_level())
        a.query_modem_info()
        # (get_config("ALL") waits for each CACFG on a queue of its own: lines between two waits are lost,
        # on a real modem too; what the modem printed is read from the listener)
        names = []
        a.nmea_listeners.append(lambda msg: msg["type"] == "CACFG" and names.append(msg["params"][0]))
        a.get_config("ALL", response_timeout=1)
        say(event="config", all=sorted(set(names)), set=sorted(a.set_config("RXP", 1) or ()),
            src=a.get_config("SRC"))
        when = datetime(2031, 5, 4, 3, 2, 1, tzinfo=timezone.utc)
        set_reply = a.set_time(when)
        now = a.get_time_info(timeout=5)
        say(event="time", set=set_reply.time.isoformat(), timed_out=set_reply.timed_out,
            ahead_s=(now[0] - when).total_seconds(), clock=now[1], pps=now[2])
        say(event="gpio", value=a.change_gpio(1, 1))
        # (wait_for_ping_reply(include_cst=True) attaches its queue for the $CACST only once $CAMPR is in: on a
        # busy host the $CACST behind it can come first and be missed, with a real modem too; a queue of ours
        # attached before the ping holds it: nothing else was received by b before)
        replies = Queue()
        b.attach_incoming_cst_queue(replies)
        b.send_ping(a.id)
        owtt, _ = b.wait_for_ping_reply(a.id, timeout=60, include_cst=True)
        cst = replies.get(timeout=30)
        say(event="ping", owtt=owtt, cst={k: cst[k] for k in ("mode", "src", "dest", "packet_type")})
        a.send_minipacket(b.id, "1ABC")
        say(event="minipacket", data=b.wait_for_minipacket(timeout=60))
        frames = a.send_test_packet(b.id, rate_num=1, num_frames=2)
        packet = packets.get(timeout=60)
        say(event="test_packet", sent=[bytes(f.data).hex() for f in frames], got=frames_of(packet))
    elif scenario == "refused":
        # the calls whose sentences the emulator does not do: each gets the modem's refusal, none hangs
        refused = []
        a.nmea_listeners.append(lambda msg: msg["type"] == "CAERR" and refused.append(",".join(msg["params"][1:])))
        a.send_sweep("up")
        a.send_tdp(dest_id=b.id, databytes=bytearray(b"ab"), rate_num=1)
        a.send_fdp_ping(b.id)
        a.send_tjn(b.id, 0, "00", "00")
        a.send_single_shot_sst()
        a.start_hibernate(hibernate_in=60, ignore_response=True)
        say(event="remus", answer=a.ping_remus(response_timeout=1))
        say(event="narrow", answer=a.ping_narrow(response_timeout=1))
        a.send_uplink_request(b.id)
        for _ in range(500):  # every refusal in (a hang guard of 5 s)
            if len(refused) >= 9:
                break
            time.sleep(0.01)
        say(event="refused", errors=refused)
    say(event="done", a=str(a.state), b=str(b.state))


if __name__ == "__main__":
    main()
