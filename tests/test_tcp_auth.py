"""The TCP GLI is for applications that hold the daemon's token (issue 23 item 4, :mod:`hilgate.gli.token`).

On connecting, hilgate sends a CHALLENGE (a fresh nonce); HELLO must carry HMAC-SHA256(token, nonce).
Without it, with a wrong token, or with a proof taken from another connection (a replay), the client
is told why and closed before it can name a link, and nothing it sends reaches one; every refusal is
counted in the daemon's status.  Connections that have not authenticated are bounded per address and
closed after 10 s.  The test that crosses users runs the daemon as root and its TCP clients as two
other uids, one in the daemon's group (which may read the token) and one not; without root it is
skipped.  The clients there are a standalone script (stdlib only), as an application in another
language would be.
"""

import json
import os
import select
import shutil
import socket
import stat
import subprocess
import tempfile
import textwrap
import time

import pytest

from daemon_kit import Daemon, free_port, quick_scene, unique, wait_until
from doorkit import Slowloris, closed_by_peer, first_tries, idle
from hilgate.client import GliError, Link
from hilgate.gli import wire
from hilgate.gli.session import AuthError, Hello, Session
from hilgate.gli.token import TokenCheck, TokenError, load_or_create, proof, read_token
from test_security import MEMBER, OUTSIDER, python_for

GROUP = 54323


def scene(a: str, b: str) -> str:
    return quick_scene("tcp-auth", a, b)


# -- the conversation, without sockets -------------------------------------------------------------------


def hello(link: str, **extra) -> bytes:
    return wire.encode_json(wire.HELLO, {"link": link, **extra})


def test_a_tcp_session_wants_the_proof_of_its_own_nonce():
    check = TokenCheck(b"t" * 40)
    session = Session(None, check)
    assert wire.Decoder().feed(session.challenge()) == [(wire.CHALLENGE, json.dumps(
        {"nonce": session.nonce.hex()}, separators=(",", ":")).encode())]
    with pytest.raises(AuthError, match="needs proof"):
        list(Session(None, check).receive(hello("a")))
    with pytest.raises(AuthError, match="authentication failed"):
        list(Session(None, check).receive(hello("a", proof=proof(b"w" * 40, session.nonce))))
    other = Session(None, check)  # a replay: the proof of another connection's nonce
    with pytest.raises(AuthError, match="authentication failed"):
        list(other.receive(hello("a", proof=proof(check.token, session.nonce))))
    for answer in (5, "x" * 64, proof(check.token, session.nonce).upper(), ["a"], {"a": 1}, "é" * 64):
        with pytest.raises(AuthError):
            list(Session(None, check).receive(hello("a", proof=answer)))
    with pytest.raises(wire.WireError, match="HELLO first"):
        list(Session(None, check).receive(wire.encode_send(2, b"x")))
    assert list(session.receive(hello("a", proof=proof(check.token, session.nonce)))) == [Hello("a", True)]
    assert session.authenticated
    assert Session("a").authenticated and Session("a").nonce is None  # a Unix socket: the group rule


def test_nonces_are_fresh():
    check = TokenCheck(b"t" * 40)
    assert len({Session(None, check).nonce for _ in range(1000)}) == 1000


# -- the token file ---------------------------------------------------------------------------------------


def test_the_daemon_makes_a_token_for_its_group_and_refuses_one_others_can_read(tmp_path):
    path = tmp_path / "tcp.token"
    group = GROUP if os.geteuid() == 0 else None
    token = load_or_create(str(path), group)
    info = os.stat(path)
    assert stat.S_IMODE(info.st_mode) == 0o640 and len(token) == 64 and int(token, 16) >= 0
    if group is not None:
        assert info.st_gid == GROUP
    assert load_or_create(str(path)) == token == read_token(str(path))  # kept across restarts
    os.chmod(path, 0o644)
    with pytest.raises(TokenError, match="readable or writable by others"):
        load_or_create(str(path))
    os.chmod(path, 0o640)
    link = tmp_path / "link.token"
    link.symlink_to(path)
    with pytest.raises(TokenError, match="symbolic link"):
        load_or_create(str(link))
    short = tmp_path / "short.token"
    short.write_text("secret\n")
    os.chmod(short, 0o600)
    with pytest.raises(TokenError, match="not a token"):
        load_or_create(str(short))
    if os.geteuid() == 0:
        theirs = tmp_path / "theirs.token"
        theirs.write_text("x" * 64)
        os.chmod(theirs, 0o600)
        os.chown(theirs, *OUTSIDER)
        with pytest.raises(TokenError, match="belongs to uid 65534"):
            load_or_create(str(theirs))


