"""Commands that say what they did (issue 25): what `hilgate send`, `app`, `pose`, `reload`, `check` and
the daemon's start print, the errors a newcomer meets (an unknown vehicle, a Zenoh prefix, addresses past
254, a link another daemon holds), and a reader that goes away (`| head`) ending a command quietly.
Real daemons, sockets, queues and Zenoh sessions on loopback; unique link ids."""

from __future__ import annotations

import os
import re
import resource
import signal
import subprocess
import sys

import pytest

from daemon_kit import Daemon, HANG_GUARD_S, free_port, hilgate, unique, wait_until
from hilgate.client import Link
from hilgate.daemon.access import AccessError, LinkLock, prepare_lock_directory
from hilgate.gli.queues import unlink_queues
from hilgate.scene import SceneError
from hilgate.scene.load import load_scene



def scene(links: dict[str, str], extra: str = "") -> str:
    rows = "\n".join(f"  {link}: {{vehicle: v{i}, address: {i + 1}, bitrate_bps: 1e5{more}}}"
                     for i, (link, more) in enumerate(links.items()))
    vehicles = "\n".join(f"  v{i}: {{pose: {{static: [{i}, 0, 0]}}}}" for i in range(len(links)))
    return (f"name: output\nchannels: {{ac: {{speed_mps: 1500}}}}\nvehicles:\n{vehicles}\nlinks:\n{rows}\n"
            f"trace: {{poses_s: 0}}\n{extra}")


@pytest.fixture
def pair(daemon_of):
    """Two links: ``a`` addressed as dccomms' vl2b reads it (everyone in range), ``b`` strict."""
    a, b = unique("oa"), unique("ob")
    return daemon_of(scene({a: "", b: ", addressing: strict"}), [a, b]), a, b


# -- hilgate send ---------------------------------------------------------------------------------

def test_send_confirms_each_frame_with_its_destination_as_the_model_reads_it(pair):
    daemon, a, b = pair
    result = hilgate("send", a, "--to", "2", "hello", "--runtime-dir", daemon.runtime)
    assert result.returncode == 0, result.stderr
    assert result.stdout == (f"{a}: frame 1 sent, 5 bytes to 2, which reaches everyone in range (addressing: auto, "
                             f"and the link's packet class carries no address on air)\n")
    result = hilgate("send", b, "--to", "1", "--runtime-dir", daemon.runtime, input="one\nthree\n")
    assert result.stdout.splitlines() == [f"{b}: frame 1 sent, 3 bytes to 1", f"{b}: frame 2 sent, 5 bytes to 1"]
    result = hilgate("send", b, "everyone", "--runtime-dir", daemon.runtime)
    assert result.stdout == f"{b}: frame 1 sent, 8 bytes to 255 (broadcast)\n"
    too_long = "x" * 5000  # beyond vl2b's payload: refused by the daemon, said, exit 1
    result = hilgate("send", b, too_long, "--runtime-dir", daemon.runtime)
    assert result.returncode == 1 and result.stdout == ""
    assert result.stderr.startswith(f"hilgate: {b}: frame 1 refused: ") and "\n" == result.stderr[-1]
    assert daemon.process.poll() is None


# -- hilgate app ----------------------------------------------------------------------------------

