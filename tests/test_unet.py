"""UnetStack applications and UnetStack modems on hilgate's channel, proven with the libraries themselves.

``unetpy``'s ``UnetSocket`` and ``fjagepy``'s ``Gateway`` (unmodified, installed by the test extra) talk to
the UnetStack door of a simulated link (``gli: [unet]``) and to emulated UnetStack modems (``emulate:
{protocol: unet}``), both ways: payloads byte for byte, and every time the node reports is the model's
(``txTime`` the transmission's start, ``rxTime`` the arrival's, 150 m at 1500 m/s apart: 100 000 µs, as
in the trace).  A UnetSocket application and a dccomms application share one channel; hilgate's own
``unet`` driver meets the emulated modem, comes in by a reload as the other families' drivers do, and
after its modem's port vanishes and comes back sends what it queued meanwhile, in order; against a scripted
modem it counts a refusal with the modem's reason and sends again, first, the frame the modem hung up on.  At the door
bad JSON, unknown actions, over-long lines, floods and a client too many are refused once each and
counted, and the other clients are served throughout.
"""

import json
import socket
import threading

import pytest

pytest.importorskip("unetpy")

from daemon_kit import HANG_GUARD_S, free_port, peer_events, unique, wait_until  # noqa: E402
from hilgate.client import Link  # noqa: E402
from hilgate.scene import SceneError, load_scene_text  # noqa: E402
from fjagepy import Gateway, Performative  # noqa: E402
from unetpy import Protocol, UnetSocket  # noqa: E402
from unetpy.constants import Services  # noqa: E402
from unetpy.messages import DatagramFailureNtf, DatagramReq, RxFrameNtf, TxFrameNtf  # noqa: E402

WAIT_MS = int(HANG_GUARD_S * 1000)  # a receive's hang guard: it returns as soon as the datagram is there
DELAY_US = 100_000  # 150 m at 1500 m/s


def head(name):
    return f"""\
name: {name}
channels: {{ac: {{speed_mps: 1500}}}}
vehicles:
  va: {{pose: {{static: [0, 0, 0]}}}}
  vb: {{pose: {{static: [150, 0, 0]}}}}
trace: {{poses_s: 0}}
links:
"""


def as_bytes(data):
    return bytes(b & 0xFF for b in data)  # fjagepy reads a Java byte[] as signed bytes


def closing(*sockets):
    for sock in sockets:
        sock.close()


def tx_times(events, link):
    return [e["t"] for e in events if e.get("link") == link and e["ev"] == "tx" and "kind" not in e]


# -- the scene ---------------------------------------------------------------------------------------------------


def scene_error(link):
    with pytest.raises(SceneError) as info:
        load_scene_text(head("checks") + f"  x: {{vehicle: va, {link}}}\n", "/tmp/scene.yaml")
    return str(info.value).split(": ", 2)[2]


def test_the_scene_says_what_a_door_or_a_unetstack_modem_lacks_in_one_line():
    spec = load_scene_text(head("ok") + "  x: {vehicle: va, gli: [unet], unet: {tcp: 1100, host: localhost}}\n"
                           "  y: {vehicle: vb, model: unet-m25m, backend: unet, modem_host: 10.0.0.2}\n", "/tmp/s.yaml")
    assert spec.links["x"].unet == (("tcp", 1100), ("host", "127.0.0.1"), ("protocol", 0))
    assert dict(spec.links["y"].options) == {"modem_host": "10.0.0.2"}
    assert scene_error("gli: [socket, unet]") == "a UnetStack door needs both gli: [..., unet] and unet: {tcp: PORT}"
    assert scene_error("unet: {tcp: 1100}") == "a UnetStack door needs both gli: [..., unet] and unet: {tcp: PORT}"
    assert scene_error("gli: [unet], unet: {tcp: 1100, protocol: 64}") == "must be at most 63, not 64"
    assert scene_error("gli: [unet], unet: {tcp: 1100, host: a.host.name}").startswith("'a.host.name' is not an IP")
    assert scene_error("emulate: {protocol: unet, pty: /tmp/u}") == \
        "the UnetStack modem speaks TCP only: give tcp (a loopback port)"
    assert scene_error("backend: unet").startswith("backend unet needs 'modem_host'")
    assert scene_error("backend: unet, modem_host: 'no spaces'") == "'no spaces' is not a host name or an IP address"