def test_a_daemon_with_an_unusable_token_does_not_start(tmp_path):
    a, b = unique("a"), unique("b")
    token = tmp_path / "open.token"
    token.write_text("y" * 64)
    os.chmod(token, 0o644)
    daemon = Daemon(tmp_path, scene(a, b), [a, b], "--tcp", str(free_port()), "--tcp-token", str(token))
    code = daemon.process.wait(60)
    output = daemon.output()
    daemon.close()
    assert code == 1 and "Traceback" not in output and "readable or writable by others" in output


# -- the daemon -------------------------------------------------------------------------------------------


class Raw:
    """A TCP peer speaking the framing by hand, as an attacker (or another language) would."""

    def __init__(self, port: int, source: str = "127.0.0.1"):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=30, source_address=(source, 0))
        self.decoder = wire.Decoder()
        self.messages: list[tuple[int, bytes]] = []

    def next(self) -> tuple[int, bytes] | None:
        """The next message, or None when hilgate has closed the connection."""
        while not self.messages:
            try:
                data = self.sock.recv(65536)
            except ConnectionResetError:
                return None
            if not data:
                return None
            self.messages += self.decoder.feed(data)
        return self.messages.pop(0)

    def nonce(self) -> bytes:
        kind, body = self.next()
        assert kind == wire.CHALLENGE
        return bytes.fromhex(json.loads(body)["nonce"])

    def refused(self) -> str:
        """hilgate's ERROR, and that it closed the connection after it."""
        kind, body = self.next()
        assert kind == wire.ERROR, (kind, body)
        assert self.next() is None
        return json.loads(body)["error"]


def test_only_applications_that_prove_the_token_reach_a_link(tmp_path, daemon_of):
    a, b = unique("a"), unique("b")
    port = free_port()
    daemon = daemon_of(scene(a, b), [a, b], "--tcp", str(port))
    token_file = os.path.join(daemon.runtime, "tcp.token")
    assert stat.S_IMODE(os.stat(token_file).st_mode) == 0o640
    token = read_token(token_file)
    with Link.open(b, runtime_dir=daemon.runtime) as receiver:
        attempts = []
        # 1. no proof at all (the clients of before this issue)
        peer = Raw(port)
        peer.nonce()
        peer.sock.sendall(hello(a) + wire.encode_send(2, b"forged 1"))
        attempts.append(peer.refused())
        # 2. a SEND without HELLO
        peer = Raw(port)
        peer.nonce()
        peer.sock.sendall(wire.encode_send(2, b"forged 2"))
        attempts.append(peer.refused())
        # 3. a guessed token
        peer = Raw(port)
        peer.sock.sendall(hello(a, proof=proof(b"0" * 64, peer.nonce())) + wire.encode_send(2, b"forged 3"))
        attempts.append(peer.refused())
        # 4. a replay: an honest connection's nonce and proof, sniffed, on a new connection
        honest = Raw(port)
        nonce = honest.nonce()
        sniffed = hello(a, proof=proof(token, nonce))
        honest.sock.sendall(sniffed)
        assert [honest.next()[0] for _ in range(2)] == [wire.STATE, wire.WELCOME]
        honest.sock.close()
        peer = Raw(port)
        peer.nonce()
        peer.sock.sendall(sniffed + wire.encode_send(2, b"forged 4"))
        attempts.append(peer.refused())
        # 5. not JSON in HELLO
        peer = Raw(port)
        peer.nonce()
        peer.sock.sendall(wire.encode(wire.HELLO, b"{not json"))
        attempts.append(peer.refused())
        assert "needs proof of the daemon's token" in attempts[0]
        assert attempts[1] == "say HELLO first"
        assert attempts[2] == attempts[3] == "authentication failed: the proof does not match this daemon's token"
        assert attempts[4].startswith("bad JSON")
        # the honest application, with the token file (its group may read it)
        with Link.open(a, tcp=("127.0.0.1", port), token_file=token_file) as sender:
            sender.send(b"honest", dst=2)
            message = receiver.recv(timeout=60)
        assert (message.src, message.data) == (1, b"honest")
        assert receiver.recv(timeout=0.5) is None  # and nothing of the forged frames
        assert daemon.status()["tcp"] == {"refused": {"auth": 5, "auth_timeout": 0, "auth_pending": 0},
                                          "waiting": 0}
    with pytest.raises(GliError, match="authentication failed"):
        Link.open(a, tcp=("127.0.0.1", port), token="z" * 64)
    with pytest.raises(GliError, match="there is none at"):  # no token found: said before connecting
        Link.open(a, tcp=("127.0.0.1", port), runtime_dir=str(tmp_path / "elsewhere"))
    events = daemon.trace_events()
    assert [e for e in events if e["ev"] == "enq"] and not any(
        "forged" in json.dumps(e) for e in events)


