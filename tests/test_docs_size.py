"""The docs are for reading: no page past 4 000 words, all of them (docs/*.md and the README) at most
30 000 (issue 39 item 4).

What counts as a word: every whitespace-separated token outside fenced code blocks, on every page,
generated reference included (a table or a generated list is read like prose, and its markup counts).
Fenced blocks (commands to type, scenes, a program's output) are copied or compared rather than read,
so they are not counted as prose.  So that a fence cannot hide prose or a narrated wall of output, a
page's fenced blocks together are held to 1 500 tokens, except what ``make bench`` writes verbatim
between ``<!-- bench:begin -->`` and ``<!-- bench:end -->`` (benchmarks/readme_bench.py: the run's own
output, never typed by hand; its prose lines still count)."""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PAGE_WORDS = 4000
ALL_WORDS = 30000
PAGE_CODE_WORDS = 1500
BENCH = re.compile(r"<!-- bench:begin -->.*?<!-- bench:end -->", re.S)


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def counts(text: str) -> tuple[int, int]:
    """(words of prose, tokens in fenced code blocks) of a page's ``text``."""
    prose = code = 0
    fenced = False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            code += len(line.split())
        else:
            prose += len(line.split())
    return prose, code


def test_counting_skips_fences_and_counts_markup():
    assert counts("one two\n```\nnot prose here\n```\n| a | b |\n") == (7, 3)


@pytest.mark.parametrize("page", pages(), ids=lambda page: page.name)
def test_no_page_is_past_the_limit(page):
    text = page.read_text(encoding="utf-8")
    prose, _ = counts(text)
    _, code = counts(BENCH.sub("", text))  # the fences make bench writes are its output, not ours
    assert prose <= PAGE_WORDS, f"{page.name}: {prose} words of prose, at most {PAGE_WORDS}"
    assert code <= PAGE_CODE_WORDS, f"{page.name}: {code} tokens in code blocks, at most {PAGE_CODE_WORDS}"


def test_all_pages_together_are_within_the_limit():
    total = sum(counts(page.read_text(encoding="utf-8"))[0] for page in pages())
    assert total <= ALL_WORDS, f"the docs have {total} words of prose, at most {ALL_WORDS}"
