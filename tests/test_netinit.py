"""``hilgate network init``: a lab's credentials, their files' modes, and what a daemon refuses to use."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys

import pytest

from hilgate.gli.zenoh_auth import CredentialError, acl, load_identity
from hilgate.commands.credentials import NetworkInitError, init_network


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_network_init_makes_one_identity_per_name_with_private_keys(tmp_path):
    root = tmp_path / "lab"
    answer = subprocess.run([sys.executable, "-m", "hilgate", "network", "init", str(root), "--hosts", "tank-pc,pier-pc",
                             "--apps", "2"], capture_output=True, text=True, timeout=60)
    assert answer.returncode == 0, answer.stderr
    assert "keep" in answer.stdout and "ca.key" in answer.stdout
    assert mode(root / "ca" / "ca.key") == 0o600 and mode(root / "ca") == 0o700
    for group, name in (("hosts", "tank-pc"), ("hosts", "pier-pc"), ("apps", "app-1"), ("apps", "app-2")):
        home = root / group / name
        assert mode(home) == 0o750 and mode(home / "key.pem") == 0o600
        assert mode(home / "cert.pem") == mode(home / "ca.pem") == mode(home / "network.json") == 0o640
        manifest = json.loads((home / "network.json").read_text())
        assert manifest == {"name": name, "role": group[:-1], "hosts": ["tank-pc", "pier-pc"], "apps": ["app-1", "app-2"]}
    from cryptography import x509

    cert = x509.load_pem_x509_certificate((root / "hosts" / "pier-pc" / "cert.pem").read_bytes())
    assert cert.subject.rfc4514_string() == "CN=pier-pc"
    # again, with one more host: what exists is kept, every manifest lists the new host
    key_before = (root / "hosts" / "tank-pc" / "key.pem").read_bytes()
    result = init_network(str(root), ["tank-pc", "pier-pc", "sim-pc"], 2)
    assert result["made"] == ["sim-pc"] and "ca" in result["kept"]
    assert (root / "hosts" / "tank-pc" / "key.pem").read_bytes() == key_before
    assert json.loads((root / "apps" / "app-1" / "network.json").read_text())["hosts"] == ["tank-pc", "pier-pc", "sim-pc"]


@pytest.mark.parametrize("hosts, apps, message", [
    ([], 1, "at least one host"),
    (["a/b"], 0, "is not a name"),
    (["a"], ["a"], "not both"),
    (["a", "a"], 0, "twice"),
])
def test_network_init_refuses_names_it_cannot_use(tmp_path, hosts, apps, message):
    with pytest.raises(NetworkInitError, match=message):
        init_network(str(tmp_path), hosts, apps)


def test_a_daemon_takes_only_its_own_private_credentials(tmp_path):
    init_network(str(tmp_path), ["A", "B"], 1)
    assert load_identity(str(tmp_path), "A", "host").name == "A"                  # the root, with --host
    assert load_identity(str(tmp_path / "hosts" / "B"), "B", "host").role == "host"  # its own directory
    with pytest.raises(CredentialError, match="are host 'B', not 'A'"):
        load_identity(str(tmp_path / "hosts" / "B"), "A", "host")
    with pytest.raises(CredentialError, match="not a host's"):
        load_identity(str(tmp_path / "apps" / "app-1"), None, "host")
    with pytest.raises(CredentialError, match="no credentials"):
        load_identity(str(tmp_path / "nowhere"), "A", "host")
    os.chmod(tmp_path / "hosts" / "A" / "key.pem", 0o644)
    with pytest.raises(CredentialError, match="readable by others"):
        load_identity(str(tmp_path), "A", "host")


def test_the_access_rules_give_each_host_its_own_name_and_applications_link_keys(tmp_path):
    init_network(str(tmp_path), ["A", "B"], 1)
    rules = acl("p", load_identity(str(tmp_path), "A", "host"))
    by_subject = {}
    for policy in rules["policies"]:
        subject = next(s for s in rules["subjects"] if s["id"] == policy["subjects"][0])["cert_common_names"][0]
        by_subject[subject] = {k for r in rules["rules"] if r["id"] in policy["rules"] and "ingress" in r["flows"]
                               for k in r["key_exprs"]}
    assert rules["default_permission"] == "deny"
    assert "p/tx/B/**" in by_subject["B"] and not any(k.startswith("p/tx/A") for k in by_subject["B"])
    assert {k for k in by_subject["app-1"]} == {"p/link/*/*/send/app-1", "p/link/*/*/recv", "p/link/*/*/state",
                                                "p/link/*/*/error/app-1", "p/link/*/*/info", "p/link/*/*/command/app-1"}
