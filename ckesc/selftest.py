"""``ckesc selftest``: the suite tests itself against the emulator's faults and its conforming variants.

Against the faultless emulator every conformance test must pass. For every fault switch, the
suite run against it must fail, and every failing test must cite one of the requirement ids the
fault names (``ckesc/emulator/faults.py``): a fault that fails nothing means a rule the suite does
not really check (except a fault that breaks only OBSERVE rules, which must fail nothing); a failing test that does not cite the broken rule means a test that fails for
the wrong reason, or cites the wrong clause. The result is the table fault -> failing tests.

An interaction fault (``kind="interaction"``: a defect where two features meet) need not fail the suite, which tests
features one at a time: the table says whether the suite catches it, and by which tests, or leaves it to ``ckesc
explore``. A test that fails for it must still cite one of its rules.

A soak fault (``kind="soak"``: a long-run defect, R19) shows only after an onset longer than the whole suite (tens
of minutes of power or of an uninterrupted RawCommand stream): the suite must MISS it, every test passing as against
the faultless emulator, and the table says it is found only by soak (``ckesc soak``). A test that fails for it is a
PROBLEM: the fault's onset is inside the suite's run (it is no long-run defect), or a test fails for another reason.

It must also have no false teeth: against every conforming variant (``ckesc/emulator/variants.py``: a
behaviour the document, or a stated READING, allows) no test may FAIL or ERROR; one that does is the
suite's bug, a reading stricter than the document. ``--variants each`` runs every alternative of every
freedom alone (so a FAIL is pinned to it), ``covering`` the few combinations that play them all,
``drawn`` the combinations ``--seeds`` draw. INCONCLUSIVE is allowed there (counted, with its reasons).

Each run is a separate ``pytest`` process (the simulated lane is deterministic), ``--jobs`` at a time.
"""

from __future__ import annotations

import ast
import functools
import os
import re
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .emulator import variants
from .emulator.faults import FAULTS, INTERACTION, SINGLE, SOAK
from .protocol.requirements import Verdict, requirement
from .reporting.causes import broken_outside_a_fail
from .reporting.durations import duration_text
from .reporting.results import RunRecord

RUN_TIMEOUT_S = 600  # one suite run takes seconds in the simulated lane; this only stops a hang


@dataclass
class FaultRun:
    fault: str | None
    rules: tuple[str, ...]
    failing: list[tuple[str, list[str]]] = field(default_factory=list)  # (test, its requirement ids)
    errors: list[str] = field(default_factory=list)
    bus_failed: list[str] = field(default_factory=list)  # failed by the live bus rules (ckesc/evidence) only
    bus_rules: list[str] = field(default_factory=list)  # the rule ids those failures named
    ran: int = 0
    problem: str = ""
    kind: str = SINGLE  # the fault's kind (faults.SINGLE, faults.INTERACTION or faults.SOAK)
    inconclusive: list[str] = field(default_factory=list)  # tests the fault left INCONCLUSIVE

    @property
    def ok(self) -> bool:
        return not self.problem

    @property
    def caught(self) -> bool:
        """Whether some test FAILed for the fault (for an interaction fault: the suite catches it)."""
        return bool(self.failing)


SCOPES = ("full", "cited")