# -- the door ---------------------------------------------------------------------------------------------------


def door_scene(a, b, pa, pb, protocol=32):
    return head("unet-door") + f"""\
  {a}: {{vehicle: va, address: 1, bitrate_bps: 2000, gli: [socket, unet], unet: {{tcp: {pa}, protocol: {protocol}}}}}
  {b}: {{vehicle: vb, address: 2, bitrate_bps: 2000, gli: [socket, unet], unet: {{tcp: {pb}, protocol: {protocol}}}}}
"""


def test_unetsocket_applications_talk_both_ways_through_unetstack_doors_with_the_models_times(daemon_of):
    a, b, pa, pb = unique("ua"), unique("ub"), free_port(), free_port()
    daemon = daemon_of(door_scene(a, b, pa, pb), [a, b])
    sa, sb = UnetSocket("localhost", pa), UnetSocket("localhost", pb)
    try:
        assert (sa.getLocalAddress(), sb.getLocalAddress()) == (1, 2)
        assert sa.host(b) == 2 and sb.host("va") == 1  # a link's id, or its vehicle's name
        phy = sa.agentForService(Services.PHYSICAL)
        assert (phy.MTU, phy[2].dataRate) == (2048, 2000.0)  # vl2b's payload; the link's bit rate
        assert sb.bind(Protocol.USER) and sa.bind(Protocol.USER)
        sa.setTimeout(WAIT_MS)
        sb.setTimeout(WAIT_MS)
        assert sa.connect(2, Protocol.USER)
        outbound = bytes(range(256)) + b"\x00\r\n+++AT"
        assert sa.send(outbound)
        got = sb.receive()
        assert isinstance(got, RxFrameNtf) and as_bytes(got.data) == outbound
        assert (got.from_, got.to, got.protocol) == (1, 2, Protocol.USER)
        back = "answer: ünïcode".encode()
        assert sb.send(back, to=1, protocol=Protocol.USER)
        reply = sa.receive()
        assert as_bytes(reply.data) == back and (reply.from_, reply.to) == (2, 1)
    finally:
        closing(sa, sb)
    daemon.stop()
    events = daemon.trace_events()
    # the node's rxTime is the arrival's start: the transmission's start in the trace plus 150 m, exactly
    (ta,), (tb,) = tx_times(events, a), tx_times(events, b)
    assert abs(got.rxTime - round(ta * 1e6) - DELAY_US) <= 1  # (each rounded to µs: within one)
    assert abs(reply.rxTime - round(tb * 1e6) - DELAY_US) <= 1


def test_fjagepys_gateway_asks_the_door_directly_and_each_time_is_the_models(daemon_of):
    a, b, pa, pb = unique("ga"), unique("gb"), free_port(), free_port()
    daemon = daemon_of(door_scene(a, b, pa, pb, protocol=0), [a, b])
    ga, gb = Gateway("localhost", pa), Gateway("localhost", pb)
    try:
        assert [agent.name for agent in ga.agents()] == ["node", "phy", "uwlink", "arp"]
        assert ga.containsAgent(ga.agent("phy")) and not ga.containsAgent(ga.agent("shell"))
        assert "org.arl.unet.Services.PHYSICAL" in ga.services()
        phy = ga.agentForService(Services.PHYSICAL)
        assert phy.name == "phy" and ga.agentForService(Services.ROUTING) is None
        assert [x.name for x in ga.agentsForService(Services.DATAGRAM)] == ["phy", "uwlink"]
        assert ga.agent("node").nodeName == a and ga.agent("node").address == 1
        gb.subscribe(gb.topic(gb.agent("phy")))
        payload = b"through fjagepy's own Gateway"
        rsp = ga.request(DatagramReq(recipient=phy, to=2, protocol=0, data=list(payload)), WAIT_MS)
        assert rsp.perf == Performative.AGREE
        tx = ga.receive(TxFrameNtf, WAIT_MS)
        rx = gb.receive(RxFrameNtf, WAIT_MS)
        assert as_bytes(rx.data) == payload and (rx.from_, rx.to, rx.protocol) == (1, 2, 0)
        assert abs(rx.rxTime - tx.txTime - DELAY_US) <= 1  # the model's propagation, in µs
    finally:
        closing(ga, gb)
    daemon.stop()
    (ta,) = tx_times(daemon.trace_events(), a)
    assert abs(tx.txTime - round(ta * 1e6)) <= 1


