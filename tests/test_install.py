"""Installed as a service (issue 11 item 8) and what the package declares (item 11).

`make install DESTDIR=…` runs for real: a venv with hilgate and its dependencies (from pip's cache or
PyPI), the unit, /etc/hilgate and logrotate's file, all under a temporary DESTDIR; the root-only steps
(the hilgate user, systemctl) are skipped there, so nothing here needs root or touches /etc or /opt.
"""

from __future__ import annotations

import ast
import importlib.metadata
import marshal
import os
import re
import shutil
import stat
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement

REPO = Path(__file__).resolve().parent.parent
PREFIX = "/opt/hilgate"
UNIT = "etc/systemd/system/hilgate.service"
ENV = "etc/hilgate/hilgate.env"
SCENE = "etc/hilgate/scene.yaml"
LOGROTATE = "etc/logrotate.d/hilgate"
MANIFEST = "opt/hilgate/share/hilgate/installed"
SYSTEM_PATHS = ["/opt/hilgate", "/etc/hilgate", "/etc/systemd/system/hilgate.service", "/etc/logrotate.d/hilgate"]


def make(*args: str, umask: int | None = None) -> subprocess.CompletedProcess:
    # PYTHON: the interpreter running the tests builds the venv (any Python >= 3.11 with venv would)
    result = subprocess.run(["make", "--no-print-directory", "-C", str(REPO), *args, f"PYTHON={sys.executable}"],
                            capture_output=True, text=True, stdin=subprocess.DEVNULL,
                            preexec_fn=None if umask is None else (lambda: os.umask(umask)))
    assert result.returncode == 0, f"make {' '.join(args)}:\n{result.stdout}\n{result.stderr}"
    return result


def system_state() -> dict:
    return {p: os.lstat(p).st_mtime_ns if os.path.lexists(p) else None for p in SYSTEM_PATHS}


def files_under(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if not p.is_dir())


def unit_settings(path: Path) -> dict[str, list[str]]:
    settings: dict[str, list[str]] = {}
    for line in path.read_text().splitlines():
        if "=" in line and not line.startswith(("#", "[")):
            key, _, value = line.partition("=")
            settings.setdefault(key.strip(), []).append(value.strip())
    return settings


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """One full `make install` (venv and dependencies) into a DESTDIR, shared by the read-only tests."""
    before = system_state()
    root = tmp_path_factory.mktemp("destdir")
    result = make("install", f"DESTDIR={root}")
    yield root, result.stdout + result.stderr
    subprocess.run(["make", "-C", str(REPO), "uninstall", f"DESTDIR={root}", "PURGE=1"], capture_output=True)
    shutil.rmtree(root, ignore_errors=True)
    assert system_state() == before, "the test touched the real /etc or /opt"


def test_install_says_where_it_writes(installed):
    root, output = installed
    assert f"creating the venv {root}/opt/hilgate (to run as {PREFIX} on the target)" in output
    assert f"installing hilgate and its dependencies into {root}/opt/hilgate (to run as {PREFIX}" in output


def test_install_writes_the_unit_env_scene_and_logrotate(installed):
    root, output = installed
    for name in (UNIT, ENV, SCENE, LOGROTATE, MANIFEST):
        mode = stat.S_IMODE((root / name).stat().st_mode)
        assert mode == 0o644, (name, oct(mode))
    unit = unit_settings(root / UNIT)
    assert unit["ExecStart"] == [f"{PREFIX}/bin/hilgate run ${{HILGATE_SCENE}} $HILGATE_ARGS"]
    env_file = unit["EnvironmentFile"][0].lstrip("-")
    assert env_file == "/" + ENV  # the unit reads the env file where install puts it
    env = dict(line.split("=", 1) for line in (root / ENV).read_text().splitlines() if line and line[0] != "#")
    assert env["HILGATE_SCENE"] == "/" + SCENE
    assert (root / SCENE).read_bytes() == (REPO / "scenes" / "demo.yaml").read_bytes()
    assert "copytruncate" in (root / LOGROTATE).read_text()
    assert (root / "opt/hilgate/share/doc/hilgate/README.md").is_file()
    assert os.readlink(root / "usr/local/bin/hilgate") == f"{PREFIX}/bin/hilgate"  # for `hilgate status`
    assert unit["Documentation"] == [f"file://{PREFIX}/share/doc/hilgate/README.md"]
    # DESTDIR: the root-only steps are skipped, and said so
    assert "DESTDIR is set: skipping the hilgate user and group and systemctl" in output
    recorded = {line.split()[2] for line in (root / MANIFEST).read_text().splitlines() if line.startswith("file ")}
    assert recorded == {"/" + UNIT, "/" + ENV, "/" + SCENE, "/" + LOGROTATE}


