"""Run reports: JUnit XML (one testsuite per spec section), a JSON record and a text summary,
under ``reports/<timestamp>/`` with ``reports/latest`` pointing at the newest run.

The JUnit file is built with the ``junit-xml`` package. That package has no per-testcase
properties, so each testcase's requirement ids, strength, verdict and measurements are added as
``<properties>`` afterwards (Jenkins shows them) and repeated as ``[[PROPERTY|name=value]]`` lines
in its system-out (GitLab and other readers that drop properties still show them).
"""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from collections import Counter, defaultdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from junit_xml import TestCase, TestSuite, to_xml_report_string

from .requirements import REQUIREMENTS, SECTION_TITLES

VERDICTS = ("PASS", "FAIL", "INCONCLUSIVE", "OBSERVED", "SKIPPED", "ERROR")


def _section_key(section: str) -> tuple:
    return tuple(int(p) if p.isdigit() else 999 for p in section.replace("-", ".").split("."))


def _properties(r) -> dict[str, str]:
    props = {"requirements": " ".join(r.requirements), "strength": r.strength, "verdict": r.outcome,
             "section": r.section}
    for lane, path in r.traces.items():
        props[f"trace.{lane}" if lane else "trace"] = path
    props.update(r.properties)
    for n, (what, value) in enumerate(r.observations):
        props[f"observation.{n}"] = f"{what}: {value}"
    return props


def junit_xml(results: list, info: dict[str, Any], out: Path | None = None) -> str:
    """The JUnit document; with ``out`` (the run's directory) each of a test's traces is also an
    ``[[ATTACHMENT|/absolute/path]]`` line (Jenkins' JUnit attachments plugin wants it absolute)."""
    by_section: dict[str, list] = defaultdict(list)
    for r in results:
        by_section[r.section].append(r)
    suites = []
    cases_props: list[dict[str, str]] = []
    for section in sorted(by_section, key=_section_key):
        cases = []
        for r in by_section[section]:
            props = _properties(r)
            lines = "\n".join(f"[[PROPERTY|{k}={v}]]" for k, v in props.items())
            if out is not None:
                lines += "".join(f"\n[[ATTACHMENT|{(out / path).resolve()}]]" for path in r.traces.values())
            tc = TestCase(f"{r.name} [{' '.join(r.requirements)}]", classname=f"ckesc.{section} {SECTION_TITLES.get(section, '')}".strip(),
                          elapsed_sec=round(r.duration, 6), stdout=lines, status=r.outcome)
            if r.outcome == "FAIL":
                tc.add_failure_info(message=r.message[:500], output=r.message, failure_type=r.strength)
            elif r.outcome == "ERROR":
                tc.add_error_info(message=r.message[:500], output=r.message)
            elif r.outcome in ("INCONCLUSIVE", "SKIPPED"):
                tc.add_skipped_info(message=r.message[:500] or r.outcome)
            cases.append(tc)
            cases_props.append(props)
        suites.append(TestSuite(f"{section} {SECTION_TITLES.get(section, '')}".strip(), cases,
                                properties={k: str(v) for k, v in info.items() if not isinstance(v, dict)}))
    text = to_xml_report_string(suites, prettyprint=False)
    root = ET.fromstring(text)
    for case, props in zip(root.iter("testcase"), cases_props):
        el = ET.Element("properties")
        for k, v in props.items():
            ET.SubElement(el, "property", name=k, value=v)
        case.insert(0, el)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def coverage(results: list) -> dict[str, Any]:
    """Which requirements a test checked, and which SHALL/READING ones no test of the run checked."""
    seen: dict[str, set[str]] = defaultdict(set)
    for r in results:
        for rid in r.requirements:
            seen[rid].add(r.outcome)
    judged = [rid for rid, req in REQUIREMENTS.items() if req.strength != "OBSERVE"]
    return {
        "covered": sorted(seen),
        "uncovered": sorted(rid for rid in judged if rid not in seen),
        "total": len(REQUIREMENTS),
        "judged": len(judged),
    }


def summary_text(results: list, info: dict[str, Any]) -> str:
    rows = defaultdict(Counter)
    for r in results:
        rows[r.section][r.outcome] += 1
    head = f"{'section':<10} {'title':<26} " + " ".join(f"{v[:6]:>6}" for v in VERDICTS)
    lines = [head, "-" * len(head)]
    total = Counter()
    for section in sorted(rows, key=_section_key):
        c = rows[section]
        total.update(c)
        lines.append(f"{section:<10} {SECTION_TITLES.get(section, '')[:26]:<26} " + " ".join(f"{c[v]:>6}" for v in VERDICTS))
    lines.append("-" * len(head))
    lines.append(f"{'all':<10} {'':<26} " + " ".join(f"{total[v]:>6}" for v in VERDICTS))
    cov = coverage(results)
    lines.append(f"requirements: {len(cov['covered'])} of {cov['total']} checked; "
                 f"SHALL/READING not checked in this run: {len(cov['uncovered'])}"
                 + (f" ({', '.join(cov['uncovered'][:12])}{' ...' if len(cov['uncovered']) > 12 else ''})" if cov["uncovered"] else ""))
    dut = ", ".join(f"{k}={info[k]}" for k in ("dut", "lane", "profile", "node_id", "bitrate", "power", "faults") if info.get(k) not in (None, ""))
    lines.append(f"DUT: {dut}")
    fails = [r for r in results if r.outcome in ("FAIL", "ERROR")]
    for r in fails[:20]:
        lines.append(f"  {r.outcome}: {r.nodeid}: {r.message.splitlines()[0][:160] if r.message else ''}")
    return "\n".join(lines)


def run_dir(base: Path, started: float) -> Path:
    """A new directory ``base/<UTC timestamp>[-n]/`` for a run that started at ``started``."""
    stamp = datetime.fromtimestamp(started, UTC).strftime("%Y%m%dT%H%M%SZ")
    out = base / stamp
    n = 1
    while True:
        try:
            out.mkdir(parents=True)
            return out
        except FileExistsError:
            n += 1
            out = base / f"{stamp}-{n}"


def write_reports(out: Path, results: list, info: dict[str, Any]) -> Path:
    """Write the run's reports into ``out`` (from :func:`run_dir`) and point ``latest`` at it."""
    base = out.parent
    (out / "junit.xml").write_text(junit_xml(results, info, out), encoding="utf-8")
    (out / "results.json").write_text(json.dumps({"info": info, "coverage": coverage(results),
                                                  "results": [r.__dict__ for r in results]}, indent=1, default=str),
                                      encoding="utf-8")
    (out / "summary.txt").write_text(summary_text(results, info) + "\n", encoding="utf-8")
    latest = base / "latest"
    tmp = base / f".latest-{os.getpid()}"
    try:
        if tmp.is_symlink() or tmp.exists():
            tmp.unlink()
        tmp.symlink_to(out.name)
        os.replace(tmp, latest)
    except OSError:  # no symlinks here: a text pointer instead
        (base / "LATEST").write_text(out.name + "\n")
    return out
