"""Comparing soak runs (``ckesc compare`` on two or more ``reports/<UTC>-soak/`` directories): per watched property,
the findings in each run, the statement's bound, and the numbers behind them: each report's R9 mean per minute (the
mean of the minutes and the worst minute's error), the GET_ESC_ID answer delays' percentiles, the resets.

Runs are given oldest first; each is compared with the one before it. A property **regressed** when it has findings
in the later run and had none in the earlier one; **fixed** the other way. Runs of different lanes, profiles, rates,
emulator faults, or an incomplete run (INTERRUPTED, STOPPED, ABORTED) are flagged, never refused.

This reads the soak's ``results.json`` as JSON (the reporting layer does not import :mod:`ckesc.soak`): the keys it
needs are checked, and a record without them is a :class:`~.comparing.RunError`. The skeleton it shares with the
suite's comparison (reading a record, the letters, the pairs, the flags' form, the page's frame) is
:mod:`.comparing`'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .comparing import RunError, comparison, differs, first_line, last_line, letter, pair_name
from .comparing import page as page_frame
from .durations import duration_text
from .htmlkit import badge, e

#: what a soak record must hold for the comparison (``ckesc soak``'s results.json)
REQUIRED = ("status", "ran_s", "duration_s", "statement", "watches", "findings", "r9_per_minute_ms")


@dataclass
class SoakRun:
    label: str
    path: str
    doc: dict[str, Any]


def parse_soak(doc: dict[str, Any], *, label: str = "", path: str = "") -> SoakRun:
    """A :class:`SoakRun`, or :class:`~.comparing.RunError` when the record lacks what the comparison reads."""
    missing = [k for k in REQUIRED if k not in doc]
    if missing or not isinstance(doc.get("statement"), list) or not isinstance(doc.get("watches"), dict):
        raise RunError(f"{path or label}: a soak record without {', '.join(missing) or 'a statement list'} (not one "
                       "this version reads)")
    return SoakRun(label=label or path, path=path, doc=doc)


# ------------------------------------------------------------------------------------------ facts of one run
def properties(run: SoakRun) -> dict[str, dict[str, Any]]:
    """Each watched property of the run: its findings (events), trials, the statement's bound and unit, its text."""
    return {s["watch"]: {"rules": s.get("rules", []), "events": int(s.get("events") or 0), "trials": s.get("trials"),
                         "unit": s.get("unit"), "bound": s.get("bound"), "text": s.get("text", "")}
            for s in run.doc["statement"]}


def r9(run: SoakRun) -> dict[str, dict[str, Any]]:
    """Per report: its interval (ms), the mean of the minutes' mean gaps, and the worst minute's mean (the one
    farthest from the interval) with its error."""
    targets = run.doc["watches"].get("report intervals", {}).get("statistics", {}).get("intervals_ms", {})
    out = {}
    for name, series in run.doc["r9_per_minute_ms"].items():
        values = [v for v in series if v is not None]
        target = targets.get(name)
        worst = max(values, key=lambda v: abs(v - target)) if values and target is not None else None
        out[name] = {"interval_ms": target, "minutes": len(values),
                     "mean_ms": round(sum(values) / len(values), 4) if values else None,
                     "worst_ms": worst, "worst_error_ms": round(worst - target, 4) if worst is not None else None}
    return out


def delays(run: SoakRun) -> dict[str, Any]:
    """The GET_ESC_ID answer delays: answers, missing ones, and the percentiles (ms)."""
    st = run.doc["watches"].get("GET_ESC_ID answers", {}).get("statistics", {})
    d = st.get("delay") or {}
    return {"answers": st.get("answers"), "missing": st.get("missing"),
            **{k: d.get(k) for k in ("p50_ms", "p90_ms", "p99_ms", "max_ms")}}


def resets(run: SoakRun) -> dict[str, Any]:
    w = run.doc["watches"].get("resets", {})
    return {"events": w.get("events"), "power_ups": w.get("statistics", {}).get("power_ups")}


