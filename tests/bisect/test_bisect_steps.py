"""The bisect's driver (ckesc/bisect/steps.py) and its report, with a scripted runner in place of ``ckesc run`` (the
real one is tried in tests/harness/test_bisect_cli.py): a line per step, each run in its own directory, and a Ctrl-C
that leaves the steps so far reported."""

from __future__ import annotations

import json
from pathlib import Path

from ckesc.bisect import report
from ckesc.bisect.core import Outcome
from ckesc.bisect.steps import StepRun, bisect


def images(tmp_path: Path, n: int) -> list[Path]:
    return [tmp_path / f"b{i:02d}.bin" for i in range(1, n + 1)]


def scripted(first_bad: int, stop_at: int | None = None):
    calls: list[Path] = []

    def runner(image: Path, out: Path) -> StepRun:
        calls.append(out)
        if stop_at is not None and len(calls) == stop_at:
            raise KeyboardInterrupt
        n = int(image.stem[1:])
        return StepRun(Outcome.BAD if n >= first_bad else Outcome.GOOD, 1.0, str(out), 0)

    return runner, calls


def test_a_line_per_step_and_each_run_in_its_own_directory(tmp_path):
    runner, calls = scripted(first_bad=6)
    said: list[str] = []
    b = bisect(images(tmp_path, 8), ["4.4.27"], runner, tmp_path / "steps", tries=3, say=said.append)
    assert b.result.first_bad == 5
    assert said[0] == f"step 1: image 4/8 {tmp_path / 'b04.bin'}: good, good -> good [2.0 s]"
    assert said[-1].startswith("canary: image 1/8")
    assert [c.name for c in calls[:3]] == ["01-b04-1", "01-b04-2", "02-b06-1"]
    report.write(b, tmp_path)
    doc = json.loads((tmp_path / "bisect.json").read_text())
    assert doc["first_bad"] == {"number": 6, "image": str(tmp_path / "b06.bin")} and doc["runs"] == len(calls)
    assert (tmp_path / "bisect.txt").read_text().startswith("bisect: found after 3 steps and 1 canary step(s)")


def test_a_ctrl_c_leaves_the_steps_so_far_reported(tmp_path):
    runner, _ = scripted(first_bad=6, stop_at=4)
    b = bisect(images(tmp_path, 8), ["4.4.27"], runner, tmp_path / "steps", say=lambda _: None)
    assert b.interrupted and b.result is None and len(b.steps) == 3
    report.write(b, tmp_path)
    assert report.last_lines(b) == ["bisect: interrupted after 3 steps and 0 canary step(s): no first bad image named"]
    assert json.loads((tmp_path / "bisect.json").read_text())["ending"] == "interrupted"
