"""A soak run's reports: ``<reports>/<UTC>-soak/`` with ``results.json`` (the whole record: the watches and their
statistics, the R9 trend per minute, the findings with the frames around them, the statement), ``junit.xml`` (a
``soak`` testsuite, one testcase per watched property, written with the junit-xml package as the run's JUnit is)
and ``summary.txt`` (what the console prints at the end)."""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path
from typing import Any

from junit_xml import TestCase, TestSuite, to_xml_report_string

from .statement import duration_text

#: findings printed in the summary (every kept one is in results.json)
SUMMARY_FINDINGS = 10


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def run_dir(reports: str | Path) -> Path:
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    out = Path(reports) / f"{stamp}-soak"
    n = 1
    while out.exists():  # two soaks in one second
        n += 1
        out = Path(reports) / f"{stamp}-soak-{n}"
    out.mkdir(parents=True)
    return out


def write(reports: str | Path, record: dict[str, Any]) -> Path:
    """The three files of ``record`` in a new run directory under ``reports``; returns it."""
    where = run_dir(reports)
    (where / "results.json").write_text(json.dumps(record, indent=1, default=str) + "\n", encoding="utf-8")
    (where / "junit.xml").write_text(junit_xml(record), encoding="utf-8")
    (where / "summary.txt").write_text(summary_text(record, where), encoding="utf-8")
    return where


def junit_xml(record: dict[str, Any]) -> str:
    """A ``soak`` testsuite: one testcase per watched property, failed with its findings, skipped where it was never
    judged; the run's status (COMPLETED, INTERRUPTED, STOPPED, ABORTED) and bench among the suite's properties."""
    findings = record["findings"]
    cases = []
    for s in record["statement"]:
        mine = [f for f in findings if f["watch"] == s["watch"]]
        tc = TestCase(f"{s['watch']} [{' '.join(s['rules'])}]", classname="ckesc.soak", elapsed_sec=record["ran_s"],
                      stdout=s["text"])
        if s["events"]:
            text = "\n".join(f"{f['t_s']:.3f} s [{' '.join(f['rules'])}] {f['message']}" for f in mine)
            tc.add_failure_info(message=s["text"][:500], output=text or s["text"], failure_type="soak")
        elif not s["trials"] and s["unit"] != "hour":
            tc.add_skipped_info(message=f"never judged: {s['text']}")
        cases.append(tc)
    props = {"status": record["status"], "lane": record["lane"], "clock": record["clock"], "profile": record["profile"],
             "duration_s": record["duration_s"], "ran_s": record["ran_s"], "node_id": record["node_id"],
             "faults": record["faults"], "started_utc": record["started_utc"]}
    if record.get("problem"):
        props["problem"] = record["problem"]
    suite = TestSuite("soak", cases, properties=props, timestamp=record["started_utc"])
    return to_xml_report_string([suite], prettyprint=True)


def summary_text(record: dict[str, Any], where: Path | None = None) -> str:
    """What a person reads at the end: the status, what ran, the statement line per property, the first findings."""
    status = record["status"]
    head = {"COMPLETED": "completed", "INTERRUPTED": "INTERRUPTED (the report holds what was watched until then)",
            "STOPPED": "stopped at its first finding (--stop-on-finding)",
            "ABORTED": f"ABORTED: {record.get('problem')}"}[status]
    host = record["host"]
    late = host["send_lateness"]
    lines = [f"soak {head}: {duration_text(record['ran_s'])} of {duration_text(record['duration_s'])} on "
             f"{record['lane']} ({record['clock']} clock) in {record['wall_s']:g} s of wall time, node {record['node_id']}, "
             f"{record['frames']['total']} frames",
             f"host stream: {host['stream_frames']} RawCommand_{record['plan']['format']} at {record['plan']['rate_hz']:g} Hz, "
             f"{host['stream_skipped']} skipped; sent late by p50 {late['p50_ms']} ms, p99 {late['p99_ms']} ms, "
             f"max {late['max_ms']} ms (the host's jitter)",
             "statement:"]
    lines += [f"  {s['watch']:<20} {s['text']}" for s in record["statement"]]
    findings = record["findings"]
    total = len(findings) + record["findings_not_kept"]
    if total:
        lines.append(f"findings: {total}" + (f" ({record['findings_not_kept']} counted, not kept)"
                                             if record["findings_not_kept"] else ""))
        for f in findings[:SUMMARY_FINDINGS]:
            lines.append(f"  {f['t_s']:.3f} s [{' '.join(f['rules'])}] {f['watch']}: {f['message']}")
        if len(findings) > SUMMARY_FINDINGS:
            lines.append(f"  ... {len(findings) - SUMMARY_FINDINGS} more in results.json")
    else:
        lines.append("findings: none")
    if where is not None:
        lines.append(f"reports: {where}")
    return "\n".join(lines) + "\n"