def test_unit_closes_the_daemon_to_other_users_and_keeps_its_limits(installed):
    root, _ = installed
    unit = unit_settings(root / UNIT)
    expected = {"User": "hilgate", "Group": "hilgate", "SupplementaryGroups": "dialout", "UMask": "0007",
                "RuntimeDirectory": "hilgate", "RuntimeDirectoryMode": "0750", "LogsDirectoryMode": "0750",
                "RestartPreventExitStatus": "2", "Restart": "on-failure", "LimitMSGQUEUE": "infinity",
                "Type": "notify", "ExecReload": "/bin/kill -HUP $MAINPID"}
    assert {key: unit.get(key, [None])[-1] for key in expected} == expected


def test_service_pty_links_agree_with_private_tmp():
    """PrivateTmp hides the daemon's /tmp from every other program: docs/operations.md must tell service users
    to put emulated modems' pty links in /run/hilgate, and the unit must say why."""
    unit = unit_settings(REPO / "systemd" / "hilgate.service")
    assert unit["PrivateTmp"] == ["yes"] and unit["ProtectSystem"] == ["strict"]
    assert "pty: /run/hilgate/" in (REPO / "systemd" / "hilgate.service").read_text()
    operations = (REPO / "docs" / "operations.md").read_text()
    assert "pty: /run/hilgate/" in operations
    for words in ("journalctl -u hilgate", "copytruncate", "systemctl reload hilgate", "SIGKILL", "make install"):
        assert words in operations, words


def test_installed_venv_runs_its_own_hilgate_with_every_dependency(installed):
    root, _ = installed
    python = root / "opt/hilgate/bin/python"
    # the scripts name the interpreter where it will be on the target, not under DESTDIR
    assert (root / "opt/hilgate/bin/hilgate").read_text().splitlines()[0] == f"#!{PREFIX}/bin/python"
    assert os.access(root / "opt/hilgate/bin/hilgate", os.X_OK)
    leftovers = [p.name for p in (root / "opt/hilgate/bin").iterdir()
                 if not p.is_symlink() and str(root).encode() in p.read_bytes()]
    assert leftovers == []
    # byte code names the sources where they will be (tracebacks show their lines)
    compiled = next((root / "opt/hilgate/lib").glob("python3*/site-packages/hilgate/__pycache__/cli.*.pyc"))
    code = marshal.loads(compiled.read_bytes()[16:])
    assert code.co_filename.startswith(f"{PREFIX}/lib/python3"), code.co_filename
    probe = ("import hilgate, hilgate.core.packets, hilgate.gli.queues, hilgate.scene.yaml_nodes, "
             "hilgate.drivers.port, hilgate.drivers.aruco, hilgate.drivers.mavlink_source; print(hilgate.__file__)")
    # run outside the checkout: `python -c` and `-m` put the working directory first on sys.path
    result = subprocess.run([str(python), "-c", probe], capture_output=True, text=True, cwd=root,
                            env={"PATH": os.environ.get("PATH", ""), "HOME": os.environ.get("HOME", "/")})
    assert result.returncode == 0, result.stderr  # fastcrc, cv2, pymavlink, serial, yaml, posix_ipc
    assert result.stdout.strip().startswith(str(root / "opt/hilgate/lib")), "not installed (editable?)"
    check = subprocess.run([str(python), "-m", "hilgate", "check", str(root / SCENE)], capture_output=True,
                           text=True, cwd=root)
    assert check.returncode == 0 and check.stdout.rstrip().endswith("ok"), check.stderr
    pip_check = subprocess.run([str(python), "-m", "pip", "check"], capture_output=True, text=True, cwd=root)
    assert pip_check.returncode == 0, pip_check.stdout
    metadata = next((root / "opt/hilgate/lib").glob("python3*/site-packages/hilgate-*.dist-info/METADATA"))
    assert "License-Expression: MIT" in metadata.read_text()