def flags(runs: list[SoakRun]) -> list[str]:
    """What makes the comparison less than like for like, one line each."""
    out = []
    for what, get in (("lanes", lambda d: d.get("lane")), ("DUT profiles", lambda d: d.get("profile")),
                      ("stream rates", lambda d: _num((d.get("plan") or {}).get("rate_hz"), " Hz")),
                      ("durations", lambda d: _num(d.get("duration_s"), " s")), ("emulator faults", lambda d: d.get("faults") or "none"),
                      ("foreign traffic", lambda d: (d.get("foreign_traffic") or {}).get("profile"))):
        out += differs(what, [_said(get(r.doc)) for r in runs])  # a soak record that does not say differs too
    for i, r in enumerate(runs):
        if r.doc["status"] != "COMPLETED":
            out.append(f"{letter(i)} ({r.label}) is {r.doc['status']}"
                       + (f": {r.doc['problem']}" if r.doc.get("problem") else "") + f", after {duration_text(r.doc['ran_s'])}")
    return out


def _said(v: Any) -> Any:
    return "-" if v is None else v


# ------------------------------------------------------------------------------------------ comparing
def diff(a: SoakRun, b: SoakRun) -> dict[str, Any]:
    """Per property from ``a`` to ``b``: regressed (findings in b, none in a), fixed, or the same."""
    pa, pb = properties(a), properties(b)
    rows = []
    for watch in list(dict.fromkeys([*pa, *pb])):
        before, after = pa.get(watch), pb.get(watch)
        if before is None or after is None:
            change = "added" if before is None else "removed"
        elif not before["events"] and after["events"]:
            change = "regressed"
        elif before["events"] and not after["events"]:
            change = "fixed"
        else:
            change = "same"
        rows.append({"watch": watch, "change": change, "before": before and before["events"],
                     "after": after and after["events"]})
    regressed = [r["watch"] for r in rows if r["change"] == "regressed"]
    return {"from": a.label, "to": b.label, "properties": rows, "regressed": regressed,
            "fixed": [r["watch"] for r in rows if r["change"] == "fixed"]}


def compare(runs: list[SoakRun]) -> dict[str, Any]:
    """Two or more soak runs, oldest first, as one JSON-ready dict."""
    return {"kind": "soak", **comparison(runs, diff, _run_row, flags(runs))}


def _run_row(r: SoakRun) -> dict[str, Any]:
    return {"label": r.label, "path": r.path, "status": r.doc["status"], "ran_s": r.doc["ran_s"], "lane": r.doc.get("lane"),
            "profile": r.doc.get("profile"), "faults": r.doc.get("faults") or "",
            "findings": len(r.doc["findings"]) + int(r.doc.get("findings_not_kept") or 0), "properties": properties(r),
            "r9": r9(r), "delays": delays(r), "resets": resets(r)}


# ------------------------------------------------------------------------------------------ text
def _num(v: Any, unit: str = "") -> str:
    return "-" if v is None else f"{v:g}{unit}"


