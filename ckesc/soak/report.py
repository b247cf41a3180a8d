"""A soak run's reports: ``<reports>/<UTC>-soak/`` with ``results.json`` (the whole record: the watches and their
statistics, the R9 trend per minute, the findings with the frames around them, the statement), ``junit.xml`` (a
``soak`` testsuite, one testcase per watched property, written with the junit-xml package as the run's JUnit is),
``summary.txt`` (what the console prints at the end) and ``report.html`` (the trends over the whole run and each
finding)."""

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
    (where / "report.html").write_text(html_page(record), encoding="utf-8")
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


# ------------------------------------------------------------------------------------------ report.html
def html_page(record: dict[str, Any]) -> str:
    """``report.html``: the status, the statement per property, the trends over the whole run on one time axis (each
    report's mean interval per minute against its target, with the findings marked), the GET_ESC_ID answer delays,
    and each finding with the frames around it. Self-contained (the reports' HTML kit: inline CSS and SVG)."""
    from ..reporting.htmlkit import CSS, badge, e, figure

    status = record["status"]
    verdict = {"COMPLETED": "FAIL" if record["findings"] or record["findings_not_kept"] else "PASS"}.get(status, status)
    rows = "".join(f"<tr><td>{e(s['watch'])}</td><td>{e(' '.join(s['rules']))}</td><td>{s['events']}</td>"
                   f"<td>{e(s['text'])}</td></tr>" for s in record["statement"])
    findings = "".join(
        f"<article class=\"fail\"><h3>{f['t_s']:.3f} s: {e(f['watch'])} [{e(' '.join(f['rules']))}]</h3>"
        f"<p class=\"msg\">{e(f['message'])}</p><details><summary>frames around it</summary><pre>"
        f"{e(chr(10).join(f['frames_before']))}\n---- the finding ----\n{e(chr(10).join(f['frames_after']))}</pre>"
        "</details></article>" for f in record["findings"])
    trend = figure("trend", "Report intervals over the run",
                   _trend_svg(record), "the mean of each minute's gaps minus the report's interval (R9), per report, "
                   "with the findings marked on the same time axis (red lines)")
    delays = figure("delays", "GET_ESC_ID answer delays", _delays_svg(record),
                    "how long after the query each answer ended (bins of a quarter of a 2 ms slot)")
    return (f"<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>ckesc soak {e(record['started_utc'])}"
            f"</title><style>{CSS}</style></head><body><h1>ckesc soak {badge(verdict)}</h1>"
            f"<p class=\"run\">{e(summary_text(record).splitlines()[0])}</p>"
            f"<h2>Statement</h2><table><tr><th>property</th><th>requirements</th><th>events</th><th>statement</th></tr>"
            f"{rows}</table><h2>Trends</h2>{trend}{delays}<h2>Findings</h2>{findings or '<p>none</p>'}</body></html>\n")


def _trend_svg(record: dict[str, Any]) -> str:
    from ..reporting.htmlkit import new_figure, svg

    fig = new_figure(9, 3)
    ax = fig.add_subplot()
    targets = record["watches"]["report intervals"]["statistics"]["intervals_ms"]
    for name, series in record["r9_per_minute_ms"].items():
        points = [(i + 1, v - targets[name]) for i, v in enumerate(series) if v is not None and name in targets]
        if points:
            ax.plot([p[0] for p in points], [p[1] for p in points], marker=".", label=name)
    for f in record["findings"]:
        ax.axvline(f["t_s"] / 60, color="#cf222e", linewidth=0.8)
    ax.set_xlabel("minutes into the run")
    ax.set_ylabel("mean gap - interval (ms)")
    ax.legend(loc="upper right")
    return svg(fig)


def _delays_svg(record: dict[str, Any]) -> str:
    from ..reporting.htmlkit import new_figure, svg

    delay = record["watches"]["GET_ESC_ID answers"]["statistics"]["delay"]
    fig = new_figure(9, 2.5)
    ax = fig.add_subplot()
    width = delay["bin_ms"]
    ax.bar([i * width for i in range(len(delay["bins"]))], delay["bins"], width=width, align="edge")
    ax.set_xlabel("answer end after the query (ms; the last bin: beyond)")
    ax.set_ylabel("answers")
    return svg(fig)
