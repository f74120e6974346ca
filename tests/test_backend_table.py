"""The backend table (hilgate.drivers.table) drives the scene loader and opens backends: a modem type
added as one row is a valid backend with its own checked options, "only for backend X", "did you
mean", a required port and an emulator, without a line changed anywhere else."""

import dataclasses
import os
import subprocess
import sys
import textwrap

import pytest

from hilgate.drivers import table
from hilgate.drivers.table import DRIVERS, Driver, Option, from_link, option
from hilgate.scene import BACKENDS, LINK_KEYS, SceneError, load_scene_text

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@dataclasses.dataclass(frozen=True)
class FakeOptions:
    port: str = option(Option("port", hint="a device such as /dev/ttyFAKE0"))
    depth_m: float = option(Option("number", 0, 100), 10.0)
    mode: str = option(Option("choice", choices=("loud", "quiet")), "quiet")
    queue_frames: int = option(Option("integer", 0, 100_000), 50)  # a key the real drivers have too
    air_bitrate_bps: float = from_link("bitrate_bps", 1.0)


class FakeBackend:
    def __init__(self, link_id, address, packet, options, scheduler, trace):
        self.args = (link_id, address, packet, options, scheduler, trace)


class FakeEmulator:
    pass


@pytest.fixture
def fake(monkeypatch):
    """One row for a 'fake' modem: the only change that a new modem type needs."""
    driver = Driver("fake", "fake modem", FakeOptions, f"{__name__}:FakeBackend", f"{__name__}:FakeEmulator")
    monkeypatch.setitem(DRIVERS, "fake", driver)
    return driver


def scene(link: str) -> str:
    return textwrap.dedent(f"""\
        channels: {{ac: {{speed_mps: 1500}}}}
        vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
        links:
          a: {{vehicle: v}}
          x: {{vehicle: v, {link}}}
        """)


def error_of(link: str) -> str:
    with pytest.raises(SceneError) as info:
        load_scene_text(scene(link), "/tmp/scene.yaml")
    return str(info.value)


def test_a_new_row_is_a_valid_backend_with_its_own_checked_options(fake):
    spec = load_scene_text(scene("backend: fake, port: /dev/ttyFAKE0, depth_m: 42, mode: loud"), "/tmp/scene.yaml")
    link = spec.links["x"]
    assert link.backend == "fake"
    assert link.options == (("port", "/dev/ttyFAKE0"), ("depth_m", 42.0), ("mode", "loud"))
    assert error_of("backend: fake, port: /dev/ttyFAKE0, depth_m: 500") == \
        "/tmp/scene.yaml:5: links.x.depth_m: must be at most 100, not 500"
    assert error_of("backend: fake, port: /dev/ttyFAKE0, mode: shout") == \
        "/tmp/scene.yaml:5: links.x.mode: must be one of loud, quiet, not the text 'shout'"
    assert error_of("backend: fake, depth_m: 1") == \
        "/tmp/scene.yaml:5: links.x: backend fake needs 'port' (a device such as /dev/ttyFAKE0)"
    assert error_of("backend: fake, port: 'bogus://x'").startswith(
        "/tmp/scene.yaml:5: links.x.port: unknown URL scheme 'bogus://'")


def test_a_new_row_takes_part_in_only_for_and_did_you_mean(fake):
    assert error_of("depth_m: 3") == "/tmp/scene.yaml:5: links.x.depth_m: only for backend fake (this link is sim)"
    assert error_of("backend: evologics, port: /dev/ttyUSB0, mode: loud") == \
        "/tmp/scene.yaml:5: links.x.mode: only for backend fake (this link is evologics)"
    assert error_of("backend: s100, port: /dev/ttyUSB0, queue_frames: 3, depth_m: 1") == \
        "/tmp/scene.yaml:5: links.x.depth_m: only for backend fake (this link is s100)"
    assert error_of("queue_frames: 3") == \
        "/tmp/scene.yaml:5: links.x.queue_frames: only for backend evologics or s100 or m64 or micromodem or unet or fake (this link is sim)"
    assert error_of("backend: fake, port: /dev/ttyFAKE0, dept_m: 1") == \
        "/tmp/scene.yaml:5: links.x.dept_m: unknown key (did you mean 'depth_m'?)"
    assert error_of("backend: fakes").endswith("links.x.backend: must be one of sim, evologics, s100, m64, micromodem, unet, fake, "
                                               "not the text 'fakes'")


def test_a_new_row_can_be_emulated_and_says_it_is_serial(fake, tmp_path):
    spec = load_scene_text(scene("emulate: {protocol: fake, pty: tty0}"), str(tmp_path / "scene.yaml"))
    assert spec.links["x"].emulate == (("protocol", "fake"), ("pty", str(tmp_path / "tty0")))
    assert error_of("emulate: {protocol: fake, tcp: 9200}") == \
        "/tmp/scene.yaml:5: links.x.emulate.tcp: only the EvoLogics modem or the UnetStack modem speaks TCP; the fake modem is serial"
    assert table.emulator_for("fake") is FakeEmulator


