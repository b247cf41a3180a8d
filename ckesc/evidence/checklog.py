"""``ckesc check-log FILE``: the bus rules over a capture from the field.

Reads a candump log, ``.asc``, ``.blf`` or anything python-can's ``LogReader`` reads, runs
:class:`~ckesc.evidence.rules.BusRules` over every frame, prints a summary per node (frames by type,
report interval statistics, comm-loss events, violations with timestamps) and writes the same as JSON
(``--json``) and a self-contained HTML page (``--html``). Exit 0: no rule broken; 1: a rule broken;
2: nothing readable (an empty file, no frame, a header only), a capture cut short (a BLF file shorter than
its header declares: the counts are printed; ``--allow-truncated`` judges what is there), or bad arguments. Damaged records are listed with their line numbers
and do not change the exit code (the summary says how many there were).
"""

from __future__ import annotations

import html
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.judgements import timing_tolerance
from .logs import capture_format, read_capture
from .rules import BusRules

_BAD_KEPT = 100  # damaged records listed; the rest counted
#: a USB adapter's timestamps: about 1 ms of jitter (the capturing bench's error, not a protocol tolerance)
USB_ADAPTER_ERROR_S = 0.001
#: ... plus an ESC's report-scheduling tick, as a real-time lane's tolerance is (judgements.timing_tolerance)
DEFAULT_TOLERANCE_S = timing_tolerance("bus timestamp", USB_ADAPTER_ERROR_S)


def check_capture(path: str, *, bitrate: int = cat.DEFAULT_BITRATE, tolerance: float = DEFAULT_TOLERANCE_S,
                  complete: bool = False, power_on: bool = False, jitter: float = 0.0) -> dict[str, Any]:
    """Run the bus rules over the capture at ``path``; the engine's summary plus the capture's damage. ``power_on``: the
    DUT's power stayed on for the whole capture (a flight), so a reset is a violation, not an observation. ``jitter``:
    the DUT's declared report-interval jitter (its profile's ``jitter_s``), which the live rules of a run and a soak
    give it too: the same ESC is judged alike by every mode."""
    rules = BusRules(tolerance=tolerance, bitrate=bitrate, complete=complete, power_known=power_on, jitter=jitter)
    bad: list[dict[str, Any]] = []
    bad_count = 0

    def on_bad(line: int | None, text: str, reason: str) -> None:
        nonlocal bad_count
        bad_count += 1
        if len(bad) < _BAD_KEPT:
            bad.append({"line": line, "reason": reason, "text": text[:200]})

    truncated: dict[str, Any] = {}

    def on_truncated(read: int, declared: int, detail: str) -> None:
        truncated.update(read=read, declared=declared, detail=detail)

    feed = rules.feed
    for can_id, data, ts, extended, remote, error, own in read_capture(path, on_bad, on_truncated):
        feed(can_id, data, ts, extended, remote, error, own)
    summary = rules.summary()
    summary["capture"] = {"path": str(path), "format": capture_format(path) or "?"}
    summary["truncated"] = truncated or None
    summary["damaged"] = {"count": bad_count, "first": bad}
    return summary


# ------------------------------------------------------------------------------------------ text
def _comm_loss(node: dict[str, Any]):
    """(time, event, time since the last throttle command, and since the last that carried the node's throttle
    channel where the reader knew it: R8's clock) of each comm-loss event, as text."""
    for ev in node["comm_loss"]:
        if "more" in ev:
            yield "", f"... {ev['more']} more events", ""
        else:
            since = f"{ev['since_last_throttle_ms']:g} ms" if "since_last_throttle_ms" in ev else ""
            if "since_last_command_ms" in ev and ev["since_last_command_ms"] != ev.get("since_last_throttle_ms"):
                since += f" ({ev['since_last_command_ms']:g} ms on its channel)"
            yield f"{ev['timestamp']:.6f}", ev["event"], since


def _stats_line(name: str, s: dict[str, Any]) -> str:
    expected = f", expected {s['expected_ms']:g} ms" if s.get("expected_ms") is not None else ""
    return (f"{name}: {s['count']} intervals, mean {s['mean_ms']:.3f} ms, min {s['min_ms']:.3f}, p50 {s['p50_ms']:.2f}, "
            f"p99 {s['p99_ms']:.2f}, max {s['max_ms']:.3f} (stdev {s['stdev_ms']:.3f}){expected}")


