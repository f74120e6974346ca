"""One behavioural suite over every row of the driver table (issue 38 item 4), as python-can runs one
back-to-back suite over every interface: a new row of ``drivers/table.py`` gets it by being a row.

Each row's driver opens its own emulated modem on a pty (the whole HIL chain on one machine); everything
the suite needs is read from the row: its required options (a choice: the first for the near modem, the
last for the far one, so an M64 pair is role a and b; a number: its minimum), its emulated modem's
options (the same rule), its limits (a simulated link states them with ``limits: {modem: NAME}``).  Per
row:

- **send and receive, in any start order**: driver → emulated modem → channel → emulated modem → driver,
  both ways, with the drivers listed before their emulated modems and after them: no "cannot open"
  warning, every driver up at its first attempt, nothing dropped;
- **size limits refused with the same text** by the driver and by a simulated link with the row's limits
  (a row that states no size, the S100, refuses nothing on either);
- **replug with garbage on the line**: the driver's port is a pty the test relays to the emulated modem;
  unplugged, the link goes down, a frame sent meanwhile waits; plugged back with garbage first on the line,
  the driver configures its modem again, comes up, and the frame goes, then one the other way;
- **swap sim ↔ driver by reload**: the application's link is simulated, then the row's driver (the far link
  an emulated modem whose applications get what it received), then simulated again, the application
  connected all along: every frame arrives, and the link's counters run on over the three backends.

Times are the model's (``--speed`` 8); waits are hang guards.
"""

import os
import select
import threading
import tty

import pytest

from daemon_kit import Daemon, PluggablePty, in_background, unique, wait_until
from hilgate.client import GliError, Link
from hilgate.drivers.table import DRIVERS, emulator_options, scene_options

SPEED = 8
ROWS = sorted(DRIVERS)
HEAD = ("channels: {ac: {speed_mps: 1500}}\n"
        "vehicles:\n  va: {pose: {static: [0, 0, 0]}}\n  vb: {pose: {static: [100, 0, 0]}}\nlinks:\n")


def _value(check, default, far: bool):
    if check.kind == "choice":
        return check.choices[-1 if far else 0]
    if check.kind in ("integer", "number") and check.minimum is not None:
        return check.minimum if default is None else default
    return default


def driver_options(name: str, far: bool = False) -> str:
    """The row's required scene options (``port`` aside), as the near or the far modem of a pair."""
    return "".join(f", {key}: {_value(check, None, far)}" for key, check, required in scene_options(DRIVERS[name])
                   if required and key != "port")


def emulate_options(name: str, far: bool = False) -> str:
    """The row's ``emulate:`` options that choose (an M64's role): the far modem takes the last choice."""
    return "".join(f", {key}: {_value(check, default, far)}" for key, check, default in emulator_options(DRIVERS[name])
                   if check.kind == "choice" and far)


def driver_link(link, name, port, address, vehicle, far=False) -> str:
    return (f"  {link}: {{vehicle: {vehicle}, backend: {name}, port: {port}, address: {address}, packet: raw, "
            f"gli: [socket]{driver_options(name, far)}}}\n")


def emulated_link(link, name, pty, address, vehicle, far=False) -> str:
    return (f"  {link}: {{vehicle: {vehicle}, address: {address}, packet: raw, gli: [socket], "
            f"emulate: {{protocol: {name}, pty: {pty}{emulate_options(name, far)}}}}}\n")


def simulated_link(link, name, address, vehicle) -> str:
    return f"  {link}: {{vehicle: {vehicle}, address: {address}, packet: raw, gli: [socket], limits: {{modem: {name}}}}}\n"


def refusal(link, payload: bytes, dst: int) -> str | None:
    """The error the daemon answers a frame with (None: taken)."""
    link.send(payload, dst=dst)
    try:
        link.command({"class": "STATUS"})  # answered in order: an ERROR for the frame comes first
    except GliError as exc:
        return str(exc)
    return None