def test_a_unetsocket_application_and_a_dccomms_application_share_one_channel(daemon_of):
    a, b, pa = unique("us"), unique("dc"), free_port()
    scene = head("unet-dccomms") + f"""\
  {a}: {{vehicle: va, address: 1, bitrate_bps: 2000, gli: [unet], unet: {{tcp: {pa}}}}}
  {b}: {{vehicle: vb, address: 2, bitrate_bps: 2000, gli: [mq]}}
"""
    daemon = daemon_of(scene, [a, b])
    sock = UnetSocket("localhost", pa)
    try:
        sock.setTimeout(WAIT_MS)
        dccomms = daemon.peer(b, "--send", "1", "--dst", "1", "--size", "12", "--receive", "1", "--timeout",
                              str(HANG_GUARD_S))
        got = sock.receive()
        assert as_bytes(got.data) == f"{b}#0000".encode()[:12] and (got.from_, got.protocol) == (2, 0)
        assert sock.send(b"hello dccomms", to=2)
        frames = [e for e in peer_events(dccomms) if e["ev"] == "frame"]
    finally:
        sock.close()
    assert [(f["payload"], f["src"], f["dst"], f["crc_ok"]) for f in frames] == [("hello dccomms", 1, 2, True)]


# -- the emulated modem ------------------------------------------------------------------------------------------


def emulated_scene(a, b, pa, pb):
    return head("unet-emulated") + f"""\
  {a}: {{vehicle: va, model: unet-m25m, address: 1, gli: [socket], emulate: {{protocol: unet, tcp: {pa}}}}}
  {b}: {{vehicle: vb, model: unet-m25m, address: 2, gli: [socket], emulate: {{protocol: unet, tcp: {pb}}}}}
"""


def test_unetsocket_and_fjagepy_through_emulated_unetstack_modems_with_the_models_times_and_fates(daemon_of):
    a, b, pa, pb = unique("ea"), unique("eb"), free_port(), free_port()
    daemon = daemon_of(emulated_scene(a, b, pa, pb), [a, b], "--speed", "4")
    sa, sb = UnetSocket("localhost", pa), UnetSocket("localhost", pb)
    try:
        phy = sa.agentForService(Services.PHYSICAL)
        assert (phy.MTU, phy[2].dataRate, phy[2].frameDuration) == (64, 1024.0, 0.5)  # models/unet-m25m.yaml
        sb.bind(Protocol.USER)
        sa.setTimeout(WAIT_MS)
        sb.setTimeout(WAIT_MS)
        sa.setSendMode(UnetSocket.BLOCKING)  # waits for the transmission's end
        data = bytes(range(200, 256)) + b"\x00\x01"
        assert sa.send(data, to=2, protocol=Protocol.USER)
        got = sb.receive()
        assert as_bytes(got.data) == data and (got.from_, got.to, got.protocol) == (1, 2, Protocol.USER)
        assert not sa.send(bytes(65), to=2, protocol=Protocol.USER)  # larger than the MTU: refused
        sa.setReliability(True)
        assert sa.send(b"acknowledged", to=2, protocol=Protocol.USER)  # the model's ACK came back
        assert as_bytes(sb.receive().data) == b"acknowledged"
        assert not sa.send(b"nobody is 9", to=9, protocol=Protocol.USER)  # no ACK after the retries: failure
        sa.agent("node").address = 5  # moves the link in the simulation; the socket is told (ParamChangeNtf)
        wait_until(lambda: sa.localAddress == 5, "the address change notified")
        sa.setReliability(None)
        assert sb.send(b"to the new address", to=5, protocol=Protocol.USER)
        assert as_bytes(sa.receive(timeout=WAIT_MS).data) == b"to the new address"
        # fjagepy's own Gateway on the emulated modem: the physical agent's times
        gw = Gateway("localhost", pb)
        gw.subscribe(gw.topic(gw.agent("phy")))
        rsp = sa.getGateway().request(DatagramReq(recipient=phy, to=2, protocol=0, data=[7] * 10), WAIT_MS)
        assert rsp.perf == Performative.AGREE
        tx = sa.getGateway().receive(TxFrameNtf, WAIT_MS)
        rx = gw.receive(RxFrameNtf, WAIT_MS)
        assert as_bytes(rx.data) == bytes([7] * 10) and abs(rx.rxTime - tx.txTime - DELAY_US) <= 1
        gw.close()
    finally:
        closing(sa, sb)
    daemon.stop()
    events = daemon.trace_events()
    retx = [e for e in events if e.get("link") == a and e["ev"] in ("retx", "giveup")]
    assert [e["ev"] for e in retx][-1] == "giveup"  # the failure is the model's: the retries, then giving up