def summary_text(s: dict[str, Any]) -> str:
    cap = s["capture"]
    lines = [f"capture: {cap['path']} ({cap['format']}): {s['frames']} frames over {s['duration_s']:.3f} s; "
             f"bit rate {s['bitrate']}, timing tolerance {s['tolerance_s'] * 1000:g} ms"]
    dmg = s["damaged"]
    if dmg["count"]:
        lines.append(f"damaged records: {dmg['count']} (not read; the rules saw the frames around them)")
        for b in dmg["first"][:10]:
            where = f"line {b['line']}" if b["line"] is not None else "record"
            lines.append(f"  {where}: {b['reason']}")
        if dmg["count"] > 10:
            lines.append(f"  ... {dmg['count'] - 10} more (all in the JSON, up to {_BAD_KEPT})")
    extras = []
    if s["standard_id_frames"]:
        extras.append(f"{s['standard_id_frames']} 11-bit frames (not CKESC)")
    if s["error_frames"]["count"]:
        extras.append(f"{s['error_frames']['count']} error frames (first at {s['error_frames']['first'][0]:.6f})")
    if s["time_jumps"]:
        extras.append(f"timestamps go back {s['time_jumps']} time(s)")
    if extras:
        lines.append("bus: " + "; ".join(extras))
    for node_id, n in s["nodes"].items():
        types = ", ".join(f"{k} {v}" for k, v in list(n["by_type"].items())[:8])
        more = f", +{len(n['by_type']) - 8} more types" if len(n["by_type"]) > 8 else ""
        lines.append(f"node {node_id:>3} [{n['role']}] {n['frames']} frames: {types}{more}")
        for name, st in n["intervals"].items():
            if st.get("count"):
                lines.append("    " + _stats_line(name, st))
        if n["intervals_from"]:
            lines.append(f"    report intervals: {n['intervals_from']}")
        if n["silences"]:
            lines.append(f"    silent {n['silences']} time(s) for longer than a power cycle takes (frames before and after not compared)")
        for when, event, since in _comm_loss(n):
            lines.append(f"    comm loss (MSG1 bit 13) {event}" + (f" at {when}" if when else "") + (f" ({since} after the last throttle command)" if since else ""))
        if n["violations"]:
            lines.append("    violations: " + ", ".join(f"{k} {v}" for k, v in n["violations"].items()))
    v = s["violations"]
    if s["observations"]:
        lines.append(f"observations ({len(s['observations'])}, never failures):")
        for o in s["observations"][:10]:
            lines.append(f"  t={o['timestamp']:.6f} node {o['node']}: {o['message']}")
    if v["count"]:
        lines.append(f"violations: {v['count']} ({', '.join(f'{k} {c}' for k, c in v['by_rule'].items())}); the first of each kind:")
        for x in v["first"][:40]:
            where = f"node {x['node']}" if x["node"] is not None else "bus"
            lines.append(f"  [{' '.join(x['rules'])} {x['strength']}] t={x['timestamp']:.6f} {where}: {x['message']}")
            lines.extend(f"      {f}" for f in x["frames"])
        lines.append("verdict: RULES BROKEN")
    else:
        lines.append("verdict: no rule broken")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ HTML
_CSS = """body{font:14px/1.4 system-ui,sans-serif;margin:2em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f2f2f2}code,pre{font:12px/1.3 ui-monospace,monospace}.bad{color:#a00}.ok{color:#070}
.hist rect{fill:#4a7ab8}h2{margin-top:1.5em}"""


def _histogram_svg(hist: dict[str, int], width: int = 360, height: int = 60) -> str:
    if not hist:
        return ""
    items = [(float(k), c) for k, c in hist.items() if k != "overflow"]
    if not items:
        return ""
    lo, hi = min(k for k, _ in items), max(k for k, _ in items)
    span = max(hi - lo, 0.5)
    top = max(c for _, c in items)
    bar = max(width / (span / 0.5 + 1), 1.0)
    rects = "".join(f'<rect x="{(k - lo) / span * (width - bar):.1f}" y="{height - c / top * height:.1f}" width="{bar:.1f}" '
                    f'height="{c / top * height:.1f}"><title>{k:g} ms: {c}</title></rect>' for k, c in items)
    return (f'<svg class="hist" width="{width}" height="{height + 14}" role="img" aria-label="interval histogram">{rects}'
            f'<text x="0" y="{height + 12}" font-size="10">{lo:g} ms</text>'
            f'<text x="{width}" y="{height + 12}" font-size="10" text-anchor="end">{hi + 0.5:g} ms</text></svg>')


