"""Time left (issue #21): the run shown as protocol time planned, spent and left, checked against a real run's end."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest
from procs import CKESC, env

from ckesc.session.progress import SHRINK_S, TABLE, RunClock, read_table

LINE = re.compile(r"^time: \[(?P<where>[^\]]+)\] protocol time (?P<spent>\d+) s of ~(?P<total>\d+) s, "
                  r"(?P<elapsed>[\d:]+) elapsed, ~(?P<left>[\d:]+) left \((?P<done>\d+) of (?P<n>\d+) tests\)$")

#: how far the estimated end of a whole faultless simulated run may be from its real end, once a tenth of its
#: tests have run (the table is that run's own, so what remains is the pace correction and the run order)
ESTIMATE_ERROR = 0.10


def test_the_pace_corrects_the_plan() -> None:
    clock = RunClock({"a": 10.0, "b": 10.0, "c": 20.0})
    clock.start(lane=100.0, wall=0.0)
    assert clock.planned == 40 and clock.lane_left == 40
    assert "planned ~40 s" in clock.line("x")
    clock.finished("a", lane=130.0, wall=3.0)  # took 30 s of lane time where 10 were expected: 3x, shrunk to 1
    assert clock.pace == pytest.approx((30 + SHRINK_S) / (10 + SHRINK_S))
    assert clock.lane_left == pytest.approx(30 * clock.pace)
    assert clock.wall_left == pytest.approx(clock.lane_left * 3.0 / 30.0)  # the run's own wall/lane ratio
    clock.finished("a", lane=140.0, wall=4.0)  # a test counted once
    assert len(clock.done) == 1


def test_a_whole_run_says_its_time_left_and_ends_where_it_said(tmp_path: Path) -> None:
    done = subprocess.run([*CKESC, "run", "-q", "--reports", str(tmp_path / "reports"), "--trace-format", "none"],
                          cwd=tmp_path, env=env(tmp_path), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    doc = json.loads((tmp_path / "reports" / "latest" / "results.json").read_text())
    real_end = doc["info"]["lane_seconds"]
    lines = [m for m in map(LINE.match, done.stdout.splitlines()) if m]
    assert len(lines) >= 20, done.stdout[-3000:]  # a line as the run enters each section (CI: no terminal)
    assert lines[-1]["where"] == "end" and int(lines[-1]["done"]) == len(doc["results"])
    sections = {m["where"] for m in lines}
    assert {"4.1 UAVCAN protocols (framing)", "4.4.22 Set/Get Freq"} <= sections
    judged = [m for m in lines if int(m["done"]) >= int(m["n"]) / 10]
    assert judged
    for m in judged:
        assert abs(int(m["total"]) - real_end) <= ESTIMATE_ERROR * real_end, (m.group(0), real_end)
    # the suite's table knows every test of the suite (a test added without remaking it is estimated blind)
    missing = {r["nodeid"] for r in doc["results"]} - set(read_table())
    assert not missing, f"{len(missing)} tests not in {TABLE.name} (remake: python -m ckesc.session.progress " \
                        f"reports/latest/results.json), e.g. {sorted(missing)[:3]}"


def test_every_conformance_module_names_its_section_from_a_test_id():
    """A batch's controller has test ids only: each module of the suite (the robustness section's too) must give its
    section's heading from an id, or the batch's progress and the docs' replayed run lose it."""
    import conformance
    from ckesc.session.progress import section_of_id

    modules = sorted(p.name for p in Path(conformance.__file__).parent.glob("test_*.py"))
    assert modules
    nameless = [m for m in modules if not section_of_id(f"conformance/{m}::test_x")]
    assert not nameless, nameless
