"""The report of a batch (``ckesc run --rig``): every bench's own run under ``<batch>/<bench>/`` as one
bench's run writes it, and beside them

* ``batch.json``: each bench's status (PASS, FAIL, ABSENT, ABORTED, BROKEN, INTERRUPTED) and why, its DUT's
  identity, its verdict counts and the worst verdict of each section;
* ``batch.html``: the benches, a bench x section verdict matrix, the DUTs' identities side by side and the
  requirement x bench matrix (both from :mod:`.compare`), with links to each bench's report;
* ``junit.xml``: every bench's JUnit merged with junitparser, one testsuite per bench and section
  (``<bench>: <section> <title>``, classnames ``ckesc.<bench>.<section>``); a bench without a report is
  one testsuite with one ERROR case saying why.

A bench's status:

| status | meaning |
|---|---|
| PASS | its run ended with no FAIL or ERROR (with ``--strict``: nor INCONCLUSIVE) |
| FAIL | a test FAILed or ERRORed, or a bus rule was broken while a SKIPPED test ran |
| ABSENT | its bench could not be used (the bus did not open, a labgrid place was not had) or its DUT did not answer before any test ran |
| ABORTED | its DUT stopped answering or its bench went away mid-run: the tests that ran have verdicts |
| BROKEN | its run ended without a report (the worker process died) |
| INTERRUPTED | Ctrl-C / SIGTERM: stopped with zero throttle; the tests that ran have verdicts |
"""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

from ..protocol.requirements import SECTION_TITLES, VERDICTS, section_key
from ..reporting import compare, comparing
from ..reporting.exits import ExitStatus, failing, failing_verdicts, worst
from ..reporting.htmlkit import CSS, badge, e
from ..reporting.report import classname
from ..reporting.results import RunRecord, requirement_result

STATUSES = ("PASS", "FAIL", "ABSENT", "ABORTED", "BROKEN", "INTERRUPTED")


def bench_status(doc: RunRecord | dict[str, Any] | None, *, setup_error: str | None = None, crash: str | None = None,
                 strict: bool = False) -> tuple[str, str]:
    """(status, why) of one bench from its ``results.json`` (None: there is none), the set-up error its worker
    met before any test, or how its worker died."""
    if setup_error:
        return "ABSENT", setup_error
    if doc is None:
        return "BROKEN", crash or "the bench's run ended without a report"
    record = doc if isinstance(doc, RunRecord) else RunRecord.from_json(doc)
    info, results = record.info, record.results
    why = str(info.get("incomplete") or "")
    if why.startswith("aborted"):
        return ("ABORTED" if results else "ABSENT"), why.removeprefix("aborted: ")
    if why.startswith("interrupted"):
        return "INTERRUPTED", why
    failed = failing(results, strict=strict)
    if bad := [r for r in failed if r.outcome in failing_verdicts(strict=strict)]:
        return "FAIL", f"{len(bad)} of {len(results)} tests " + ("FAILed, ERRORed or were INCONCLUSIVE" if strict else
                                                                  "FAILed or ERRORed")
    if failed:
        return "FAIL", f"bus rules broken while {len(failed)} SKIPPED test(s) ran"
    if not results:
        return "BROKEN", crash or why or "no test ran"
    return "PASS", why if why.startswith("subset") else ""


#: a bench's status as a run's exit status: the batch's is the worst of them (:func:`~ckesc.reporting.exits.worst`)
STATUS_EXITS = {"PASS": ExitStatus.OK, "FAIL": ExitStatus.FAILED, "ABSENT": ExitStatus.ABORTED,
                "ABORTED": ExitStatus.ABORTED, "BROKEN": ExitStatus.ABORTED, "INTERRUPTED": ExitStatus.INTERRUPTED}


def exit_status(statuses: list[str], *, interrupted: bool = False) -> ExitStatus:
    """The batch's exit status: 130 interrupted, 1 a bench FAILed, 3 a bench ABSENT, ABORTED or BROKEN, 0 all passed."""
    return worst([STATUS_EXITS[s] for s in statuses] + ([ExitStatus.INTERRUPTED] if interrupted else []))


def read_results(bench_dir: Path) -> RunRecord | None:
    """The bench's results.json, None when there is none this version reads."""
    try:
        return RunRecord.read(bench_dir / "results.json")
    except (OSError, ValueError, KeyError, TypeError):
        return None