def test_a_datagram_the_modems_fifo_has_no_room_for_fails_at_once_with_the_models_cause(daemon_of):
    a, b, pa = unique("fa"), unique("fb"), free_port()
    scene = head("unet-fifo") + f"""\
  {a}: {{vehicle: va, model: unet-m25m, address: 1, fifo_bytes: 64, gli: [], emulate: {{protocol: unet, tcp: {pa}}}}}
  {b}: {{vehicle: vb, model: unet-m25m, address: 2, gli: [socket]}}
"""
    daemon = daemon_of(scene, [a, b])
    gw = Gateway("localhost", pa)
    try:
        phy = gw.agentForService(Services.PHYSICAL)
        requests = [DatagramReq(recipient=phy, to=2, protocol=0, data=[n] * 60) for n in range(3)]
        for req in requests:  # at once: the first goes on air, the second waits in the FIFO, the third has no room
            gw.send(req)
        fates = {}
        while len(fates) < 3:
            msg = gw.receive(lambda m: isinstance(m, (TxFrameNtf, DatagramFailureNtf)), WAIT_MS)
            assert msg is not None, f"fates so far: {fates}"
            fates[msg.inReplyTo] = msg
    finally:
        gw.close()
    assert [type(fates[r.msgID]).__name__ for r in requests] == ["TxFrameNtf", "TxFrameNtf", "DatagramFailureNtf"]
    assert fates[requests[2].msgID].reason == "dropped by the modem (fifo)"
    daemon.stop()
    drops = [e for e in daemon.trace_events() if e["ev"] == "drop" and e.get("link") == a]
    assert [e["cause"] for e in drops] == ["fifo"]


# -- hilgate's driver ---------------------------------------------------------------------------------------------


def driver_scene(ap, far, em, port, real, modem_there=True, door=0):
    gli = f"gli: [socket, unet], unet: {{tcp: {door}}}"
    app = (f"{{vehicle: va, model: unet-m25m, backend: unet, modem_host: 127.0.0.1, port: {port}, address: 1, "
           f"{gli}}}" if real else f"{{vehicle: va, model: unet-m25m, address: 1, {gli}}}")
    text = head("unet-driver") + f"""\
  {ap}: {app}
  {far}: {{vehicle: vb, model: unet-m25m, address: 2, gli: [socket]}}
"""
    if real and modem_there:
        text += (f"  {em}: {{vehicle: va, model: unet-m25m, address: 3, gli: [], "
                 f"emulate: {{protocol: unet, tcp: {port}}}}}\n")
    return text


