"""The docs are for reading: no page past 4 000 words, all of them (docs/*.md and the README) at most
30 000 (issue 39 item 4).

What counts: every whitespace-separated token outside fenced code blocks, generated reference
included (a table is read like prose).  Fenced blocks (commands, scenes, a program's output) are
copied or compared rather than read, so they are not counted as prose; but so that a fence cannot hide
prose or a wall of narrated output, a page's fenced blocks together are held to 1 500 tokens."""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PAGE_WORDS = 4000
ALL_WORDS = 30000
PAGE_CODE_WORDS = 1500


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def counts(page: Path) -> tuple[int, int]:
    """(prose words, words in fenced code blocks) of ``page``."""
    prose = code = 0
    fenced = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            code += len(line.split())
        else:
            prose += len(line.split())
    return prose, code


@pytest.mark.parametrize("page", pages(), ids=lambda page: page.name)
def test_no_page_is_past_the_limit(page):
    prose, code = counts(page)
    assert prose <= PAGE_WORDS, f"{page.name}: {prose} words of prose, at most {PAGE_WORDS}"
    assert code <= PAGE_CODE_WORDS, f"{page.name}: {code} words in code blocks, at most {PAGE_CODE_WORDS}"


def test_all_pages_together_are_within_the_limit():
    total = sum(counts(page)[0] for page in pages())
    assert total <= ALL_WORDS, f"the docs have {total} words of prose, at most {ALL_WORDS}"
