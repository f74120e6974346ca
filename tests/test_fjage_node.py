"""fjåge's JSON protocol and a UnetStack node's agents, without a port (hilgate/core/fjage.py, unet_node.py).

The codec turns any bytes into events and never raises; the node answers the directory, parameters and
datagram requests as ``fjagepy`` and ``unetpy`` read them, publishes to the peers that want a topic, and
refuses what it cannot act on once, counted by cause: bad JSON and over-long lines close that peer, an
unknown action or a message no agent understands is answered and the peer stays.  The same node, on a
port in front of a link, is tested with the libraries themselves in tests/test_unet.py.
"""

import base64
import json

from hypothesis import given, settings
from hypothesis import strategies as st

from fuzzkit import examples
from hilgate.core import fjage
from hilgate.core.fjage import Alive, Bad, Deliver, FjageCodec, Request, Response, Wants
from hilgate.core.unet_node import BURST, UnetNode


class Host:
    """A node's host with a link of its own: what it is written, sent and refused is kept."""

    node_name = "lnk"

    def __init__(self, address=1, writable=False):
        self._address = address
        self.writable = writable
        self.out = {}
        self.sent = []
        self.closed = []
        self.refusals = []
        self.t = 2.5

    @property
    def address(self):
        return self._address

    def now(self):
        return self.t

    def phy_params(self):
        return {"MTU": 64, "dataRate": 1024.0, "frameDuration": 0.5, "busy": False}

    def set_address(self, address):
        if self.writable:
            self._address = address
        return self.writable

    def transmit(self, datagram):
        self.sent.append(datagram)
        return None

    def resolve(self, name):
        return {"other": 2}.get(name)

    def hold(self, client):
        pass

    def write(self, client, data):
        self.out.setdefault(client, []).extend(json.loads(line) for line in data.splitlines())
        return True

    def close_client(self, client):
        self.closed.append(client)

    def refused(self, cause):
        self.refusals.append(cause)


def line(obj):
    return json.dumps(obj).encode() + b"\n"


def request(clazz, recipient, perf="REQUEST", **data):
    return {"action": "send", "relay": True, "message": {"clazz": clazz, "data": {
        "msgID": "m1", "perf": perf, "sender": "gw", "recipient": recipient, **data}}}


def node_with_peer(**host):
    h = Host(**host)
    node = UnetNode(h)
    node.connect("p")
    return node, h


def replies(h, peer="p"):
    return h.out.pop(peer, [])


# -- the codec -------------------------------------------------------------------------------------------------


def test_the_codec_reads_every_kind_of_line_and_a_line_split_anywhere():
    lines = (line({"id": "1", "action": "agents"}) + line({"alive": True})
             + line({"action": "wantsMessagesFor", "agentIDs": ["gw", "#phy__ntf"]})
             + line({"action": "send", "relay": False, "message": {"clazz": "x.Y", "data": {"a": 1}}})
             + line({"id": "2", "inResponseTo": "agents", "agentIDs": []}) + b"\n")
    whole = FjageCodec().receive_data(lines)
    codec = FjageCodec()
    pieces = [e for i in range(len(lines)) for e in codec.receive_data(lines[i:i + 1])]
    assert whole == pieces == [Request("1", "agents", {"id": "1", "action": "agents"}), Alive(True),
                               Wants(("gw", "#phy__ntf")), Deliver({"clazz": "x.Y", "data": {"a": 1}}, False),
                               Response("2", "agents", {"id": "2", "inResponseTo": "agents", "agentIDs": []})]


def test_the_codec_refuses_bad_lines_in_one_line_each_and_breaks_only_on_framing():
    events = FjageCodec().receive_data(line({"id": "7", "action": "reboot"}) + line([1, 2]) + line({"x": 1}))
    assert events[0] == Bad("unknown action 'reboot'", False, "7", "reboot")
    assert events[1] == Bad("a JSON list, not an object", True)
    assert len(events) == 2  # nothing is read after the framing broke
    codec = FjageCodec(max_line=100)
    assert codec.receive_data(b"{" * 50) == []
    assert codec.receive_data(b"a" * 60) == [Bad("a line longer than 100 bytes", True)]
    assert codec.pending == 0 and codec.receive_data(line({"alive": True})) == []
    assert FjageCodec().receive_data(b"{\"id\": 1\n")[0].fatal


PIECES = [b"\n", b"{", b"}", b'"', b"[", b'{"action":"send"}\n', b'{"id":"1","action":"agents"}\n']


@settings(max_examples=examples(300), deadline=None)
@given(st.lists(st.one_of(st.binary(max_size=60), st.sampled_from(PIECES)), max_size=20))
def test_fuzz_the_codec_never_raises_and_holds_at_most_a_line(chunks):
    codec = FjageCodec(max_line=256)
    for chunk in chunks:
        for event in codec.receive_data(chunk):
            assert isinstance(event, (Request, Deliver, Wants, Alive, Response, Bad))
        assert codec.pending <= 256 + 60


