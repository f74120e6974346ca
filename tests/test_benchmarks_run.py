"""The benchmarks of `make bench` that run in seconds on a small case still run: a benchmark is code
that calls the product from outside the tests, and one that broke (bellhop_lookup.py asked for a
channel attribute the propagation seam had renamed) was only found by a whole `make bench`.  The
figures of these runs mean nothing and nothing here reads them; only that each ran to the end and
printed its summary line.

The benchmarks that start daemons (and pin processes to CPUs) run too, each on the smallest case its
arguments allow, alone (conftest.SERIAL): only that each exits 0 and prints every one of its figure
lines, never what the figures say.  Their link ids carry their process id, their queues are unlinked
when their daemons stop, and their ports are free ones below the kernel's ephemeral range
(tests/ports.py)."""

import os
import re
import shutil
import subprocess
import sys
import tempfile

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

SMALL = {
    "ring_scale": (["benchmarks/ring_scale.py", "--nodes", "5", "10", "--sim-time", "20", "--repeats", "1"],
                   "wall per offered frame against N = 5"),
    "dense_ring": (["benchmarks/ring_scale.py", "--geometry", "sink", "--nodes", "40", "--sim-time", "20",
                    "--repeats", "1"], "peak MB"),
    "ring_aloha": (["benchmarks/ring_aloha.py", "--nodes", "5", "--sim-time", "60", "--repeats", "1"],
                   "N = 5: hilgate PDR"),
    "pass_cost": (["benchmarks/pass_cost.py", "200"], "200 passes: p10"),
    "pass_instructions": (["benchmarks/pass_instructions.py", "50"], "instructions per pass"),
    "bellhop_lookup": (["benchmarks/bellhop_lookup.py", "--quick"], "BELLHOP / Thorp: ratio"),
    "aruco": (["benchmarks/aruco.py", "--frames", "5", "--repeats", "1"], "error at 1-2 m: median"),
}

# name → (argv, lines that must be printed: each a regular expression a line must match from its start)
WITH_DAEMONS = {
    "gli_roundtrip": (["benchmarks/gli_roundtrip.py", "--round-trips", "200", "--frames", "200", "--repeats", "1",
                       "--placement", "same"],
                      [r"repeat 1, +same CPU: bare POSIX-queue ping-pong .* bare Python relay .* through hilgate "
                       r"\(4 hops\) p50 ",
                       r" +same CPU: bare p50 .* added by hilgate p50 .* hilgate beyond the relay p50 ",
                       *(rf"throughput through one link, 20-byte payloads, +{offered}: .* frames/s received, \d+ lost"
                         for offered in ("5,000/s offered", "10,000/s offered", "20,000/s offered", "flat out"))]),
    "multihost": (["benchmarks/multihost.py", "--round-trips", "150", "--frames", "200", "--repeats", "1",
                   "--placement", "same", "--on-time", "5"],
                  [r"repeat 1, +same CPU: bare Zenoh p50 .* hilgate, TLS p50 .* hilgate, insecure p50 ",
                   r" +same CPU: bare Zenoh .* ratio TLS/bare ",
                   *(rf" +same CPU, +{side}: round trip .* = both ways .* \+ the rest " for side in ("tls", "insecure")),
                   r"delivery on the wall clock A -> B .* p50 ",
                   *(rf"throughput A -> B, 20-byte payloads, +{offered}: .* frames/s received, \d+ lost"
                     for offered in ("5,000/s offered", "10,000/s offered", "flat out"))]),
    "many_links": (["benchmarks/many_links.py", "--links", "2", "--rate", "10", "--seconds", "1", "--warmup", "0.5",
                    "--readers", "1", "--placement", "same"],
                   [r" +same CPU, +adaptive: \d+ frames delivered in the window, \d+ sent in it; lateness .* daemon CPU "]),
    # ns-3 is a peer this machine need not have: a Python without it is told, and the run goes on
    "realtime_lateness": (["benchmarks/realtime_lateness.py", "--seconds", "0.5", "--bare-seconds", "0.5", "--nodes", "2",
                           "--rate", "10", "--apps", "1", "--repeats", "1", "--placement", "same", "--warm-up", "0.5",
                           "--read-after", "0.3", "--ns3-python", sys.executable],
                          [r"ns-3: not run \(", r"run 1, +same CPU, +bare: lateness at the application p50 ",
                           r"run 1, +same CPU, hilgate: lateness at the application p50 .* daemon CPU ",
                           r" +same CPU: bare .* hilgate .* ns-3 not run; ratio hilgate / bare "]),
    # 18 s of `make soak`'s hour: reloads every 4 s, one restart of B watched 8 s after; it exits 1 when a
    # frame is unexplained, delivered twice or out of order (so this asserts the account balances)
    "soak": (["benchmarks/soak.py", "--minutes", "0.3", "--reload-every", "4", "--restart-every", "6",
              "--sample-every", "2", "--watch-after-restart", "8"],
             [r"soak: .* at 100 frames/s, a reload every 4 s, B restarted every 6 s; ",
              r"reloads: \d+ \(\d+ refused or unanswered\); restarts of B: 1; ",
              r"memory of daemon A \(one run, \d+ samples\): RSS .* slope ",
              r"memory of daemon B \(run 2, ", r"restart of B: down .* s after",
              r"account: sent \d+ = delivered \d+ \+ lost \d+ \(.*\) \+ unexplained 0; delivered twice 0, out of order 0; ",
              r"account balanced: "]),
    # four conditions (quiet/busy x normal/--realtime); as root the instrument and --realtime are real time
    "realtime_load": (["benchmarks/realtime_load.py", "--seconds", "0.5", "--bare-seconds", "0.5", "--nodes", "2",
                       "--rate", "10", "--apps", "1", "--repeats", "1", "--placement", "same", "--hogs", "1",
                       "--wakers", "1", "--writers", "1", "--writer-mib", "4", "--settle", "0.5", "--warm-up", "0.5",
                       "--read-after", "0.3", "--ns3-python", sys.executable],
                      [r"ns-3: not run \(", r"instrument \(applications, readers\): ",
                       *(rf"run 1, +same CPU, +{load}, +{scheduling}, +{side}: lateness p50 .* p99 "
                         for load in ("quiet", "busy") for scheduling in ("normal", "realtime") for side in ("bare", "hilgate")),
                       r"run 1, +same CPU, +busy, +realtime, hilgate: .* the daemon says: .*; neighbours .* CPU s per wall s",
                       *(rf" +{load} +{scheduling} +[0-9.]+ / +[0-9.]+ \(" for load in ("quiet", "busy")
                         for scheduling in ("normal", "realtime")),
                       *(rf" +same CPU, +{scheduling}: bare [0-9.]+, hilgate [0-9.]+" for scheduling in ("normal", "realtime")),
                       r"  same CPU, busy: hilgate's median p99 .* with --realtime "]),
    # 4 daemons (in network namespaces as root, else on loopback) against one
    "hosts_scale": (["benchmarks/hosts_scale.py", "--links", "2", "--rate", "2", "--seconds", "1", "--repeats", "1",
                     "--warm-up", "0.5", "--read-after", "0.3"],
                    [r"4 daemons: (one per network namespace|on loopback)",
                     *(rf"run 1, +{side}: lateness p50 .* delivered of .* daemon CPU s per wall s: .* heard late \d+, "
                       rf"missing between hosts \d+" for side in ("4 daemons", "1 daemon")),
                     r" +4 daemons: lateness p50 .* CPU per daemon [0-9.]+ [0-9.]+ [0-9.]+ [0-9.]+ s per wall s",
                     r" +1 daemon: lateness p50 .* CPU per daemon [0-9.]+ s per wall s"]),
    # (two of its four cases: the doors' test is tests/test_door_fairness.py, and make test's serial part is long)
    "floods": (["benchmarks/floods.py", "--seconds", "1", "--flood-margin", "0.3", "--cases", "zenoh", "tx"],
               [*(rf"{case}, baseline: honest \d+ of \d+ frames received \(no flood\)"
                  for case in ("zenoh door", "B's frames at A")),
                *(rf"{case}, .*: honest \d+ of \d+ frames received during the flood .* delay p50 "
                  for case in ("zenoh door", "B's frames at A")),
                r"  daemon RSS \d+ MB -> peak \d+ MB \(after \d+ MB\); STATUS answered \d+ of \d+ during the flood"]),
    "web_cost": (["benchmarks/web_cost.py", "--seconds", "0.5", "--repeats", "1", "--warm-up", "0.2"],
                 [r" +no web door +CPU ", r" +--web, no page +CPU ", r" +a page connected +CPU .* pictures ",
                  r" +3 pages connected +CPU .* pictures ", r" +--web, no page adds ", r" +a page connected adds ",
                  r" +3 pages connected adds "]),
    # (in Chromium: skipped by its own test where the browser is missing)
    "web_redraws": (["benchmarks/web_redraws.py", "--seconds", "0.5", "--repeats", "1", "--warm-up", "0.2",
                     "--case", "demo", "--case", "exp1-acoustic-100x"],
                    [r" +demo +median +[\d.]+, min", r" +exp1-acoustic-100x +median ", r"Page redraws in headless Chromium"]),
}


