"""A driver link listed before the emulated link whose modem it opens starts without a word (issue 38).

The daemon opened each link in the scene's order, and a driver opens its port at once (in a thread):
listed first, it looked for a pty the emulated link below it had not made yet, logged a WARNING ("cannot
open …: No such file") and recovered half a second later, in 4 starts out of 6.  Every row of the
driver table here, each way its driver reaches its emulated modem (``tests/bench_kit.py``: a pty, a
loopback TCP port), each driver before its emulated modem, at start and again added by a reload: no
warning, every driver up at its first attempt (one ``link`` line in the trace: ``up``).
"""

from bench_kit import benches
from daemon_kit import SCENE_HEAD, unique

BENCHES = benches()


def pairs(tmp_path, ids, tag, first_address):
    """A driver link before the emulated link whose modem it opens, for each way of each row of the table
    (the two with the same address, as a modem and its driver have)."""
    lines = []
    for address, bench in enumerate(BENCHES, first_address):
        driver, emulated = ids[bench]
        where = bench.place(tmp_path, f"{bench.name}-{bench.reach.way}{tag}")
        lines.append(f"  {driver}: {{vehicle: va, backend: {bench.name}, address: {address}, gli: [socket], "
                     f"{bench.driver_keys(where)}}}\n")
        lines.append(f"  {emulated}: {{vehicle: vb, address: {address}, gli: [socket], emulate: {bench.emulate(where)}}}\n")
    return "".join(lines)


def test_drivers_listed_before_their_emulated_modems_open_them_at_the_first_attempt(tmp_path, daemon_of):
    first = {bench: (unique("d"), unique("e")) for bench in BENCHES}
    added = {bench: (unique("d"), unique("e")) for bench in BENCHES}
    scene = f"{SCENE_HEAD}links:\n" + pairs(tmp_path, first, "1", 1)
    links = [link for pair in first.values() for link in pair]
    daemon = daemon_of(scene, links)
    daemon.wait_up(*(driver for driver, _ in first.values()))
    daemon.reload(scene + pairs(tmp_path, added, "2", 11))
    daemon.wait_up(*(driver for driver, _ in added.values()))
    daemon.stop()
    # (only the start-up's own warning: a loaded host may warn of other things, a command answered late)
    warnings = [line for line in daemon.output().splitlines() if "WARNING" in line and "cannot open" in line]
    assert not warnings, "\n".join(warnings)
    events = daemon.trace_events()
    for driver, _ in [*first.values(), *added.values()]:
        assert [e["state"] for e in events if e["ev"] == "link" and e["link"] == driver][:1] == ["up"]