def test_systemd_analyze_verifies_the_installed_unit(installed, tmp_path):
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed here")
    root, _ = installed
    # verify checks that ExecStart's program exists: point it at the staged copy, nothing else changes
    unit = tmp_path / "hilgate.service"
    unit.write_text((root / UNIT).read_text().replace(f"={PREFIX}/bin/", f"={root}{PREFIX}/bin/"))
    result = subprocess.run([analyze, "verify", str(unit)], capture_output=True, text=True)
    complaints = [line for line in (result.stdout + result.stderr).splitlines() if "hilgate" in line]
    assert result.returncode == 0 and complaints == [], result.stdout + result.stderr


class TestReinstall:
    """(A class of its own: `make test` hands test files and classes to its workers whole, and this test
    takes a minute and a half: beside the module's installed venv, not after it.)"""

    def test_reinstall_keeps_changed_configuration_and_uninstall_leaves_it_clean(self, tmp_path):
        before = system_state()
        root = tmp_path / "destdir"
        fast = "PIP_ARGS=--no-deps"  # this test is about the files; the full venv is the fixture's
        make("install", f"DESTDIR={root}", fast, umask=0o077)  # root's umask may be strict: the daemon must read
        for path in [root / UNIT, root / SCENE, *(root / "opt/hilgate/lib").rglob("hilgate/*.py")]:
            assert stat.S_IMODE(path.stat().st_mode) & 0o044 == 0o044, path
        (root / SCENE).write_text((root / SCENE).read_text() + "# our lab\n")
        (root / ENV).write_text((root / ENV).read_text() + "HILGATE_LOG_LEVEL=debug\n")
        unchanged_logrotate = (root / LOGROTATE).read_text()

        again = make("install", f"DESTDIR={root}", fast).stdout
        assert "kept /etc/hilgate/scene.yaml" in again
        assert (root / SCENE).read_text().endswith("# our lab\n")  # never overwritten
        assert "kept /etc/hilgate/hilgate.env (changed since it was installed)" in again
        assert (root / ENV).read_text().endswith("HILGATE_LOG_LEVEL=debug\n")
        assert (root / (ENV + ".new")).read_text() == (REPO / "systemd" / "hilgate.env").read_text()
        assert (root / LOGROTATE).read_text() == unchanged_logrotate

        gone = make("uninstall", f"DESTDIR={root}").stdout
        assert "kept /etc/hilgate/scene.yaml: changed since it was installed" in gone
        assert "kept /etc/hilgate/hilgate.env: changed since it was installed" in gone
        assert files_under(root) == sorted([ENV, SCENE])

        make("uninstall", f"DESTDIR={root}", "PURGE=1")
        assert not root.exists() or list(root.iterdir()) == []
        # a scene that was there before install is the user's: never replaced, never removed
        (root / "etc/hilgate").mkdir(parents=True)
        (root / SCENE).write_bytes((REPO / "scenes" / "demo.yaml").read_bytes())
        make("install", f"DESTDIR={root}", fast)
        make("uninstall", f"DESTDIR={root}")
        assert files_under(root) == [SCENE]
        assert system_state() == before


# -- pyproject.toml (item 11) ------------------------------------------------------------------------

def project() -> dict:
    with open(REPO / "pyproject.toml", "rb") as file:
        return tomllib.load(file)


def normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def imported_modules() -> dict[str, str]:
    """Top-level names of every absolute import in hilgate/, models/ and drivers/ → a file importing it."""
    found: dict[str, str] = {}
    for folder in ("hilgate", "models", "drivers"):
        for path in sorted((REPO / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    found.setdefault(name.split(".")[0], str(path.relative_to(REPO)))
    return found


def test_every_third_party_import_is_declared():
    meta = project()["project"]
    core = {normalized(Requirement(r).name) for r in meta["dependencies"]}
    extras = {normalized(Requirement(r).name) for reqs in meta["optional-dependencies"].values() for r in reqs}
    providers = importlib.metadata.packages_distributions()
    undeclared = []
    for module, where in imported_modules().items():
        if module in sys.stdlib_module_names or module == "hilgate":
            continue
        distributions = {normalized(d) for d in providers.get(module, [])}
        assert distributions, f"{module} (imported by {where}) is not installed: which package provides it?"
        if not distributions & (core | extras):
            undeclared.append(f"{module} ({where}, from {', '.join(sorted(distributions))})")
    assert undeclared == [], "imported but not declared in pyproject.toml: " + "; ".join(undeclared)
    assert "matplotlib" not in core and "matplotlib" in extras  # only `hilgate report` needs it


def test_declared_minimums_are_what_runs_here():
    meta = project()["project"]
    requirements = [*meta["dependencies"], *(r for reqs in meta["optional-dependencies"].values() for r in reqs)]
    for text in requirements:
        requirement = Requirement(text)
        assert requirement.specifier, f"{text}: pin the minimum version that was tested"
        if requirement.marker is not None and not requirement.marker.evaluate():
            continue  # not for this Python (pyasyncore: only from 3.12)
        version = importlib.metadata.version(requirement.name)
        assert requirement.specifier.contains(version, prereleases=True), f"{text}, but {version} is what runs here"


def test_license_is_an_spdx_expression_without_setuptools_banner():
    data = project()
    assert data["project"]["license"] == "MIT"  # a table is deprecated: setuptools prints a banner
    setuptools = next(Requirement(r) for r in data["build-system"]["requires"] if r.startswith("setuptools"))
    assert not setuptools.specifier.contains("76.9") and setuptools.specifier.contains("77.0.0")


def test_make_targets_run_what_the_readme_says():
    def last_line(target: str, *variables: str) -> str:
        result = subprocess.run(["make", "--no-print-directory", "-n", "-C", str(REPO), target, *variables],
                                capture_output=True, text=True)
        assert result.returncode == 0, result.stderr
        return result.stdout.strip().splitlines()[-1]

    assert last_line("fuzz") == 'HILGATE_FUZZ=1 .venv/bin/python -m pytest -q -k "fuzz or redteam"'
    allowed = shutil.which("unshare") and subprocess.run(["unshare", "--ipc", "true"], capture_output=True).returncode == 0
    isolate = "unshare --ipc " if allowed else ""  # an IPC namespace of its own where allowed (the Makefile's ISOLATE)
    assert last_line("test") == f"{isolate}.venv/bin/python -m pytest -q -m serial --durations=10"  # after the parallel part
    assert last_line("run") == ".venv/bin/hilgate run scenes/demo.yaml"
    assert last_line("run", "ARGS=--tcp 4280 --runtime-dir /tmp/x") == ".venv/bin/hilgate run scenes/demo.yaml --tcp 4280 --runtime-dir /tmp/x"
    assert last_line("sim", "SCENE=lab.yaml", "ARGS=--until 600 --seed 3") == ".venv/bin/hilgate sim lab.yaml --until 600 --seed 3"


STUB = """#!/bin/sh
echo "$(basename "$0") $*" >>"{log}"
case "$(basename "$0") $*" in
    "id -u") echo 0 ;;
    "getent group dialout") echo "dialout:x:20:" ;;
    "getent passwd hilgate") test -e "{accounts}.user" || exit 2 ;;
    "getent group hilgate") test -e "{accounts}.group" || exit 2 ;;
    "useradd "*) touch "{accounts}.user" ;;
    "groupadd "*) touch "{accounts}.group" ;;
    "userdel "*) rm "{accounts}.user" ;;
    "groupdel "*) rm "{accounts}.group" ;;
    "getent "*) exit 2 ;;
    "systemctl is-active "*) exit 3 ;;
esac
exit 0
"""


class TestRootSteps:
    """(A class of its own: `make test` hands test files and classes to its workers whole, and this test
    takes a minute and a half: beside the module's installed venv, not after it.)"""

    def test_root_steps_on_a_real_system(self, tmp_path):
        """Without DESTDIR, as root and under systemd: the account, dialout and systemctl steps, run against
        stub commands (id says root) and paths under tmp_path, so the test needs no root and changes nothing."""
        before = system_state()
        stubs, log = tmp_path / "stubs", tmp_path / "commands.log"
        stubs.mkdir()
        for name in ("id", "getent", "groupadd", "useradd", "usermod", "userdel", "groupdel", "systemctl"):
            (stubs / name).write_text(STUB.format(log=log, accounts=tmp_path / "accounts"))
            (stubs / name).chmod(0o755)
        (tmp_path / "systemd-running").mkdir()
        places = [f"PREFIX={tmp_path}/opt/hilgate", f"SYSCONFDIR={tmp_path}/etc", f"UNITDIR={tmp_path}/units",
                  f"LOGROTATEDIR={tmp_path}/logrotate.d", f"BINDIR={tmp_path}/bin", "PIP_ARGS=--no-deps"]
        env = dict(os.environ, PATH=f"{stubs}:{os.environ['PATH']}", HILGATE_SYSTEMD_RUN_DIR=str(tmp_path / "systemd-running"))

        def run(*args: str) -> str:
            result = subprocess.run(["make", "--no-print-directory", "-C", str(REPO), *args, *places,
                                     f"PYTHON={sys.executable}"], capture_output=True, text=True, env=env)
            assert result.returncode == 0, result.stdout + result.stderr
            return result.stdout

        output = run("install")
        commands = log.read_text().splitlines()
        assert "groupadd --system hilgate" in commands
        assert ("useradd --system --gid hilgate --home-dir /var/lib/hilgate --no-create-home --shell /usr/sbin/nologin "
                "--comment hilgate daemon hilgate") in commands
        assert "usermod -a -G dialout hilgate" in commands
        assert "systemctl daemon-reload" in commands and "systemctl enable --now hilgate" in output
        unit = unit_settings(tmp_path / "units" / "hilgate.service")  # the chosen paths, consistently
        assert unit["ExecStart"][0].startswith(f"{tmp_path}/opt/hilgate/bin/hilgate run ")
        assert unit["EnvironmentFile"] == [f"-{tmp_path}/etc/hilgate/hilgate.env"]
        assert f"HILGATE_SCENE={tmp_path}/etc/hilgate/scene.yaml" in (tmp_path / "etc/hilgate/hilgate.env").read_text()

        log.unlink()
        output = run("uninstall")
        commands = log.read_text().splitlines()
        assert commands.index("systemctl disable --now hilgate") < commands.index("systemctl daemon-reload")
        assert not any(c.startswith(("userdel", "groupdel")) for c in commands)  # kept without PURGE, and said
        assert "kept the hilgate user and group" in output
        assert files_under(tmp_path / "etc") == [] and not (tmp_path / "opt/hilgate").exists()
        assert not (tmp_path / "units/hilgate.service").exists() and not (tmp_path / "bin/hilgate").exists()

        log.unlink()
        run("install")  # the accounts exist now: not created again
        assert not any(c.startswith(("useradd", "groupadd")) for c in log.read_text().splitlines())
        run("uninstall", "PURGE=1")
        commands = log.read_text().splitlines()
        assert "userdel hilgate" in commands and "groupdel hilgate" in commands
        assert system_state() == before
