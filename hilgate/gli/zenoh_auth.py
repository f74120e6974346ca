"""Who may say what on a network of daemons: the Zenoh configuration of a daemon's or an application's
session, authenticated by mutual TLS and restricted by Zenoh's own access control.

A lab's credentials (``hilgate network init``) are one certificate authority and one identity per host
and per application, each a directory::

    ca.pem        the lab's CA (the only one a session trusts)
    cert.pem      this identity's certificate: its common name is the host's or application's name
    key.pem       its private key (0600: never readable by others)
    network.json  {"name", "role": "host" | "app", "hosts": [...], "apps": [...]}

Every session (daemon or application) speaks TLS only (``transport/link/protocols``), asks the other
side for a certificate of the same CA (``enable_mtls``), and lets in from each peer only what that
peer's common name may say (``access_control``, default deny; the rules are :func:`acl`).  A host's
keys carry its name (``<prefix>/tx/<host>/…``, :mod:`hilgate.daemon.network`), so the rules say
"host H publishes only under H" without naming a link or a vehicle.  Names are not checked against the
address a peer connects from (``verify_name_on_connect`` off): the lab's addresses are not known when
its credentials are made, and what a peer may do depends on the name its certificate proves, not on
where it is.

Without credentials (``zenoh: {insecure: true}``) a session is plain TCP and anyone who reaches it may
say anything; the daemon warns at every start.
"""

from __future__ import annotations

import json
import os
import re
import stat
from dataclasses import dataclass
from typing import Any

__all__ = ["Identity", "CredentialError", "load_identity", "session_config", "acl", "NAME", "MAX_MESSAGE_BYTES",
           "SIZE_FILTER_BYTES"]

NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")  # (a host name: hilgate.scene.hosts.HOST_NAME)
MAX_MESSAGE_BYTES = 1 << 20
"""The largest message Zenoh reassembles (``transport/link/rx/max_message_size``; Zenoh's default is 1 GiB):
a hilgate message is at most a few tens of kB (a host's status with hundreds of links, ~200 kB), and a
larger one is dropped by Zenoh before any of it reaches Python."""

RECONNECT_MAX_MS = 1000
"""The longest wait between two attempts to reach a ``connect`` endpoint again (Zenoh's default grows to
4 s): a link that comes back is used within about a second (measured: tests/test_host_faults.py)."""
SIZE_FILTER_BYTES = 1 << 17
"""Messages on the keys a session names as bounded (transmissions, poses, GLI SENDs) longer than this
are dropped by Zenoh's ``low_pass_filter`` as they arrive; hilgate's own checks (64 kB) count those
between."""
MANIFEST = "network.json"
ALL_MESSAGES = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"]


class CredentialError(ValueError):
    """Credentials that cannot be used (missing, unreadable, of another host, readable by others)."""


@dataclass(frozen=True)
class Identity:
    directory: str
    name: str
    role: str  # "host" or "app"
    hosts: tuple[str, ...]
    apps: tuple[str, ...]

    @property
    def ca(self) -> str:
        return os.path.join(self.directory, "ca.pem")

    @property
    def cert(self) -> str:
        return os.path.join(self.directory, "cert.pem")

    @property
    def key(self) -> str:
        return os.path.join(self.directory, "key.pem")