def honest(link: str, port: int, token_file: str):
    """The honest application's attempt: open ``link`` over TCP with the token (True: in)."""
    def attempt() -> bool:
        with Link.open(link, tcp=("127.0.0.1", port), token_file=token_file, timeout=60) as opened:
            return opened.address == 1
    return attempt


def test_connections_that_do_not_authenticate_are_bounded_and_time_out(daemon_of):
    """At most 8 from one address wait to authenticate: a ninth takes the place of the oldest, which is
    told so and closed (it has had the longest to prove the token); each is closed at the deadline."""
    a, b = unique("a"), unique("b")
    port = free_port()
    daemon = daemon_of(scene(a, b), [a, b], "--tcp", str(port), "--auth-timeout", "3")
    token_file = os.path.join(daemon.runtime, "tcp.token")
    idle = [Raw(port) for _ in range(8)]
    for peer in idle:
        peer.nonce()  # each was accepted (and counted) before the next connects
    ninth = Raw(port)
    ninth.nonce()
    assert idle[0].refused() == "too many connections wait to authenticate from 127.0.0.1: the oldest is closed"
    assert daemon.status()["tcp"]["waiting"] == 8
    assert honest(a, port, token_file)()  # from the same address: it takes the place of the next oldest
    assert idle[1].refused().startswith("too many connections wait to authenticate")
    with Link.open(a, runtime_dir=daemon.runtime) as local:  # the Unix socket is not affected
        assert local.address == 1
    for peer in idle[2:] + [ninth]:  # after 3 s without HELLO each is told so and closed
        assert peer.refused() == "no HELLO within 3 s"
    tcp = daemon.status()["tcp"]
    assert tcp["refused"]["auth_timeout"] == 7 and tcp["refused"]["auth_pending"] == 2 and tcp["waiting"] == 0


def test_idle_strangers_on_many_addresses_do_not_keep_a_token_holder_out(daemon_of):
    """Issue 37 item 4: 64 connections from 127.0.0.2-9 that never prove the token filled every place
    among those waiting to authenticate, and the honest client was refused ("too many connections
    waiting to authenticate") until they timed out.  Now the newcomer is let in, and the oldest of the
    address holding the most waiting connections makes room."""
    a, b = unique("a"), unique("b")
    port = free_port()
    daemon = daemon_of(scene(a, b), [a, b], "--tcp", str(port))
    token_file = os.path.join(daemon.runtime, "tcp.token")
    strangers = idle(port)
    assert daemon.status()["tcp"]["waiting"] == 64
    assert first_tries(honest(a, port, token_file), 5) == [True] * 5
    tcp = daemon.status()["tcp"]
    # the first made room (the oldest of 127.0.0.2, all holding 8); the others found its place free
    assert [sock for sock in strangers if closed_by_peer(sock)] == strangers[:1]
    assert tcp["refused"]["auth_pending"] == 1 and tcp["waiting"] == 63


def test_strangers_waiting_to_authenticate_take_no_clients_place(daemon_of):
    """--max-clients counts the clients a link serves: 64 strangers waiting on TCP kept an application
    of the Unix socket (and the honest TCP client) out once they and the others reached it."""
    a, b = unique("a"), unique("b")
    port = free_port()
    daemon = daemon_of(scene(a, b), [a, b], "--tcp", str(port), "--max-clients", "2")
    token_file = os.path.join(daemon.runtime, "tcp.token")
    strangers = idle(port)
    with Link.open(a, runtime_dir=daemon.runtime) as local, Link.open(b, runtime_dir=daemon.runtime) as other:
        assert (local.address, other.address) == (1, 2)
        with pytest.raises(GliError, match="too many clients"):  # the limit itself holds
            Link.open(a, runtime_dir=daemon.runtime)
    assert honest(a, port, token_file)()
    assert len(strangers) == 64


def test_a_slowloris_on_many_addresses_does_not_keep_a_token_holder_out(daemon_of):
    """Issue 37 item 4: 64 connections from 127.0.0.2-9 trickling HELLO a byte a second (each closed one
    opened again at once) kept the honest client out 21 times in 23."""
    a, b = unique("a"), unique("b")
    port = free_port()
    daemon = daemon_of(scene(a, b), [a, b], "--tcp", str(port))
    token_file = os.path.join(daemon.runtime, "tcp.token")
    attempt = honest(a, port, token_file)

    def paced() -> bool:
        time.sleep(0.25)  # tries spread over the attack (pacing only: nothing is timed)
        return attempt()

    with Slowloris(port, hello(a, proof=proof(b"0" * 64, b"n" * 32))):
        wait_until(lambda: daemon.status()["tcp"]["waiting"] == 64, "the slowloris's 64 connections")
        tries = first_tries(paced, 8)
        assert daemon.status()["tcp"]["waiting"] >= 60  # the attack went on meanwhile
    assert tries == [True] * 8


