"""The client side of the GLI over Zenoh (:mod:`hilgate.gli.zenoh_door` has the key layout): the same
``send``/``recv``/``command`` as the socket client, from any host of the network.

    from hilgate.client import Link

    with Link.open("rov_ac", zenoh="tcp/192.168.1.10:7447") as link:   # a daemon to connect to
        link.send(b"hello", dst=2)
        print(link.recv(timeout=5.0))

``zenoh`` is an endpoint, a list of them, or a dict ``{"connect": [...], "prefix": "hilgate",
"credentials": "DIR", "config": "zenoh.json5"}``.  ``credentials`` is an application's directory from
``hilgate network init`` (``DIR/apps/app-1``): the session is then TLS with that certificate, and lets
in only what the lab's hosts say about their links (:mod:`hilgate.gli.zenoh_auth`); without it, plain
TCP (a network of daemons started ``insecure``).  Zenoh delivers on its own threads; received frames
wait in a queue.
"""

from __future__ import annotations

import json
import queue
import struct
import time
import uuid
from typing import Any

from ..core.names import zenoh_prefix_problem
from ..core.packets import BROADCAST
from .zenoh_auth import Identity, load_identity, session_config
from .zenoh_door import link_key

_RECV = struct.Struct(">BBd")


def _session(zenoh_option: Any) -> tuple[Any, str, Identity | None]:
    import zenoh

    if isinstance(zenoh_option, str):
        zenoh_option = {"connect": [zenoh_option]}
    elif isinstance(zenoh_option, (list, tuple)):
        zenoh_option = {"connect": list(zenoh_option)}
    options = dict(zenoh_option or {})
    prefix = str(options.get("prefix", "hilgate"))
    if zenoh_prefix_problem(prefix):
        raise ValueError(f"Zenoh prefix {prefix!r}: {zenoh_prefix_problem(prefix)}")
    identity = load_identity(str(options["credentials"]), role="app") if options.get("credentials") else None
    # (an application listens nowhere unless told: it connects to daemons, and learns of the others from them)
    config = session_config(listen=list(options.get("listen", [])), connect=list(options.get("connect", [])),
                            identity=identity, prefix=prefix,
                            multicast_scouting=bool(options.get("multicast_scouting", False)),
                            config_file=options.get("config"))
    from .socket_client import GliError

    try:
        session = zenoh.open(config)
    except zenoh.ZError as exc:
        raise GliError(f"cannot open a Zenoh session: {str(exc).splitlines()[0] if str(exc) else exc}") from None
    deadline = time.monotonic() + 2.0
    while options.get("connect") and time.monotonic() < deadline and not list(session.info.peers_zid()):
        time.sleep(0.02)
    if options.get("connect") and not list(session.info.peers_zid()):
        session.close()
        raise GliError(_nobody_at(list(options["connect"]), identity is not None))
    return session, prefix, identity


def _nobody_at(endpoints: list[str], with_credentials: bool) -> str:
    """No daemon took the connection: on an authenticated network (``hilgate network init``) the usual
    cause is an application without its credentials, whose plain TCP a TLS listener refuses."""
    where = ", ".join(endpoints)
    if not with_credentials:
        return (f"no daemon took a connection at {where}: a network made with hilgate network init takes only "
                f"applications with their credentials (--zenoh-credentials DIR/apps/NAME, or Link.open(zenoh="
                f"{{'connect': [...], 'credentials': DIR}})); else no daemon listens there")
    return (f"no daemon took a connection at {where} with these credentials: no daemon listens there, or its "
            f"certificates come from another network's CA (hilgate network init)")


def _prefix_hint(session: Any, link_id: str, prefix: str) -> str:
    """Where the link is served instead, if a daemon holds its liveliness token under another prefix
    (``<prefix>/alive/<host>/link/<link>/<zid>``): the usual cause is a scene's ``zenoh: prefix:``.  An
    application's credentials may not ask for liveliness: on an authenticated network only the generic
    advice is given."""
    found = set()
    try:
        for reply in session.liveliness().get(f"**/alive/*/link/{link_id}/**", timeout=1.0):
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                found.add(key[:key.rfind("/alive/", 0, key.rfind(f"/link/{link_id}/"))])
    except Exception:  # a hint only: the error it decorates says what matters
        pass
    found.discard(prefix)
    if found:
        return (f"; it is served under {', '.join(repr(p) for p in sorted(found))}: give that prefix "
                f"(Link.open(..., prefix=...), --zenoh-prefix)")
    return ("; a network whose scene sets zenoh: prefix: needs the same prefix here (Link.open(..., prefix=...), "
            "--zenoh-prefix)")


