"""The frame's path through the daemon stays as long as docs/architecture.md says it is: a pass traced call
by call (tests/framepath.py) against the numbers the page states, so the page cannot go stale and a
longer path is a decision, not an accident."""

import os
import re
import subprocess
import sys
import tempfile

from framepath import Path, trace_one_frame

PAGE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "docs", "architecture.md")


def stated() -> tuple[tuple[int, int], tuple[int, int]]:
    text = open(PAGE, encoding="utf-8").read()
    found = re.findall(r"\*\*(\d+) calls in (\d+) files\*\*", text)
    assert len(found) == 2, "docs/architecture.md states the frame's path and READY as **N calls in M files**"
    (frame_calls, frame_files), (ready_calls, ready_files) = found
    return (int(frame_calls), int(frame_files)), (int(ready_calls), int(ready_files))


def test_the_frame_path_and_ready_are_as_long_as_the_architecture_page_says(tmp_path):
    path = trace_one_frame(str(tmp_path))
    assert path.delivered == 1, "the traced frame did not reach link b's application"
    frame, ready = stated()
    got_frame = (len(path.frame), len(Path.files(path.frame)))
    got_ready = (len(path.ready), len(Path.files(path.ready)))
    listing = "\n".join(f"{file}: {name}" for file, name in path.calls)
    assert (got_frame, got_ready) == (frame, ready), (
        f"the path is {got_frame[0]} calls in {got_frame[1]} files and READY {got_ready[0]} in {got_ready[1]}; "
        f"docs/architecture.md says {frame} and {ready}: shorten it again, or walk the new path in the page "
        f"(python tests/framepath.py lists it):\n{listing}")


def test_the_listing_leaves_nothing_in_the_temporary_folder():
    """``python tests/framepath.py`` left a ``hilgate-path-*`` folder in $TMPDIR at every run (issue 39).
    Its $TMPDIR here is a short folder of its own (pytest's are too long for the daemon's Unix sockets)."""
    script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "framepath.py")
    with tempfile.TemporaryDirectory(prefix="fp-") as scratch:
        run = subprocess.run([sys.executable, script], env={**os.environ, "TMPDIR": scratch},
                             capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr
        assert "delivered: 1" in run.stdout
        assert os.listdir(scratch) == []