def bench_record(name: str, bench_dir: Path, batch_dir: Path, *, description: str = "", command: str = "",
                 setup_error: str | None = None, crash: str | None = None, strict: bool = False) -> dict[str, Any]:
    """One bench's line of ``batch.json``."""
    doc = read_results(bench_dir)
    status, why = bench_status(doc, setup_error=setup_error, crash=crash, strict=strict)
    rel = bench_dir.relative_to(batch_dir).as_posix() if bench_dir.is_relative_to(batch_dir) else str(bench_dir)
    rec: dict[str, Any] = {"name": name, "description": description, "status": status, "why": why, "command": command,
                           "report_dir": rel, "counts": {}, "sections": {}, "identity": {}}
    if doc is not None:
        rec["counts"] = {str(v): n for v, n in Counter(r.outcome for r in doc.results).items()}
        by_section: dict[str, list[str]] = defaultdict(list)
        for r in doc.results:
            by_section[r.section or ""].append(r.outcome)
        for n in doc.not_run:
            by_section.setdefault(n.get("section") or "", [])
        rec["sections"] = {s: (requirement_result(v) if v else compare.NOT_RUN)
                           for s, v in sorted(by_section.items(), key=lambda kv: section_key(kv[0]))}
        rec["identity"] = compare.identity(doc.info, name)
        rec["run_id"] = doc.info.get("run_id")
        for f in ("report.html", "summary.txt", "junit.xml", "results.json"):
            if (bench_dir / f).is_file():
                rec.setdefault("files", {})[f] = f"{rel}/{f}"
    return rec


def batch_doc(records: list[dict[str, Any]], *, rig: str, started: float, finished: float, interrupted: bool) -> dict[str, Any]:
    statuses = [r["status"] for r in records]
    sections = sorted({s for r in records for s in r["sections"]}, key=section_key)
    return {"rig": rig, "started": started, "finished": finished, "seconds": round(finished - started, 3),
            "interrupted": interrupted, "exit_status": exit_status(statuses, interrupted=interrupted),
            "statuses": dict(Counter(statuses)), "sections": sections, "benches": records}


def progress_line(rec: dict[str, Any], seconds: float | None = None, where: Path | None = None) -> str:
    """One bench finished, for the console (``where``: the batch's directory, as the console should name it)."""
    counts = ", ".join(f"{n} {v}" for v in VERDICTS for k, n in rec["counts"].items() if k == v)
    took = f" in {seconds:.1f} s" if seconds is not None else ""
    return (f"bench {rec['name']}: {rec['status']}{took}" + (f" ({counts})" if counts else "")
            + (f": {rec['why']}" if rec["why"] and rec["status"] != "PASS" else "") + f"  {(where / rec['report_dir']) if where else rec['report_dir']}/")


# ------------------------------------------------------------------------------------------ JUnit
def merged_junit(records: list[dict[str, Any]], batch_dir: Path) -> str:
    """Every bench's ``junit.xml`` as one document: one testsuite per bench and section (junitparser)."""
    from junitparser import Error, JUnitXml, TestCase, TestSuite

    merged = JUnitXml(name=f"ckesc batch {batch_dir.name}")
    for rec in records:
        path = batch_dir / rec["report_dir"] / "junit.xml"
        if path.is_file():
            xml = JUnitXml.fromfile(str(path))
            suites = [xml] if isinstance(xml, TestSuite) else list(xml)
            for suite in suites:
                suite.name = f"{rec['name']}: {suite.name}"
                suite.add_property("bench", rec["name"])
                suite.add_property("bench_status", rec["status"])
                for case in suite:
                    case.classname = _bench_classname(rec["name"], case.classname or "")
                merged.add_testsuite(suite)
            continue
        suite = TestSuite(f"{rec['name']}: bench")
        suite.add_property("bench", rec["name"])
        suite.add_property("bench_status", rec["status"])
        case = TestCase("bench", classname=f"ckesc.{rec['name']}.bench")
        case.result = [Error(message=f"{rec['status']}: {rec['why']}"[:500], type_=rec["status"])]
        suite.add_testcase(case)
        merged.add_testsuite(suite)
    merged.update_statistics()
    text = merged.tostring()
    return text.decode("utf-8") if isinstance(text, bytes) else str(text)


def _bench_classname(bench: str, cls: str) -> str:
    """``ckesc.s4_4_22_set_get_freq`` -> ``ckesc.<bench>.s4_4_22_set_get_freq``: Jenkins shows a package per bench
    with a class per section, and GitLab keys the cases of two benches apart."""
    head, _, tail = cls.partition(".")
    return f"{head or 'ckesc'}.{bench}.{tail or classname('')[6:]}"