@functools.lru_cache(maxsize=1)
def citations() -> dict[str, set[str]]:
    """requirement id -> the conformance modules (dotted) with a test citing it, read from the modules'
    source (their ``@pytest.mark.requirement`` decorators) without a pytest run."""
    import conformance

    out: dict[str, set[str]] = {}
    for path in sorted(Path(conformance.__file__).parent.glob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test"):
                for deco in node.decorator_list:
                    if (isinstance(deco, ast.Call) and isinstance(deco.func, ast.Attribute)
                            and deco.func.attr == "requirement"):
                        for arg in deco.args:
                            if isinstance(arg, ast.Constant):
                                out.setdefault(arg.value, set()).add(f"conformance.{path.stem}::{node.name}")
    return out


def scope_targets(fault: str | None, scope: str) -> list[str]:
    """What a run covers: the whole suite, or (``cited``) the modules with a test citing one of the
    fault's rules - where a caught fault must show; a test elsewhere failing for the wrong reason is
    only seen by the full scope."""
    if scope == "full" or fault is None:
        return ["conformance"]
    cited = citations()
    modules = {t.split("::")[0] for rule in FAULTS[fault].rules for t in cited.get(rule, ())}
    return sorted(modules) or ["conformance"]


def _suite(targets: list[str], args: list[str]) -> tuple[list[dict[str, Any]] | None, str]:
    """One suite run in its own pytest process: its results.json results, or None and why there are none."""
    with tempfile.TemporaryDirectory(prefix="ckesc-selftest-") as tmp:
        cmd = [sys.executable, "-m", "pytest", "--pyargs", *targets, "-q", "-p", "no:cacheprovider",
               # deterministic, as ckesc run: the plugin's run order (pytest-randomly off), labgrid only a library
               "-p", "no:randomly", "-p", "no:labgrid", "--ckesc-reports", tmp, "--ckesc-trace-format", "none", "--ckesc-no-html", *args]  # results.json is read
        try:
            done = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONHASHSEED": "0"},
                                  timeout=RUN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            return None, f"the suite run did not finish in {RUN_TIMEOUT_S} s (a hang in the emulator or the suite)"
        reports = sorted(Path(tmp).glob("*/results.json"))
        if not reports:
            return None, f"no report (pytest exit {done.returncode}): {done.stdout[-800:]}{done.stderr[-800:]}"
        return RunRecord.read(reports[-1]).results, ""


def run_suite(fault: str | None, pytest_args: list[str] = (), scope: str = "full") -> FaultRun:
    rules = FAULTS[fault].rules if fault else ()
    run = FaultRun(fault, rules, kind=FAULTS[fault].kind if fault else SINGLE)
    results, run.problem = _suite(scope_targets(fault, scope), [*pytest_args, *(["--emulator-faults", fault] if fault else [])])
    if results is None:
        return run
    return judge(run, results)


def judge(run: FaultRun, results: list[Any]) -> FaultRun:
    """The self-test's judgement of one suite run (its results.json results) against ``run.fault``."""
    fault, rules = run.fault, run.rules
    run.ran = len(results)
    for r in results:
        if r.outcome == Verdict.FAIL:
            # a test failed by the bus rules (ckesc/evidence) also cites the ids of the rules the traffic broke
            run.failing.append((r.nodeid, list(dict.fromkeys(r.requirements + r.bus_rules))))
            if r.bus_rules and not set(r.requirements) & set(rules):  # failed for the bus rules alone
                run.bus_failed.append(r.nodeid)
                run.bus_rules = list(dict.fromkeys(run.bus_rules + r.bus_rules))
        elif r.outcome == Verdict.ERROR:
            run.errors.append(f"{r.nodeid}: {r.message[:200]}")
        elif r.outcome == Verdict.INCONCLUSIVE:
            run.inconclusive.append(r.nodeid)
        elif broken_outside_a_fail(r):  # a bus rule broken while a SKIPPED test ran: the rule's failure
            run.failing.append((r.nodeid, list(r.bus_rules)))
            run.bus_failed.append(r.nodeid)
            run.bus_rules = list(dict.fromkeys(run.bus_rules + r.bus_rules))
    if fault is None:
        if run.failing or run.errors:
            run.problem = f"{len(run.failing)} failed and {len(run.errors)} errored against the faultless emulator"
    elif run.kind == SOAK:
        # a long-run defect: the suite must miss it (the proof that only a soak finds it)
        if run.failing:
            run.problem = (f"{len(run.failing)} test(s) failed for a soak fault, which the suite must miss (its onset "
                           f"{_minutes(FAULTS[fault].onset_s)} is inside the suite's run?): "
                           f"{', '.join(t for t, _ in run.failing[:5])}")
        elif run.errors:
            run.problem = f"{len(run.errors)} test(s) errored: {run.errors[0]}"
    elif observe_only(rules):
        # an OBSERVE rule is recorded, never failed: the fault must fail nothing
        if run.failing:
            run.problem = f"{len(run.failing)} test(s) failed for a fault that breaks only OBSERVE rule(s) {', '.join(rules)}"
        elif run.errors:
            run.problem = f"{len(run.errors)} test(s) errored: {run.errors[0]}"
    else:
        wrong = [t for t, ids in run.failing if not set(ids) & set(rules)]
        if not run.failing and run.kind != INTERACTION:  # an interaction fault may pass the suite: explore's
            run.problem = f"no test failed (fault breaks {', '.join(rules)})"
        elif wrong:
            run.problem = f"{len(wrong)} failing test(s) cite none of {', '.join(rules)}: {', '.join(wrong[:5])}"
        elif run.errors:
            run.problem = f"{len(run.errors)} test(s) errored: {run.errors[0]}"
    return run


def _minutes(seconds: float | None) -> str:
    """An onset for people: ``20 min``, ``54 min 37 s`` (:func:`~ckesc.reporting.durations.duration_text`)."""
    return "-" if seconds is None else duration_text(seconds)


def observe_only(rules: tuple[str, ...]) -> bool:
    """Whether every rule a fault breaks is OBSERVE: no test may fail for it."""
    return bool(rules) and all(requirement(r).strength == "OBSERVE" for r in rules)


def selftest(faults: list[str] | None = None, jobs: int | None = None, pytest_args: list[str] = (),
             progress=None, scope: str = "full") -> list[FaultRun]:
    names = [None] + list(faults if faults is not None else FAULTS)
    if scope == "cited":
        citations()  # read once, here: ast.parse from several threads at once can fail in CPython 3.11
    jobs = jobs or max(os.cpu_count() or 1, 1)
    out: list[FaultRun] = []
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        for run in pool.map(lambda f: run_suite(f, list(pytest_args), scope), names):
            out.append(run)
            if progress:
                progress(run, len(out), len(names))
    return out


@dataclass
class VariantRun:
    """The whole suite against one conforming variant: nothing may FAIL or ERROR."""

    label: str  # "exp_frames=msg2", "covering 2/3", "drawn 7"
    options: dict[str, Any]
    failing: list[str] = field(default_factory=list)  # "test: message"
    errors: list[str] = field(default_factory=list)
    inconclusive: list[str] = field(default_factory=list)  # "test: reason"
    ran: int = 0
    problem: str = ""

    @property
    def ok(self) -> bool:
        return not self.problem

    @property
    def allowed_by(self) -> list[str]:
        return list(dict.fromkeys(i for name in self.options for i in variants.FREEDOMS[name].allowed_by))

    def what(self) -> str:
        text = variants.describe(self.options)
        return text if self.label == text else f"{self.label} ({text})"


VARIANT_SETS = ("each", "covering", "drawn", "all")
_VERDICT_PREFIX = re.compile(r"^([\w.]+(Error|Exception|Inconclusive): )?(INCONCLUSIVE: )?")


def variant_matrix(which: str = "all", seeds: list[int] = ()) -> list[tuple[str, dict[str, Any]]]:
    """(label, EscConfig options) per run: ``each`` alternative alone, the ``covering`` combinations, the
    combinations ``seeds`` draw (``drawn``), or ``all`` of them."""
    out: list[tuple[str, dict[str, Any]]] = []
    if which in ("each", "all"):
        out += [(variants.describe(v), v) for v in variants.each()]
    if which in ("covering", "all"):
        cover = variants.covering()
        out += [(f"covering {i}/{len(cover)}", v) for i, v in enumerate(cover, 1)]
    if which in ("drawn", "all"):
        out += [(f"drawn {seed}", variants.draw(seed)) for seed in seeds]
    return out


def run_variant(label: str, options: dict[str, Any], pytest_args: list[str] = ()) -> VariantRun:
    run = VariantRun(label, options)
    args = [a for k, v in options.items() for a in ("--emulator-option", f"{k}={v}")]
    results, run.problem = _suite(["conformance"], [*pytest_args, *args])
    if results is None:
        return run
    run.ran = len(results)
    for r in results:
        bucket = {Verdict.FAIL: run.failing, Verdict.ERROR: run.errors, Verdict.INCONCLUSIVE: run.inconclusive}.get(r.outcome)
        if bucket is not None:
            message = _VERDICT_PREFIX.sub("", r.message.strip()).splitlines()
            bucket.append(f"{r.nodeid}: {message[0][:160] if message else ''}")
    if run.failing or run.errors:
        first = (run.failing or run.errors)[0].split(": ", 1)[0]
        verb = "FAILed" if run.failing else "ERRORed"
        more = len(run.failing) + len(run.errors) - 1
        run.problem = (f"the suite's bug: {first} {verb} on conforming variant {run.what()} (allowed by "
                       f"{', '.join(run.allowed_by)})" + (f"; and {more} more" if more else ""))
    return run


def variant_selftest(matrix: list[tuple[str, dict[str, Any]]], jobs: int | None = None, pytest_args: list[str] = (),
                     progress=None) -> list[VariantRun]:
    jobs = jobs or max(os.cpu_count() or 1, 1)
    out: list[VariantRun] = []
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        for run in pool.map(lambda lv: run_variant(lv[0], lv[1], list(pytest_args)), matrix):
            out.append(run)
            if progress:
                progress(run, len(out), len(matrix))
    return out


def headline(faults: list[FaultRun], variant_runs: list[VariantRun]) -> str:
    """The self-test in one line: ``every fault caught, no variant failed``, or what did not hold."""
    bad_faults = [r for r in faults[1:] if not r.ok]
    bad_variants = [r for r in variant_runs if not r.ok]
    parts = []
    if faults and faults[0].fault is None:
        parts.append("the faultless emulator passes" if faults[0].ok else "the faultless emulator does NOT pass")
    if len(faults) > 1:
        interactions = [r for r in faults[1:] if r.kind == INTERACTION]
        soaks = [r for r in faults[1:] if r.kind == SOAK]
        bad = [r for r in bad_faults if r.kind != SOAK]
        caught = "every single fault caught" if interactions or soaks else "every fault caught"
        if len(faults) - 1 > len(soaks):
            parts.append(caught if not bad else f"{len(bad)} of {len(faults) - 1 - len(soaks)} faults NOT caught cleanly")
        if interactions:
            parts.append(f"{sum(r.caught for r in interactions)} of {len(interactions)} interaction faults caught by "
                         "the suite (the rest left to ckesc explore)")
        if soaks:
            missed = sum(r.ok for r in soaks)
            parts.append(f"{missed} of {len(soaks)} long-run faults missed by the suite, as they must be (found only "
                         "by soak)" + (f"; {len(soaks) - missed} NOT" if missed < len(soaks) else ""))
    if variant_runs:
        parts.append(f"no variant failed ({len(variant_runs)} runs)" if not bad_variants
                     else f"{len(bad_variants)} of {len(variant_runs)} variant runs FAILED or ERRORED (the suite's bugs)")
    return ", ".join(p for p in parts if p)


def variant_table(runs: list[VariantRun]) -> str:
    lines = ["| conforming variant | allowed by | tests | inconclusive | verdict |", "|---|---|---|---|---|"]
    for r in runs:
        reasons = sorted({i.split(": ", 1)[-1][:100] for i in r.inconclusive})  # the same reason once
        inc = f"{len(r.inconclusive)}" + (f" ({'; '.join(reasons[:2])}{'; ...' if len(reasons) > 2 else ''})" if reasons else "")
        lines.append(f"| {r.what()} | {' '.join(r.allowed_by)} | {r.ran} | {inc} | "
                     f"{'ok' if r.ok else 'PROBLEM: ' + r.problem} |")
    return "\n".join(lines)


def table(runs: list[FaultRun]) -> str:
    lines = ["| fault | rules | failing tests | verdict |", "|---|---|---|---|"]
    for r in runs:
        name = r.fault or "(none: faultless emulator)"
        # the tests that failed on their own checks; the many a bus-rule violation fails are summed up
        bus = set(r.bus_failed)
        own = [t for t, _ in r.failing if t not in bus]
        tests = "<br>".join(t.split("::", 1)[-1] for t in own[:8]) + (f"<br>... +{len(own) - 8}" if len(own) > 8 else "")
        if bus:
            tests += (f"{'<br>' if tests else ''}{len(bus)} test(s) failed by the live bus rules "
                      f"({' '.join(r.bus_rules)})")
        verdict = ("ok (OBSERVE only: recorded, never failed)" if observe_only(r.rules) else "ok") if r.ok else "PROBLEM: " + r.problem
        if r.kind == SOAK and r.ok:
            verdict = f"found only by soak: the suite misses it (onset {_minutes(FAULTS[r.fault].onset_s)})"
        if r.kind == INTERACTION and r.ok:
            verdict = (f"interaction: caught by {len(r.failing)} test(s)" if r.caught else
                       "interaction: not caught by the suite, left to ckesc explore"
                       + (f" ({len(r.inconclusive)} test(s) INCONCLUSIVE)" if r.inconclusive else ""))
        lines.append(f"| {name} | {' '.join(r.rules)} | {tests or '-'} | {verdict} |")
    return "\n".join(lines)
