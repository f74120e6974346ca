"""One behavioural suite over every row of the driver table (issue 38 item 4), as python-can runs one
back-to-back suite over every interface: a new row of ``drivers/table.py`` gets it by being a row.

Each row's driver opens its own emulated modem (the whole HIL chain on one machine) the way the row
declares (its ``reach``: on a pty, on a loopback TCP port; a row with several ways runs the suite on
each); everything the suite needs is read from the row (``tests/bench_kit.py``): how its driver reaches
its modem, its other required options (a choice: the first for the near modem, the last for the far one,
so an M64 pair is role a and b; a number: its minimum), its emulated modem's options (the same rule), its
limits (a simulated link states them with ``limits: {modem: NAME}``).  Per row and way:

- **send and receive, in any start order**: driver → emulated modem → channel → emulated modem → driver,
  both ways, with the drivers listed before their emulated modems and after them: no "cannot open"
  warning, every driver up at its first attempt, nothing dropped;
- **size limits refused with the same text** by the driver and by a simulated link with the row's limits
  (a row that states no size, the S100, refuses nothing on either);
- **replug with garbage on the line**: the driver's port is a cable the test relays to the emulated modem
  (``tests/cable_kit.py``: a pty, or a TCP port whose connection drops and is refused while unplugged);
  unplugged, the link goes down, a frame sent meanwhile waits; plugged back with garbage first on the
  line, the driver configures its modem again, comes up, and the frame goes, then one the other way;
- **swap sim ↔ driver by reload**: the application's link is simulated, then the row's driver (the far link
  an emulated modem whose applications get what it received), then simulated again, the application
  connected all along: every frame arrives, and the link's counters run on over the three backends.

Times are the model's (``--speed`` 8); waits are hang guards.
"""

import pytest

from bench_kit import bench_params
from daemon_kit import Daemon, unique, wait_until
from hilgate.client import GliError, Link

SPEED = 8
BENCHES = bench_params()
HEAD = ("channels: {ac: {speed_mps: 1500}}\n"
        "vehicles:\n  va: {pose: {static: [0, 0, 0]}}\n  vb: {pose: {static: [100, 0, 0]}}\nlinks:\n")


def driver_link(link, bench, where, address, vehicle, far=False) -> str:
    return (f"  {link}: {{vehicle: {vehicle}, backend: {bench.name}, address: {address}, packet: raw, "
            f"gli: [socket], {bench.driver_keys(where, far)}}}\n")


def emulated_link(link, bench, where, address, vehicle, far=False) -> str:
    return (f"  {link}: {{vehicle: {vehicle}, address: {address}, packet: raw, gli: [socket], "
            f"emulate: {bench.emulate(where, far)}}}\n")


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
@pytest.mark.parametrize("bench", BENCHES)
def test_a_row_sends_and_receives_both_ways_whatever_the_start_order(tmp_path, daemon_of, bench, order):
    da, db, ea, eb, sim = (unique(p) for p in ("da", "db", "ea", "eb", "s"))
    pa, pb = bench.place(tmp_path, "a"), bench.place(tmp_path, "b")
    drivers = driver_link(da, bench, pa, 1, "va") + driver_link(db, bench, pb, 2, "vb", far=True)
    emulated = emulated_link(ea, bench, pa, 1, "va") + emulated_link(eb, bench, pb, 2, "vb", far=True)
    links = (drivers + emulated) if order == "drivers first" else (emulated + drivers)
    daemon = daemon_of(HEAD + links + simulated_link(sim, bench.name, 9, "va"), [da, db, ea, eb, sim],
                       "--speed", str(SPEED))
    daemon.wait_up(da, db)
    limits = bench.driver.limits
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
    # (a driver that has not heard its modem's report of the last frame yet holds it: stopped then, it drops it)
    wait_until(lambda: all(daemon.link_status(link)["ready"] for link in (da, db)), "the drivers done with their frames")
    daemon.stop()
    assert not [line for line in daemon.output().splitlines() if " WARNING " in line and "cannot open" in line]
    assert first_states(daemon, da, db) == {da: ["up"], db: ["up"]}
    losses = [e for e in daemon.trace_events() if e["ev"] in ("drop", "err") and e.get("link") in (da, db)]
    assert [e["cause"] for e in losses] == (["size"] if most is not None else [])


GARBAGE = b"\x00\xff\xfe garbage \x1b[0m\r\n+++\r\n$CA\r\nwr\nAT\r\n\xa5\x5a\x00"


@pytest.mark.parametrize("bench", BENCHES)
def test_a_row_comes_back_after_a_replug_with_garbage_on_the_line(tmp_path, bench):
    da, db, ea, eb = (unique(p) for p in ("da", "db", "ea", "eb"))
    pa, pb = bench.place(tmp_path, "a"), bench.place(tmp_path, "b")
    emulated = HEAD + emulated_link(ea, bench, pa, 1, "va") + emulated_link(eb, bench, pb, 2, "vb", far=True)
    daemon = Daemon(tmp_path, emulated, [da, db, ea, eb], "--speed", str(SPEED))
    relay = None
    try:
        daemon.wait_for("READY=1")
        relay = bench.cable(tmp_path, pa)  # the cable to the emulated modem, then its driver (a reload)
        daemon.reload(emulated + driver_link(da, bench, relay.where, 1, "va")
                      + driver_link(db, bench, pb, 2, "vb", far=True))
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
            relay.plug(GARBAGE)  # what the line carries as the adapter comes back (a host's first bytes on TCP)
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


@pytest.mark.parametrize("bench", BENCHES)
def test_a_row_swaps_with_a_simulated_link_by_reload_and_keeps_its_counters(tmp_path, daemon_of, bench):
    app, far, ea = unique("ap"), unique("far"), unique("ea")
    pe, pf = bench.place(tmp_path, "e"), bench.place(tmp_path, "f")
    name = bench.name

    def scene(real: bool) -> str:
        if not real:
            return HEAD + simulated_link(app, name, 1, "va") + simulated_link(far, name, 2, "vb")
        return HEAD + (driver_link(app, bench, pe, 1, "va") + emulated_link(ea, bench, pe, 1, "va")
                       + emulated_link(far, bench, pf, 2, "vb", far=True))

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
