#!/usr/bin/env python3
"""Instructions per daemon pass and per bare Python relay pass, counted by callgrind: the primary evidence
for a cut of the frame's path on a shared machine (wall time moves with the load, instructions do not:
deterministic here to a few tens a pass).

``pass_cost.py`` runs under ``valgrind --tool=callgrind`` with instrumentation and collection off at the
start (Python's start-up and the imports run uninstrumented, several times faster); it starts
instrumentation once its modules are imported, and switches collection on and off around each pass after
its warm-up (``pass_cost.CALLGRIND_WARM_UP``), so only the daemon's own pass is counted (its
``epoll_wait``, the queue's ``receive``, the frame's and READY's ``send``, and its Python), never the
harness's ``send`` and drains, and dumps the daemon's passes and the relay's apart.  Needs valgrind, its ``callgrind.h`` and a C compiler (``apt-get install valgrind gcc``).

    python benchmarks/pass_instructions.py [PASSES (counted, default 1000)]
"""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CALLGRIND_H = "/usr/include/valgrind/callgrind.h"
sys.path.insert(0, HERE)
from pass_cost import CALLGRIND_WARM_UP  # noqa: E402


def totals(path: str) -> tuple[str, int]:
    """(the dump's trigger, its total instructions) of one callgrind output file."""
    trigger, total = "", 0
    with open(path) as handle:
        for line in handle:
            if line.startswith("desc: Trigger:"):
                trigger = line.split(":", 2)[2].strip()
            elif line.startswith(("totals:", "summary:")):
                total = int(line.split()[1])
    return trigger, total


def main() -> int:
    counted = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    if shutil.which("valgrind") is None or shutil.which("cc") is None or not os.path.exists(CALLGRIND_H):
        print(f"pass_instructions: not run (it needs valgrind, {CALLGRIND_H} and a C compiler: apt-get install valgrind gcc)")
        return 0
    directory = tempfile.mkdtemp(prefix="hilgate-callgrind-")
    out = os.path.join(directory, "callgrind.out")
    environment = dict(os.environ, PASS_COST_CALLGRIND="1", PYTHONHASHSEED="0")
    try:
        subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", "--collect-atstart=no", f"--callgrind-out-file={out}",
                        sys.executable, os.path.join(HERE, "pass_cost.py"), str(counted + CALLGRIND_WARM_UP)],
                       env=environment, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        found = dict(totals(path) for path in glob.glob(out + "*"))
    finally:
        shutil.rmtree(directory, ignore_errors=True)
    daemon = next((n for trigger, n in found.items() if "daemon" in trigger), None)
    relay = next((n for trigger, n in found.items() if "relay" in trigger), None)
    if daemon is None or relay is None:
        print(f"pass_instructions: callgrind's dumps not found ({sorted(found)})")
        return 1
    print(f"instructions per pass (callgrind, {counted:,} passes counted after {CALLGRIND_WARM_UP} warm-up): "
          f"daemon {daemon / counted:,.0f}, bare Python relay {relay / counted:,.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
