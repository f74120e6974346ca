"""The README is for newcomers and short; the reference lives in docs/ pages it links.  Every relative
link of the README and of the docs/ pages must lead to a file of the checkout, and an anchor to a
heading of that page (as GitHub spells the heading's slug)."""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def pages():
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    text = FENCE.sub("", page.read_text(encoding="utf-8"))
    return {slug(line.lstrip("#")) for line in text.splitlines() if re.match(r"^#{1,6} ", line)}


def links(page: Path) -> list[str]:
    return LINK.findall(FENCE.sub("", page.read_text(encoding="utf-8")))


@pytest.mark.parametrize("page", pages(), ids=lambda page: page.name)
def test_every_relative_link_leads_somewhere(page):
    dead = []
    for target in links(page):
        if re.match(r"^[a-z]+:", target):
            continue  # https:, mailto:
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            dead.append(target)
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            dead.append(target)
    assert dead == []


def test_every_docs_page_is_reached_from_the_readme():
    seen, todo = set(), [REPO / "README.md"]
    while todo:
        page = todo.pop()
        if page in seen or not page.exists() or page.suffix != ".md":
            continue
        seen.add(page)
        todo += [(page.parent / target.partition("#")[0]).resolve() for target in links(page)
                 if not re.match(r"^[a-z]+:", target) and target.partition("#")[0]]
    unreached = [page.name for page in sorted((REPO / "docs").glob("*.md")) if page.resolve() not in seen]
    assert unreached == []


# -- the quick start: its length, and every command run as written ------------------------------------

import os  # noqa: E402
import shlex  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
import uuid  # noqa: E402
import warnings  # noqa: E402

from daemon_kit import HANG_GUARD_S, free_port  # noqa: E402  (every wait: a hang guard)

README = REPO / "README.md"
QUICK_START = "## Quick start"
DEMO_LINKS = ("bluerov_rf", "rov2_rf", "bluerov_ac", "rov2_ac", "auv_ac")
TWO_HOST_LINKS = ("rov_rf", "rov2_rf", "rov_ac", "boat_ac")
TANK_LINKS = ("tank_evo", "tank_pier")


def words(text: str) -> int:
    return len(re.findall(r"\S+", text))


def quick_start() -> str:
    text = README.read_text(encoding="utf-8")
    start = text.index(f"\n{QUICK_START}\n")
    end = text.find("\n## ", start + 1)
    return text[start:end if end >= 0 else len(text)]


def test_the_readme_is_short_and_its_quick_start_shorter():
    assert words(quick_start()) <= 1500
    assert words(README.read_text(encoding="utf-8")) <= 4000


def transcript() -> list[tuple[str, list[str]]]:
    """Every ``$ command`` of the quick start's code blocks, with the lines the README shows it print."""
    shown: list[tuple[str, list[str]]] = []
    fence = None  # the open block's language ("" for a terminal transcript), None outside blocks
    for line in quick_start().splitlines():
        if line.startswith("```"):
            fence = line[3:].strip() if fence is None else None
        elif fence == "" and line.startswith("$ "):
            shown.append((line[2:].split("  #")[0].strip(), []))
        elif fence == "" and shown and line.strip():
            shown[-1][1].append(line)
    return shown


def _normal(line: str) -> str:
    """Numbers vary from run to run (times, counters, ports): compared as '#'; spaces as one."""
    return re.sub(r"\s+", " ", re.sub(r"\d+(\.\d+)?", "#", line)).strip()


def shows(actual: str, expected: list[str]) -> bool:
    """The README's lines appear in the output in that order ('…' standing for anything)."""
    lines = [_normal(line) for line in actual.splitlines()]
    position = 0
    for line in expected:
        pattern = re.compile(re.escape(_normal(line)).replace("…", ".*"))
        while position < len(lines) and not pattern.fullmatch(lines[position]):
            position += 1
        if position == len(lines):
            return False
        position += 1
    return True


