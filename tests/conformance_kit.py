"""The conformance tables of docs/conformance.md and docs/conformance-micromodem.md, one per modem family,
kept as data that tests check.

Each family's module (``tests/conformance_<family>.py``) lists :class:`Row` s: every command, notification
and setting of the vendor's public documentation, what the real modem does, what hilgate's emulator does
(and, where it does not, what it answers instead), what hilgate's driver does with it and which outside
library's call exercises it in a test.  ``tests/test_conformance.py`` holds the rows to the code, so the
document cannot drift from it:

- the tables in the pages are exactly :func:`render` of the rows (``python tests/conformance_kit.py``
  writes them there; :data:`PAGES` says which page holds which family's: one page would be past the
  docs' 4 000 words);
- every entry of the emulator's command table is some row's (``keys``): a command added to an emulator
  without its row fails;
- a row's ``probe`` sent to the emulated modem gets an answer that matches its ``answer``; a row without a
  probe names the test that exercises it (``tested``: the file and a text in it);
- a row's ``driver_code`` is in the driver's source, and each call in ``library`` exists in the library
  and is called in a test.
"""

from __future__ import annotations

import importlib
import os
import re
import sys
from dataclasses import dataclass

HERE = os.path.dirname(os.path.abspath(__file__))
DOCS = os.path.join(os.path.dirname(HERE), "docs")
PAGES = {"evologics": "conformance.md", "s100": "conformance.md", "m64": "conformance.md",
         "micromodem": "conformance-micromodem.md", "micromodem-rates": "conformance-micromodem.md"}
FAMILIES = ("evologics", "s100", "m64", "micromodem")
HEADER = ("| command / notification / setting | real modem | emulator | hilgate's driver | outside library, in a test |\n"
          "|---|---|---|---|---|\n")


@dataclass(frozen=True)
class Row:
    item: str                      # as the vendor's document writes it (markdown)
    real: str                      # what the real modem does, from that document (or the second sources)
    emulator: str                  # what the emulator does; what it answers instead when it does not
    driver: str = "—"              # what hilgate's driver does with it
    library: tuple[str, ...] = ()  # "Class.method" of the outside library that a test calls for it
    probe: bytes | None = None     # sent to the emulated modem (tests/test_conformance.py) …
    answer: bytes | None = None    # … which answers something this regular expression finds
    keys: tuple[str, ...] = ()     # the entries of the emulator's command table the row covers
    tested: tuple[str, str] | None = None  # (test file, a text in it): where a test exercises the row
    driver_code: str | None = None  # a text of the driver's source that does it

    def cells(self) -> list[str]:
        library = ", ".join(f"`{call}()`" for call in self.library) or "—"
        return [self.item, self.real, self.emulator, self.driver, library]


def rows(family: str) -> list[Row]:
    return list(importlib.import_module(f"conformance_{family}").ROWS)


def _cell(text: str) -> str:
    return text.replace("\n", " ").replace("|", "\\|").replace("\\\\|", "\\|")


def render(family: str) -> str:
    """The family's table in markdown (what its page holds between its markers)."""
    if family in EXTRA:
        return EXTRA[family]()
    return HEADER + "".join("| " + " | ".join(_cell(c) for c in row.cells()) + " |\n" for row in rows(family))


def micromodem_rates() -> str:
    """The Micro-Modem's rates as the emulator times them, each bit rate with its source."""
    from hilgate.drivers.micromodem_codec import RATE_SOURCES, RATES

    return ("| rate | frames × bytes | bit/s (source) | air time of a full packet |\n|---|---|---|---|\n"
            + "".join(f"| {n} | {r.frames} × {r.frame_bytes} | {r.bitrate_bps:g} ({RATE_SOURCES[n]}) | "
                      f"{r.airtime(r.frames):.2f} s |\n" for n, r in RATES.items()))


EXTRA = {"micromodem-rates": micromodem_rates}
BLOCKS = FAMILIES + tuple(EXTRA)


def markers(family: str) -> tuple[str, str]:
    source = "drivers/micromodem_codec.py" if family in EXTRA else f"tests/conformance_{family}.py"
    return (f"<!-- conformance:{family} (written by tests/conformance_kit.py from {source}) -->\n",
            f"<!-- /conformance:{family} -->\n")


def documented(text: str, family: str) -> str | None:
    """The table between the family's markers in ``text`` (None: no markers)."""
    start, end = markers(family)
    found = re.search(re.escape(start) + r"(.*?)" + re.escape(end), text, re.S)
    return found.group(1) if found else None


def page(family: str) -> str:
    """The path of the page that holds ``family``'s table."""
    return os.path.join(DOCS, PAGES[family])


def write_docs() -> None:
    for path in sorted(set(map(page, BLOCKS))):
        with open(path, encoding="utf-8") as f:
            text = f.read()
        for family in (family for family in BLOCKS if page(family) == path):
            start, end = markers(family)
            if documented(text, family) is None:
                raise SystemExit(f"{path}: no markers for {family}: put {start.strip()} and {end.strip()} where its "
                                 "table goes")
            text = re.sub(re.escape(start) + r".*?" + re.escape(end), lambda _: start + render(family) + end, text,
                          flags=re.S)
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)


if __name__ == "__main__":
    sys.path.insert(0, HERE)
    write_docs()
    print(f"wrote the conformance tables of {', '.join(BLOCKS)} into {', '.join(sorted(set(PAGES.values())))}")