def test_app_says_when_it_is_attached_and_what_it_did_at_exit(pair):
    daemon, a, b = pair
    pingpong = os.path.join(os.path.dirname(__file__), "..", "examples", "apps", "pingpong.py")
    command = [sys.executable, "-m", "hilgate", "app", "--runtime-dir", daemon.runtime]
    pong = subprocess.Popen([*command, f"{pingpong}:Pong", "--link", b], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        daemon.wait_clients(b)
        ping = subprocess.run([*command, f"{pingpong}:Ping", "--link", a, "--param", "period_s=0.2",
                               "--param", "count=3", "--param", "peer=2", "--until", "1.5"],
                              capture_output=True, text=True, timeout=HANG_GUARD_S)
        # Pong has answered all three once a's modem has received three frames
        wait_until(lambda: daemon.link_status(a)["rx_packets"] >= 3, "three pongs")
    finally:
        pong.send_signal(signal.SIGINT)  # Ctrl-C: the application stops and says what it did
        out, err = pong.communicate(timeout=HANG_GUARD_S)
    socket_a = os.path.join(daemon.runtime, "gli", f"{a}.sock")
    socket_b = os.path.join(daemon.runtime, "gli", f"{b}.sock")
    assert ping.returncode == 0, ping.stderr
    lines = ping.stderr.splitlines()
    assert lines[0] == f"Ping: link {a}: address 1, backend sim, vl2b; through socket {socket_a}"
    assert re.fullmatch(rf"Ping: stopped after 1\.5 s; link {a}: 3 frames sent, [0-3] received", lines[1]), lines
    assert len(lines) == 2 and ping.stdout == ""
    assert pong.returncode == 0 and out == ""
    assert err.splitlines()[0] == f"Pong: link {b}: address 2, backend sim, vl2b; through socket {socket_b}"
    assert re.fullmatch(rf"Pong: stopped after \d+\.\d s; link {b}: 3 frames sent, 3 received", err.splitlines()[1])


# -- hilgate pose, reload, a closed pipe ------------------------------------------------------------

def test_pose_refuses_a_vehicle_the_scene_does_not_have(pair):
    daemon, a, b = pair
    result = hilgate("pose", "v1", "v11", "--runtime-dir", daemon.runtime)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr == "hilgate: pose: no vehicle 'v11' in the running scene (did you mean 'v1'?); its vehicles: v0, v1\n"
    result = hilgate("pose", "nosuchvehicle", "--runtime-dir", daemon.runtime)
    assert (result.returncode, result.stderr) == (2, "hilgate: pose: no vehicle 'nosuchvehicle' in the running scene; its vehicles: v0, v1\n")


def test_reload_says_what_runs_or_why_the_old_scene_stays(pair):
    daemon, a, b = pair
    text = daemon.scene.read_text()
    daemon.scene.write_text(text.replace(f"  {b}: {{vehicle: v1, address: 2,", f"  {b}: {{vehicle: v1, address: 3,"))
    result = hilgate("reload", "--runtime-dir", daemon.runtime)
    assert (result.returncode, result.stdout) == (0, f"reloaded: 2 links ({a}=sim, {b}=sim)\n"), result.stderr
    daemon.scene.write_text(text.replace("bitrate_bps: 1e5", "bitrate_bsp: 1e5", 1))
    result = hilgate("reload", "--runtime-dir", daemon.runtime)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.startswith("hilgate: reload refused, the daemon keeps its scene: ")
    assert "bitrate_bsp: unknown key (did you mean 'bitrate_bps'?)" in result.stderr
    assert daemon.link_status(b)["state"] == "up" and daemon.process.poll() is None


def closed_pipe_run(*args: str) -> subprocess.CompletedProcess:
    """The command with a stdout whose reader has gone before it writes anything (as `| head` once
    head has its lines): every write fails with EPIPE, whatever the timing."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return subprocess.run([sys.executable, "-m", "hilgate", *args], stdout=write_end, stderr=subprocess.PIPE,
                              text=True, timeout=HANG_GUARD_S)
    finally:
        os.close(write_end)


@pytest.mark.parametrize("command", [["pose"], ["status", "--watch", "0.05"], ["status"]])
def test_a_reader_that_goes_away_ends_a_command_quietly(pair, command):
    daemon, a, b = pair
    result = closed_pipe_run(*command, "--runtime-dir", daemon.runtime)
    assert (result.returncode, result.stderr) == (141, "")


def test_a_closed_pipe_is_quiet_for_commands_without_a_daemon_too():
    demo = os.path.join(os.path.dirname(__file__), "..", "scenes", "demo.yaml")
    for args in (["check", demo], ["sim", demo, "--until", "5"]):
        result = closed_pipe_run(*args)
        assert (result.returncode, result.stderr) == (141, ""), args


# -- the daemon's start ------------------------------------------------------------------------------

def start(tmp_path, text: str, queue_budget: int | None = None) -> str:
    """The log of a daemon that runs a moment of model time, with this user's queue budget lowered (for
    scenes without queues: the budget is the user's, shared with every other test run), else lifted
    where allowed (LimitMSGQUEUE=infinity, as under systemd)."""
    path = tmp_path / "scene.yaml"
    path.write_text(text)

    def limit() -> None:
        try:
            wanted = resource.RLIM_INFINITY if queue_budget is None else queue_budget
            resource.setrlimit(resource.RLIMIT_MSGQUEUE, (wanted, wanted))
        except (ValueError, OSError):
            pass

    result = hilgate("run", str(path), "--runtime-dir", str(tmp_path / "rt"), "--until", "0.2",
                     "--no-status-line", preexec_fn=limit)
    assert result.returncode == 0, result.stderr
    return result.stderr


def test_the_start_line_lists_the_endpoints_opened_and_the_queue_budget_only_when_it_matters(tmp_path):
    a, b = unique("sa"), unique("sb")
    try:
        log = start(tmp_path, scene({a: ", packet: vl1b", b: ", packet: vl1b, gli: [socket]"}))
        assert "endpoints: POSIX queues /ID_{tx,rx}_dlnk_phy (1 link), sockets " in log and "(2 links), control" in log
        unlink_queues([a, b])
        # no queues at all: neither the budget nor queues in the start line
        log = start(tmp_path, scene({a: ", gli: [socket]", b: ", gli: [socket]"}), queue_budget=100_000)
        assert "queue" not in log.lower().replace("queues_max", "")
        rt = tmp_path / "rt"
        assert f"2 links ({a}=sim, {b}=sim), endpoints: sockets {rt}/gli/ID.sock (2 links), control {rt}/control.sock;" in log
        pty = tmp_path / "ttyEVO"
        log = start(tmp_path, scene({a: f", gli: [socket], emulate: {{protocol: evologics, pty: {pty}}}"}))
        assert (f"endpoints: sockets {rt}/gli/ID.sock (1 link), {a} as an emulated evologics modem at pty {pty}, "
                f"control {rt}/control.sock;") in log
    finally:
        unlink_queues([a, b])


PLAN = """
import logging, resource, sys
resource.setrlimit(resource.RLIMIT_MSGQUEUE, (int(sys.argv[1]), int(sys.argv[1])))
logging.basicConfig(level=logging.INFO, format="%(message)s")
from hilgate.gli.queues import plan_message_size
print(plan_message_size(int(sys.argv[2])))
"""


@pytest.mark.parametrize("budget, links, said", [(100_000, 2, True), (200_000, 1, False), (100_000, 0, False)])
def test_the_queue_budget_is_said_only_when_dccomms_size_would_not_fit(budget, links, said):
    """Two links' queues at dccomms' 10 × 8192 bytes need 331 520 bytes, one link's 165 760; none, nothing."""
    result = subprocess.run([sys.executable, "-c", PLAN, str(budget), str(links)], capture_output=True, text=True,
                            timeout=HANG_GUARD_S)
    assert result.stdout == "False\n", result.stderr  # sized for the packet class either way while finite
    line = (f"POSIX queues are sized for each link's packet class: {links} links at dccomms' 10 × 8192 bytes "
            f"would need {links * 165760} of this user's {budget}-byte queue budget (ulimit -q; "
            f"LimitMSGQUEUE=infinity, as in the systemd unit, gives dccomms' size)\n")
    assert result.stderr == (line if said else "")


# -- hilgate check and the scene's errors -------------------------------------------------------------

def test_check_shows_each_links_emulator_port_and_host(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text("""\
name: where
channels: {ac: {speed_mps: 1500}}
vehicles:
  v0: {pose: {static: [0, 0, 0]}}
  v1: {pose: {static: [1, 0, 0]}}
links:
  emu: {vehicle: v0, host: pier-pc, address: 1, emulate: {protocol: evologics, pty: ttyEVO1}}
  real: {vehicle: v1, host: tank-pc, backend: evologics, port: /dev/ttyUSB0, channel: ac, address: 2}
  tcp: {vehicle: v1, host: tank-pc, address: 3, emulate: {protocol: evologics, tcp: 9200}}
""")
    result = hilgate("check", str(path))
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stdout.splitlines() if not line.startswith("    limits ")]
    assert lines[1] == f"  emu: sim on v0, addr 1, ac, 1000 bit/s, mac none, packet vl2b, emulates evologics at pty {tmp_path}/ttyEVO1, host pier-pc"
    assert lines[2].startswith("  real: evologics on v1, addr 2, ac, ") and lines[2].endswith(", port /dev/ttyUSB0, host tank-pc")
    assert lines[3].endswith(", emulates evologics at TCP port 9200, host tank-pc")


def many_links(n: int, extra: str = "") -> str:
    rows = "\n".join(f"  l{i}: {{vehicle: v, channel: ac{extra}}}" for i in range(n))
    return f"name: many\nchannels: {{ac: {{speed_mps: 1500}}}}\nvehicles:\n  v: {{pose: {{static: [0, 0, 0]}}}}\nlinks:\n{rows}\n"


def test_the_address_error_says_how_to_go_past_254(tmp_path):
    path = tmp_path / "many.yaml"
    path.write_text(many_links(254))
    load_scene(str(path))  # 1..254
    path.write_text(many_links(255))
    with pytest.raises(SceneError) as caught:
        load_scene(str(path))
    text = str(caught.value)
    assert "links.l254: no free address left (1..254 are taken); give links an address: of their own" in text
    assert "up to 65534 under hilgate sim (this link's packet class keeps addresses off the air; hilgate run takes 0..254 only)" in text
    path.write_text(many_links(255, ", packet: dlf16"))
    with pytest.raises(SceneError, match="cannot take one above 254: packet class dlf16 carries a one-byte address on air"):
        load_scene(str(path))


HOLDER = """
import sys
from hilgate.daemon.access import LinkLock
lock = LinkLock(sys.argv[2], sys.argv[1])
print("held", flush=True)
sys.stdin.read()
"""


def test_a_held_link_names_the_holders_whole_command_line(tmp_path):
    link = unique("held")
    locks = str(tmp_path / "locks")
    prepare_lock_directory(locks)
    tail = "--trace /var/log/some/where/far/down/a/long/path/" + "x" * 200 + "/trace.jsonl scene-of-the-holder.yaml"
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, locks, link, tail], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        with pytest.raises(AccessError) as caught:
            LinkLock(link, locks)
        assert f"process {holder.pid} of " in str(caught.value)
        assert str(caught.value).endswith(f"{link} {tail}") or f"{link} {tail}" in str(caught.value)
    finally:
        holder.stdin.close()
        holder.wait(HANG_GUARD_S)