class Walk:
    """The quick start run as a newcomer would, in a directory of its own: the README's commands word
    for word, except that link ids carry a token of this run (two runs on one machine would share the
    demo's ids), the runtime directories are this run's, and so is the Zenoh port."""

    def __init__(self, tmp_path):
        self.dir = tmp_path
        self.token = uuid.uuid4().hex[:6]
        self.links = [*DEMO_LINKS, *TWO_HOST_LINKS, *TANK_LINKS]
        self.port = free_port()
        self.runtime = tmp_path / "rt"
        self.substitutions = [(r"\b7447\b", str(self.port)), (r"/tmp/tank-pc\b", str(tmp_path / "tank-pc")),
                              (r"/tmp/pier-pc\b", str(tmp_path / "pier-pc")), (r"/tmp/tank(?![-\w])", str(tmp_path / "tank")),
                              (r"/tmp/hilgate-tank-evo\b", str(tmp_path / "tank-evo"))]
        self.substitutions += [(rf"\b{re.escape(link)}\b", f"{link}_{self.token}") for link in dict.fromkeys(self.links)]
        shutil.copytree(REPO / "scenes", tmp_path / "scenes")  # the checkout's, as a newcomer has them
        shutil.copytree(REPO / "examples", tmp_path / "examples", ignore=shutil.ignore_patterns("__pycache__"))
        for scene in (tmp_path / "scenes").glob("*.yaml"):
            scene.write_text(self.mine(scene.read_text()))
        self.shown: dict[str, list[list[str]]] = {}  # a command the README shows twice prints two things
        for command, lines in transcript():
            self.shown.setdefault(self.mine(command), []).append([self.mine(line) for line in lines])
        self.checked: dict[str, int] = {}  # how many of each command's outputs were checked
        self.ran: list[str] = []
        self.processes: list[Process] = []
        self.env = dict(os.environ, RUNTIME_DIRECTORY=str(self.runtime), PYTHONUNBUFFERED="1")

    def mine(self, text: str) -> str:
        for pattern, replacement in self.substitutions:
            text = re.sub(pattern, replacement, text)
        return text

    def argv(self, command: str) -> list[str]:
        words_ = shlex.split(command)
        if words_[0] == "hilgate":
            return [sys.executable, "-m", "hilgate", *words_[1:]]
        if words_[0] == "make":  # the .venv make test installed, not made again here
            return ["make", "--no-print-directory", "-C", str(REPO), "-o", ".venv/.installed", *words_[1:],
                    f"SCENE={self.dir / 'scenes' / 'demo.yaml'}", "ARGS=--no-status-line"]
        return words_

    def start(self, command: str, ready: str | None = None) -> "Process":
        command = self.mine(command)
        process = Process(command, self.argv(command), self.dir, self.env)
        self.ran.append(command)
        self.processes.append(process)
        if ready is not None:
            process.wait_for(ready)
        return process

    def run(self, command: str, until_shown: bool = False) -> str:
        """Run to the end and check the output against the README's; ``until_shown``: run again until
        it shows what the README shows (a status that is still catching up)."""
        deadline = time.monotonic() + HANG_GUARD_S
        while True:
            process = self.start(command)
            output = process.finish()
            if shows(output, self.expected(command)) or not until_shown or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        self.check(command, output)
        assert process.code == 0, f"{command}: exit status {process.code}\n{output}"
        return output

    def expected(self, command: str) -> list[str]:
        """What the README shows the command print at this point of the walk (its n-th appearance)."""
        command = self.mine(command)  # mine() twice changes nothing: a token follows '_', so no \b
        assert command in self.shown, f"`{command}` is not in the README's quick start"
        occurrences = self.shown[command]
        assert self.checked.get(command, 0) < len(occurrences), f"`{command}` run more often than the README shows"
        return occurrences[self.checked.get(command, 0)]

    def check(self, command: str, output: str) -> None:
        expected = self.expected(command)
        assert shows(output, expected), (
            f"`{command}` printed:\n{output}\nwhere the README shows:\n" + "\n".join(expected))
        self.checked[self.mine(command)] = self.checked.get(self.mine(command), 0) + 1

    def stop(self, process: "Process", sig: int = signal.SIGINT) -> str:
        output = process.finish(sig)
        self.check(process.command, output)
        return output

    def close(self) -> None:
        for process in self.processes:
            process.finish(signal.SIGTERM)
        self.unlink_queues()

    def unlink_queues(self) -> None:
        """Remove the queues this walk's daemons made (dccomms' rule: nobody unlinks them): each part of
        the walk then needs only its own scene's share of the user's queue budget, which every test run
        on the machine shares."""
        from hilgate.gli.queues import unlink_queues

        unlink_queues(f"{link}_{self.token}" for link in self.links)


