"""``ckesc selftest``: the suite tests itself against the emulator's faults.

Against the faultless emulator every conformance test must pass. For every fault switch, the
suite run against it must fail, and every failing test must cite one of the requirement ids the
fault names (``ckesc/emulator/faults.py``): a fault that fails nothing means a rule the suite does
not really check (except a fault that breaks only OBSERVE rules, which must fail nothing); a failing test that does not cite the broken rule means a test that fails for
the wrong reason, or cites the wrong clause. The result is the table fault -> failing tests.

Each run is a separate ``pytest`` process (the simulated lane is deterministic), ``--jobs`` at a time.
"""

from __future__ import annotations

import ast
import functools
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from .emulator.faults import FAULTS
from .harness.causes import broken_outside_a_fail
from .protocol.requirements import requirement

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

    @property
    def ok(self) -> bool:
        return not self.problem


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


def run_suite(fault: str | None, pytest_args: list[str] = (), scope: str = "full") -> FaultRun:
    rules = FAULTS[fault].rules if fault else ()
    run = FaultRun(fault, rules)
    with tempfile.TemporaryDirectory(prefix="ckesc-selftest-") as tmp:
        cmd = [sys.executable, "-m", "pytest", "--pyargs", *scope_targets(fault, scope), "-q", "-p", "no:cacheprovider",
               # deterministic, as ckesc run: the plugin's run order (pytest-randomly off), labgrid only a library
               "-p", "no:randomly", "-p", "no:labgrid", "--ckesc-reports", tmp, "--ckesc-trace-format", "none", "--ckesc-no-html", *pytest_args]  # results.json is read
        if fault:
            cmd += ["--emulator-faults", fault]
        try:
            done = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONHASHSEED": "0"},
                                  timeout=RUN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            run.problem = f"the suite run did not finish in {RUN_TIMEOUT_S} s (a hang in the emulator or the suite)"
            return run
        reports = sorted(Path(tmp).glob("*/results.json"))
        if not reports:
            run.problem = f"no report (pytest exit {done.returncode}): {done.stdout[-800:]}{done.stderr[-800:]}"
            return run
        doc = json.loads(reports[-1].read_text())
    results = doc["results"]
    run.ran = len(results)
    for r in results:
        if r["outcome"] == "FAIL":
            # a test failed by the bus rules (ckesc/evidence) also cites the ids of the rules the traffic broke
            run.failing.append((r["nodeid"], list(dict.fromkeys(r["requirements"] + r.get("bus_rules", [])))))
            if r.get("bus_rules") and not set(r["requirements"]) & set(rules):  # failed for the bus rules alone
                run.bus_failed.append(r["nodeid"])
                run.bus_rules = list(dict.fromkeys(run.bus_rules + r["bus_rules"]))
        elif r["outcome"] == "ERROR":
            run.errors.append(f"{r['nodeid']}: {r['message'][:200]}")
        elif broken_outside_a_fail(r):  # a bus rule broken while a SKIPPED test ran: the rule's failure
            run.failing.append((r["nodeid"], list(r["bus_rules"])))
            run.bus_failed.append(r["nodeid"])
            run.bus_rules = list(dict.fromkeys(run.bus_rules + r["bus_rules"]))
    if fault is None:
        if run.failing or run.errors:
            run.problem = f"{len(run.failing)} failed and {len(run.errors)} errored against the faultless emulator"
    elif observe_only(rules):
        # an OBSERVE rule is recorded, never failed: the fault must fail nothing
        if run.failing:
            run.problem = f"{len(run.failing)} test(s) failed for a fault that breaks only OBSERVE rule(s) {', '.join(rules)}"
        elif run.errors:
            run.problem = f"{len(run.errors)} test(s) errored: {run.errors[0]}"
    else:
        wrong = [t for t, ids in run.failing if not set(ids) & set(rules)]
        if not run.failing:
            run.problem = f"no test failed (fault breaks {', '.join(rules)})"
        elif wrong:
            run.problem = f"{len(wrong)} failing test(s) cite none of {', '.join(rules)}: {', '.join(wrong[:5])}"
        elif run.errors:
            run.problem = f"{len(run.errors)} test(s) errored: {run.errors[0]}"
    return run


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
        lines.append(f"| {name} | {' '.join(r.rules)} | {tests or '-'} | {verdict} |")
    return "\n".join(lines)
