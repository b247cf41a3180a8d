"""A soak run's reports: ``<reports>/<UTC>-soak/`` with ``results.json`` (the whole record: the watches and their
statistics, the R9 trend per minute, the findings with the frames around them, the statement), ``junit.xml`` (a
``soak`` testsuite, one testcase per watched property, written with the junit-xml package as the run's JUnit is),
``summary.txt`` (what the console prints at the end) and ``report.html`` (the trends over the whole run and each
finding)."""

from __future__ import annotations

import datetime as _dt
import json
import time
from pathlib import Path
from typing import Any

from junit_xml import TestCase, TestSuite, to_xml_report_string

from ..reporting.durations import duration_text
from ..reporting.report import run_dir

#: findings printed in the summary (every kept one is in results.json)
SUMMARY_FINDINGS = 10


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def new_dir(reports: str | Path) -> Path:
    """A new run directory under ``reports`` (made at the start when the run keeps a trace in it)."""
    return run_dir(Path(reports), time.time(), "soak")


def write(reports: str | Path, record: dict[str, Any], where: Path | None = None) -> Path:
    """The report files of ``record`` in ``where`` (default: a new run directory under ``reports``); returns it."""
    where = where or new_dir(reports)
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
             f"{record['lane']} ({record['clock']} clock) in {duration_text(record['wall_s'])} of wall time, node {record['node_id']}, "
             f"{record['frames']['total']} frames",
             f"host stream: {host['stream_frames']} RawCommand_{record['plan']['format']} at {record['plan']['rate_hz']:g} Hz, "
             f"{host['stream_skipped']} skipped; sent late by p50 {late['p50_ms']} ms, p99 {late['p99_ms']} ms, "
             f"max {late['max_ms']} ms (the host's jitter)"
             + (f"; the host process used {host['cpu_percent']:g} % of a CPU" if host.get("cpu_percent") is not None
                and host.get("processes", 1) == 1 else "")
             + (f"; the host's two processes (the simulated world's and the reader's) used {host['cpu_percent']:g} % of "
                "a CPU" if host.get("cpu_percent") is not None and host.get("processes", 1) == 2 else ""),
             "statement:"]
    if foreign := record.get("foreign_traffic"):
        lines.insert(2, f"foreign traffic: {foreign['profile']}, {foreign['frames']} frames of other nodes "
                        f"({foreign['load'] * 100:.1f} % of the bus), not judged as the ESC's")
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


#: the plots' size (SVG user units) and margin
_W, _H, _M = 900, 240, 48
_COLOURS = ("#0969da", "#1a7f37", "#8250df")


def _axes(x_max: float, y_lo: float, y_hi: float, x_label: str, y_label: str) -> tuple[list[str], Any, Any]:
    """An SVG plot's frame, its labels and its two scales (value -> SVG coordinate)."""
    y_lo, y_hi = (y_lo - 1, y_hi + 1) if y_hi <= y_lo else (y_lo, y_hi)
    x_max = x_max or 1

    def x(v: float) -> float:
        return round(_M + v / x_max * (_W - 2 * _M), 1)

    def y(v: float) -> float:
        return round(_H - _M - (v - y_lo) / (y_hi - y_lo) * (_H - 2 * _M), 1)

    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {_W} {_H}" font-size="11">',
             f'<rect x="{_M}" y="{_M}" width="{_W - 2 * _M}" height="{_H - 2 * _M}" fill="none" stroke="#57606a"/>',
             f'<text x="{_W / 2}" y="{_H - 8}" text-anchor="middle">{x_label}</text>',
             f'<text x="12" y="{_H / 2}" transform="rotate(-90 12 {_H / 2})" text-anchor="middle">{y_label}</text>',
             f'<text x="{_M - 4}" y="{y(y_hi) + 4}" text-anchor="end">{y_hi:.3g}</text>',
             f'<text x="{_M - 4}" y="{y(y_lo) + 4}" text-anchor="end">{y_lo:.3g}</text>',
             f'<text x="{x(x_max)}" y="{_H - _M + 14}" text-anchor="end">{x_max:g}</text>',
             f'<text x="{_M}" y="{_H - _M + 14}">0</text>']
    return parts, x, y


def _trend_svg(record: dict[str, Any]) -> str:
    """Each report's mean gap per minute minus its interval (ms) over the run, the findings as red lines: drawn as
    plain SVG (a day is 1440 points per report)."""
    targets = record["watches"]["report intervals"]["statistics"]["intervals_ms"]
    lines = {name: [(i + 1, v - targets[name]) for i, v in enumerate(series) if v is not None]
             for name, series in record["r9_per_minute_ms"].items() if name in targets}
    values = [v for pts in lines.values() for _, v in pts] or [0.0]
    minutes = max(record["ran_s"] / 60, 1)
    parts, x, y = _axes(minutes, min(values), max(values), "minutes into the run", "mean gap - interval (ms)")
    for f in record["findings"]:
        parts.append(f'<line x1="{x(f["t_s"] / 60)}" x2="{x(f["t_s"] / 60)}" y1="{_M}" y2="{_H - _M}" '
                     'stroke="#cf222e" stroke-width="0.8"/>')
    for k, (name, pts) in enumerate(lines.items()):
        colour = _COLOURS[k % len(_COLOURS)]
        if pts:
            parts.append(f'<polyline fill="none" stroke="{colour}" points="'
                         + " ".join(f"{x(m)},{y(v)}" for m, v in pts) + '"/>')
        parts.append(f'<text x="{_W - _M - 60}" y="{_M + 14 + 14 * k}" fill="{colour}">{name}</text>')
    return "".join(parts) + "</svg>"


def _delays_svg(record: dict[str, Any]) -> str:
    """The GET_ESC_ID answer delays' histogram (its last bin: beyond twice the 64 ms bound)."""
    delay = record["watches"]["GET_ESC_ID answers"]["statistics"]["delay"]
    bins, width = delay["bins"], delay["bin_ms"]
    parts, x, y = _axes(len(bins) * width, 0, max(bins) or 1, "answer end after the query (ms)", "answers")
    for i, n in enumerate(bins):
        if n:
            parts.append(f'<rect x="{x(i * width)}" y="{y(n)}" width="{round(max(x((i + 1) * width) - x(i * width), 1), 1)}" '
                         f'height="{round(y(0) - y(n), 1)}" fill="#0969da"/>')
    return "".join(parts) + "</svg>"
