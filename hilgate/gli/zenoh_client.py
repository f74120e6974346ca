"""The client side of the GLI over Zenoh (:mod:`hilgate.gli.zenoh_door` has the key layout): the same
``send``/``recv``/``command`` as the socket client, from any host of the network.

    from hilgate.client import Link

    with Link.open("rov_ac", zenoh="tcp/192.168.1.10:7447") as link:   # a daemon to connect to
        link.send(b"hello", dst=2)
        print(link.recv(timeout=5.0))

``zenoh`` is an endpoint, a list of them, or a dict ``{"connect": [...], "prefix": "hilgate",
"config": "zenoh.json5"}``.  Zenoh delivers on its own threads; received frames wait in a queue.
"""

from __future__ import annotations

import json
import queue
import struct
import threading
import time
import uuid
from typing import Any

from ..core.names import zenoh_prefix_problem
from ..core.packets import BROADCAST
from .zenoh_door import link_key

_RECV = struct.Struct(">BBd")


def _session(zenoh_option: Any) -> tuple[Any, str]:
    import zenoh

    if isinstance(zenoh_option, str):
        zenoh_option = {"connect": [zenoh_option]}
    elif isinstance(zenoh_option, (list, tuple)):
        zenoh_option = {"connect": list(zenoh_option)}
    options = dict(zenoh_option or {})
    prefix = str(options.get("prefix", "hilgate"))
    if zenoh_prefix_problem(prefix):
        raise ValueError(f"Zenoh prefix {prefix!r}: {zenoh_prefix_problem(prefix)}")
    config = zenoh.Config.from_file(options["config"]) if options.get("config") else zenoh.Config()
    if not options.get("config"):
        config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", json.dumps(bool(options.get("multicast_scouting", False))))
    config.insert_json5("listen/endpoints", json.dumps(list(options.get("listen", ["tcp/127.0.0.1:0"]))))
    if options.get("connect"):
        config.insert_json5("connect/endpoints", json.dumps(list(options["connect"])))
    session = zenoh.open(config)
    deadline = time.monotonic() + 2.0
    while options.get("connect") and time.monotonic() < deadline and not list(session.info.peers_zid()):
        time.sleep(0.02)
    return session, prefix


def _prefix_hint(session: Any, link_id: str, prefix: str) -> str:
    """Where the link is served instead, if a daemon holds its liveliness token under another prefix
    (``<prefix>/alive/links/<link>/<host>/<zid>``): the usual cause is a scene's ``zenoh: prefix:``."""
    found = set()
    try:
        for reply in session.liveliness().get(f"**/alive/links/{link_id}/**", timeout=1.0):
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                found.add(key[:key.rfind(f"/alive/links/{link_id}/")])
    except Exception:  # a hint only: the error it decorates says what matters
        pass
    found.discard(prefix)
    if found:
        return (f"; it is served under {', '.join(repr(p) for p in sorted(found))}: give that prefix "
                f"(Link.open(..., prefix=...), --zenoh-prefix)")
    return ("; a network whose scene sets zenoh: prefix: needs the same prefix here (Link.open(..., prefix=...), "
            "--zenoh-prefix)")


class ZenohLink:
    """One link of the network, reached over Zenoh (see :class:`hilgate.gli.client.Link`)."""

    def __init__(self, session: Any, prefix: str, link_id: str, info: dict[str, Any]):
        from .client import GliError, Message

        self._GliError, self._Message = GliError, Message
        self.session = session
        self.prefix = prefix
        self.id = link_id
        self.info = info
        self.client = uuid.uuid4().hex[:16]
        self.ready = bool(info.get("ready"))
        self.inbox: queue.Queue = queue.Queue()
        self.errors: queue.Queue = queue.Queue()
        self._lock = threading.Lock()
        self.publisher = session.declare_publisher(link_key(prefix, link_id, "send"))
        self.subscribers = [
            session.declare_subscriber(link_key(prefix, link_id, "recv"), self._on_recv),
            session.declare_subscriber(link_key(prefix, link_id, "state"), self._on_state),
            session.declare_subscriber(link_key(prefix, link_id, f"error/{self.client}"), self._on_error),
        ]

    @classmethod
    def open(cls, link_id: str, zenoh_option: Any, timeout: float = 5.0) -> "ZenohLink":
        from .client import GliError

        session, prefix = _session(zenoh_option)
        try:
            info = None
            deadline = time.monotonic() + timeout
            while info is None and time.monotonic() < deadline:
                for reply in session.get(link_key(prefix, link_id, "info"), timeout=min(1.0, timeout)):
                    if reply.ok is not None:
                        info = json.loads(reply.ok.payload.to_bytes())
                        break
            if info is None:
                raise GliError(f"no daemon on the network serves link {link_id!r} under the Zenoh prefix "
                               f"{prefix!r}{_prefix_hint(session, link_id, prefix)}")
            link = cls(session, prefix, link_id, info)
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
            self.inbox.put(self._Message(src, dst, t, data[_RECV.size:]))

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
        for reply in self.session.get(link_key(self.prefix, self.id, "command"), payload=json.dumps(request).encode(),
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
