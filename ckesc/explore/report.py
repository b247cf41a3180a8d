"""What an exploration leaves behind, in ``reports/<run>/`` like a run's: results.json, junit.xml (testsuite
``explore``), report.html (each finding's steps as a table, the DUT's and the model's observations side by side),
and per finding a replay file (``ckesc explore --replay``), a standalone pytest test and the trace (BLF)."""

from __future__ import annotations

import html
import json
import pprint
import textwrap
from pathlib import Path
from typing import Any, Mapping, Sequence

import can

from ..protocol.requirements import requirement
from .actions import Action, program_from_json, program_json
from .engine import Found, Stats
from .judge import ExploreFinding

REPLAY_FORMAT = "ckesc-explore-replay/1"


# ------------------------------------------------------------------------------------------ replay files
def replay_data(found: Found, bench: Mapping[str, Any], seed: int | None, trace: str | None = None) -> dict[str, Any]:
    f = found.finding
    return {"format": REPLAY_FORMAT, "bench": dict(bench), "seed": seed, "program": program_json(found.program),
            "finding": f.to_json(), "trace": trace}


def load_replay(path: str | Path) -> tuple[dict[str, Any], list[Action], dict[str, Any] | None]:
    """(bench options, program, the finding it showed) of a replay file; a bare JSON list is a program alone."""
    data = json.loads(Path(path).read_text())
    if isinstance(data, list):
        return {}, program_from_json(data), None
    if data.get("format") != REPLAY_FORMAT:
        raise ValueError(f"{path}: not a ckesc explore replay file (format {data.get('format')!r})")
    return dict(data.get("bench") or {}), program_from_json(data["program"]), data.get("finding")