def test_bytes_are_read_in_either_form_and_written_as_a_java_node_writes_them():
    data = bytes(range(256))
    assert fjage.decode_bytes(fjage.encode_bytes(data)) == data
    assert fjage.decode_bytes([b - 256 if b > 127 else b for b in data]) == data  # fjagepy's signed bytes
    assert fjage.decode_bytes(list(data)) == data
    assert fjage.encode_bytes(b"hi") == {"clazz": "[B", "data": base64.b64encode(b"hi").decode()}
    for bad in ([256], [1.5], "text", {"clazz": "[B", "data": "!!"}, [True]):
        assert fjage.decode_bytes(bad) is None


# -- the node -------------------------------------------------------------------------------------------------


def test_the_directory_names_the_agents_and_their_services_and_no_null_agent():
    node, h = node_with_peer()
    for ident, action, extra in (("1", "agents", {}), ("2", "containsAgent", {"agentID": "phy"}),
                                 ("3", "containsAgent", {"agentID": "shell"}),
                                 ("4", "agentForService", {"service": "org.arl.unet.Services.NODE_INFO"}),
                                 ("5", "agentsForService", {"service": "org.arl.unet.Services.DATAGRAM"}),
                                 ("6", "agentForService", {"service": "org.arl.unet.Services.ROUTING"}),
                                 ("7", "services", {})):
        node.receive("p", line({"id": ident, "action": action, **extra}))
    answers = {a["id"]: a for a in replies(h)}
    assert answers["1"]["agentIDs"] == ["node", "phy", "uwlink", "arp"]
    assert (answers["2"]["answer"], answers["3"]["answer"]) == (True, False)
    assert answers["4"]["agentID"] == "node"
    assert answers["5"]["agentIDs"] == ["phy", "uwlink"]
    assert "agentID" not in answers["6"]  # a null agentID is a broken answer to fjagepy: it waits 6 s
    assert "org.arl.unet.Services.ADDRESS_RESOLUTION" in answers["7"]["services"]


def test_parameters_are_answered_short_or_qualified_and_the_address_is_the_hosts_to_change():
    node, h = node_with_peer(address=3)
    node.receive("p", line(request("org.arl.fjage.param.ParameterReq", "node", index=-1, requests=[], param="address",
                                   value=None)))
    rsp = replies(h)[0]["message"]
    assert rsp["clazz"] == "org.arl.fjage.param.ParameterRsp"
    assert rsp["data"]["inReplyTo"] == "m1" and rsp["data"]["recipient"] == "gw"
    assert (rsp["data"]["param"], rsp["data"]["value"]) == ("org.arl.unet.nodeinfo.NodeInfoParam.address", 3)
    node.receive("p", line(request("org.arl.fjage.param.ParameterReq", "phy", index=2, requests=[{"param": "dataRate"}],
                                   param="org.arl.unet.phy.PhysicalChannelParam.MTU", value=None)))
    rsp = replies(h)[0]["message"]["data"]
    assert (rsp["value"], rsp["values"]) == (64, {"org.arl.unet.phy.PhysicalChannelParam.dataRate": 1024.0})
    node.receive("p", line(request("org.arl.fjage.param.ParameterReq", "node", index=-1, requests=[], param="address",
                                   value=9)))
    rsp = replies(h)[0]["message"]["data"]
    assert rsp["value"] == 3 and rsp["param"] not in rsp["readonly"]  # the door's host keeps its link's address


def test_a_new_address_is_told_once_to_the_peers_that_want_parameter_changes():
    node, h = node_with_peer(writable=True)
    node.connect("q")
    node.receive("p", line({"action": "wantsMessagesFor", "agentIDs": ["gw", "#org.arl.unet.Topics.PARAMCHANGE",
                                                                        "#node__ntf"]}))
    node.receive("p", line(request("org.arl.fjage.param.ParameterReq", "node", index=-1, requests=[], param="address",
                                   value=7)))
    out = replies(h)
    assert [m["message"]["clazz"] for m in out] == ["org.arl.fjage.param.ParameterRsp", "org.arl.unet.ParamChangeNtf"]
    ntf = out[1]["message"]["data"]
    assert ntf["sender"] == "node" and ntf["paramValues"] == {"org.arl.unet.nodeinfo.NodeInfoParam.address": 7}
    assert "q" not in h.out  # it wants nothing
    node.address_changed()
    assert replies(h) == []