def test_the_handshake_has_one_deadline_however_slowly_it_trickles(daemon_of):
    """The deadline is for the whole handshake, from the connection on: a HELLO trickled a byte at a time
    is closed at it, however many bytes keep coming (a deadline per byte would never come)."""
    a, b = unique("a"), unique("b")
    port = free_port()
    daemon = daemon_of(scene(a, b), [a, b], "--tcp", str(port), "--auth-timeout", "1")
    peer = Raw(port)
    message = hello(a, proof=proof(read_token(os.path.join(daemon.runtime, "tcp.token")), peer.nonce()))
    sent = 0
    while sent < len(message) - 1:  # a byte every 20 ms: 1 s is about 50 of its bytes
        readable, _, _ = select.select([peer.sock], [], [], 0.02)
        if readable:
            break
        peer.sock.send(message[sent:sent + 1])
        sent += 1
    assert peer.refused() == "no HELLO within 1 s"
    assert daemon.status()["tcp"]["refused"]["auth_timeout"] == 1


CLIENT = textwrap.dedent("""\
    # A TCP GLI client with the standard library only, run as another user.
    import hashlib, hmac, json, socket, struct, sys
    port, link, token_path, guess = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
    def message(kind, body):
        return struct.pack(">IB", len(body) + 1, kind) + body
    def read(sock):
        header = b""
        while len(header) < 5:
            chunk = sock.recv(5 - len(header))
            if not chunk:
                return None, b""
            header += chunk
        length, kind = struct.unpack(">IB", header)
        body = b""
        while len(body) < length - 1:
            body += sock.recv(length - 1 - len(body))
        return kind, body
    result = {}
    try:
        token = open(token_path, "rb").read().strip()
        result["token"] = "read"
    except OSError as exc:
        token = guess.encode()
        result["token"] = type(exc).__name__
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    kind, body = read(sock)
    nonce = bytes.fromhex(json.loads(body)["nonce"])
    proof = hmac.new(token, nonce, hashlib.sha256).hexdigest()
    sock.sendall(message(1, json.dumps({"link": link, "proof": proof}).encode()))
    kind, body = read(sock)
    while kind == 5:  # STATE comes before WELCOME
        kind, body = read(sock)
    result["answer"] = {2: "WELCOME", 6: "ERROR"}.get(kind, str(kind))
    if kind == 6:
        result["error"] = json.loads(body)["error"]
    try:
        sock.sendall(message(3, bytes([2]) + b"from uid %d" % __import__("os").getuid()))
        sock.sendall(message(7, b'{"class": "STATUS"}'))
        while kind not in (8, None):  # the REPLY: the frame before it was taken
            kind, body = read(sock)
    except OSError:
        pass
    print(json.dumps(result))
""")


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run clients as other users")
def test_another_user_without_the_token_cannot_send_through_tcp_but_a_member_of_the_group_can(daemon_of):
    base = tempfile.mkdtemp(prefix="hilgate-tcp-", dir="/tmp")
    os.chmod(base, 0o711)
    a, b = unique("a"), unique("b")
    port = free_port()
    daemon = daemon_of(scene(a, b), [a, b], "--group", str(GROUP), "--tcp", str(port),
                    runtime=os.path.join(base, "rt"))
    try:
        python = python_for(*OUTSIDER)
        if python is None:
            pytest.skip("no Python interpreter that another user may run")
        token_file = os.path.join(daemon.runtime, "tcp.token")
        assert os.stat(token_file).st_gid == GROUP and stat.S_IMODE(os.stat(token_file).st_mode) == 0o640

        def attempt(uid, gid, groups=()):
            out = subprocess.run([python, "-c", CLIENT, str(port), a, token_file, "g" * 64], capture_output=True,
                                 text=True, timeout=60, user=uid, group=gid, extra_groups=list(groups),
                                 env={"PATH": os.environ.get("PATH", ""), "HOME": "/"})
            assert out.returncode == 0, out.stderr
            return json.loads(out.stdout)

        with Link.open(b, runtime_dir=daemon.runtime) as receiver:
            outsider = attempt(*OUTSIDER)
            assert outsider == {"token": "PermissionError", "answer": "ERROR",
                                "error": "authentication failed: the proof does not match this daemon's token"}
            member = attempt(*MEMBER, groups=[GROUP])
            assert member == {"token": "read", "answer": "WELCOME"}
            message = receiver.recv(timeout=60)
            assert (message.src, message.data) == (1, b"from uid %d" % MEMBER[0])
            assert receiver.recv(timeout=0.5) is None  # nothing from the outsider
        assert daemon.status()["tcp"]["refused"]["auth"] == 1
    finally:
        shutil.rmtree(base, ignore_errors=True)
