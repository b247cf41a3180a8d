"""The soak's statement: the rule of three, per hour of run or per trial."""

from __future__ import annotations

import pytest

from ckesc.reporting.durations import duration_text
from ckesc.soak.statement import Statement


def test_the_rule_of_three_per_hour_as_the_issue_words_it():
    s = Statement("resets", ("R19",), "resets", "reset", 0, 8 * 3600)
    assert s.bound == pytest.approx(0.375)
    assert s.text == "0 resets in 8 h: the reset rate is below 0.375 per hour at 95 % confidence"


def test_per_trial_and_with_events():
    s = Statement("GET_ESC_ID answers", ("R2",), "answers late", "answer late", 0, 600, "answer", 600)
    assert s.bound == pytest.approx(0.005) and "below 0.5 % at 95 % confidence" in s.text
    found = Statement("resets", ("R19",), "resets", "reset", 2, 3600)
    assert found.bound is None and found.text == "2 resets in 1 h"
    assert Statement("x", (), "answers late", "answer late", 0, 10, "answer", 0).bound is None  # nothing judged


def test_durations_read_as_people_write_them():
    assert [duration_text(s) for s in (28800, 5400, 600, 42.5)] == ["8 h", "1 h 30 min", "10 min", "42.5 s"]

