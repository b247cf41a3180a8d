"""The release gate (issue #37, item 2): ``ckesc run ... --baseline DIR`` ends with ``ckesc compare``'s comparison against a
committed earlier run and exits 1 on a regression, its reasons leading summary.txt and ending the console.

Tried as a user meets it: real ``ckesc run`` processes on the simulated lane, one small section (4.4.3 GET_ESC_ID,
three tests), against a baseline that is a real run of the faultless emulator, made once for the module. The issue's
own check: the faultless emulator against a baseline of itself exits 0; with one fault switched on (``answer_late``:
answers 80 ms late) exit 1, naming the regressed requirement first. A margin that shrank while every test still
passes is a reason too (a baseline whose margins were wider: the faultless run's record with one margin widened)."""

from __future__ import annotations

import json
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from procs import CKESC, env

SECTION = "4.4.3"
ONE_TEST = "conformance/test_s4_4_3_get_esc_id.py::test_reply_comes_in_the_node_slot"


def _run(tmp: Path, reports: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CKESC, "run", "-q", "--reports", str(tmp / reports), *args], cwd=tmp, env=env(tmp),
                          capture_output=True, text=True, timeout=300)


def _record(tmp: Path, reports: str) -> dict:
    return json.loads((tmp / reports / "latest" / "results.json").read_text(encoding="utf-8"))


def _gate_lines(stdout: str) -> list[str]:
    """The console's gate: from its ``gate:`` line to pytest's own count line that ends the console."""
    lines = stdout.rstrip("\n").splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("gate: "))
    assert all(ln.startswith("  ") for ln in lines[start + 1:-1]), lines[start:]  # nothing but the gate after it
    return lines[start:-1]


@pytest.fixture(scope="module")
def baseline(tmp_path_factory) -> Path:
    """A committed earlier run: the faultless emulator's 4.4.3, its directory copied out of the reports (as a CI
    job commits one), so that ``reports/latest`` moving on cannot change it."""
    tmp = tmp_path_factory.mktemp("baseline")
    done = _run(tmp, "reports", SECTION)
    assert done.returncode == 0, done.stdout + done.stderr
    return Path(shutil.copytree((tmp / "reports" / "latest").resolve(), tmp / "fw-1.0"))


def test_the_faultless_emulator_against_a_baseline_of_itself_passes_the_gate(tmp_path, baseline):
    done = _run(tmp_path, "reports", SECTION, "--baseline", str(baseline))
    assert done.returncode == 0, done.stdout + done.stderr
    assert _gate_lines(done.stdout) == [f"gate: NO REGRESSION against baseline {baseline} (3 tests both ran; margin "
                                        "threshold 10 %)"]
    gate = _record(tmp_path, "reports")["info"]["gate"]
    assert (gate["baseline"], gate["verdict"], gate["reasons"]) == (str(baseline), "NO REGRESSION", [])
    summary = (tmp_path / "reports" / "latest" / "summary.txt").read_text(encoding="utf-8")
    assert summary.startswith("gate: NO REGRESSION")


def test_one_fault_fails_the_gate_naming_the_regressed_requirement_first(tmp_path, baseline):
    done = _run(tmp_path, "reports", SECTION, "--baseline", str(baseline), "--emulator-faults", "answer_late")
    assert done.returncode == 1, done.stdout + done.stderr
    said = _gate_lines(done.stdout)
    assert said[0].startswith(f"gate: REGRESSED against baseline {baseline}"), said
    assert said[1] == "  requirement 4.4.3-4 (SHALL) regressed: PASS -> FAIL", said  # SHALL first, then R2 (READING)
    assert said[2] == "  requirement R2 (READING) regressed: PASS -> FAIL", said
    assert any(ln.startswith("  test conformance/test_s4_4_3_get_esc_id.py::") and "PASS -> FAIL (broke 4.4.3-4 R2)" in ln
               for ln in said), said
    gate = _record(tmp_path, "reports")["info"]["gate"]
    assert gate["verdict"] == "REGRESSED" and gate["regressed"]["requirements"] == ["4.4.3-4", "R2"]
    assert [f"  {r}" for r in gate["reasons"][:len(said) - 1]] == said[1:]  # the console's reasons are the record's
    summary = (tmp_path / "reports" / "latest" / "summary.txt").read_text(encoding="utf-8").splitlines()
    assert summary[:3] == said[:3]  # the gate leads summary.txt
    run = tmp_path / "reports" / "latest"
    props = {p.get("name"): p.get("value") for p in ET.parse(run / "junit.xml").getroot().find("testsuite/properties")}
    assert (props["gate.verdict"], props["gate.reason.0"]) == ("REGRESSED", gate["reasons"][0])
    page = (run / "report.html").read_text(encoding="utf-8")
    assert '<div class=banner role=alert id=gate>gate: REGRESSED' in page