def crossed(sender, receiver, payload: bytes, dst: int) -> bytes | None:
    sender.send(payload, dst=dst)
    message = receiver.recv(timeout=120)
    return None if message is None else message.data


def first_states(daemon, *links) -> dict:
    events = daemon.trace_events()
    return {link: [e["state"] for e in events if e["ev"] == "link" and e["link"] == link][:1] for link in links}


@pytest.mark.parametrize("order", ["drivers first", "emulated first"])
@pytest.mark.parametrize("name", ROWS)
def test_a_row_sends_and_receives_both_ways_whatever_the_start_order(tmp_path, daemon_of, name, order):
    da, db, ea, eb, sim = (unique(p) for p in ("da", "db", "ea", "eb", "s"))
    pa, pb = tmp_path / "a", tmp_path / "b"
    drivers = driver_link(da, name, pa, 1, "va") + driver_link(db, name, pb, 2, "vb", far=True)
    emulated = emulated_link(ea, name, pa, 1, "va") + emulated_link(eb, name, pb, 2, "vb", far=True)
    links = (drivers + emulated) if order == "drivers first" else (emulated + drivers)
    daemon = daemon_of(HEAD + links + simulated_link(sim, name, 9, "va"), [da, db, ea, eb, sim], "--speed", str(SPEED))
    daemon.wait_up(da, db)
    limits = DRIVERS[name].limits
    with Link.open(da, runtime_dir=daemon.runtime) as la, Link.open(db, runtime_dir=daemon.runtime) as lb, \
            Link.open(sim, runtime_dir=daemon.runtime) as ls:
        payload = b"the suite: \r\n\x00,*+++AT from a"
        assert crossed(la, lb, payload, dst=2) == payload
        assert crossed(lb, la, payload[::-1], dst=1) == payload[::-1]
        most = limits.most(limits.send_as) if limits.send_as else None
        if most is not None:  # one byte more than the modem takes: the same words from the driver and the model
            too_large = b"x" * (most + 1)
            words = refusal(la, too_large, dst=2)
            assert words is not None and words == refusal(ls, too_large, dst=2)
            assert f"at most {most}" in words
        else:
            assert limits.refusal(10_000) is None  # (nothing stated: nothing refused, driver or model)
    daemon.stop()
    assert not [line for line in daemon.output().splitlines() if " WARNING " in line and "cannot open" in line]
    assert first_states(daemon, da, db) == {da: ["up"], db: ["up"]}
    losses = [e for e in daemon.trace_events() if e["ev"] in ("drop", "err") and e.get("link") in (da, db)]
    assert [e["cause"] for e in losses] == (["size"] if most is not None else [])


class Relay(PluggablePty):
    """The driver's port: a pty the test unplugs and plugs back, relaying bytes to and from the emulated
    modem's pty as a cable would (nothing passes while unplugged)."""

    def __init__(self, path: str, modem: str):
        self.modem = os.open(modem, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.modem)
        super().__init__(path)
        self.from_modem, self.reader = in_background(self._relay)

    def answer(self, data: bytes) -> bytes:
        os.write(self.modem, data)
        return b""

    def _relay(self, stop: threading.Event) -> None:
        while not stop.is_set():
            ready, _, _ = select.select([self.modem], [], [], 0.02)
            if ready:
                self.write(os.read(self.modem, 4096))  # (dropped while unplugged)

    def close(self) -> None:
        self.from_modem.set()
        self.reader.join()
        super().close()
        os.close(self.modem)


GARBAGE = b"\x00\xff\xfe garbage \x1b[0m\r\n+++\r\n$CA\r\nwr\nAT\r\n\xa5\x5a\x00"