@pytest.mark.parametrize("name", sorted(SMALL))
def test_a_benchmark_runs_to_its_summary_on_a_small_case(name):
    """...and leaves nothing in the temporary directory (every `make test` runs them: pass_cost.py left a
    scene and a runtime directory in /tmp at each run, 182 of them on this machine by the afternoon)."""
    argv, summary = SMALL[name]
    environment = {k: v for k, v in os.environ.items() if k != "NS3_PYTHON"}  # ns-3 is make bench's, not ours
    scratch = tempfile.mkdtemp(prefix="hb-")  # (short: a daemon's socket paths go under it)
    environment["TMPDIR"] = scratch
    try:
        result = subprocess.run([sys.executable, *argv], cwd=REPO, env=environment, capture_output=True, text=True,
                                timeout=600)
        left = sorted(os.listdir(scratch))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    if name == "bellhop_lookup" and "BELLHOP: not run" in result.stdout:
        pytest.skip(result.stdout.strip())  # no BELLHOP program: `make test` makes .venv-bellhop
    if name == "pass_instructions" and "not run" in result.stdout:
        pytest.skip(result.stdout.strip())  # no valgrind here: `make test` does not install it
    assert result.returncode == 0, f"{' '.join(argv)}: exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    assert summary in result.stdout, result.stdout
    assert left == [], f"{' '.join(argv)} left these in its temporary directory"


@pytest.mark.parametrize("name", sorted(WITH_DAEMONS))
def test_a_benchmark_with_daemons_prints_its_figures_on_a_small_case(name):
    argv, figures = WITH_DAEMONS[name]
    if name == "web_redraws":
        from browser_kit import missing

        if missing() is not None:
            pytest.skip(missing())
    environment = {k: v for k, v in os.environ.items() if k != "NS3_PYTHON"}
    result = subprocess.run([sys.executable, *argv], cwd=REPO, env=environment, capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 0, f"{' '.join(argv)}: exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    lines = result.stdout.splitlines()
    missing = [figure for figure in figures if not any(re.match(figure, line) for line in lines)]
    assert not missing, f"no line matches {missing}:\n{result.stdout}"
