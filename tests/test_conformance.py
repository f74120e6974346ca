"""The conformance tables of docs/conformance.md and docs/conformance-micromodem.md are produced from tests (issue 38 item 2): they are the rows of
``tests/conformance_<family>.py`` (``conformance_kit``), and each row is held to the code here, so that
the document cannot drift from what the emulators and drivers do."""

import glob
import os
import re
import time

import pytest
import serial

from conformance_kit import BLOCKS, FAMILIES, HERE, PAGES, documented, page, render, rows
from daemon_kit import unique

REPO = os.path.dirname(HERE)
LIBRARIES = {"WlModem": ("wlmodem", "WlModem"), "WlUDPSocket": ("wlmodem", "WlUDPSocket"),
             "Micromodem": ("acomms.micromodem", "Micromodem")}
DRIVER_SOURCES = {"evologics": ("evologics.py", "evologics_codec.py"), "s100": ("s100.py", "s100_codec.py"),
                  "m64": ("m64.py", "m64_codec.py"), "micromodem": ("micromodem.py", "micromodem_codec.py")}
NOT_DONE = re.compile(r"\bnot\b|\bnever\b|\bnone\b|no .* model", re.I)


def test_the_docs_hold_the_tables_the_rows_make():
    for family in BLOCKS:
        text = open(page(family), encoding="utf-8").read()
        assert documented(text, family) == render(family), (
            f"docs/{PAGES[family]}'s {family} table is not its rows': run `python tests/conformance_kit.py`")


def emulator_table(family: str) -> set[str]:
    """The entries of the family's emulator's command table (what a row must cover)."""
    if family == "evologics":
        from hilgate.drivers.evologics_emulator import EvologicsEmulator
        from hilgate.drivers.evologics_settings import RANGES
        return set(EvologicsEmulator.COMMANDS) | {f"{p}{name}" for name in RANGES for p in "!?"}
    if family == "m64":
        from hilgate.drivers.m64_emulator import M64Emulator
        return set(M64Emulator.COMMANDS)
    if family == "micromodem":
        from hilgate.drivers.micromodem_emulator import MicromodemEmulator
        return set(MicromodemEmulator.COMMANDS)
    return set()  # the S100 takes no commands


@pytest.mark.parametrize("family", FAMILIES)
def test_every_entry_of_the_emulators_command_table_has_its_row(family):
    table = emulator_table(family)
    covered = {key for row in rows(family) for key in row.keys}
    assert table - covered == set(), f"{family}: commands without a row in tests/conformance_{family}.py"
    stale = covered - table - ({f"@{name}" for name in covered if name[:1] in "!?"} if family == "evologics" else set())
    assert {key for key in stale if not (family == "evologics" and key[:1] == "@")} == set(), f"{family}: rows name {stale}"


@pytest.mark.parametrize("family", FAMILIES)
def test_a_row_the_emulator_is_not_probed_for_names_its_test_or_says_what_it_does_instead(family):
    for row in rows(family):
        if row.probe is not None:
            assert row.answer is not None, row.item
            continue
        if row.tested is not None:
            path, text = row.tested
            with open(os.path.join(HERE, path), encoding="utf-8") as f:
                assert text in f.read(), f"{family} {row.item}: {path} has no {text!r}"
        else:
            assert NOT_DONE.search(row.emulator), f"{family} {row.item}: no probe, no test, and nothing said it is not done"


def _test_sources() -> str:
    own = {os.path.basename(p) for p in glob.glob(os.path.join(HERE, "conformance_*.py"))}
    return "".join(open(p, encoding="utf-8").read() for p in glob.glob(os.path.join(HERE, "**", "*.py"), recursive=True)
                   if os.path.basename(p) not in own)


@pytest.mark.parametrize("family", FAMILIES)
def test_a_rows_driver_use_is_in_the_drivers_source_and_its_library_calls_exist_and_are_called(family):
    source = "".join(open(os.path.join(REPO, "drivers", name), encoding="utf-8").read()
                     for name in DRIVER_SOURCES[family])
    tests = _test_sources()
    for row in rows(family):
        if row.driver_code is not None:
            assert row.driver_code in source, f"{family} {row.item}: the driver has no {row.driver_code!r}"
        for call in row.library:
            owner, method = call.split(".")
            module, name = LIBRARIES[owner]
            library = pytest.importorskip(module)
            assert callable(getattr(getattr(library, name), method, None)), f"{call} is no call of {module}"
            assert f".{method}(" in tests, f"{family} {row.item}: no test calls {call}"


# -- the probes, against emulated modems ---------------------------------------------------------------------

EOL = {"evologics": b"", "m64": b"", "micromodem": b""}  # (the probes carry their own line ends)
ASYNC = {"evologics": re.compile(rb"(DELIVERED|FAILED)[^\r]*\r\n")}  # reports of earlier probes, not answers


def scene(tmp_path, ids) -> str:
    def link(name, vehicle, address, protocol, extra=""):
        return (f"  {ids[name]}: {{vehicle: {vehicle}, channel: {protocol}, address: {address}, gli: [socket], "
                f"emulate: {{protocol: {protocol}, pty: {tmp_path / name}{extra}}}}}\n")
    return ("channels: {evologics: {speed_mps: 1500}, m64: {speed_mps: 1500}, micromodem: {speed_mps: 1500}}\n"
            "vehicles:\n  va: {pose: {static: [0, 0, 0]}}\n  vb: {pose: {static: [10, 0, 0]}}\nlinks:\n"
            + link("evologics", "va", 1, "evologics") + link("evologics_far", "vb", 2, "evologics")
            + link("m64", "va", 1, "m64", ", role: a, channel: 1")
            + link("micromodem", "va", 1, "micromodem") + link("micromodem_far", "vb", 2, "micromodem"))


def ask(port, family: str, probe: bytes, answer: bytes, timeout: float = 30.0) -> bytes:
    """Send ``probe``; the bytes that came until ``answer`` was found in them (with the family's asynchronous
    reports of earlier probes taken out)."""
    port.reset_input_buffer()
    port.write(probe)
    got = b""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got += port.read(4096)
        seen = ASYNC[family].sub(b"", got) if family in ASYNC else got
        if re.search(answer, seen, re.S):
            return seen
    raise AssertionError(f"{family}: {probe!r} got {got!r}, not {answer!r}")


def test_every_probe_gets_the_answer_its_row_says(tmp_path, daemon_of):
    names = ("evologics", "evologics_far", "m64", "micromodem", "micromodem_far")
    ids = {name: unique("c") for name in names}
    daemon_of(scene(tmp_path, ids), list(ids.values()), "--speed", "8")
    for family in ("evologics", "m64", "micromodem"):
        with serial.Serial(str(tmp_path / family), 115200, timeout=0.05) as port:
            for row in rows(family):
                if row.probe is not None:
                    ask(port, family, row.probe, row.answer)