def test_hilgates_driver_comes_in_by_a_reload_meets_the_emulator_and_loses_nothing_it_queued(daemon_of, busy_host):
    """The swap of the other families: the link's applications (a socket client, and a UnetSocket on its
    door) stay connected while a reload puts a real modem's driver behind the link; beside busy neighbours,
    as every family's driver meets its emulator (tests/conftest.py's busy_host)."""
    ap, far, em, port, door = unique("ap"), unique("far"), unique("em"), free_port(), free_port()
    daemon = daemon_of(driver_scene(ap, far, em, port, real=False, door=door), [ap, far, em], "--speed", "4")
    usock = UnetSocket("localhost", door)
    with Link.open(ap, runtime_dir=daemon.runtime) as la, Link.open(far, runtime_dir=daemon.runtime) as lf:
        la.send(b"simulated", dst=2)
        assert lf.recv(timeout=HANG_GUARD_S).data == b"simulated"
        assert usock.send(b"a UnetSocket, simulated", to=2)
        assert lf.recv(timeout=HANG_GUARD_S).data == b"a UnetSocket, simulated"
        daemon.reload(driver_scene(ap, far, em, port, real=True, door=door))
        daemon.wait_up(ap)  # the driver set the emulated modem's address and found its agents
        assert usock.send(b"a UnetSocket, through the real modem", to=2)
        assert lf.recv(timeout=HANG_GUARD_S).data == b"a UnetSocket, through the real modem"
        la.send(b"through the driver", dst=2)
        message = lf.recv(timeout=HANG_GUARD_S)
        assert (message.data, message.src) == (b"through the driver", 1)  # the driver set the modem's address 1
        lf.send(b"back to the driver", dst=1)
        assert la.recv(timeout=HANG_GUARD_S).data == b"back to the driver"
        daemon.reload(driver_scene(ap, far, em, port, real=True, modem_there=False, door=door))  # its port vanishes
        wait_until(lambda: daemon.link_status(ap)["state"] != "up", "the driver's link down")
        for n in range(3):
            la.send(b"queued %d" % n, dst=2)
        daemon.reload(driver_scene(ap, far, em, port, real=True, door=door))  # the modem is back
        got = [lf.recv(timeout=HANG_GUARD_S) for _ in range(3)]
        assert [m.data for m in got] == [b"queued 0", b"queued 1", b"queued 2"]
        # the far end has the last frame; the driver its TxFrameNtf once it reads it: a daemon stopped
        # before that closes the driver with the frame in its hands (dropped, closed)
        wait_until(lambda: daemon.link_status(ap)["ready"], "the driver done with what it queued")
    usock.close()
    daemon.stop()
    events = daemon.trace_events()
    configured = [e for e in events if e["ev"] == "modem_config" and e.get("link") == ap]
    assert len(configured) >= 2 and all(e["value"] == e["asked"] == 1 for e in configured)
    assert not [e for e in events if e["ev"] == "drop" and e.get("link") == ap], [(e.get("cause"), e.get("src"), e.get("size")) for e in events if e["ev"] == "drop"]


# -- what the door refuses -----------------------------------------------------------------------------------------


def raw_client(port):
    sock = socket.create_connection(("127.0.0.1", port), timeout=HANG_GUARD_S)
    return sock


def read_line(sock):
    data = b""
    while not data.endswith(b"\n"):
        chunk = sock.recv(65536)
        if not chunk:
            break
        data += chunk
    return data


def closed_after(sock):
    sock.settimeout(HANG_GUARD_S)
    try:
        while sock.recv(65536):
            pass
    except ConnectionResetError:
        pass
    return True


def test_bad_json_unknown_actions_long_lines_floods_and_a_client_too_many_are_refused_once_and_counted(daemon_of):
    a, b, pa, pb = unique("ra"), unique("rb"), free_port(), free_port()
    daemon = daemon_of(door_scene(a, b, pa, pb), [a, b])
    honest = UnetSocket("localhost", pa)
    try:
        bad = raw_client(pa)
        bad.sendall(b"{this is not json\n")
        assert json.loads(read_line(bad))["error"].startswith("not JSON") and closed_after(bad)
        odd = raw_client(pa)
        odd.sendall(b'{"id": "x1", "action": "reboot"}\n{"id": "x2", "action": "agents"}\n')
        assert json.loads(read_line(odd)) == {"id": "x1", "inResponseTo": "reboot", "error": "unknown action 'reboot'"}
        assert json.loads(read_line(odd))["agentIDs"] == ["node", "phy", "uwlink", "arp"]  # it stays
        long = raw_client(pa)
        try:
            long.sendall(b"[" + b"1," * 200_000)
        except OSError:
            pass  # closed while it was still writing
        assert closed_after(long)
        flood = raw_client(pa)
        try:
            flood.sendall(b'{"alive": true}\n' * 2000)
        except OSError:
            pass
        assert closed_after(flood)
        crowd = [raw_client(pa) for _ in range(31)]  # with the honest one and odd: one too many
        assert json.loads(read_line(crowd[-1])) == {"error": "too many clients (32)"} and closed_after(crowd[-1])
        closing(*crowd, odd)
        assert honest.getLocalAddress() == 1  # served throughout
    finally:
        honest.close()
    causes = daemon.link_status(a)["drop_causes"]
    assert {k: causes.get(k) for k in ("unet_bad_json", "unet_unknown_action", "unet_long_line", "unet_flood")} == {
        "unet_bad_json": 1, "unet_unknown_action": 1, "unet_long_line": 1, "unet_flood": 1}
    assert causes["unet_clients"] >= 1
    assert "Traceback" not in daemon.output()


