"""BENCHMARKS.md stays a page a user can read: at most 400 lines, a top table with one row
per measure (figure, command, date, machine) whose cells are short, and no diary."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(30)
ROOT = Path(__file__).resolve().parents[2]
MAX_LINES = 400
MAX_WORDS = 25
COLUMNS = ["measure", "figure", "command", "date", "machine"]
# A cell is split on pipes that are not escaped (`\|` inside a command).
CELL = re.compile(r"(?<!\\)\|")
DATE = re.compile(r"^20\d\d-\d\d-\d\d(, 20\d\d-\d\d-\d\d)*$")
# How the work was organised, not what the project measures.
DIARY = re.compile(r"of mine|earlier runs?\b|\bruns [A-Z]-[A-Z]\b|\bthe lead\b|\bhelper\b",
                   re.IGNORECASE)


def text() -> str:
    return (ROOT / "BENCHMARKS.md").read_text()


def top_table(page: str) -> list[list[str]]:
    section = page.split("\n## ", 2)[1]
    rows = [line for line in section.splitlines() if line.startswith("|")]
    return [[c.strip() for c in CELL.split(row)[1:-1]] for row in rows]


def test_at_most_400_lines() -> None:
    assert len(text().splitlines()) <= MAX_LINES


def test_the_top_table_has_one_short_row_per_measure() -> None:
    header, rule, *rows = top_table(text())
    assert header == COLUMNS
    assert set("".join(rule)) <= {"-", ":"}
    assert rows
    measures = [row[0] for row in rows]
    assert len(set(measures)) == len(measures), "a measure appears twice"
    for row in rows:
        assert len(row) == len(COLUMNS), row
        long = [cell for cell in row if len(cell.split()) > MAX_WORDS]
        assert not long, f"cells over {MAX_WORDS} words: {long}"
        assert DATE.match(row[3]), row[3]


def test_no_diary() -> None:
    found = [m.group(0) for m in DIARY.finditer(text())]
    assert not found, found