class ZenohLink:
    """One link of the network, reached over Zenoh (see :class:`hilgate.gli.socket_client.Link`)."""

    sock = None
    """(A socket link's ``sock``; this one has none: its frames come on Zenoh's threads.)"""

    def __init__(self, session: Any, prefix: str, link_id: str, info: dict[str, Any], host: str,
                 client: str | None = None):
        from .socket_client import GliError, Message

        self._GliError, self._Message = GliError, Message
        self.session = session
        self.prefix = prefix
        self.id = link_id
        self.host = host
        self.info = info
        self.client = client or uuid.uuid4().hex[:16]
        self.ready = bool(info.get("ready"))
        self.inbox: queue.Queue = queue.Queue()
        self.errors: queue.Queue = queue.Queue()
        self.publisher = session.declare_publisher(self._key(f"send/{self.client}"))
        self.subscribers = [
            session.declare_subscriber(self._key("recv"), self._on_recv),
            session.declare_subscriber(self._key("state"), self._on_state),
            session.declare_subscriber(self._key(f"error/{self.client}"), self._on_error),
        ]

    def _key(self, leaf: str) -> str:
        return link_key(self.prefix, self.host, self.id, leaf)

    @classmethod
    def open(cls, link_id: str, zenoh_option: Any, timeout: float = 5.0) -> "ZenohLink":
        from .socket_client import GliError

        session, prefix, identity = _session(zenoh_option)
        try:
            answers: dict[str, dict[str, Any]] = {}
            deadline = time.monotonic() + timeout
            while not answers and time.monotonic() < deadline:
                for reply in session.get(link_key(prefix, "*", link_id, "info"), timeout=min(1.0, timeout)):
                    if reply.ok is None:
                        continue
                    host = str(reply.ok.key_expr)[len(prefix) + 6:].partition("/")[0]
                    try:
                        info = json.loads(reply.ok.payload.to_bytes())
                    except ValueError:
                        continue
                    if isinstance(info, dict) and info.get("link") == link_id:
                        answers[host] = info
            if not answers:
                raise GliError(f"no daemon on the network serves link {link_id!r} under the Zenoh prefix "
                               f"{prefix!r}{_prefix_hint(session, link_id, prefix)}")
            if len(answers) > 1:  # (with credentials each answers under its own name: both are hosts of the lab)
                raise GliError(f"link {link_id!r} is served by several hosts ({', '.join(sorted(answers))})")
            host, info = next(iter(answers.items()))
            link = cls(session, prefix, link_id, info, host, identity.name if identity else None)
            time.sleep(0.05)  # let the daemon learn of our subscriptions before the first frame for us
            return link
        except BaseException:
            session.close()
            raise

    # -- Zenoh's threads --------------------------------------------------------------------------

    def _on_recv(self, sample: Any) -> None:
        data = sample.payload.to_bytes()
        if len(data) >= _RECV.size:
            src, dst, t = _RECV.unpack_from(data)
            self.inbox.put(self._Message(self.id, src, dst, t, data[_RECV.size:]))

    def _on_state(self, sample: Any) -> None:
        self.ready = sample.payload.to_bytes()[:1] == b"\x01"

    def _on_error(self, sample: Any) -> None:
        try:
            self.errors.put(str(json.loads(sample.payload.to_bytes()).get("error")))
        except ValueError:
            self.errors.put("unreadable error")

    # -- the Link API ------------------------------------------------------------------------------

    @property
    def address(self) -> int:
        return int(self.info["address"])

    @property
    def max_payload(self) -> int:
        return int(self.info["max_payload"])

    def send(self, data: bytes, dst: int = BROADCAST, timeout: float | None = None) -> None:
        if not 0 <= dst <= 255:
            raise ValueError("dst must be 0..255 (255 broadcasts)")
        self._raise_error()
        self.publisher.put(bytes([dst]) + bytes(data), attachment=self.client.encode())

    def _raise_error(self) -> None:
        try:
            raise self._GliError(self.errors.get_nowait())
        except queue.Empty:
            pass

    def recv(self, timeout: float | None = None) -> Any:
        self._raise_error()
        try:
            return self.inbox.get(timeout=timeout)
        except queue.Empty:
            self._raise_error()
            return None

    def command(self, request: dict[str, Any], timeout: float = 5.0) -> Any:
        for reply in self.session.get(self._key(f"command/{self.client}"), payload=json.dumps(request).encode(),
                                      timeout=timeout):
            if reply.ok is not None:
                answer = json.loads(reply.ok.payload.to_bytes())
                if isinstance(answer, dict) and answer.get("class") == "ERROR":
                    raise self._GliError(str(answer.get("error")))
                return answer
        raise self._GliError("no reply from hilgate")

    def close(self) -> None:
        for entity in (*self.subscribers, self.publisher):
            try:
                entity.undeclare()
            except Exception:
                pass
        self.session.close()

    def __enter__(self) -> "ZenohLink":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
