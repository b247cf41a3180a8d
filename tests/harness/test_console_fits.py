"""A failing run's console ends with what a person reads first (issue #38): the counts, then the failures by cause
within a screen of them; each test's traceback and pytest's short summary only with ``--verbose`` (the reports hold
every test's detail); no pytest header naming the installed package's directory as the rootdir."""

from __future__ import annotations

import subprocess
from pathlib import Path

from procs import CKESC, env

SCREEN = 50  # lines


def _run(tmp_path: Path, *extra: str) -> list[str]:
    done = subprocess.run([*CKESC, "run", *extra, "--reports", str(tmp_path / "reports"), "--trace-format", "none",
                           "4.4.5", "4.4.26", "--emulator-faults", "report_interval_wrong,esc_information_bcd_date"],
                          cwd=tmp_path, env=env(tmp_path), capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stdout[-2000:] + done.stderr[-2000:]
    return done.stdout.splitlines()


def test_a_failing_run_ends_with_its_counts_and_causes(tmp_path: Path):
    lines = _run(tmp_path)
    assert not any(line.startswith("rootdir:") for line in lines), lines[:8]
    assert not any("= FAILURES =" in line or "short test summary" in line for line in lines), "\n".join(lines)
    counts = next(i for i, line in enumerate(lines) if line.startswith("all "))
    causes = next(i for i, line in enumerate(lines) if line.startswith("failures by cause"))
    assert 0 < causes - counts < SCREEN, "\n".join(lines[counts:])
    assert "failed" in lines[-1], lines[-1]  # pytest's closing line: the counts again, last


def test_verbose_adds_each_failing_tests_detail(tmp_path: Path):
    lines = _run(tmp_path, "--verbose")
    assert any("= FAILURES =" in line for line in lines) and any("short test summary" in line for line in lines)
