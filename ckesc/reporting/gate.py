"""The release gate (``ckesc run ... --baseline DIR``, issue #37): the run compared with a committed earlier run of the
same bench, a regression failing it.

The comparison is ``ckesc compare``'s (:func:`ckesc.reporting.compare.diff`, its words and threshold), over the tests
**both runs ran**: a baseline of another selection gates only what the two share (the gate says how many it compared
and how many each run had that the other did not), and one that shares no test with the run is refused before any
test runs (:func:`shared_tests`). The gate is stricter than ``ckesc compare``'s exit status in one thing: a timing
margin that shrank beyond the threshold is a reason too, even while it still passes.

A **reason** is one line; the regressed requirements first, then the regressed tests, then the margins that shrank
(:func:`judge`). The verdict is :data:`REGRESSED` with a reason, :data:`NO_REGRESSION` without, and :data:`NOT_JUDGED`
for a run that did not end (aborted, interrupted: its own status says so). The run's exit status takes the verdict in
the one place it is decided (:func:`ckesc.reporting.exits.of_run`, ``regressed``). Only :func:`load` reads a file."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ..protocol.requirements import STRENGTHS
from .compare import DEFAULT_THRESHOLD, Run, diff, flags, read_run
from .comparing import RunError

REGRESSED, NO_REGRESSION, NOT_JUDGED = "REGRESSED", "NO REGRESSION", "NOT JUDGED"
#: reasons shown on the console and in summary.txt; results.json keeps them all
SHOWN = 20
__all__ = ["DEFAULT_THRESHOLD", "NOT_JUDGED", "NO_REGRESSION", "REGRESSED", "Run", "RunError", "judge", "lines", "load",
           "not_judged", "properties", "shared_tests"]


def load(path: str | Path) -> Run:
    """The baseline at ``path``: a run's report directory or its ``results.json``, a conformance run's. Raises
    :class:`~ckesc.reporting.comparing.RunError` (one line: which and why) for anything else."""
    return read_run(path)


def shared_tests(baseline: Run, nodeids: Iterable[str]) -> list[str]:
    """Which of ``nodeids`` (the tests a run selected) the baseline has a verdict for."""
    return [n for n in nodeids if n in baseline.results]


def _restricted(run: Run, keep: set[str]) -> Run:
    return Run(label=run.label, path=run.path, info=run.info, results={n: r for n, r in run.results.items() if n in keep})


def _strongest_first(strength: str) -> int:
    """A regressed requirement's place among the reasons: SHALL first (one this version does not know last)."""
    return STRENGTHS.index(strength) if strength in STRENGTHS else len(STRENGTHS)


def judge(baseline: Run, current: Run, *, threshold: float = DEFAULT_THRESHOLD) -> dict[str, Any]:
    """The gate's record (results.json's ``info["gate"]``): the baseline, the threshold, the verdict, its reasons
    (one line each, regressed requirements first), what was compared, and the comparison's flags (notes, never
    reasons: different suite revisions, lanes, ...)."""
    both = baseline.results.keys() & current.results.keys()
    pair = diff(_restricted(baseline, both), _restricted(current, both), threshold=threshold)
    reqs = sorted(pair["requirements"]["regressed"], key=lambda r: _strongest_first(r["strength"]))
    reasons = [f"requirement {r['requirement']}" + (f" ({r['strength']})" if r["strength"] else "")
               + f" regressed: {r['before']} -> {r['after']}" for r in reqs]
    reasons += [f"test {t['test']} regressed: {t['before']} -> {t['after']}"
                + (f" (broke {' '.join(t['broke'])})" if t["broke"] else "") for t in pair["tests"]["regressed"]]
    reasons += [f"timing margin shrank: {m['measurement']}: {m['before_ms']:.4g} ms -> {m['after_ms']:.4g} ms "
                f"(measured {m['value_before_ms']:.4g} -> {m['value_after_ms']:.4g} ms, limit {m['limit_after']})"
                for m in pair["margins_shrank"]]
    if not both:
        reasons.append("nothing compared: the run has no verdict of a test the baseline ran")
    return {"baseline": baseline.path, "baseline_run": baseline.label, "threshold": threshold,
            "verdict": REGRESSED if reasons else NO_REGRESSION, "reasons": reasons,
            "compared": {"tests": len(both), "only_in_baseline": len(baseline.results.keys() - both),
                         "only_in_run": len(current.results.keys() - both)},
            "regressed": {"requirements": [r["requirement"] for r in reqs],
                          "tests": [t["test"] for t in pair["tests"]["regressed"]],
                          "margins": [m["measurement"] for m in pair["margins_shrank"]]},
            "notes": [f for f in flags([baseline, current]) if " is incomplete: SUBSET" not in f]}


def not_judged(path: str, why: str) -> dict[str, Any]:
    """The gate's record of a run it did not judge (``why``: the run aborted, was interrupted, the baseline went)."""
    return {"baseline": path, "verdict": NOT_JUDGED, "reasons": [], "why": why}


def properties(gate: dict[str, Any]) -> dict[str, str]:
    """The gate as JUnit testsuite properties: its baseline, verdict and each reason (``gate.reason.0``, ...)."""
    return {"gate.baseline": str(gate.get("baseline")), "gate.verdict": str(gate.get("verdict")),
            **{f"gate.reason.{n}": r for n, r in enumerate(gate.get("reasons", []))}}


def lines(gate: dict[str, Any] | None) -> list[str]:
    """The gate as the console's last lines and summary.txt's first: the verdict against the baseline, then one line
    per reason (at most :data:`SHOWN`), then its notes."""
    if not gate:
        return []
    if gate["verdict"] == NOT_JUDGED:
        return [f"gate: NOT JUDGED against baseline {gate['baseline']}: {gate.get('why', '')}"]
    c = gate["compared"]
    head = (f"gate: {gate['verdict']} against baseline {gate['baseline']} ({c['tests']} tests both ran"
            + (f"; {c['only_in_baseline']} of the baseline's not run here" if c["only_in_baseline"] else "")
            + (f"; {c['only_in_run']} not in the baseline" if c["only_in_run"] else "")
            + f"; margin threshold {gate['threshold'] * 100:g} %)")
    reasons = gate["reasons"]
    out = [head + (f": {len(reasons)} reasons" if len(reasons) != 1 else ": 1 reason") if reasons else head]
    out += [f"  {r}" for r in reasons[:SHOWN]]
    if len(reasons) > SHOWN:
        out.append(f"  ... {len(reasons) - SHOWN} more (results.json's gate has them all)")
    out += [f"  note: {n}" for n in gate.get("notes", [])]
    return out