# -- errors that say what to do (issue 40 item 3) -------------------------------------------------------

def test_a_link_the_daemon_does_not_serve_is_answered_with_its_links(pair, tmp_path):
    daemon, a, b = pair
    result = hilgate("send", "nc_nope", "hi", "--runtime-dir", daemon.runtime)
    assert result.returncode == 1
    assert result.stderr == (f"hilgate: the daemon at {daemon.runtime} serves no link 'nc_nope' over its sockets; "
                             f"its links: {', '.join(sorted([a, b]))}\n")
    nobody = tmp_path / "nobody"
    nobody.mkdir()
    result = hilgate("listen", a, "--runtime-dir", str(nobody))
    assert result.returncode == 1
    assert result.stderr == (f"hilgate: no hilgate daemon runs with the runtime directory {nobody} (cannot reach "
                             f"link {a!r}): start one, or give this command the --runtime-dir the daemon was "
                             f"started with\n")


def test_an_application_without_credentials_is_told_to_bring_them(tmp_path):
    """A network made with ``hilgate network init`` takes only applications with their credentials: one
    without them is told so, not sent to look at the key prefix."""
    creds = tmp_path / "creds"
    assert hilgate("network", "init", str(creds), "--hosts", "h1", "--apps", "1").returncode == 0
    link, port = unique("zc"), free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    daemon = Daemon(tmp_path, scene({link: ""}, f"zenoh: {{lease_s: 5, credentials: {creds}}}\n"), [link],
                    "--host", "h1", "--zenoh-listen", endpoint)
    try:
        daemon.wait_for("READY=1")
        result = hilgate("send", link, "hello", "--zenoh", endpoint)
        assert result.returncode == 1 and "--zenoh-credentials DIR/apps/NAME" in result.stderr, result.stderr
        assert "prefix" not in result.stderr
        apps = sorted((creds / "apps").iterdir())
        result = hilgate("send", link, "hello", "--zenoh", endpoint, "--zenoh-credentials", str(apps[0]))
        assert result.returncode == 0, result.stderr
    finally:
        daemon.close()


