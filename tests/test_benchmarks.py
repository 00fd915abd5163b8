"""The benchmark runner (``benchmarks/``) lists its cases and writes the tables BENCHMARKS.md has.

Nothing is timed here (that is ``make bench``): the runner's registry is imported and its
report rendered from rows of cases that did not run, to catch a case family that no longer registers or a table
whose columns drifted from the committed BENCHMARKS.md.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BENCH = ROOT / "benchmarks"


@pytest.fixture(scope="module")
def harness():
    sys.path.insert(0, str(BENCH))
    try:
        import cases  # noqa: F401  (registers the tables and cases)
        import harness
        import targets  # noqa: F401

        yield harness
    finally:
        sys.path.remove(str(BENCH))


def test_every_table_has_cases_and_the_list_shows_them(harness) -> None:
    listed = subprocess.run([sys.executable, str(BENCH / "run.py"), "--list"], capture_output=True, text=True,
                            check=True, timeout=120).stdout.split("\n")
    names = [line.split()[0] for line in listed if line.strip()]
    assert names == sorted(harness.CASES, key=lambda n: harness.CASES[n].last)
    assert {c.table for c in harness.CASES.values()} == set(harness.TABLES)


def test_tables_match_the_committed_report(harness) -> None:
    committed = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    rows = {name: {"case": name, "error": "not run"} for name in harness.CASES}
    report = harness.render(harness.Run(rows=rows, array_dir=ROOT), {"CPU": "-"}, "-", quick=False)
    for table in harness.TABLES.values():
        header = "| " + " | ".join(c.header for c in table.columns) + " |"
        assert header in report
        section = re.search(rf"^## {re.escape(table.title)}\n\n(.*?)\n\n(\|[^\n]*\|)$", committed, flags=re.S | re.M)
        assert section, f"BENCHMARKS.md has no section {table.title!r}"
        assert section[1] == table.description, f"{table.title}: description differs from BENCHMARKS.md"
        assert section[2] == header, f"{table.title}: columns differ from BENCHMARKS.md"
    for title in harness.SECTIONS:
        assert f"\n## {title}\n" in committed and f"\n## {title}\n" in report