def load_identity(path: str, name: str | None = None, role: str | None = None) -> Identity:
    """The identity in ``path``: an identity's own directory, or the root ``hilgate network init`` made
    (then ``<path>/hosts/<name>`` or ``<path>/apps/<name>``).  ``name``/``role``: what it must be."""
    path = os.path.abspath(path)
    candidates = [path]
    if name is not None:
        candidates.insert(0, os.path.join(path, "hosts" if role == "host" else "apps", name))
    directory = next((c for c in candidates if os.path.isfile(os.path.join(c, MANIFEST))), None)
    if directory is None:
        raise CredentialError(f"no credentials in {path} (no {MANIFEST}{f' for {name}' if name else ''}; "
                              f"make them with: hilgate network init DIR --hosts ... --apps N)")
    identity = _read_manifest(directory)
    for value in (identity.name, *identity.hosts, *identity.apps):
        if not NAME.fullmatch(value):
            raise CredentialError(f"{directory}: {value!r} is not a name (letters, digits, '_', '.', '-')")
    if identity.role not in ("host", "app"):
        raise CredentialError(f"{directory}: role {identity.role!r} is neither host nor app")
    if name is not None and identity.name != name:
        raise CredentialError(f"the credentials in {directory} are {identity.role} {identity.name!r}, not {name!r}")
    if role is not None and identity.role != role:
        raise CredentialError(f"the credentials in {directory} are an {identity.role}'s ({identity.name!r}), "
                              f"not a {role}'s")
    _check_files(identity)
    return identity


def _read_manifest(directory: str) -> Identity:
    """The identity that ``directory``'s manifest names (unchecked), or a CredentialError if it is none."""
    try:
        with open(os.path.join(directory, MANIFEST), encoding="utf-8") as handle:
            manifest = json.loads(handle.read(1 << 20))
        return Identity(directory, str(manifest["name"]), str(manifest["role"]),
                        tuple(str(h) for h in manifest["hosts"]), tuple(str(a) for a in manifest["apps"]))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CredentialError(f"{os.path.join(directory, MANIFEST)} is not a hilgate network manifest: {exc}") from None


def _check_files(identity: Identity) -> None:
    """A CredentialError unless the identity's CA, certificate and key are there, and its key is readable by
    this process but not by others."""
    for needed in (identity.ca, identity.cert, identity.key):
        if not os.path.isfile(needed):
            raise CredentialError(f"{needed} is missing")
    mode = os.stat(identity.key).st_mode
    if mode & stat.S_IRWXO:
        raise CredentialError(f"{identity.key} is readable by others ({stat.filemode(mode)}): chmod 600 it")
    try:
        with open(identity.key, "rb"):
            pass
    except OSError as exc:
        raise CredentialError(f"cannot read {identity.key}: {exc.strerror}") from None


def _allow(rule_id: str, messages: list[str], keys: list[str], flow: str = "ingress") -> dict[str, Any]:
    return {"id": rule_id, "messages": messages, "flows": [flow], "permission": "allow", "key_exprs": keys}