def _ctrl_c_as_at_a_terminal() -> None:
    """In the command's process: SIGINT does what it does at a user's terminal.  A test run started in the
    background by a script (``make test &``, a CI runner) has SIGINT ignored, which its children inherit, and a
    Python program started so keeps ignoring it: `hilgate listen` then outlived its Ctrl-C, twice a walk, until
    the 90 s guard killed it (the serial part of make test took 202 s where the walk takes 23)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _process_state(pid: int) -> str:
    """What a process that does not end is doing: its state, where it waits, and which signals it blocks,
    ignores and catches (a hex mask each; SIGINT is bit 1)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            fields = dict(line.split(":", 1) for line in status if ":" in line)
        with open(f"/proc/{pid}/wchan") as wchan:
            waits = wchan.read()
    except OSError as exc:
        return str(exc)
    return ", ".join([f"waits in {waits}", *(f"{k} {fields[k].strip()}" for k in ("State", "SigBlk", "SigIgn", "SigCgt")
                                             if k in fields)])


class Process:
    """One command of the walk, its output (stdout and stderr as a terminal shows them) read as it comes."""

    def __init__(self, command: str, argv: list[str], cwd, env):
        self.command = command  # as the README has it (with this walk's ids)
        self.popen = subprocess.Popen(argv, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True, start_new_session=True,
                                      preexec_fn=_ctrl_c_as_at_a_terminal)
        self.lines: list[str] = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        self.code: int | None = None

    def _read(self) -> None:
        for line in self.popen.stdout:
            self.lines.append(line)

    @property
    def output(self) -> str:
        return "".join(self.lines)

    def wait_for(self, text: str) -> None:
        deadline = time.monotonic() + HANG_GUARD_S
        while text not in self.output:
            assert self.popen.poll() is None or text in self.output, f"{self.command} ended:\n{self.output}"
            assert time.monotonic() < deadline, f"no {text!r} from {self.command}:\n{self.output}"
            time.sleep(0.05)

    def finish(self, sig: int | None = None) -> str:
        """Wait for the end (after ``sig`` to its process group, as Ctrl-C is); its whole output."""
        if sig is not None and self.popen.poll() is None:
            os.killpg(self.popen.pid, sig)
        try:
            self.code = self.popen.wait(HANG_GUARD_S)
        except subprocess.TimeoutExpired:
            stuck = _process_state(self.popen.pid)
            os.killpg(self.popen.pid, signal.SIGKILL)
            self.code = self.popen.wait()
            # (said, with what the process was doing: a test that passes slowly is still worth knowing about)
            warnings.warn(f"`{self.command}` had not ended {HANG_GUARD_S:.0f} s after "
                          f"{signal.Signals(sig).name if sig else 'its start'}: killed ({stuck}); "
                          f"the walk's own signals: {_process_state(os.getpid())}; its last lines:\n"
                          + "".join(self.lines[-10:]))
        self.reader.join(HANG_GUARD_S)
        if not self.reader.is_alive():
            self.popen.stdout.close()
        return self.output


@pytest.fixture
def walk(tmp_path):
    walk = Walk(tmp_path)
    try:
        yield walk
    finally:
        walk.close()


