"""Durations said exactly, in one function for every command (issue #38): ``ckesc/reporting/durations.py``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from ckesc.reporting.durations import duration_text

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("seconds, said", [
    (90, "1 min 30 s"), (457.3, "7 min 37 s"), (457.5, "7 min 38 s"), (3605, "1 h 0 min 5 s"), (3660, "1 h 1 min"),
    (0, "0 s"), (0.04, "0 s"), (59.94, "59.9 s"), (59.96, "1 min"), (60, "1 min"), (119.6, "2 min"), (-90, "-1 min 30 s"),
    (90061, "25 h 1 min 1 s")])
def test_a_duration_is_said_exactly_never_cut(seconds, said):
    """Issue #38: 90 s was "1 min" (cut at the minute) while the statement was computed from 90 s; 457 s "7 min"."""
    assert duration_text(seconds) == said


def test_no_other_module_cuts_a_duration_to_whole_minutes():
    """The truncation the issue found was ``int(seconds // 60)`` said as minutes: no module does it again."""
    cut = re.compile(r"(int\(\w+ // 60\)|round\(\w+\) // 60|divmod\(round\(\w+\), 60\))")
    found = [f"{p.relative_to(ROOT)}:{n}" for p in sorted((ROOT / "ckesc").rglob("*.py"))
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if cut.search(line)]
    assert found == [], "format the duration with ckesc.reporting.durations.duration_text"