def _widened(baseline: Path, into: Path) -> tuple[Path, str]:
    """A copy of the baseline whose first timing margin is twice as wide (its value as much further from the limit):
    the record of a firmware that answered sooner. Returns the copy and that measurement's test."""
    copy = Path(shutil.copytree(baseline, into))
    doc = json.loads((copy / "results.json").read_text(encoding="utf-8"))
    for r in doc["results"]:
        for m in r["measured"]:
            if m.get("unit") == "ms" and (m.get("margin") or 0) > 0 and m["op"] == "<=":
                m["value"] -= m["margin"]
                m["margin"] *= 2
                (copy / "results.json").write_text(json.dumps(doc), encoding="utf-8")
                return copy, r["nodeid"]
    raise AssertionError("no timing measurement with a limit in the baseline")


def test_a_margin_that_shrank_beyond_the_threshold_fails_the_gate_while_every_test_passes(tmp_path, baseline):
    wider, test = _widened(baseline, tmp_path / "fw-0.9")
    done = _run(tmp_path, "shrank", SECTION, "--baseline", str(wider))
    assert done.returncode == 1, done.stdout + done.stderr
    assert "3 passed" in done.stdout
    said = _gate_lines(done.stdout)
    assert said[0].endswith(": 1 reason"), said
    assert said[1].startswith(f"  timing margin shrank: {test} :: "), said
    # every test passed, and the page does not say PASS: the run exits 1
    page = (tmp_path / "shrank" / "latest" / "report.html").read_text(encoding="utf-8")
    assert '<span class="v v-REGRESSED">REGRESSED</span> 3 tests' in page
    # the same shrink inside a looser threshold: no reason (the margin fell by half of the baseline's)
    done = _run(tmp_path, "loose", SECTION, "--baseline", str(wider), "--baseline-threshold", "60")
    assert done.returncode == 0, done.stdout + done.stderr
    assert _gate_lines(done.stdout)[0].startswith("gate: NO REGRESSION"), done.stdout


def test_a_baseline_of_another_selection_gates_only_the_tests_both_ran(tmp_path, baseline):
    done = _run(tmp_path, "reports", ONE_TEST, "--baseline", str(baseline), "--emulator-faults", "answer_late")
    assert done.returncode == 1, done.stdout + done.stderr
    said = _gate_lines(done.stdout)
    assert "(1 tests both ran; 2 of the baseline's not run here;" in said[0], said
    assert _record(tmp_path, "reports")["info"]["gate"]["compared"] == {"tests": 1, "only_in_baseline": 2, "only_in_run": 0}


def test_a_baseline_that_shares_no_test_with_the_selection_is_refused_before_any_test(tmp_path, baseline):
    done = _run(tmp_path, "reports", "4.4.20", "--baseline", str(baseline))
    assert done.returncode == 2, done.stdout + done.stderr
    said = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(said) == 1 and f"--baseline {baseline}: that run has no verdict of any of the" in said[0], done.stderr
    assert "sections 4.4.3" in said[0]
    assert not (tmp_path / "reports").exists(), "a refused run wrote a report"
