"""Rows from installed packages (issue 39 item 1): each table takes the rows of its entry-point group
(``hilgate.drivers``, ``hilgate.doors``, ``hilgate.pose_sources``, ``hilgate.macs``, ``hilgate.propagation``)
at start, and a package that cannot join says which package it is.  The packages are folders on
``PYTHONPATH`` (``plugin_kit``); ``test_plugin_package.py`` installs one with pip into a fresh venv."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from daemon_kit import Daemon, unique
from plugin_kit import LABMODEM, hilgate, installed

LAB_SCENE = """channels: {ac: {speed_mps: 1500}}
vehicles: {a: {pose: {static: [0, 0, 1]}}, b: {pose: {static: [10, 0, 1]}}}
links:
  x: {vehicle: a, address: 1, backend: labmodem, port: PTY}
  y: {vehicle: b, address: 2, emulate: {protocol: labmodem, pty: PTY}}
"""

ROWS = {
    "labrows/__init__.py": "",
    "labrows/door.py": ('import os\n'
                        'from hilgate.core.door_table import DoorRow\n'
                        'ROW = DoorRow("labdoor", "the lab\'s door", "labrows.door:open_door", gli=True)\n'
                        'class LabDoor:\n'
                        '    def __init__(self, path):\n'
                        '        self.path = path\n'
                        '    def open(self, port):\n'
                        '        if "labdoor" not in port.gli:\n'
                        '            return None\n'
                        '        with open(self.path, "a") as out:\n'
                        '            out.write(f"opened {port.id}\\n")\n'
                        '        return port.id\n'
                        '    def update(self, handle, port):\n'
                        '        return handle\n'
                        '    def close(self, handle):\n'
                        '        if handle is None:\n'
                        '            return  # (a link that does not name this door)\n'
                        '        with open(self.path, "a") as out:\n'
                        '            out.write(f"closed {handle}\\n")\n'
                        'def open_door(setting):\n'
                        '    return LabDoor(os.path.join(setting.options.runtime_dir, "labdoor.txt"))\n'),
    "labrows/pose.py": ('from hilgate.scene.pose_table import PoseSourceRow\n'
                        'ROW = PoseSourceRow("labgps", "the lab\'s GPS", "labrows.pose:check", None)\n'
                        'def check(node, path):\n'
                        '    from hilgate.scene.checks import Fields, text\n'
                        '    f = Fields(node, path, ("url",))\n'
                        '    return (("url", f.get("url", text)),)\n'),
    "labrows/mac.py": ('from hilgate.models.mac import NoMac\n'
                       'class LabMac(NoMac):\n'
                       '    """NoMac by another name."""\n'),
    "labrows/propagation.py": ('from hilgate.models.propagation import StraightLine\n'
                               'from hilgate.models.propagations import PropagationModel\n'
                               'ROW = PropagationModel("lab-slow", "sound at half the speed",\n'
                               '                       lambda channel: StraightLine(channel.speed_mps / 2, channel.min_delay_s))\n'),
}
GROUPS = {"hilgate.doors": {"labdoor": "labrows.door:ROW"}, "hilgate.pose_sources": {"labgps": "labrows.pose:ROW"},
          "hilgate.macs": {"labmac": "labrows.mac:LabMac"}, "hilgate.propagation": {"lab-slow": "labrows.propagation:ROW"}}


def test_a_driver_row_of_an_installed_package_is_used_by_a_scene(tmp_path):
    site = installed(tmp_path / "site", "hilgate-labmodem", "0.1.0", {"hilgate.drivers": {"labmodem": "labmodem.row:ROW"}},
                     packages=(LABMODEM / "labmodem",))
    (tmp_path / "lab.yaml").write_text(LAB_SCENE.replace("PTY", str(tmp_path / "pty")))
    check = hilgate(site, "check", "lab.yaml", cwd=tmp_path)
    assert check.returncode == 0 and check.stdout.rstrip().endswith("ok"), check.stdout + check.stderr
    assert "x: labmodem on a" in check.stdout and "emulates labmodem at pty" in check.stdout
    without = hilgate(tmp_path / "empty", "check", "lab.yaml", cwd=tmp_path)
    assert without.returncode != 0 and "lab.yaml:4: links.x.backend" in without.stderr


def test_rows_of_every_group_join_their_tables_and_a_scene_names_them(tmp_path):
    site = installed(tmp_path / "site", "hilgate-labrows", "2.0", GROUPS, ROWS)
    (tmp_path / "rows.yaml").write_text(
        "channels: {ac: {speed_mps: 1500, propagation: lab-slow}}\n"
        "vehicles: {a: {pose: {static: [0, 0, 1]}}, b: {pose: {static: [750, 0, 1]}},\n"
        "           c: {pose: {labgps: {url: 'udp:1'}}, initial: [5, 0, 1]}}\n"
        "links:\n  x: {vehicle: a, address: 1, mac: labmac}\n  y: {vehicle: b, address: 2, mac: labmac}\n"
        "flows: [{from: x, to: y, interval_s: 10, size_bytes: 8}]\n")
    tables = hilgate(site, "check", "rows.yaml", cwd=tmp_path)
    assert tables.returncode == 0 and tables.stdout.rstrip().endswith("ok"), tables.stdout + tables.stderr
    assert "mac labmac" in tables.stdout
    sim = hilgate(site, "sim", "rows.yaml", "--until", "12", "--trace", "t.jsonl", "-q", cwd=tmp_path)
    assert sim.returncode == 0, sim.stderr
    events = [json.loads(line) for line in (tmp_path / "t.jsonl").read_text().splitlines()]
    tx = next(e for e in events if e["ev"] == "tx")
    rx = next(e for e in events if e["ev"] == "rx")
    assert (tx["t"], rx["t"]) == (0.0, 1.064)  # 8 bytes at 1000 bit/s, then 750 m at half of 1500 m/s (not 0.564)
    misspelt = (tmp_path / "rows.yaml").read_text().replace("propagation: lab-slow", "propagation: lab-slw")
    (tmp_path / "misspelt.yaml").write_text(misspelt)
    wrong = hilgate(site, "check", "misspelt.yaml", cwd=tmp_path)
    assert "misspelt.yaml:1: channels.ac.propagation: unknown propagation model 'lab-slw' (did you mean 'lab-slow'?)" \
        in wrong.stderr, wrong.stderr


def test_a_row_that_takes_a_built_in_name_refuses_the_start_naming_its_package(tmp_path):
    site = installed(tmp_path / "site", "labclash", "1.0", {"hilgate.drivers": {"s100": "labmodem.row:ROW"}},
                     packages=(LABMODEM / "labmodem",))
    (tmp_path / "one.yaml").write_text("channels: {ac: {speed_mps: 1500}}\nvehicles: {}\nlinks: {}\n")
    answer = hilgate(site, "check", "one.yaml", cwd=tmp_path)
    assert answer.returncode != 0
    assert ("plug-in 's100' of hilgate.drivers (package labclash 1.0, labmodem.row:ROW): 's100' is a built-in name"
            in answer.stderr), answer.stderr


def test_a_plug_in_that_fails_to_load_refuses_the_start_naming_its_package(tmp_path):
    site = installed(tmp_path / "site", "labbroken", "0.3", {"hilgate.macs": {"broken": "labbroken:LabMac"}},
                     {"labbroken.py": "import a_module_nobody_has\n"})
    (tmp_path / "one.yaml").write_text("channels: {ac: {speed_mps: 1500}}\nvehicles: {}\nlinks: {}\n")
    answer = hilgate(site, "check", "one.yaml", cwd=tmp_path)
    assert answer.returncode != 0
    assert ("plug-in 'broken' of hilgate.macs (package labbroken 0.3, labbroken:LabMac) failed to load: "
            "ModuleNotFoundError: No module named 'a_module_nobody_has'") in answer.stderr, answer.stderr


def test_the_door_and_pose_source_tables_take_the_rows_of_a_package(tmp_path):
    site = installed(tmp_path / "site", "hilgate-labrows", "2.0", GROUPS, ROWS)
    code = ("from hilgate.core.door_table import DOORS; from hilgate.scene.pose_table import POSE_SOURCES; "
            "print(list(DOORS)); print(list(POSE_SOURCES))")
    answer = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(site)),
                            capture_output=True, text=True, timeout=120)
    assert answer.stdout.splitlines() == ["['mq', 'socket', 'emulate', 'unet', 'ros2', 'zenoh', 'labdoor']",
                                          "['mavlink', 'aruco', 'ros2', 'labgps']"], answer.stderr


def test_a_daemon_opens_a_package_door_for_the_links_that_name_it(tmp_path):
    site = installed(tmp_path / "site", "hilgate-labrows", "2.0", GROUPS, ROWS)
    near, far = unique("lab"), unique("other")
    daemon = Daemon(tmp_path, "channels: {ac: {speed_mps: 1500}}\nvehicles: {a: {pose: {static: [0, 0, 1]}}}\n"
                              f"links:\n  {near}: {{vehicle: a, address: 1, gli: [socket, labdoor]}}\n"
                              f"  {far}: {{vehicle: a, address: 2, gli: [socket]}}\n",
                    [near, far], env={"PYTHONPATH": str(site)})
    try:
        daemon.wait_for("READY=1")
        daemon.stop()
        opened = (Path(daemon.runtime) / "labdoor.txt").read_text().splitlines()
    finally:
        daemon.close()
    assert opened == [f"opened {near}", f"closed {near}"]