def acl(prefix: str, identity: Identity) -> dict[str, Any]:
    """Zenoh's ``access_control`` for a session of ``identity``: what it lets in from each peer.

    A host H may: publish under ``tx/H``, ``pose/H``, ``link/H``, ``ack/H``; answer ``status/H`` and
    ``link/H`` queries; hold liveliness tokens under ``alive/H``; subscribe to and query the others'
    transmissions, poses, reports, statuses and tokens.  An application A may (on daemons) only put SENDs under
    ``link/*/*/send/A``, subscribe to links' ``recv``, ``state`` and its own ``error/A``, and query
    ``info`` and ``command/A``; on an application's session only hosts' link keys get in.  Anything
    else from anyone (another application, a certificate of a name the manifest does not list) is
    refused: the default is deny."""
    p = prefix
    # what goes out: anything to a host, only link keys to an application (not even which hosts are alive)
    rules = [_allow("out", ALL_MESSAGES, [f"{p}/**"], "egress"), _allow("out-app", ALL_MESSAGES, [f"{p}/link/**"], "egress")]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for i, host in enumerate(identity.hosts):
        if identity.role == "host":
            granted = [
                (["put", "delete"], [f"{p}/tx/{host}/**", f"{p}/pose/{host}/**", f"{p}/link/{host}/**",
                                     f"{p}/ack/{host}/**"]),
                (["declare_subscriber"], [f"{p}/tx/**", f"{p}/pose/**", f"{p}/link/{host}/**", f"{p}/ack/**"]),
                (["declare_queryable", "reply"], [f"{p}/status/{host}", f"{p}/link/{host}/**"]),
                (["query"], [f"{p}/status/**"]),
                (["liveliness_token"], [f"{p}/alive/{host}/**"]),
                (["liveliness_query", "declare_liveliness_subscriber"], [f"{p}/alive/**"]),
            ]
        else:  # an application's session: only what a host says about its own links
            granted = [
                (["put", "delete", "reply", "declare_subscriber", "declare_queryable"], [f"{p}/link/{host}/**"]),
            ]
        ids = []
        for j, (messages, keys) in enumerate(granted):
            rules.append(_allow(f"h{i}r{j}", messages, keys))
            ids.append(f"h{i}r{j}")
        subjects.append({"id": f"h{i}", "cert_common_names": [host]})
        policies.append({"rules": ["out", *ids], "subjects": [f"h{i}"]})
    if identity.role == "host":
        for i, app in enumerate(identity.apps):
            granted = [
                (["put"], [f"{p}/link/*/*/send/{app}"]),
                (["declare_subscriber"], [f"{p}/link/*/*/recv", f"{p}/link/*/*/state", f"{p}/link/*/*/error/{app}"]),
                (["query"], [f"{p}/link/*/*/info", f"{p}/link/*/*/command/{app}"]),
            ]
            ids = []
            for j, (messages, keys) in enumerate(granted):
                rules.append(_allow(f"a{i}r{j}", messages, keys))
                ids.append(f"a{i}r{j}")
            subjects.append({"id": f"a{i}", "cert_common_names": [app]})
            policies.append({"rules": ["out-app", *ids], "subjects": [f"a{i}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def session_config(*, listen: list[str] | tuple[str, ...], connect: list[str] | tuple[str, ...] = (),
                   identity: Identity | None, prefix: str, multicast_scouting: bool = False,
                   lease_s: float | None = None, config_file: str | None = None,
                   size_filter: list[str] | tuple[str, ...] = ()) -> Any:
    """The Zenoh configuration of a daemon's or an application's session: peer mode, multicast scouting
    off unless asked, the endpoints, the lease, reconnection at least every second; with an identity TLS-only, mutual, and the ACL of
    :func:`acl` (``tcp/`` endpoints are read as ``tls/``); without one, plain TCP."""
    import zenoh

    config = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    if not config_file:
        config.insert_json5("mode", '"peer"')
    if identity is not None:
        listen, connect = [_tls(e) for e in listen], [_tls(e) for e in connect]
    config.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast_scouting)))
    config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(list(dict.fromkeys(connect))))
    if json.loads(config.get_json("connect/retry") or "null") is None:  # (a configuration file's stays)
        config.insert_json5("connect/retry", json.dumps({"period_max_ms": RECONNECT_MAX_MS}))
    if lease_s is not None:
        config.insert_json5("transport/link/tx/lease", str(int(lease_s * 1000)))
        config.insert_json5("transport/link/tx/keep_alive", "4")
    config.insert_json5("transport/link/rx/max_message_size", str(MAX_MESSAGE_BYTES))
    if size_filter:
        config.insert_json5("low_pass_filter", json.dumps([{
            "id": "hilgate-sizes", "flows": ["ingress"], "messages": ["put", "query", "reply"],
            "key_exprs": list(size_filter), "size_limit": SIZE_FILTER_BYTES}]))
    if identity is not None:
        config.insert_json5("transport/link/protocols", '["tls"]')
        config.insert_json5("transport/link/tls", json.dumps({
            "root_ca_certificate": identity.ca, "enable_mtls": True, "verify_name_on_connect": False,
            "listen_private_key": identity.key, "listen_certificate": identity.cert,
            "connect_private_key": identity.key, "connect_certificate": identity.cert,
            "close_link_on_expiration": True}))
        config.insert_json5("access_control", json.dumps(acl(prefix, identity)))
    return config


def _tls(endpoint: str) -> str:
    return "tls/" + endpoint[4:] if endpoint.startswith("tcp/") else endpoint