def test_a_row_says_how_its_driver_reaches_its_emulated_device_and_the_scene_follows(fake, monkeypatch):
    """One declaration, ``reach``: where the emulated device can be (the scene's ``emulate:`` keys) and the
    driver's options that name it there (what a bench of the row, tests/bench_kit.py, is built from)."""
    tcp = table.Reach("tcp", (("port", "socket://127.0.0.1:{where}"),))
    monkeypatch.setitem(DRIVERS, "fake", dataclasses.replace(fake, reach=(tcp,)))
    spec = load_scene_text(scene("emulate: {protocol: fake, tcp: 9300}"), "/tmp/scene.yaml")
    assert spec.links["x"].emulate == (("protocol", "fake"), ("tcp", 9300))
    assert error_of("emulate: {protocol: fake, pty: tty0}") == \
        "/tmp/scene.yaml:5: links.x.emulate.pty: the fake modem speaks TCP only: give tcp (a loopback port)"
    assert tcp.driver_options(9300) == {"port": "socket://127.0.0.1:9300"}
    with pytest.raises(ValueError, match="reach way 'usb'"):
        table.Reach("usb", (("port", "{where}"),))


def test_every_rows_reach_names_options_of_its_own_driver():
    for name, driver in DRIVERS.items():
        keys = {key for key, _, _ in table.scene_options(driver)}
        for reach in driver.reach:
            assert set(dict(reach.options)) <= keys, (name, reach)
    assert [(r.way, r.driver_options(1100)) for r in DRIVERS["unet"].reach] == \
        [("tcp", {"modem_host": "127.0.0.1", "port": "1100"})]
    assert [r.way for r in DRIVERS["evologics"].reach] == ["pty", "tcp"]


def test_open_backend_builds_the_rows_options_with_those_from_the_link(fake):
    spec = load_scene_text(scene("backend: fake, port: /dev/ttyFAKE0, address: 7, bitrate_bps: 900"),
                           "/tmp/scene.yaml").links["x"]
    trace = [].append
    backend = table.open_backend(spec, "the scheduler", trace)
    link_id, address, packet, options, scheduler, given_trace = backend.args
    assert (link_id, address, packet.name, scheduler, given_trace) == ("x", 7, "vl2b", "the scheduler", trace)
    assert options == FakeOptions(port="/dev/ttyFAKE0", air_bitrate_bps=900.0)


def test_the_s100_paces_at_the_links_bitrate(monkeypatch):
    """As the router did: the S100's air bitrate is the link's bitrate_bps, not a key of its own."""
    monkeypatch.setitem(DRIVERS, "s100", dataclasses.replace(DRIVERS["s100"], backend=f"{__name__}:FakeBackend"))
    spec = load_scene_text(scene("backend: s100, port: /dev/ttyUSB0, bitrate_bps: 2400, rtscts: true"),
                           "/tmp/scene.yaml").links["x"]
    options = table.open_backend(spec, None, None).args[3]
    # and the S100's limits (45-byte pieces without flow control), the driver's own without a preset
    assert options == table.S100Options(port="/dev/ttyUSB0", rtscts=True, air_bitrate_bps=2400.0,
                                        limits=table.S100_LIMITS)


def test_the_built_in_rows_keep_todays_names_keys_and_classes():
    from hilgate.drivers.evologics_emulator import EvologicsEmulator
    from hilgate.drivers.s100_emulator import S100Emulator
    from hilgate.drivers.evologics import EvologicsBackend, EvologicsOptions
    from hilgate.drivers.s100 import S100Backend, S100Options
    from hilgate.core.tables import resolve

    assert BACKENDS == ("sim", "evologics", "s100", "m64", "micromodem", "unet")
    assert LINK_KEYS[-26:] == ("port", "baud", "im", "ack", "source_level", "gain", "extended", "im_retries",
                               "command_timeout_s", "delivery_timeout_s", "queue_frames", "eol", "rtscts",
                               "role", "modem_channel", "queued_packets", "poll_s", "diagnostic_s",  # m64
                               "rate", "cycle_timeout_s", "ack_timeout_s",  # micromodem
                               "modem_host", "unet_protocol", "send_timeout_s",  # unet
                               "emulate", "addressing")
    assert EvologicsOptions is table.EvologicsOptions and S100Options is table.S100Options
    assert resolve(DRIVERS["evologics"].backend) is EvologicsBackend
    assert resolve(DRIVERS["s100"].backend) is S100Backend
    assert {name: table.emulator_for(name) for name in ("evologics", "s100")} == {"evologics": EvologicsEmulator,
                                                                                 "s100": S100Emulator}
    assert table.emulated_protocols() == ("evologics", "s100", "m64", "micromodem", "unet")
    assert S100Options("/dev/x") == S100Options(port="/dev/x", baud=9600, rtscts=False, air_bitrate_bps=1800.0,
                                                queue_frames=50)
    assert EvologicsOptions("socket://h:1").eol_bytes() == b"\n"


def test_checking_a_scene_imports_no_driver():
    """The table names drivers; reading a scene (in hilgate check, or the reload worker) imports none."""
    code = ("import sys; from hilgate.scene import load_scene_text; "
            f"load_scene_text({scene('emulate: {protocol: evologics, tcp: 9200}')!r}); "
            "print(sorted(m for m in sys.modules if m.startswith(('serial', 'hilgate.drivers'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True).stdout
    assert out.strip() == "['hilgate.drivers', 'hilgate.drivers.table']"