def test_datagrams_are_agreed_or_refused_with_the_reason_and_their_fates_told_to_the_requester():
    node, h = node_with_peer()
    data = list(b"hello")
    node.receive("p", line(request("org.arl.unet.DatagramReq", "phy", data=data, to=0, protocol=32)))
    assert [m["message"]["data"]["perf"] for m in replies(h)] == ["AGREE"]
    datagram = h.sent[0]
    assert (datagram.data, datagram.to, datagram.protocol, datagram.agent) == (b"hello", 255, 32, "phy")
    node.transmitted(datagram, 1.25)
    ntf = replies(h)[0]["message"]
    assert ntf["clazz"] == "org.arl.unet.phy.TxFrameNtf"
    assert (ntf["data"]["inReplyTo"], ntf["data"]["txTime"], ntf["data"]["recipient"]) == ("m1", 1250000, "gw")
    node.failed(datagram, "late")  # a fate is told once
    assert replies(h) == []
    for fields, reason in (({"data": list(bytes(65)), "to": 2}, "65 bytes exceed the MTU (64)"),
                           ({"data": data, "to": 2, "reliability": True}, "the physical agent does not send reliably"),
                           ({"data": data, "to": 2, "protocol": 64}, "protocol 64 is not 0-63"),
                           ({"data": "nope", "to": 2}, "data is no byte array")):
        node.receive("p", line(request("org.arl.unet.DatagramReq", "phy", **fields)))
        rsp = replies(h)[0]["message"]
        assert rsp["clazz"] == "org.arl.unet.RefuseRsp" and rsp["data"]["reason"].startswith(reason)
    assert h.refusals == ["datagram"] * 4
    node.receive("p", line(request("org.arl.unet.DatagramReq", "uwlink", data=data, to=2, reliability=True)))
    assert replies(h)[0]["message"]["data"]["perf"] == "AGREE"
    node.failed(h.sent[-1], "no acknowledgement")
    ntf = replies(h)[0]["message"]
    assert ntf["clazz"] == "org.arl.unet.DatagramFailureNtf" and ntf["data"]["to"] == 2


def test_received_frames_go_to_the_agents_topic_or_its_snoop_topic_once_per_peer():
    node, h = node_with_peer()
    node.connect("q")
    node.receive("p", line({"action": "wantsMessagesFor", "agentIDs": ["gw", "#phy__ntf", "#phy__snoop__ntf"]}))
    node.receive("q", line({"action": "wantsMessagesFor", "agentIDs": ["gw2", "#uwlink__ntf"]}))
    assert node.received("phy", 2, 255, 0, b"\x00\xff", 3.0, -60.04) == 1
    ntf = replies(h)[0]["message"]
    assert ntf["clazz"] == "org.arl.unet.phy.RxFrameNtf"
    fields = ntf["data"]
    assert (fields["from"], fields["to"], fields["rxTime"], fields["rssi"]) == (2, 0, 3000000, -60.0)
    assert fjage.decode_bytes(ntf["data"]["data"]) == b"\x00\xff"
    assert node.received("phy", 2, 9, 0, b"x", 3.0) == 1  # for another node: overheard
    assert replies(h)[0]["message"]["data"]["recipient"] == "#phy__snoop__ntf"
    assert node.received("uwlink", 2, 1, 33, b"x", 3.0) == 1
    assert replies(h, "q")[0]["message"]["clazz"] == "org.arl.unet.DatagramNtf"


def test_what_the_node_cannot_act_on_is_refused_once_and_counted():
    node, h = node_with_peer()
    node.connect("q")
    node.receive("p", line({"id": "9", "action": "shutdown"}))
    assert replies(h) == [{"id": "9", "inResponseTo": "shutdown", "error": "unknown action 'shutdown'"}]
    node.receive("p", line(request("org.arl.unet.phy.BeaconReq", "phy")))
    assert replies(h)[0]["message"]["data"]["perf"] == "NOT_UNDERSTOOD"
    node.receive("p", line(request("org.arl.unet.DatagramReq", "nobody", data=[1])))
    assert replies(h)[0]["message"]["data"]["perf"] == "FAILURE"
    node.receive("p", b"{not json}\n" + line({"id": "1", "action": "agents"}))
    assert [r.get("error", "")[:8] for r in replies(h)] == ["not JSON"] and h.closed == ["p"]
    node.receive("q", b"x" * (fjage.MAX_LINE + 1))
    assert replies(h, "q") == [{"error": f"a line longer than {fjage.MAX_LINE} bytes"}] and h.closed == ["p", "q"]
    assert dict(node.refused) == {"unknown_action": 1, "not_understood": 1, "no_agent": 1, "bad_json": 1,
                                  "long_line": 1}
    assert sorted(h.refusals) == sorted(node.refused)


def test_a_flood_is_refused_once_and_closes_only_that_peer():
    clock = [0.0]
    h = Host()
    node = UnetNode(h, clock=lambda: clock[0])
    node.connect("p")
    node.connect("q")
    node.receive("p", line({"alive": True}) * (BURST + 50))
    out = replies(h)
    assert len(out) == BURST + 1 and out[-1] == {"error": f"more than {BURST} lines at once or 200 a second"}
    assert h.closed == ["p"] and node.refused["flood"] == 1
    node.receive("q", line({"id": "1", "action": "agents"}))
    assert replies(h, "q")[0]["agentIDs"]  # the others are served