def summary_html(s: dict[str, Any]) -> str:
    e = html.escape
    cap = s["capture"]
    v = s["violations"]
    verdict = (f'<p class="bad"><b>{v["count"]} violation(s)</b>: ' + e(", ".join(f"{k} {c}" for k, c in v["by_rule"].items())) + "</p>"
               if v["count"] else '<p class="ok"><b>No rule broken.</b></p>')
    out = [f"<!doctype html><html><head><meta charset='utf-8'><title>ckesc check-log {e(cap['path'])}</title>"
           f"<style>{_CSS}</style></head><body><h1>ckesc check-log</h1>",
           f"<p><code>{e(cap['path'])}</code> ({e(cap['format'])}): {s['frames']} frames over {s['duration_s']:.3f} s, bit rate "
           f"{s['bitrate']}, timing tolerance {s['tolerance_s'] * 1000:g} ms; {s['standard_id_frames']} 11-bit frames, "
           f"{s['error_frames']['count']} error frames, {s['damaged']['count']} damaged records.</p>", verdict]
    out.append("<h2>Nodes</h2><table><tr><th>node</th><th>role</th><th>frames</th><th>by type</th><th>violations</th></tr>")
    for node_id, n in s["nodes"].items():
        types = "<br>".join(f"{e(k)}: {c}" for k, c in n["by_type"].items())
        viol = "<br>".join(f"{e(k)}: {c}" for k, c in n["violations"].items()) or "-"
        out.append(f"<tr><td>{e(node_id)}</td><td>{e(n['role'])}</td><td>{n['frames']}</td><td>{types}</td><td>{viol}</td></tr>")
    out.append("</table><h2>Report intervals</h2><table><tr><th>node</th><th>frame</th><th>intervals</th><th>mean / min / p50 / "
               "p99 / max (ms)</th><th>expected</th><th>histogram</th></tr>")
    for node_id, n in s["nodes"].items():
        for name, st in n["intervals"].items():
            if not st.get("count"):
                continue
            figures = " / ".join(f"{st[k]:g}" for k in ("mean_ms", "min_ms", "p50_ms", "p99_ms", "max_ms"))
            expected = f"{st['expected_ms']:g} ms" if st.get("expected_ms") is not None else "not stated"
            out.append(f"<tr><td>{e(node_id)}</td><td>{e(name)}</td><td>{st['count']}</td><td>{figures}</td><td>{expected}</td>"
                       f"<td>{_histogram_svg(st.get('histogram', {}))}</td></tr>")
    out.append("</table><h2>Comm loss (MSG1 bit 13)</h2><table><tr><th>node</th><th>time</th><th>event</th>"
               "<th>since the last throttle command</th></tr>")
    for node_id, n in s["nodes"].items():
        for when, event, since in _comm_loss(n):
            out.append(f"<tr><td>{e(node_id)}</td><td>{when}</td><td>{e(event)}</td><td>{since or '-'}</td></tr>")
    out.append("</table>")
    for title, rows in (("Violations (the first of each kind)", v["first"]), ("Observations (never failures)", s["observations"])):
        out.append(f"<h2>{title}</h2><table><tr><th>time</th><th>node</th><th>rules</th><th>what</th><th>frames</th></tr>")
        for x in rows:
            frames = e("\n".join(x["frames"]))
            out.append(f"<tr><td>{x['timestamp']:.6f}</td><td>{e(str(x['node']))}</td><td>{e(' '.join(x['rules']))} "
                       f"{e(x['strength'])}</td><td>{e(x['message'])}</td><td><pre>{frames}</pre></td></tr>")
        out.append("</table>")
    if s["damaged"]["count"]:
        out.append("<h2>Damaged records</h2><table><tr><th>line</th><th>reason</th><th>text</th></tr>")
        for b in s["damaged"]["first"]:
            out.append(f"<tr><td>{e(str(b['line']))}</td><td>{e(b['reason'])}</td><td><code>{e(b['text'])}</code></td></tr>")
        out.append("</table>")
    out.append("</body></html>")
    return "\n".join(out)