@pytest.mark.parametrize("name", ROWS)
def test_a_row_comes_back_after_a_replug_with_garbage_on_the_line(tmp_path, name):
    da, db, ea, eb = (unique(p) for p in ("da", "db", "ea", "eb"))
    port, pa, pb = tmp_path / "port", tmp_path / "a", tmp_path / "b"
    emulated = HEAD + emulated_link(ea, name, pa, 1, "va") + emulated_link(eb, name, pb, 2, "vb", far=True)
    daemon = Daemon(tmp_path, emulated, [da, db, ea, eb], "--speed", str(SPEED))
    relay = None
    try:
        daemon.wait_for("READY=1")
        relay = Relay(str(port), str(pa))  # the cable to the emulated modem, then its driver (a reload)
        daemon.reload(emulated + driver_link(da, name, port, 1, "va") + driver_link(db, name, pb, 2, "vb", far=True))
        daemon.wait_up(da, db)

        def state():
            return daemon.link_status(da)["state"]

        with Link.open(da, runtime_dir=daemon.runtime) as la, Link.open(db, runtime_dir=daemon.runtime) as lb:
            assert crossed(la, lb, b"before", dst=2) == b"before"
            # (the modem done with it: a frame still in its hands when the cable goes is sent again whole)
            wait_until(lambda: daemon.link_status(da)["ready"], "the modem done with the frame")
            relay.unplug()
            wait_until(lambda: state() == "down", "the link down")
            la.send(b"sent while unplugged", dst=2)
            relay.plug()
            relay.write(GARBAGE)  # what the line carries as the adapter comes back
            wait_until(lambda: state() == "up", "the link up again")
            message = lb.recv(timeout=120)
            assert message is not None and message.data == b"sent while unplugged"
            assert crossed(lb, la, b"and back", dst=1) == b"and back"
        assert daemon.process.poll() is None
        daemon.stop()
        states = [e["state"] for e in daemon.trace_events() if e["ev"] == "link" and e["link"] == da]
        assert states[0] != "down" and states.count("down") == 1 and states[-1] == "up", states
    finally:
        daemon.close()
        if relay is not None:
            relay.close()


@pytest.mark.parametrize("name", ROWS)
def test_a_row_swaps_with_a_simulated_link_by_reload_and_keeps_its_counters(tmp_path, daemon_of, name):
    app, far, ea = unique("ap"), unique("far"), unique("ea")
    pe, pf = tmp_path / "e", tmp_path / "f"

    def scene(real: bool) -> str:
        if not real:
            return HEAD + simulated_link(app, name, 1, "va") + simulated_link(far, name, 2, "vb")
        return HEAD + (driver_link(app, name, pe, 1, "va") + emulated_link(ea, name, pe, 1, "va")
                       + emulated_link(far, name, pf, 2, "vb", far=True))

    daemon = daemon_of(scene(False), [app, far, ea], "--speed", str(SPEED))
    with Link.open(app, runtime_dir=daemon.runtime) as la, Link.open(far, runtime_dir=daemon.runtime) as lf:
        assert crossed(la, lf, b"simulated", dst=2) == b"simulated"
        daemon.reload(scene(True))
        daemon.wait_up(app)
        assert crossed(la, lf, b"through the row's driver", dst=2) == b"through the row's driver"
        daemon.reload(scene(False))
        # what the removed emulated modems had on the air finishes as the physics says: wait (model time)
        reloads = wait_until(lambda: (lambda r: r if len(r) >= 2 else None)(
            [e["t"] for e in daemon.trace_so_far() if e["ev"] == "reload"]), "the second reload in the trace")
        wait_until(lambda: any(e["t"] > reloads[-1] + 5 for e in daemon.trace_so_far()), "the model's clock")
        assert crossed(la, lf, b"simulated again", dst=2) == b"simulated again"
        status = daemon.link_status(app)
        assert (status["tx_packets"], status["drops"], status["backend"]) == (3, 0, "sim")
    daemon.stop()
    backends = [e["changes"][app]["backend"] for e in daemon.trace_events() if e["ev"] == "reload"]
    assert backends == [["sim", name], [name, "sim"]]