def test_every_quick_start_command_prints_what_the_readme_shows(walk):
    # (a) an application against simulated modems
    daemon = walk.start("make run", ready="started: scene")
    listener = walk.start("hilgate listen rov2_rf", ready="listening on")
    walk.run("hilgate send bluerov_rf --to 2 hello")
    listener.wait_for(": hello")
    walk.stop(listener)
    walk.run("hilgate status", until_shown=True)
    pong = walk.start("hilgate app examples/apps/pingpong.py:Pong --link rov2_ac", ready="Pong: link")
    walk.run("hilgate app examples/apps/pingpong.py:Ping --link bluerov_ac --param period_s=2 --param peer=2 "
             "--param count=5 --until 12")
    assert "Pong: stopped after" in walk.stop(pong)  # Ctrl-C: its summary
    walk.stop(daemon)
    walk.unlink_queues()

    # (b) one link to a real modem, without a restart: the emulated one of scenes/tank.yaml
    walk.run("cp scenes/demo.yaml lab.yaml")
    daemon = walk.start("hilgate run lab.yaml", ready="started: scene")
    tank = walk.start("hilgate run scenes/tank.yaml --runtime-dir /tmp/tank", ready="started: scene")
    new_line = walk.mine(re.search(r"^```yaml\n(  rov2_ac: .*)\n```", quick_start(), re.M).group(1))
    lab = walk.dir / "lab.yaml"
    lab.write_text(re.sub(rf"^  rov2_ac_{walk.token}: .*$", lambda _: new_line, lab.read_text(), flags=re.M))
    walk.run("hilgate reload")
    walk.run("hilgate status", until_shown=True)
    walk.stop(daemon)
    walk.stop(tank)
    walk.unlink_queues()

    # (c) the experiment in virtual time, with figures
    walk.run("hilgate sim scenes/demo.yaml --trace demo.jsonl --summary demo.json")
    walk.run("hilgate report demo.jsonl demo.json --out demo-report")
    assert (walk.dir / "demo-report" / "index.html").is_file()

    # (d) two PCs, one network of modems (here, two daemons on this one)
    walk.run("hilgate network init lab-creds --hosts tank-pc,pier-pc --apps 2")
    tank = walk.start("hilgate run scenes/two-hosts.yaml --host tank-pc --zenoh-credentials lab-creds "
                      "--zenoh-listen tcp/127.0.0.1:7447 --runtime-dir /tmp/tank-pc", ready="joined the network")
    pier = walk.start("hilgate run scenes/two-hosts.yaml --host pier-pc --zenoh-credentials lab-creds "
                      "--zenoh-connect tcp/127.0.0.1:7447 --runtime-dir /tmp/pier-pc", ready="joined the network")
    tank.wait_for("host pier-pc is up")
    listener = walk.start("hilgate listen rov_ac --runtime-dir /tmp/tank-pc", ready="listening on")
    walk.run("hilgate send boat_ac --to 1 hello from the pier --runtime-dir /tmp/pier-pc")
    listener.wait_for("hello from the pier")
    walk.stop(listener)
    walk.run("hilgate status --network --runtime-dir /tmp/tank-pc", until_shown=True)
    walk.stop(pier)
    walk.stop(tank)

    # and nothing the README shows was left out
    assert {command: len(outputs) for command, outputs in walk.shown.items()} == walk.checked


def test_the_docs_point_at_nothing_outside_the_repository():
    """Users have the repository, not the team's working material beside it (issue 39 item 4), nor the paths
    of the machine a figure was measured on (a benchmark's output quoted with its absolute paths)."""
    outside = re.compile(r"DESIGN\.md|shared/protocols|shared/peers|\.\./shared|(?<![\w.])/(work|home|root)/")
    found = [f"{page.name}:{n}" for page in pages() for n, line in enumerate(page.read_text().splitlines(), 1)
             if outside.search(line)]
    assert found == []