class ScriptedModem:
    """A UnetStack modem's API reduced to a script, on a loopback port: it answers the driver's start-up,
    refuses the first datagram, hangs up on the second without answering, and agrees to everything on the
    next connection.  What each connection received is kept."""

    def __init__(self):
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.connections = []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        self.server.settimeout(HANG_GUARD_S)
        for number in range(2):
            try:
                conn, _ = self.server.accept()
            except OSError:
                return
            got = []
            self.connections.append(got)
            with conn:
                self._talk(conn, number, got)

    def _talk(self, conn, number, got):
        reader = conn.makefile("rb")
        for raw in reader:
            obj = json.loads(raw)
            action = obj.get("action")
            if action in ("agentForService", "agentsForService"):
                service = obj["service"].rsplit(".", 1)[1]
                answer = {"id": obj["id"], "inResponseTo": action}
                if action == "agentsForService":
                    answer["agentIDs"] = ["phy"]
                elif service in ("NODE_INFO", "PHYSICAL"):
                    answer["agentID"] = "node" if service == "NODE_INFO" else "phy"
                conn.sendall(json.dumps(answer).encode() + b"\n")
            elif action == "send":
                data = obj["message"]["data"]
                reply = {"msgID": f"r{len(got)}", "sender": data["recipient"], "recipient": data["sender"],
                         "inReplyTo": data["msgID"]}
                if obj["message"]["clazz"].endswith("ParameterReq"):
                    got.append(("address", data["value"]))
                    reply.update(perf="INFORM", param=data["param"], value=data["value"])
                    clazz = "org.arl.fjage.param.ParameterRsp"
                else:
                    got.append(("datagram", bytes(data["data"]), data["to"], data["protocol"]))
                    datagrams = sum(1 for g in got if g[0] == "datagram")
                    if number == 0 and datagrams == 2:
                        return  # hangs up with the datagram unanswered
                    refused = number == 0 and datagrams == 1
                    if refused:
                        reply.update(perf="REFUSE", reason="scripted refusal")
                    else:
                        reply["perf"] = "AGREE"
                    clazz = "org.arl.unet.RefuseRsp" if refused else "org.arl.fjage.Message"
                self._send(conn, clazz, reply)
                if clazz == "org.arl.fjage.Message":
                    ntf = {"msgID": "t", "perf": "INFORM", "sender": "phy", "recipient": data["sender"],
                           "inReplyTo": data["msgID"], "txTime": 1}
                    self._send(conn, "org.arl.unet.phy.TxFrameNtf", ntf)

    @staticmethod
    def _send(conn, clazz, data):
        conn.sendall(json.dumps({"action": "send", "message": {"clazz": clazz, "data": data}}).encode() + b"\n")

    def close(self):
        self.server.close()


def test_the_driver_counts_a_refusal_and_sends_again_what_the_modem_had_not_answered_for(daemon_of):
    link = unique("dr")
    modem = ScriptedModem()
    scene = head("unet-scripted") + f"""\
  {link}: {{vehicle: va, backend: unet, modem_host: 127.0.0.1, port: {modem.port}, address: 6, unet_protocol: 33,
           packet: raw, gli: [socket]}}
"""
    daemon = daemon_of(scene, [link])
    try:
        daemon.wait_up(link)
        with Link.open(link, runtime_dir=daemon.runtime) as app:
            for text in (b"refused", b"cut short", b"after"):
                app.send(text, dst=9)
            wait_until(lambda: len(modem.connections) == 2 and len(modem.connections[1]) >= 3,
                       lambda: f"the modem got {modem.connections}")
            # (the modem's TxFrameNtf for the last read by the driver: stopped before, it drops it, closed)
            wait_until(lambda: daemon.link_status(link)["tx_packets"] == 2, "both frames counted as sent")
    finally:
        modem.close()
    first, second = modem.connections
    assert first == [("address", 6), ("datagram", b"refused", 9, 33), ("datagram", b"cut short", 9, 33)]
    assert second == [("address", 6), ("datagram", b"cut short", 9, 33), ("datagram", b"after", 9, 33)]
    daemon.stop()
    events = [e for e in daemon.trace_events() if e.get("link") == link]
    assert [e["cause"] for e in events if e["ev"] == "drop"] == ["refused"]
    refusals = [e["reason"] for e in events if e["ev"] == "err" and e.get("cause") == "modem"]
    assert refusals == ["refused: scripted refusal"]
