"""The bisect's report: ``bisect.json`` (every step's runs: image, outcome, time, where its run's report is, the
failing tests, the image's SHA-256) and ``bisect.txt`` (the same for a reader, the end first) in
``--reports DIR/<timestamp>-bisect/``, beside the ``steps/`` the runs wrote their reports into."""

from __future__ import annotations

import json
from pathlib import Path

from .core import Ending
from .steps import Bisect, step_line


def last_lines(b: Bisect) -> list[str]:
    """The lines that end the console and lead the text report: the first bad image named, or why there is none."""
    r = b.result
    canaries = sum(1 for s, _ in b.steps if s.canary)
    if r is None:
        return [f"bisect: interrupted after {len(b.steps) - canaries} steps and {canaries} canary step(s): no first bad "
                "image named"]
    head = (f"bisect: {r.ending.value} after {len(b.steps) - canaries} steps and {canaries} canary step(s), "
            f"{sum(len(rs) for _, rs in b.steps)} runs, {b.seconds:.1f} s")
    if r.ending is Ending.FOUND and r.first_bad is not None:
        return [head, f"first bad image: {b.name(r.first_bad)}", f"last good image: {b.name(r.good)}"]
    return [head, f"no first bad image: {r.reason}",
            f"still between: last good {b.name(r.good)}, first known bad {b.name(r.bad)}"]


def text(b: Bisect) -> str:
    lines = [*last_lines(b), "", f"selection: {' '.join(b.selection)}", f"tries: {b.tries} (a majority decides), "
             f"canary: {b.canary}", "", "steps:"]
    n = 0
    for step, runs in b.steps:
        n += not step.canary
        lines.append("  " + step_line(b, n, step, runs))
        for run in runs:
            failing = f" failing: {', '.join(run.failing)}" if run.failing else ""
            lines.append(f"    {run.outcome.value} [{run.seconds:.1f} s] {run.reports}{failing}")
    return "\n".join(lines) + "\n"


def write(b: Bisect, where: Path) -> None:
    (where / "bisect.json").write_text(json.dumps(b.record(), indent=1) + "\n", encoding="utf-8")
    (where / "bisect.txt").write_text(text(b), encoding="utf-8")