def write_trace(path: Path, messages: Sequence[can.Message]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with can.BLFWriter(str(path)) as w:
        for m in messages:
            w.on_message_received(m)


def steps_table(found: Found) -> list[tuple[int, str, str]]:
    """(number, step, lane time) of each step, the read-back the runner appends included."""
    from .runner import PROBE

    rows = []
    for i, a in enumerate(list(found.program) + list(PROBE)):
        t = found.outcome.steps[i] if i < len(found.outcome.steps) else (0.0, 0.0)
        rows.append((i + 1, a.describe() + ("  (read-back)" if i >= len(found.program) else ""), f"{t[0]:.3f}-{t[1]:.3f} s"))
    return rows


def write_test(path: Path, data: Mapping[str, Any], rows: list[tuple[int, str, str]], name: str) -> None:
    """A standalone pytest test: it runs the program on the bench and fails while the DUT still shows the finding."""
    f = data["finding"]
    quotes = "\n".join(f"    {r} ({requirement(r).strength}): {requirement(r).quote}" for r in f["requirements"])
    steps = "\n".join(f"    {n:>2}. {s}  [{t}]" for n, s, t in rows)
    doc = (f'"""Found by ckesc explore (seed {data.get("seed")}): {f["what"]}\n\n'
           f"The requirement the model's behaviour comes from:\n{quotes}\n\n"
           f"Steps (lane time from the program's start):\n{steps}\n\n"
           f"    DUT:   {f['dut']}\n    model: {f['model']}\n\n"
           f"Trace (BLF): {data.get('trace')}\n"
           f"Run: python -m pytest {path.name}  (it fails while the DUT shows the finding)\n"
           '"""')
    body = f'''
from __future__ import annotations

import pytest

from ckesc.explore.actions import program_from_json
from ckesc.explore.runner import Session

BENCH = {pprint.pformat(dict(data["bench"]), indent=4)}
PROGRAM = {pprint.pformat(list(data["program"]), indent=4)}
FINDING = {f["key"]!r}


@pytest.mark.requirement(*{list(f["requirements"])!r})
def test_{name}():
    session = Session(BENCH)
    try:
        outcome = session.run(program_from_json(PROGRAM))
    finally:
        session.close()
    shown = [f for f in outcome.findings if f.key == FINDING]
    if shown:
        pytest.fail("\\n".join(f.text() for f in shown), pytrace=False)
'''
    path.write_text(doc + "\n" + body)


# ------------------------------------------------------------------------------------------ the run's reports
def write_reports(out: Path, found: list[Found], stats: Stats, info: Mapping[str, Any]) -> dict[str, Any]:
    """Every file of an exploration's report directory; returns results.json's content."""
    records = []
    for i, fd in enumerate(found, 1):
        name = f"finding_{i}"
        trace = out / "traces" / f"{name}.blf"
        write_trace(trace, fd.outcome.messages)
        data = replay_data(fd, info["bench"], info.get("seed"), str(trace.resolve()))
        (out / "findings").mkdir(exist_ok=True)
        replay = out / "findings" / f"{name}.replay.json"
        replay.write_text(json.dumps(data, indent=2) + "\n")
        rows = steps_table(fd)
        test = out / "findings" / f"test_{name}.py"
        write_test(test, data, rows, name)
        records.append({**data["finding"], "name": name, "replay": str(replay), "test": str(test), "trace": str(trace),
                        "steps": [{"n": n, "step": s, "time": t} for n, s, t in rows],
                        "found_after": {"programs": fd.programs_before, "steps": fd.steps_before,
                                        "seconds": round(fd.seconds_before, 3),
                                        "lane_seconds": round(fd.lane_seconds_before, 3)},
                        "shrink_runs": fd.shrink_runs, "shrinking_cut": fd.cut, "also": list(fd.also), "all": [g.to_json() for g in fd.outcome.findings]})
    results = {"info": {**info, "programs": stats.programs, "steps": stats.steps, "wall_seconds": round(stats.wall, 3),
                        "lane_seconds": round(stats.lane, 3),
                        "steps_per_second": round(stats.steps / stats.wall, 2) if stats.wall else None,
                        "features": sorted(stats.features), "feature_pairs": len(stats.pairs)},
               "findings": records}
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    _junit(out / "junit.xml", records, results["info"])
    (out / "report.html").write_text(_html(records, results["info"]))
    return results


def _junit(path: Path, records: list[dict], info: Mapping[str, Any]) -> None:
    from junit_xml import TestCase, TestSuite, to_xml_report_string

    cases = []
    summary = TestCase("exploration", classname="ckesc.explore", elapsed_sec=info.get("wall_seconds"))
    summary.stdout = (f"{info['programs']} programs, {info['steps']} steps, {info['feature_pairs']} feature pairs, "
                      f"lane time {info['lane_seconds']} s")
    cases.append(summary)
    for r in records:
        c = TestCase(r["name"], classname="ckesc.explore")
        c.add_failure_info(message=f"[{' '.join(r['requirements'])} {r['strength']}] {r['what']}",
                           output=f"DUT: {r['dut']}\nmodel: {r['model']}\nreplay: {r['replay']}\n[[ATTACHMENT|{r['trace']}]]")
        cases.append(c)
    props = {k: str(v) for k, v in info.items() if not isinstance(v, (list, dict))}
    suite = TestSuite("explore", cases, properties=props)
    path.write_text(to_xml_report_string([suite]))


def _html(records: list[dict], info: Mapping[str, Any]) -> str:
    e = html.escape
    parts = [f"<h1>ckesc explore: {len(records)} finding(s)</h1>",
             f"<p>{info['programs']} programs, {info['steps']} steps ({info.get('steps_per_second')} steps/s), "
             f"{info['feature_pairs']} feature pairs exercised, lane time {info['lane_seconds']} s, seed {info.get('seed')}, "
             f"lane {e(str(info.get('lane')))}, faults {e(str(info.get('faults') or 'none'))}</p>"]
    for r in records:
        rows = "".join(f"<tr><td>{n['n']}</td><td>{e(n['step'])}</td><td>{e(n['time'])}</td></tr>" for n in r["steps"])
        quotes = "".join(f"<li><b>{e(q)}</b> ({requirement(q).strength}): {e(requirement(q).quote)}</li>" for q in r["requirements"])
        parts.append(
            f"<section><h2>{e(r['name'])}: [{e(' '.join(r['requirements']))} {e(r['strength'])}] {e(r['what'])}</h2>"
            f"<ul>{quotes}</ul><table><tr><th>#</th><th>step</th><th>lane time</th></tr>{rows}</table>"
            f"<table><tr><th></th><th>observed</th></tr><tr><td>DUT</td><td>{e(r['dut'])}</td></tr>"
            f"<tr><td>model</td><td>{e(r['model'])}</td></tr></table>"
            f"<p>replay: <code>ckesc explore --replay {e(r['replay'])}</code>; test: <code>{e(r['test'])}</code>; "
            f"trace: <code>{e(r['trace'])}</code>; found after {r['found_after']['programs']} programs "
            f"({r['found_after']['seconds']} s), shrunk in {r['shrink_runs']} runs"
            f"{' (cut short by the budget: a shorter program may show it too)' if r['shrinking_cut'] else ''}</p></section>")
    style = ("body{font-family:sans-serif;margin:2em}table{border-collapse:collapse;margin:.5em 0}"
             "td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}code{font-size:90%}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>ckesc explore</title><style>{style}</style></head>"
            f"<body>{''.join(parts)}</body></html>\n")


def summary_text(found: list[Found], stats: Stats, out: Path | None) -> str:
    lines = [stats.line()]
    if found:
        lines.append(f"{len(found)} finding{'s' if len(found) != 1 else ''}, in the order first seen (a problem seen only "
                     "beside a shorter one of the same round is listed under it):")
    else:
        lines.append("nothing found")
    for i, fd in enumerate(found, 1):
        f: ExploreFinding = fd.finding
        steps = f"{len(fd.program)} step{'s' if len(fd.program) != 1 else ''}"
        shrunk = (f"{steps}, shrinking cut short by the budget: a shorter program may show it too" if fd.cut
                  else f"{steps} after shrinking")
        lines.append(f"finding {i} (after {fd.programs_before} programs, {fd.seconds_before:.1f} s; {shrunk}):")
        lines.append(textwrap.indent(f.text(), "  "))
        keys = {g.key for g in fd.outcome.findings}
        if earlier := [str(j) for j, e in enumerate(found[:i - 1], 1) if e.key in keys]:
            lines.append(f"  its program also shows the problem of finding {', '.join(earlier)} (perhaps its cause)")
        if fd.also:
            lines.append(f"  also seen beside it (consequences, not shrunk): {'; '.join(fd.also)}")
        lines.extend(f"    {n:>2}. {s}" for n, s, _ in steps_table(fd))
    if out is not None:
        lines.append(f"reports: {out}")
    return "\n".join(lines)
