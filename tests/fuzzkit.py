"""How long the fuzz tests run: bounded to seconds in CI, for minutes under ``make fuzz``.

Every fuzz test takes its example count from :func:`examples` (``@settings(max_examples=examples(300))``)
and is named ``test_fuzz_*`` so that ``make fuzz`` (``HILGATE_FUZZ=1 pytest -k "fuzz or redteam"``) finds it
(the red team at the doors, ``test_redteam_doors.py``, takes its number of tries from it too).
``HILGATE_FUZZ`` multiplies the counts (default 100 when set to 1).
"""

from __future__ import annotations

import os


def scale() -> int:
    value = os.environ.get("HILGATE_FUZZ", "")
    if not value or value == "0":
        return 1
    try:
        return max(1, int(value)) if value != "1" else 100
    except ValueError:
        return 100


def examples(ci_count: int) -> int:
    """``ci_count`` in CI, many more under ``make fuzz``."""
    return ci_count * scale()