def text(doc: dict[str, Any]) -> str:
    """The comparison for the console."""
    runs = doc["runs"]
    lines = [first_line(doc, "soak")]
    lines += [f"  {r['letter']}  {r['label']}  {r['path']}  {r['status']}, {duration_text(r['ran_s'])} on {r['lane']}"
              + (f", faults {r['faults']}" if r["faults"] else "") + f", {r['findings']} findings" for r in runs]
    lines += [f"! {f}" for f in doc["flags"]]
    watches = list(dict.fromkeys(w for r in runs for w in r["properties"]))
    lines += ["", "findings per watched property, and the statement's bound"]
    for w in watches:
        lines.append(f"  {w}:")
        for r in runs:
            p = r["properties"].get(w)
            lines.append(f"    {r['letter']} " + ("(not watched)" if p is None else
                                                 f"{p['events']} findings; {p['text']}"))
    reports = list(dict.fromkeys(n for r in runs for n in r["r9"]))
    lines += ["", "R9: each report's mean gap per minute (mean of the minutes; worst minute, its error)"]
    for n in reports:
        cells = []
        for r in runs:
            s = r["r9"].get(n)
            cells.append(f"{r['letter']} -" if not s or s["mean_ms"] is None else
                         f"{r['letter']} {s['mean_ms']:g} ms (worst {s['worst_ms']:g} ms, {s['worst_error_ms']:+g} ms)")
        target = next((r["r9"][n]["interval_ms"] for r in runs if n in r["r9"]), None)
        lines.append(f"  {n} (every {_num(target, ' ms')}): " + "; ".join(cells))
    lines += ["", "GET_ESC_ID answer delays (p50 / p90 / p99 / max), answers, missing"]
    lines += [f"  {r['letter']} " + " / ".join(_num(r["delays"][k], " ms") for k in ("p50_ms", "p90_ms", "p99_ms", "max_ms"))
              + f", {_num(r['delays']['answers'])} answers, {_num(r['delays']['missing'])} missing" for r in runs]
    lines += ["", "resets: " + "; ".join(f"{r['letter']} {_num(r['resets']['events'])} (power-ups counted "
                                          f"{_num(r['resets']['power_ups'])})" for r in runs)]
    for i, p in enumerate(doc["pairs"]):
        lines.append("")
        lines.append(f"{pair_name(doc, i)}: " + (f"REGRESSED {', '.join(p['regressed'])}" if p["regressed"] else "no regression")
                     + (f"; fixed {', '.join(p['fixed'])}" if p["fixed"] else ""))
        lines += [f"  {r['watch']}: {r['before']} -> {r['after']} findings" for r in p["properties"]
                  if r["change"] in ("regressed", "fixed")]
    lines += ["", last_line(doc, lambda p: ", ".join(p["regressed"]))]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ HTML
def page(doc: dict[str, Any]) -> str:
    """The comparison as one self-contained HTML page, in report.html's style."""
    runs = doc["runs"]
    heads = "".join(f"<th>{e(r['letter'])}<div class=note>{e(r['label'])}</div></th>" for r in runs)
    watches = list(dict.fromkeys(w for r in runs for w in r["properties"]))
    prop_rows = "".join(
        f'<tr data-watch="{e(w)}"><td>{e(w)}</td>' + "".join(
            "<td>-</td>" if w not in r["properties"] else
            f"<td><b>{r['properties'][w]['events']}</b> {e(r['properties'][w]['text'])}</td>" for r in runs) + "</tr>"
        for w in watches)
    reports = list(dict.fromkeys(n for r in runs for n in r["r9"]))
    r9_rows = "".join(
        f"<tr><td>{e(n)}</td>" + "".join(
            "<td>-</td>" if not r["r9"].get(n) or r["r9"][n]["mean_ms"] is None else
            f"<td>{r['r9'][n]['mean_ms']:g} ms (worst {r['r9'][n]['worst_ms']:g} ms, "
            f"{r['r9'][n]['worst_error_ms']:+g} ms)</td>" for r in runs) + "</tr>" for n in reports)
    delay_rows = "".join(f"<tr><td>{k.removesuffix('_ms')}</td>" + "".join(f"<td>{e(_num(r['delays'][k]))}</td>" for r in runs)
                         + "</tr>" for k in ("answers", "missing", "p50_ms", "p90_ms", "p99_ms", "max_ms"))
    pairs = "".join(f"<li>{e(pair_name(doc, i))}: {badge('REGRESSED' if p['regressed'] else 'NO REGRESSION')} "
                    + e("; ".join(f"{r['watch']} {r['before']} -> {r['after']} findings" for r in p["properties"]
                                  if r["change"] in ("regressed", "fixed"))) + "</li>" for i, p in enumerate(doc["pairs"]))
    return page_frame(doc, heading="CKESC soak comparison", lead=f"{len(runs)} soak runs, oldest first", body=[
        f"<ul id=pairs>{pairs}</ul><h2>Findings per watched property</h2><table id=properties><tr><th>property</th>{heads}"
        f"</tr>{prop_rows}</table><h2>R9: mean gap per minute</h2><table id=r9><tr><th>report</th>{heads}</tr>{r9_rows}"
        f"</table><h2>GET_ESC_ID answer delays (ms)</h2><table id=delays><tr><th></th>{heads}</tr>{delay_rows}</table>"])
