"""``ckesc explore`` on the command line: its exit statuses and its reports directory (~4 s)."""

from __future__ import annotations

import json

import pytest

from ckesc.cli import main
from ckesc.cli.explore import parse_budget


@pytest.mark.parametrize("text, seconds", [("90", 90), ("90s", 90), ("10m", 600), ("1h30m", 5400), ("1.5m", 90)])
def test_budget(text, seconds):
    assert parse_budget(text) == seconds


def test_a_finding_is_exit_1_with_a_report(tmp_path, capsys):
    code = main(["explore", "--emulator-faults", "second_suspend_latches", "--budget", "60s", "--max-programs", "40",
                 "--seed", "1", "--first", "--reports", str(tmp_path), "--database", "none", "-q"])
    assert code == 1
    (run,) = [p for p in tmp_path.iterdir() if p.name.endswith("-explore")]
    results = json.loads((run / "results.json").read_text())
    assert results["findings"][0]["requirements"] == ["4.4.2-1", "4.4.2-T"]
    assert results["info"]["bench"]["emulator_faults"] == "second_suspend_latches"
    assert "finding 1" in capsys.readouterr().out


def test_nothing_found_is_exit_0(tmp_path):
    assert main(["explore", "--budget", "60s", "--max-programs", "10", "--reports", str(tmp_path), "-q",
                 "--database", str(tmp_path / "db")]) == 0


def test_usage_errors_are_exit_2(tmp_path):
    assert main(["explore", "--emulator-faults", "nosuch", "--budget", "1s", "--reports", str(tmp_path)]) == 2
    assert main(["explore", "--budget", "soon"]) == 2
    assert main(["explore", "--selftest", "nosuch"]) == 2
