#!/usr/bin/env python3
"""A soak (issue 36 item 5): two daemons of one scene for an hour, traffic, reloads and restarts; the
daemons' memory over time and an account of every frame.

Hosts A and B, each a daemon in a network namespace of its own (benchmarks/netns.py: as root; elsewhere
both on loopback, and it says so), joined over Zenoh with the lab's credentials (TLS).  50 links, 25 on
each host, ten to a channel (five of each host), 100 frames a second in all: each link sends 2 frames a
second of 20 bytes, in turn to a link of the other host and to one of its own (soak_app.py: one
application process per host on the socket GLI).  Every ``--reload-every`` seconds both daemons reload
the scene (``RELOAD`` on the control socket) in which a spare vehicle has moved and a spare link on a
channel of its own comes or goes; every ``--restart-every`` seconds daemon B is restarted (SIGTERM,
then started again with the same credentials, as ``systemctl restart`` does): B's application pauses
its sending two seconds before (a daemon does not account what it holds when it stops: what B's own
applications sent is not the point; what A's send to B meanwhile is) and goes on once it is back, its
links opened again.

Printed: each daemon's resident memory (``/proc/PID/status`` VmRSS every ``--sample-every`` s) with a
least-squares line, MB per hour (A after a warm-up of a tenth of the run; each run of B over its life),
how long after each restart B's application got A's frames again, and the account (soak_account.py):
every frame the applications sent is delivered or traced by a daemon with its cause.  Exit status 1 if
any frame is unexplained, delivered twice or out of order.

    python benchmarks/soak.py [--minutes 60] [--reload-every 60] [--restart-every 600] [--sample-every 10]
                              [--watch-after-restart 30] [--loopback] [--keep DIR]

A restart comes only while ``--watch-after-restart`` seconds of the run are left after it: B's new run
is watched that long at least (its memory, A's frames reaching it again).  ``make soak`` runs the hour;
tests/test_benchmarks_run.py 18 s of it (reloads every 4 s, one restart, 8 s watched after it).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(1, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
from ports import free_port  # noqa: E402  (ports outside the ephemeral range: tests/ports.py)
import netns  # noqa: E402
from daemon_harness import Daemon  # noqa: E402
from soak_account import Run, account  # noqa: E402

LINKS = 50
PER_CHANNEL = 10  # five of each host
RATE = 2.0  # frames a second per link
SIZE = 20
LEASE_S = 5.0  # (a loaded machine starves Zenoh's threads now and then: at 1 s, hosts were seen down)
PAUSE_S = 2.0  # B's application stops sending this long before B stops
SETTLE_S = 60.0  # at the end: the longest wait for the hosts to settle what is on its way


class Layout:
    """The scene's links: names, hosts, addresses, channels, and where each application sends."""

    def __init__(self, tag: str):
        self.links = [f"s{tag}l{i:02d}" for i in range(LINKS)]
        self.host = {}
        self.address = {}
        self.channel = {}
        self.destinations = {}
        half = PER_CHANNEL // 2
        for i, link in enumerate(self.links):
            group, j = divmod(i, PER_CHANNEL)
            self.host[link] = "A" if j < half else "B"
            self.address[link] = i + 1
            self.channel[link] = f"c{group}"
            partner = i + half if j < half else i - half  # the other host's link, same channel
            side = 0 if j < half else half
            neighbour = group * PER_CHANNEL + side + (j - side + 1) % half  # one of its own host's
            self.destinations[link] = [partner + 1, neighbour + 1]
        self.spare = f"s{tag}spare"

    def of(self, host: str) -> list[str]:
        return [link for link in self.links if self.host[link] == host]

    def scene(self, prefix: str, credentials: str, version: int) -> str:
        lines = [f"name: soak",
                 "channels: {" + ", ".join(f"c{g}: {{speed_mps: 1500}}" for g in range(LINKS // PER_CHANNEL))
                 + ", spare: {speed_mps: 1500}}",
                 f"zenoh: {{prefix: {prefix}, lease_s: {LEASE_S}, credentials: {credentials}}}",
                 "trace: {poses_s: 0}",
                 "vehicles:"]
        for i in range(LINKS):
            angle = 2 * math.pi * i / LINKS
            lines.append(f"  v{i}: {{pose: {{static: [{100 * math.cos(angle):.2f}, {100 * math.sin(angle):.2f}, -5]}}}}")
        lines.append(f"  spare: {{pose: {{static: [{version % 7}, 0, -10]}}}}")  # moved at every reload
        lines.append("links:")
        for i, link in enumerate(self.links):
            lines.append(f"  {link}: {{vehicle: v{i}, host: {self.host[link]}, address: {self.address[link]}, "
                         f"channel: {self.channel[link]}, bitrate_bps: 1000000, addressing: strict, gli: [socket]}}")
        if version % 2:  # comes and goes at every reload
            lines.append(f"  {self.spare}: {{vehicle: spare, host: A, address: 200, channel: spare, "
                         f"bitrate_bps: 1000000, gli: [socket]}}")
        return "\n".join(lines) + "\n"


class Host:
    """The daemon of one host, started again as often as asked; each run in a directory of its own, all
    with one runtime directory (its applications' sockets are where they were)."""

    def __init__(self, name: str, base: str, within: tuple[str, ...], args: tuple[str, ...]):
        self.name, self.base, self.within, self.args = name, base, within, args
        self.runtime = os.path.join(base, f"{name}-rt")
        self.daemon: Daemon | None = None
        self.runs: list[Run] = []
        self.rss: list[list[tuple[float, float]]] = []  # per run: (wall, MB)

    def start(self, scene: str) -> None:
        run = len(self.runs)
        directory = os.path.join(self.base, f"{self.name}{run}")
        os.makedirs(directory)
        trace = os.path.join(directory, "trace.jsonl")
        self.runs.append(Run(self.name, trace, time.time()))
        self.rss.append([])
        self.daemon = Daemon(scene, (), (*self.args, "--trace", trace, "--runtime-dir", self.runtime), directory=directory,
                             name=self.name, within=self.within)
        self.daemon.runtime = self.runtime  # (the control socket is in the one runtime directory)

    def stop(self) -> None:
        if self.daemon is not None:
            self.daemon.close()
            self.runs[-1].stop = time.time()
            self.daemon = None

    def sample(self) -> None:
        if self.daemon is not None:
            try:
                with open(f"/proc/{self.daemon.process.pid}/status") as handle:
                    kb = next(int(line.split()[1]) for line in handle if line.startswith("VmRSS:"))
            except (OSError, StopIteration):
                return
            self.rss[-1].append((time.time(), kb / 1024))

    def write_scene(self, scene: str) -> None:
        with open(os.path.join(os.path.dirname(self.daemon.log_path), f"{self.name}.yaml"), "w") as handle:
            handle.write(scene)

    def status(self) -> dict:
        return self.daemon.status()


def slope(samples: list[tuple[float, float]]) -> float | None:
    """Least-squares MB per hour of ``(wall, MB)`` samples."""
    if len(samples) < 3:
        return None
    n = len(samples)
    mx = sum(t for t, _ in samples) / n
    my = sum(m for _, m in samples) / n
    sxx = sum((t - mx) ** 2 for t, _ in samples)
    return sum((t - mx) * (m - my) for t, m in samples) / sxx * 3600 if sxx else None


def wait_for(predicate, what: str, timeout: float = 120.0, every: float = 0.2):
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(every)


def sees(host: Host, other: str) -> bool:
    try:
        return {v["host"]: v["state"] for v in host.status()["network"]["hosts"]}.get(other) == "up"
    except Exception:
        return False


def clients(host: Host, links: list[str]) -> bool:
    try:
        counts = {l["id"]: l["clients"] for l in host.status()["links"]}
    except Exception:
        return False
    return all(counts.get(link, 0) >= 1 for link in links)


def unsettled(host: Host) -> int:
    return host.status()["network"]["unsettled"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--reload-every", type=float, default=60.0, help="seconds between reloads")
    parser.add_argument("--restart-every", type=float, default=600.0, help="seconds between B's restarts")
    parser.add_argument("--sample-every", type=float, default=10.0, help="seconds between memory samples")
    parser.add_argument("--watch-after-restart", type=float, default=30.0,
                        help="the least seconds of the run left after a restart of B (none later)")
    parser.add_argument("--loopback", action="store_true", help="both daemons on loopback, even as root")
    parser.add_argument("--keep", help="keep the traces and logs in this directory (default: removed)")
    args = parser.parse_args()
    started = datetime.datetime.now(datetime.timezone.utc)
    load = os.getloadavg()
    why = "--loopback" if args.loopback else netns.why_not()
    spaces = None
    if why is None:
        try:
            spaces = netns.Namespaces(2)
        except (OSError, subprocess.CalledProcessError) as exc:
            why = f"ip netns failed: {getattr(exc, 'stderr', '') or exc}".strip()
    base = args.keep or tempfile.mkdtemp(prefix="hgsoak-")
    os.makedirs(base, exist_ok=True)
    tag = uuid.uuid4().hex[:6]
    layout = Layout(tag)
    apps: dict[str, subprocess.Popen] = {}
    hosts: dict[str, Host] = {}
    try:
        from hilgate.commands.credentials import init_network

        credentials = os.path.join(base, "creds")
        init_network(credentials, ["A", "B"], 1)
        if spaces is not None:
            listen = {h: f"tls/{spaces.address(i)}:7447" for i, h in enumerate("AB")}
            within = {h: spaces.command(i) for i, h in enumerate("AB")}
        else:
            listen = {h: f"tls/127.0.0.1:{free_port()}" for h in "AB"}
            within = {h: () for h in "AB"}
        prefix = f"hilgate-soak-{tag}"
        version = 0
        scene = layout.scene(prefix, credentials, version)
        hosts["A"] = Host("A", base, within["A"], ("--host", "A", "--zenoh-listen", listen["A"]))
        hosts["B"] = Host("B", base, within["B"], ("--host", "B", "--zenoh-listen", listen["B"],
                                                   "--zenoh-connect", listen["A"]))
        hosts["A"].start(scene)
        hosts["B"].start(scene)
        wait_for(lambda: sees(hosts["A"], "B") and sees(hosts["B"], "A"), "the hosts to meet")
        print(f"soak: {started:%Y-%m-%d %H:%M} UTC, {os.cpu_count()} cores, load average "
              f"{load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} at the start; {args.minutes:g} min, "
              f"{LINKS} links (25 on host A, 25 on host B, {LINKS // PER_CHANNEL} channels) at {LINKS * RATE:g} frames/s, "
              f"a reload every {args.reload_every:g} s, B restarted every {args.restart_every:g} s; "
              + ("hosts in network namespaces joined by veth pairs and a bridge (TLS)" if spaces is not None
                 else f"both hosts on loopback (TLS): {why}"), flush=True)
        logs = {}
        for host in "AB":
            logs[host] = os.path.join(base, f"app-{host}.json")
            specs = [f"{link}={','.join(map(str, layout.destinations[link]))}" for link in layout.of(host)]
            apps[host] = subprocess.Popen([sys.executable, os.path.join(HERE, "soak_app.py"), "--runtime",
                                           hosts[host].runtime, "--log", logs[host], "--rate", str(RATE),
                                           "--size", str(SIZE), *specs])
        for host in "AB":
            wait_for(lambda: clients(hosts[host], layout.of(host)), f"host {host}'s application on every link")
        t0 = time.monotonic()
        end = t0 + args.minutes * 60
        next_reload, next_restart, next_sample = t0 + args.reload_every, t0 + args.restart_every, t0
        reloads = refused = 0
        restarts: list[tuple[float, float]] = []  # (wall B stopped, wall B was back)
        while time.monotonic() < end:
            now = time.monotonic()
            if now >= next_sample:
                for host in hosts.values():
                    host.sample()
                next_sample += args.sample_every
            if now >= next_reload:
                version += 1
                scene = layout.scene(prefix, credentials, version)
                for host in hosts.values():
                    host.write_scene(scene)
                    reloads += 1
                    try:
                        refused += not host.daemon.control({"class": "RELOAD"}).get("ok")
                    except Exception as exc:  # (a loaded machine: the answer took over 10 s; the soak goes on)
                        refused += 1
                        print(f"reload of {host.name}: no answer ({type(exc).__name__}: {exc})", flush=True)
                next_reload += args.reload_every
            if now >= next_restart and now + PAUSE_S + args.watch_after_restart < end:
                apps["B"].send_signal(signal.SIGUSR1)
                time.sleep(PAUSE_S)
                hosts["B"].stop()
                stopped = time.time()
                hosts["B"].start(scene)
                wait_for(lambda: sees(hosts["A"], "B") and sees(hosts["B"], "A"), "the hosts to meet again")
                restarts.append((stopped, time.time()))
                apps["B"].send_signal(signal.SIGUSR2)
                next_restart += args.restart_every
            time.sleep(max(0.0, min(next_sample, next_reload, next_restart, end) - time.monotonic()))
        for app in apps.values():
            app.send_signal(signal.SIGUSR1)
        time.sleep(PAUSE_S)
        wait_for(lambda: unsettled(hosts["A"]) == 0 and unsettled(hosts["B"]) == 0, "the hosts to settle", SETTLE_S)
        for host in hosts.values():
            host.sample()
        for app in apps.values():
            app.send_signal(signal.SIGTERM)
        for app in apps.values():
            app.wait(120)
        for host in hosts.values():
            host.stop()
        ended = os.getloadavg()
        with open(os.path.join(base, "rss.json"), "w") as handle:  # (kept with --keep: the account again, offline)
            json.dump({"rss": {name: host.rss for name, host in hosts.items()},
                       "runs": [vars(run) for run in hosts["A"].runs + hosts["B"].runs],
                       "host": layout.host, "address": layout.address}, handle)
        report(layout, hosts, [json.load(open(logs[h])) for h in "AB"], restarts, reloads, refused, args, ended)
        result = account([json.load(open(logs[h])) for h in "AB"], hosts["A"].runs + hosts["B"].runs,
                         layout.host, layout.address)
        lost = ", ".join(f"{cause} {n}" for cause, n in result.lost.most_common()) or "none"
        print(f"account: sent {result.sent} = delivered {result.delivered} + lost {sum(result.lost.values())} "
              f"({lost}) + unexplained {len(result.unexplained)}; delivered twice {result.twice}, out of order "
              f"{result.out_of_order}; sent but never taken by a daemon {result.not_taken}; traced and yet "
              f"delivered {dict(result.overlap) or 0}; loss lines matching no frame {dict(result.unmatched) or 0}; "
              f"messages missed between the hosts (net_gap lines) {result.net_gaps}")
        if result.unexplained:
            print(f"  unexplained (link, number, destination address, wall): {result.unexplained[:20]}")
        print("account balanced: every frame sent is delivered once, in order, or traced with its cause"
              if result.balanced else "account NOT BALANCED: frames unexplained, delivered twice or out of order")
        return 0 if result.balanced else 1
    finally:
        for app in apps.values():
            if app.poll() is None:
                app.kill()
                app.wait()
        for host in hosts.values():
            host.stop()
        if spaces is not None:
            spaces.close()
        if not args.keep:
            shutil.rmtree(base, ignore_errors=True)


def report(layout: Layout, hosts: dict[str, Host], logs: list[dict], restarts: list[tuple[float, float]],
           reloads: int, refused: int, args, load: tuple[float, float, float]) -> None:
    print(f"reloads: {reloads} ({refused} refused or unanswered); restarts of B: {len(restarts)}; load average "
          f"{load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} at the end")
    warm = args.minutes * 60 / 10
    a = hosts["A"].rss[0]
    if a:
        after = [(t, m) for t, m in a if t >= a[0][0] + warm]
        second = [(t, m) for t, m in a if t >= (a[0][0] + a[-1][0]) / 2]
        print(f"memory of daemon A (one run, {len(a)} samples): RSS {a[0][1]:.1f} MB at the start, "
              f"{a[-1][1]:.1f} MB at the end, max {max(m for _, m in a):.1f} MB; slope "
              f"{_mb(slope(a))} over the whole run, {_mb(slope(after))} after the first {warm / 60:g} min, "
              f"{_mb(slope(second))} over the second half")
        step = max(60.0, args.minutes * 6)  # (a tenth of the run)
        marks = [next(m for t, m in a if t >= a[0][0] + k * step) for k in range(int((a[-1][0] - a[0][0]) // step) + 1)]
        print(f"  RSS of daemon A every {step / 60:g} min: " + ", ".join(f"{m:.1f}" for m in marks) + " MB")
    slopes = []
    for run, samples in enumerate(hosts["B"].rss):
        if samples:
            s = slope(samples)
            if s is not None:
                slopes.append(s)
            print(f"memory of daemon B (run {run + 1}, {len(samples)} samples over "
                  f"{(samples[-1][0] - samples[0][0]) / 60:.1f} min): RSS {samples[0][1]:.1f} MB at the start, "
                  f"{samples[-1][1]:.1f} MB at the end, max {max(m for _, m in samples):.1f} MB; slope {_mb(s)}")
    if slopes:
        print(f"memory of daemon B: slope over its runs, min / median / max {min(slopes):+.2f} / "
              f"{sorted(slopes)[len(slopes) // 2]:+.2f} / {max(slopes):+.2f} MB/hour")
    got_b = sorted(wall for log in logs for link, source, number, wall in log["got"] if layout.host[link] == "B"
                   and layout.host[_link_at(layout, source)] == "A")
    for stopped, back in restarts:
        first = next((w for w in got_b if w > back), None)
        print(f"restart of B: down {back - stopped:.2f} s (SIGTERM to READY and met again); A's frames reached "
              f"B's application again " + (f"{first - back:.2f} s after" if first is not None else "never"))


def _link_at(layout: Layout, address: int) -> str:
    return next(link for link, a in layout.address.items() if a == address)


def _mb(value: float | None) -> str:
    return "n/a" if value is None else f"{value:+.2f} MB/hour"


if __name__ == "__main__":
    sys.exit(main())
