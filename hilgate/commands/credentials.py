"""``hilgate network init DIR --hosts tank-pc,pier-pc --apps 4``: a lab's credentials for a network of
daemons (what they are and how a session uses them: :mod:`hilgate.gli.zenoh_auth`).

Writes::

    DIR/ca/ca.pem, DIR/ca/ca.key          the certificate authority (keep ca.key off the lab's PCs)
    DIR/hosts/<host>/                     one identity per host: ca.pem, cert.pem, key.pem, network.json
    DIR/apps/<app>/                       one per application (app-1 … app-N, or the names given)

Keys are ECDSA P-256, certificates valid ten years, signed by the CA; key files are 0600, the others
0640, directories 0750 (the daemon's group may read certificates and manifests, only the owner a key).
Run again with more names, the CA and the identities already there are kept (their keys unchanged)
and every manifest is rewritten with the new lists: copy each host's and application's directory
again, since a session lets in only the names its own manifest lists.  Sits above the rooms, with the
commands: it uses the ``cryptography`` package, which nothing else needs.
"""

from __future__ import annotations

import datetime
import json
import os
from typing import Any

from ..gli.zenoh_auth import MANIFEST, NAME

__all__ = ["init_network", "NetworkInitError"]

VALID_DAYS = 3650


class NetworkInitError(ValueError):
    """Names or a directory ``network init`` cannot use."""


def _write(path: str, data: bytes, mode: int) -> None:
    """Create ``path`` with ``mode`` from the start (never a moment readable by others), replacing
    whatever file was there; a symlink at ``path`` is replaced, never followed."""
    tmp = f"{path}.tmp{os.getpid()}"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, mode)
    try:
        os.fchmod(fd, mode)  # (the umask may have narrowed it; never widened beyond mode)
        os.write(fd, data)
    finally:
        os.close(fd)
    os.replace(tmp, path)


def _mkdir(path: str) -> None:
    os.makedirs(path, mode=0o750, exist_ok=True)
    os.chmod(path, 0o750)


def _names(hosts: list[str], apps: list[str] | int) -> tuple[list[str], list[str]]:
    app_names = [f"app-{i}" for i in range(1, apps + 1)] if isinstance(apps, int) else list(apps)
    for name in (*hosts, *app_names):
        if not NAME.fullmatch(name):
            raise NetworkInitError(f"{name!r} is not a name (letters, digits, '_', '.', '-'; at most 64)")
    if not hosts:
        raise NetworkInitError("a network needs at least one host (--hosts tank-pc,pier-pc)")
    both = sorted(set(hosts) & set(app_names))
    if both:
        raise NetworkInitError(f"{', '.join(both)}: a name is a host's or an application's, not both")
    for group in (hosts, app_names):
        if len(set(group)) != len(group):
            raise NetworkInitError("a name is given twice")
    return hosts, app_names


def init_network(directory: str, hosts: list[str], apps: list[str] | int) -> dict[str, Any]:
    """Create or extend the credentials in ``directory``; returns what was made and kept."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    hosts, app_names = _names(hosts, apps)
    now = datetime.datetime.now(datetime.timezone.utc)
    not_before, not_after = now - datetime.timedelta(hours=1), now + datetime.timedelta(days=VALID_DAYS)

    def subject(name: str) -> Any:
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])

    def pem_key(key: Any) -> bytes:
        return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                 serialization.NoEncryption())

    _mkdir(directory)
    ca_dir = os.path.join(directory, "ca")
    _mkdir(ca_dir)
    os.chmod(ca_dir, 0o700)
    ca_key_path, ca_pem_path = os.path.join(ca_dir, "ca.key"), os.path.join(ca_dir, "ca.pem")
    made, kept = [], []
    if os.path.isfile(ca_key_path) and os.path.isfile(ca_pem_path):
        with open(ca_key_path, "rb") as handle:
            ca_key = serialization.load_pem_private_key(handle.read(), None)
        with open(ca_pem_path, "rb") as handle:
            ca_cert = x509.load_pem_x509_certificate(handle.read())
        kept.append("ca")
    else:
        ca_key = ec.generate_private_key(ec.SECP256R1())
        ca_cert = (x509.CertificateBuilder().subject_name(subject("hilgate-ca")).issuer_name(subject("hilgate-ca"))
                   .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
                   .not_valid_before(not_before).not_valid_after(not_after)
                   .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
                   .add_extension(x509.KeyUsage(False, False, False, False, False, True, True, False, False), critical=True)
                   .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), critical=False)
                   .sign(ca_key, hashes.SHA256()))
        _write(ca_key_path, pem_key(ca_key), 0o600)
        _write(ca_pem_path, ca_cert.public_bytes(serialization.Encoding.PEM), 0o640)
        made.append("ca")
    ca_pem = ca_cert.public_bytes(serialization.Encoding.PEM)
    for role, group, names in (("host", "hosts", hosts), ("app", "apps", app_names)):
        _mkdir(os.path.join(directory, group))
        for name in names:
            home = os.path.join(directory, group, name)
            _mkdir(home)
            key_path, cert_path = os.path.join(home, "key.pem"), os.path.join(home, "cert.pem")
            if os.path.isfile(key_path) and os.path.isfile(cert_path):
                kept.append(name)
            else:
                key = ec.generate_private_key(ec.SECP256R1())
                cert = (x509.CertificateBuilder().subject_name(subject(name)).issuer_name(ca_cert.subject)
                        .public_key(key.public_key()).serial_number(x509.random_serial_number())
                        .not_valid_before(not_before).not_valid_after(not_after)
                        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
                        .add_extension(x509.SubjectAlternativeName([x509.DNSName(name)]), critical=False)
                        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                              ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
                        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
                                       critical=False)
                        .sign(ca_key, hashes.SHA256()))
                _write(key_path, pem_key(key), 0o600)
                _write(cert_path, cert.public_bytes(serialization.Encoding.PEM), 0o640)
                made.append(name)
            _write(os.path.join(home, "ca.pem"), ca_pem, 0o640)
            manifest = {"name": name, "role": role, "hosts": hosts, "apps": app_names}
            _write(os.path.join(home, MANIFEST), (json.dumps(manifest, indent=1) + "\n").encode(), 0o640)
    return {"directory": os.path.abspath(directory), "made": made, "kept": kept, "hosts": hosts, "apps": app_names}