def test_emulate_names_a_link_the_scene_lacks_as_such(tmp_path):
    scene_file = tmp_path / "lab.yaml"
    scene_file.write_text(scene({"rov2_ac": "", "rov2_rf": ""}))
    result = hilgate("emulate", "evologics", str(scene_file), "--link", "rov2_a", "--pty", str(tmp_path / "tty"))
    assert result.returncode == 2
    assert result.stderr == (f"hilgate: --link: no link 'rov2_a' in {scene_file} (did you mean 'rov2_ac'?); "
                             f"its links: rov2_ac, rov2_rf\n")


# -- the Zenoh prefix ----------------------------------------------------------------------------------

def test_applications_name_the_networks_zenoh_prefix(tmp_path):
    link, prefix, port = unique("zp"), unique("lab"), free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    daemon = Daemon(tmp_path, scene({link: ""}, f"zenoh: {{prefix: {prefix}, lease_s: 5, insecure: true}}\n"), [link],
                    "--host", "h1", "--zenoh-listen", endpoint)
    try:
        daemon.wait_for("READY=1")
        result = hilgate("send", link, "hello", "--zenoh", endpoint)
        assert result.returncode == 1 and result.stdout == ""
        assert result.stderr == (f"hilgate: no daemon on the network serves link {link!r} under the Zenoh prefix "
                                 f"'hilgate'; it is served under {prefix!r}: give that prefix (Link.open(..., "
                                 f"prefix=...), --zenoh-prefix)\n")
        result = hilgate("send", link, "hello", "--zenoh", endpoint, "--zenoh-prefix", prefix)
        assert (result.returncode, result.stdout) == (0, f"{link}: frame 1 sent, 5 bytes to 255 (broadcast)\n"), result.stderr
        with Link.open(link, zenoh=endpoint, prefix=prefix) as opened:
            assert opened.address == 1 and opened.prefix == prefix
        with pytest.raises(ValueError, match="key prefix"):
            Link.open(link, zenoh=endpoint, prefix="lab/*")
        with pytest.raises(ValueError, match="give zenoh= too"):
            Link.open(link, prefix=prefix)
        result = hilgate("listen", link, "--zenoh-prefix", prefix)
        assert result.returncode == 2 and "give --zenoh ENDPOINT too" in result.stderr
        result = hilgate("app", "x.py:X", "--link", link, "--zenoh", endpoint, "--zenoh-prefix", "a b")
        assert result.returncode == 2 and "key prefix is one to four words" in result.stderr
    finally:
        daemon.close()
        unlink_queues([link])