# ------------------------------------------------------------------------------------------ HTML
def page(doc: dict[str, Any], batch_dir: Path) -> str:
    """``batch.html``: self-contained, in report.html's style."""
    records = doc["benches"]
    overall = {ExitStatus.OK: "PASS", ExitStatus.INTERRUPTED: "INTERRUPTED"}.get(doc["exit_status"], "FAIL")
    counts = ", ".join(f"{n} {s}" for s in STATUSES for k, n in doc["statuses"].items() if k == s)
    parts = [f"<header><h1>CKESC batch</h1><p class=run>{badge(overall)} {len(records)} benches ({e(counts)}), rig "
             f"{e(doc['rig'])}, {doc['seconds']:.1f} s; exit status {doc['exit_status']}</p>"
             + ("<p class=banner role=alert>INTERRUPTED: every bench was stopped with zero throttle; each report says what "
                "ran</p>" if doc["interrupted"] else "") + "</header>",
             _bench_table(records), _section_matrix(doc)]
    runs = []
    for rec in records:
        d = read_results(batch_dir / rec["report_dir"])
        if d is not None:
            try:
                run = compare.parse_run(d, label=rec["name"])
            except comparing.RunError:
                continue
            runs.append((rec["name"], run))
    if len(runs) >= 2:
        cmp = compare.compare([r for _, r in runs])
        for head, (name, _) in zip(cmp["runs"], runs):
            head["letter"] = name  # the benches head the columns
        matrix = compare.matrix_table(cmp).replace("Requirements x runs", "Requirements x benches")
        parts += [compare.identity_table(cmp["runs"]), matrix]
    elif runs:
        name, run = runs[0]
        parts.append(compare.identity_table([{"letter": name, "label": run.label,
                                                "identity": compare.identity(run.info, run.label)}]))
    return (f"<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>CKESC batch {e(batch_dir.name)}</title>"
            f"<style>{CSS}{comparing.EXTRA_CSS}{_EXTRA_CSS}</style></head><body>\n"
            + "\n".join(parts) + "\n</body></html>\n")


def _links(rec: dict[str, Any]) -> str:
    files = rec.get("files") or {}
    return " ".join(f'<a href="{e(path)}">{e(name)}</a>' for name, path in files.items()) or "no report"


def _bench_table(records: list[dict[str, Any]]) -> str:
    rows = []
    for rec in records:
        ident = rec["identity"]
        dut = ", ".join(f"{k} {ident[k]}" for k in ("firmware date", "hardware version", "node id", "profile", "lane")
                        if k in ident)
        counts = ", ".join(f"{n} {v}" for v in VERDICTS for k, n in rec["counts"].items() if k == v)
        rows.append(f'<tr data-bench="{e(rec["name"])}" data-status="{e(rec["status"])}"><th>{e(rec["name"])}'
                    f'<div class=note>{e(rec["description"])}</div></th><td>{badge(rec["status"])}</td>'
                    f'<td>{e(rec["why"])}</td><td>{e(dut)}</td><td>{e(counts)}</td><td>{_links(rec)}</td></tr>')
    return ("<section id=benches><h2>Benches</h2><table class=benches><tr><th>bench</th><th>status</th><th>why</th>"
            f"<th>DUT</th><th>verdicts</th><th>reports</th></tr>{''.join(rows)}</table></section>")


def _section_matrix(doc: dict[str, Any]) -> str:
    records = doc["benches"]
    heads = "".join(f'<th data-bench="{e(r["name"])}">{e(r["name"])}</th>' for r in records)
    rows = []
    for s in doc["sections"]:
        cells = []
        for r in records:
            v = r["sections"].get(s, compare.NOT_RUN if r["sections"] else r["status"])
            cells.append(f'<td class="cell c-{e(v.replace(" ", "-"))}" data-bench="{e(r["name"])}">{e(v)}</td>')
        rows.append(f'<tr data-section="{e(s)}"><th>{e(s)} {e(SECTION_TITLES.get(s, ""))}</th>{"".join(cells)}</tr>')
    return (f"<section id=sections><h2>Sections x benches</h2><p class=note>Each cell: the worst verdict of the section's "
            f"tests on that bench.</p><table class=matrix><tr><th>section</th>{heads}</tr>{''.join(rows)}</table></section>")


_EXTRA_CSS = """
.v-ABSENT{background:#953800}.v-ABORTED{background:#953800}.v-BROKEN{background:#6e7781}.v-INTERRUPTED{background:#bf8700}
.benches td{font-size:.85rem}.c-NOT-RUN{color:#afb8c1}
"""


def write(batch_dir: Path, records: list[dict[str, Any]], *, rig: str, started: float, finished: float,
          interrupted: bool) -> dict[str, Any]:
    """Write ``batch.json``, ``batch.html`` and the merged ``junit.xml`` into ``batch_dir``; returns the doc."""
    doc = batch_doc(records, rig=rig, started=started, finished=finished, interrupted=interrupted)
    (batch_dir / "batch.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    (batch_dir / "junit.xml").write_text(merged_junit(records, batch_dir), encoding="utf-8")
    (batch_dir / "batch.html").write_text(page(doc, batch_dir), encoding="utf-8")
    return doc
