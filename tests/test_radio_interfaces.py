"""The narrow interfaces around the radio, checked on the source: MACs use their modem only through
``MacHost``; the medium reads of a radio only what ``Radio`` documents; frames are built in one place.
And what those interfaces promise: ``tau_at``, ``new_frame``/``control_frame``."""

import ast
import os

import pytest

from hilgate.models.frame import ACK, BROADCAST
from hilgate.models.mac import MacHost
from hilgate.models.medium import Channel
from netkit import Net

REPO = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
MODELS = os.path.join(REPO, "models")


def host_members() -> set[str]:
    names = set(MacHost.__annotations__)
    names |= {name for name, value in vars(MacHost).items() if callable(value) and not name.startswith("_")}
    return names


def modem_uses(path: str) -> set[str]:
    """Attributes read or called on ``modem`` / ``self.modem`` in a MAC's source."""
    tree = ast.parse(open(path).read())
    used = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            value = node.value
            if (isinstance(value, ast.Name) and value.id == "modem") or (
                    isinstance(value, ast.Attribute) and value.attr == "modem"
                    and isinstance(value.value, ast.Name) and value.value.id == "self"):
                used.add(node.attr)
    return used


MAC_SOURCES = [os.path.join(MODELS, name) for name in ("mac.py", "csaloha.py", "sfama.py")] + [
    os.path.join(REPO, "tests", "example_mac.py")]


@pytest.mark.parametrize("path", MAC_SOURCES, ids=os.path.basename)
def test_macs_use_their_modem_only_through_machost(path):
    used = modem_uses(path)
    assert used, "the walk found nothing: has the MAC stopped calling its host 'modem'?"
    assert used <= host_members(), f"not in MacHost: {sorted(used - host_members())}"


def test_the_simulated_modem_is_a_machost():
    net = Net(Channel("ac", 1500.0, 0.01))
    modem = net.modem("a")
    missing = [name for name in host_members() if not hasattr(modem, name)]
    assert not missing


def test_tau_at_is_the_delay_on_the_modems_transmit_channel():
    net = Net(Channel("ac", 1500.0, 0.01), Channel("rf", 2.25e7))
    acoustic = net.modem("a", channel="ac")
    rf = net.modem("b", channel="rf")
    assert acoustic.tau_at(300.0) == 0.01 + 300.0 / 1500.0
    assert rf.tau_at(6.0) == 6.0 / 2.25e7


def test_new_frame_and_control_frame():
    net = Net()
    a = net.modem("a", address=7)
    first = a.new_frame("b", 3, 20, flow="flow-stats", app_frame=b"x")
    net.clock.run(2.5)
    ack = a.control_frame(ACK, 5, 3, "b", first)
    assert (first.id, first.src_link, first.dst_link, first.dst_addr, first.size, first.t0, first.src_addr) == \
        (1, "a", "b", 3, 20, 0.0, 7)
    assert (ack.id, ack.kind, ack.ref, ack.flow, ack.t0, ack.src_addr, ack.app_frame) == \
        (2, ACK, first, "flow-stats", 2.5, 7, None)
    assert a.new_frame("*", BROADCAST, 1).id == 3


def frame_constructions(path: str) -> list[tuple[str, int, str]]:
    """``Frame(...)`` calls of the models' Frame in a file: (file, line, enclosing function)."""
    tree = ast.parse(open(path).read())
    local = {alias.asname or alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
             and (node.module or "").endswith("frame") for alias in node.names if alias.name == "Frame"}
    found = []

    def visit(node, function):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                visit(child, child.name)
                continue
            if isinstance(child, ast.Call) and isinstance(child.func, ast.Name) and child.func.id in local:
                found.append((os.path.relpath(path, REPO), child.lineno, function))
            visit(child, function)

    visit(tree, "<module>")
    return found


def test_frames_are_built_in_one_place():
    sources = []
    for folder in ("models", "hilgate", "drivers"):
        for root, _, files in os.walk(os.path.join(REPO, folder)):
            sources += [os.path.join(root, f) for f in files if f.endswith(".py")]
    calls = [call for path in sources for call in frame_constructions(path)]
    # ... and, for a frame another host's modem made, where its message is read back (daemon/netcodec.py)
    assert [(f, fn) for f, _, fn in calls] == [(os.path.join("models", "modem.py"), "new_frame"),
                                              (os.path.join("hilgate", "daemon", "netcodec.py"), "frame")], calls


RADIO_NAMES = {"radio", "sender", "receiver", "target", "end"}
WHAT_THE_MEDIUM_READS = {"address", "tx_channel", "rx_channel", "range_m", "pose", "host", "listens",
                         "judges_all", "air", "arrive", "arrive_refused", "unreachable"}
WHAT_A_PATH_READS = {"acoustic", "bitrate_bps", "error"}  # models/path.py, which the medium asks per pair


def radio_attributes(module: str) -> set[str]:
    tree = ast.parse(open(os.path.join(MODELS, module)).read())
    used = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            value = node.value
            if (isinstance(value, ast.Name) and value.id in RADIO_NAMES) or (
                    isinstance(value, ast.Attribute) and value.attr == "radio"):
                used.add(node.attr)
    return used


def test_the_medium_touches_a_radio_only_through_what_radio_documents():
    # (the medium and its neighbour index, which it builds from the radios)
    assert radio_attributes("medium.py") | radio_attributes("neighbours.py") == WHAT_THE_MEDIUM_READS
    assert radio_attributes("path.py") == WHAT_A_PATH_READS
