"""The HTML conformance report: ``reports/<run>/report.html``, one self-contained file per run.

Built from what the run recorded (``results.json``), so ``ckesc report DIR`` can rebuild it:

* the DUT's identity (ESC Information 240, node id, profile, lane, clock, bit rate, power, faults);
* a matrix of spec sections by verdict;
* the failures grouped by cause, first (causes.py): each distinct problem once, with its first
  occurrence and the tests it showed in (collapsed);
* what failed, with its evidence (measurements with limit, margin, clock; observations; traces);
* plots (matplotlib, inlined as SVG, full page width): answer delay per node against that node's own
  limits (its R2 slot and the 64 ms bound), one marker per service, violations red and labelled;
  report intervals as their deviation from the target with the tolerance band (the intervals the bus
  rules judged, as evidence/tracker.py pairs them); the comm-loss (R8) timelines;
* every requirement of the table with its result, the tests that checked it and their evidence.

Inline CSS and SVG only, no script and no external URL; traces are linked relative to the file.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.requirements import REQUIREMENTS, SECTION_TITLES, VERDICTS, Verdict, section_key
from . import gate
from .causes import groups
from .htmlkit import CSS, anchor, badge, e, figure, new_figure, svg
from .results import (
    WORST_FIRST,
    Result,
    RunInfo,
    RunRecord,
    broken_requirements,
    claim_text,
    firmware_rows,
    incomplete_banner,
    profile_warnings,
    requirement_result,
)


def build(out: Path) -> Path:
    """Write ``out/report.html`` from ``out/results.json``; returns its path."""
    page = render(RunRecord.read(out / "results.json"), run=out.name)
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


# ----------------------------------------------------------------------------------------- page
def _gate(record: dict[str, Any] | None) -> str:
    """The release gate's verdict and reasons (``--baseline``), as summary.txt leads with them: a banner when it
    regressed or could not judge."""
    said = gate.lines(record)
    if not said:
        return ""
    kind = "claim" if record and record.get("verdict") == gate.NO_REGRESSION else "banner role=alert"
    return (f"<div class={kind} id=gate>{e(said[0])}" + ("<ul>" + "".join(f"<li>{e(x.strip())}</li>" for x in said[1:])
            + "</ul>" if said[1:] else "") + "</div>")


def render(doc: RunRecord | dict[str, Any], *, run: str = "") -> str:
    """The page of a run, from its :class:`RunRecord` (or a parsed results.json)."""
    record = doc if isinstance(doc, RunRecord) else RunRecord.from_json(doc)
    info: RunInfo = record.info
    results = record.results
    counts = Counter(r.outcome for r in results)
    banner = incomplete_banner(info)
    # never a green PASS for less than the whole suite: ABORTED / INTERRUPTED / SUBSET / INCOMPLETE
    overall = Verdict.FAIL if counts[Verdict.FAIL] or counts[Verdict.ERROR] else (banner.split(" ")[0] if banner else Verdict.PASS)
    if overall != Verdict.FAIL and (info.get("gate") or {}).get("verdict") == gate.REGRESSED:  # (--baseline: exit 1)
        overall = gate.REGRESSED
    parts = [
        f"<header><h1>CKESC conformance report</h1><p class=run>run {e(run)} &middot; "
        f"{badge(overall)} {len(results)} tests: "
        + ", ".join(f"{counts[v]} {v}" for v in VERDICTS if counts[v])
        + (f", {info.get('not_run', 0)} not run" if info.get("not_run") else "") + "</p>"
        + (f'<p class=banner role=alert>{e(banner)}</p>' if banner else "")
        + _gate(info.get("gate"))
        + (f"<p class=claim>{e(claim_text(info))}</p>" if info.get("not_claimed") else "")
        + "".join(f"<p class=claim>{e(w)}</p>" for w in profile_warnings(info)) + "</header>",
        _causes(results),
        _identity(info),
        _matrix(results),
        _failures(results),
        _plots(results, info),
        _requirements(results),
        _tests(results),
    ]
    return (f"<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>CKESC conformance report {e(run)}</title>"
            f"<style>{CSS}</style></head><body>\n" + "\n".join(parts) + "\n</body></html>\n")


def _identity(info: dict[str, Any]) -> str:
    rows = [("DUT", info.get("dut")), ("node id", info.get("node_id")), ("profile", info.get("profile")),
            ("lane", info.get("lane")), ("clock", info.get("clock")), ("bit rate", f"{info['bitrate']} bit/s" if info.get("bitrate") else None),
            ("power control", info.get("power")), ("timing error (the bench's)", f"{info['timing_error_s'] * 1000:g} ms" if "timing_error_s" in info else None),
            ("report-interval jitter allowance (the DUT's)", f"{info['jitter_s'] * 1000:g} ms" if "jitter_s" in info else None),
            ("conformance claim", claim_text(info).removeprefix("claim: ") if "not_claimed" in info else None),
            ("emulator faults", info.get("faults") or None),
            ("echo of the host's frames", None if info.get("echo") is None else
             f"{'yes' if info['echo'] else 'no'} ({info.get('echo_note', '')}); timed by: {info.get('own_frames_clock')}, "
             f"error {(info.get('own_frames_error_s') or 0.0) * 1000:g} ms"),
            ("bus failures recovered", "; ".join(info.get("bus_recoveries") or []) or None)]
    esc = info.get("esc_information")
    if isinstance(esc, dict):
        rows.append(("firmware date", cat.firmware_date(esc)))
        rows += [(k.replace("_", " "), v) for k, v in esc.items() if not k.startswith("firmware_")]
    elif "esc_information" in info:
        rows.append(("ESC information (240)", "no answer"))
    rows += firmware_rows(info)
    body = "".join(f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in rows if v not in (None, ""))
    return f'<section id=dut><h2>Device under test</h2><table class="kv">{body}</table></section>'


def _matrix(results: list[Result]) -> str:
    rows: dict[str, Counter] = defaultdict(Counter)
    for r in results:
        rows[r.section][r.outcome] += 1
    head = "<tr><th>section</th><th>title</th>" + "".join(f"<th>{badge(v)}</th>" for v in VERDICTS) + "</tr>"
    body = []
    total: Counter = Counter()
    for section in sorted(rows, key=section_key):
        c = rows[section]
        total.update(c)
        body.append(f'<tr data-section="{e(section)}"><td>{e(section)}</td><td>{e(SECTION_TITLES.get(section, ""))}</td>'
                    + "".join(_count_cell(v, c[v]) for v in VERDICTS) + "</tr>")
    body.append('<tr class=total data-section=all><td>all</td><td></td>' + "".join(_count_cell(v, total[v]) for v in VERDICTS) + "</tr>")
    return f"<section id=matrix><h2>Sections by verdict</h2><table class=matrix>{head}{''.join(body)}</table></section>"


def _count_cell(verdict: str, n: int) -> str:
    cls = f"n c-{verdict}" if n else "n zero"
    return f'<td class="{cls}" data-verdict="{verdict}">{n}</td>'


def _evidence(r: dict[str, Any]) -> str:
    out = []
    ms = r.measurements
    if ms:
        rows = "".join(f"<tr><td>{e(m.get('name', ''))}</td><td>{e(m.get('value', ''))}</td><td>{e(m.get('limit', ''))}</td>"
                       f"<td>{e(m.get('margin', ''))}</td><td>{e(m.get('clock', ''))}{e(' ' + m['error']) if 'error' in m else ''}</td>"
                       f"<td>{badge(m.get('verdict', ''))}</td></tr>" for m in ms)
        out.append("<table class=meas><tr><th>measured</th><th>value</th><th>limit</th><th>margin</th><th>clock</th><th></th></tr>"
                   f"{rows}</table>")
    obs = r.observations or []
    if obs:
        out.append("<ul class=obs>" + "".join(f"<li><b>{e(w)}</b>: {e(v)}</li>" for w, v in obs) + "</ul>")
    traces = r.traces or {}
    if traces:
        out.append("<p class=traces>trace: " + " ".join(f'<a href="{e(p)}">{e(lane or "DUT")}: {e(Path(p).name)}</a>'
                                                       for lane, p in traces.items()) + "</p>")
    return "".join(out)


def _failures(results: list[Result]) -> str:
    bad = [r for r in results if r.outcome in (Verdict.FAIL, Verdict.ERROR, Verdict.INCONCLUSIVE)]
    if not bad:
        return "<section id=failures><h2>Failures</h2><p>No test failed, errored or was inconclusive.</p></section>"
    items = []
    for r in sorted(bad, key=lambda r: (WORST_FIRST.index(r.outcome), section_key(r.section))):
        reqs = ", ".join(f'<a href="#req-{e(i)}">{e(i)}</a>' for i in r.requirements)
        items.append(f'<article class="fail" data-nodeid="{e(r.nodeid)}"><h3>{badge(r.outcome)} {e(r.nodeid)}</h3>'
                     f"<p>{e(r.section)} {e(SECTION_TITLES.get(r.section, ''))} &middot; {reqs} ({e(r.strength)})</p>"
                     f"<pre>{e(r.message)}</pre>{_evidence(r)}</article>")
    return (f"<section id=failures><h2>Failures ({len(bad)})</h2><details{' open' if len(bad) <= 10 else ''}>"
            f"<summary>every test that failed, errored or was inconclusive, with its evidence</summary>"
            f"{''.join(items)}</details></section>")


def _causes(results: list[Result]) -> str:
    """The run's distinct problems first (causes.groups), each with its first occurrence, frames and
    trace, the tests it showed in collapsed under it: never k copies of one."""
    gs = groups(results)
    if not gs:
        return ""
    items = []
    for n, g in enumerate(gs, start=1):
        traces = " ".join(f'<a href="{e(p)}">{e(lane or "DUT")}: {e(Path(p).name)}</a>' for lane, p in g.traces.items())
        reqs = ", ".join(f'<a href="#req-{e(i)}">{e(i)}</a>' for i in g.rules)
        tests = "".join(f'<li><a href="#t-{anchor(t)}">{e(t)}</a>'
                        + (f" ({e(g.unjudged[t])}: seen while it ran)" if t in g.unjudged else "") + "</li>"
                        for t in g.tests)
        items.append(
            f'<article class="cause" id="cause-{n}" data-tests="{len(g.tests)}" data-strength="{e(g.strength)}">'
            f'<h3>{badge(g.outcome)} {e(g.strength)} {e(g.title)} <span class=count>&ndash; in {len(g.tests)} '
            f'test{"s" if len(g.tests) != 1 else ""}</span></h3>'
            f'<p>{reqs} &middot; first in <a href="#t-{anchor(g.first_test)}">{e(g.first_test)}</a>'
            + (f" &middot; trace: {traces}" if traces else "") + "</p>"
            f"<pre>{e(g.first)}</pre>"
            f"<details><summary>{len(g.tests)} test{'s' if len(g.tests) != 1 else ''} with this problem</summary>"
            f"<ul class=tests>{tests}</ul></details></article>")
    n_tests = len({t for g in gs for t in g.tests})
    return (f"<section id=causes><h2>Failures by cause ({len(gs)} distinct, in {n_tests} tests)</h2>"
            f"<p class=note>Each problem once, SHALL before READING, the most widespread first; a test can show "
            f"several.</p>{''.join(items)}</section>")


def _requirements(results: list[Result]) -> str:
    by_req: dict[str, list[Result]] = defaultdict(list)
    for r in results:
        for rid in r.requirements:
            by_req[rid].append(r)
    rows = []
    for rid, req in sorted(REQUIREMENTS.items(), key=lambda kv: (section_key(kv[1].section), kv[0])):
        tests = by_req.get(rid, [])
        result = requirement_result([t.outcome for t in tests])
        listed = "".join(f'<li>{badge(t.outcome)} <a href="#t-{anchor(t.nodeid)}">{e(t.name)}</a></li>' for t in tests)
        rows.append(f'<tr id="req-{e(rid)}" data-result="{e(result)}"><td>{e(rid)}</td><td>{e(req.strength)}</td>'
                    f"<td>{e(req.section)}</td><td>{badge(result)}</td><td><q>{e(req.quote)}</q>"
                    + (f"<div class=note>{e(req.note)}</div>" if req.note else "")
                    + (f"<ul class=tests>{listed}</ul>" if listed else "") + "</td></tr>")
    return ("<section id=requirements><h2>Requirements</h2><table class=reqs><tr><th>id</th><th>strength</th><th>section</th>"
            f"<th>result</th><th>requirement and tests</th></tr>{''.join(rows)}</table></section>")


def _tests(results: list[Result]) -> str:
    rows = []
    for r in sorted(results, key=lambda r: section_key(r.section)):
        rows.append(f'<tr id="t-{anchor(r.nodeid)}"><td>{badge(r.outcome)}</td><td>{e(r.nodeid)}'
                    + (f"<div class=msg>{e(r.message.splitlines()[0][:300])}</div>" if r.message else "")
                    + f"{_evidence(r)}</td><td>{e(r.section)}</td><td>{r.lane_seconds:.3f} s</td></tr>")
    return ("<section id=tests><h2>Tests and their evidence</h2><table class=tests><tr><th>verdict</th><th>test</th>"
            f"<th>section</th><th>lane time</th></tr>{''.join(rows)}</table></section>")


# ----------------------------------------------------------------------------------------- plots
#: one marker per service in the answer-delay plot
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">", "h", "p")


def _plots(results: list[Result], info: dict[str, Any]) -> str:
    clock = info.get("clock", "")
    err = (info.get("timing_error_s") or 0.0) * 1000
    parts = ["<section id=plots><h2>Timing</h2>"]
    answers: dict[int, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    intervals: dict[tuple[str, float], list[float]] = defaultdict(list)
    timelines = []
    for r in results:
        ev = r.evidence or {}
        for node, by_request in ev.get("answers", {}).items():
            for request, delays in by_request.items():
                answers[int(node)][request].extend(delays)
        for report, by_target in ev.get("intervals", {}).items():
            for target, gaps in by_target.items():
                intervals[(report, float(target))].extend(gaps)
        if "comm_loss" in ev:
            timelines.append((r, ev["comm_loss"]))
    if answers:
        drawn, late = _answer_plot(answers, err)
        parts.append(figure(
            "answer-delay", "Answer delay per node against its own limits", drawn,
            "Every service request the suite made and its answer, request on the bus to the answer's last bit "
            + (f"({e(clock)} clock)" if info.get("echo") is not False else
               f"(the request by the host clock at send: the adapter does not echo; the answer by the {e(clock)} clock)")
            + f", one marker per service. Green band: the node's answer slot, (node id % 32) x "
            f"{cat.ANSWER_SLOT_S * 1000:g} ms to {cat.ANSWER_SLOT_S * 1000:g} ms later (R2); dashed: the "
            f"{cat.ANSWER_DELAY_MAX_S * 1000:g} ms bound (4.4.2-4, 4.4.3-4). Red: {late} answer(s) outside a limit"
            + (f" (beyond the stated error of +-{err:g} ms)" if err else "") + "; each node's latest is labelled."
            + (_why_red(results, ("R2", "4.4.2-4", "4.4.3-4"), "answer",
                        "the suite judges each answer allowing for the time frames queued on the bus ahead of it could "
                        "take (long at a low bit rate), which this plot does not draw") if late else "")))
    else:
        parts.append("<p>No answered request was recorded.</p>")
    if intervals:
        tol = float(info.get("interval_tolerance_ms") or 0.0)
        drawn, outside = _interval_plot(intervals, tol)
        parts.append(figure(
            "report-intervals", "Report intervals: deviation from their target", drawn,
            f"Time between consecutive MSG1/MSG2/MSG3 of the DUT minus the interval its latest Set/Get Freq answer "
            f"stated (ms, linear; box: quartiles, whiskers: min and max). Grey band: the tolerance, +-{tol:g} ms; red: "
            f"{outside} interval(s) outside it (the bus rules also allow for bus queueing). The intervals the bus rules "
            f"judged, start to start: none before the DUT stated a target, none across a power cycle, a suspension or "
            f"a Set Freq change, nor up to the second report after a restart (R9a)."
            + (_why_red(results, ("R9",), "interval",
                        "the bus rules hold each gap to its target within this tolerance widened by the time frames "
                        "queued on the bus ahead of either report could take, and by the DUT's declared jitter; R9 "
                        "itself judges a report's mean interval") if outside else "")))
    else:
        parts.append("<p>No report interval was recorded.</p>")
    if timelines:
        parts.append(figure("comm-loss", "Comm-loss timelines (R8)", _comm_loss_plot(timelines),
                             f"MSG1 around the end of a throttle stream: grey ticks are commands, dots MSG1 with bit 13 "
                             f"(comm fault) clear or set. Dashed: {cat.COMM_LOSS_TIMEOUT_S * 1000:g} ms after the last command."))
    parts.append("</section>")
    return "".join(parts)


def _why_red(results: list[Result], rules: tuple[str, ...], what: str, excused: str) -> str:
    """The caption's sentence that says what its red marks mean for the verdicts: which tests FAILed on ``rules``,
    or, where none did, why a red mark is no failure (``excused``)."""
    failed = [r for r in results if r.outcome == Verdict.FAIL and set(rules) & set(broken_requirements(r))]
    if failed:
        return (f" {len(failed)} test(s) FAILed on {' / '.join(rules)} (their rows below say which {what}s); any other "
                f"red mark broke no rule: {excused}.")
    return f" No test FAILed on {' / '.join(rules)}: a red mark here broke no rule, as {excused}."


def _answer_plot(answers: dict[int, dict[str, list[float]]], err: float) -> tuple[str, int]:
    """The answer-delay plot and how many answers broke a limit: their node's slot end (R2) or 64 ms."""
    import numpy as np

    nodes = sorted(answers)
    services = sorted({s for by in answers.values() for s in by})
    marker = {s: _MARKERS[i % len(_MARKERS)] for i, s in enumerate(services)}
    fig = new_figure(11.0, 4.2)
    ax = fig.add_subplot()
    limit = cat.ANSWER_DELAY_MAX_S * 1000
    slot_w = cat.ANSWER_SLOT_S * 1000
    rng = np.random.default_rng(0)
    late = 0
    top = limit
    for i, node in enumerate(nodes):
        start = (node % cat.ANSWER_SLOTS) * slot_w
        band = ax.fill_between([i - 0.42, i + 0.42], start, start + slot_w, color="#1a7f37", alpha=0.25, linewidth=0)
        band.set_gid(f"slot-node-{node}")
        worst: tuple[float, str] | None = None
        for s in services:
            d = np.array(answers[node].get(s, [])) * 1000
            if not len(d):
                continue
            bad = (d > start + slot_w + err) | (d > limit + err)
            late += int(bad.sum())
            x = i + rng.uniform(-0.3, 0.3, len(d))
            ax.scatter(x[~bad], d[~bad], s=14, marker=marker[s], facecolors="none", edgecolors="#0969da",
                       linewidths=0.7, alpha=0.6, rasterized=int((~bad).sum()) > 400)
            if bad.any():
                pts = ax.scatter(x[bad], d[bad], s=22, marker=marker[s], color="#cf222e", zorder=3,
                                 rasterized=int(bad.sum()) > 400)
                pts.set_gid(f"late-node-{node}-{s}")
                if worst is None or d[bad].max() > worst[0]:
                    worst = (float(d[bad].max()), s)
            top = max(top, float(d.max()))
        if worst is not None:
            ax.annotate(f"{worst[0]:.1f} ms", (i, worst[0]), textcoords="offset points", xytext=(0, 6), ha="center",
                        color="#cf222e", fontsize=10)
    line = ax.axhline(limit, color="#cf222e", linestyle="--", linewidth=1.2)
    line.set_gid("answer-delay-limit")
    ax.text(1.0, limit, f" limit {limit:g} ms", transform=ax.get_yaxis_transform(), va="center", color="#cf222e")
    for s in services:
        ax.scatter([], [], marker=marker[s], facecolors="none", edgecolors="#0969da", label=s)
    ax.legend(loc="upper left", bbox_to_anchor=(1.08, 1.0), title="service", frameon=False)
    ax.set_xticks(range(len(nodes)), [f"node {n}\nn={sum(len(v) for v in answers[n].values())}" for n in nodes])
    ax.set_xlim(-0.6, len(nodes) - 0.4)
    ax.set_ylabel("answer delay (ms)")
    ax.set_ylim(0, top * 1.18)
    ax.grid(axis="y", alpha=0.3)
    return svg(fig), late


def _interval_plot(intervals: dict[tuple[str, float], list[float]], tol: float) -> tuple[str, int]:
    """The deviation plot - one panel per report and target, each on its own linear scale - and how many
    intervals are outside the tolerance band."""
    import numpy as np

    keys = sorted(intervals)
    cols = min(7, len(keys))
    rows = -(-len(keys) // cols)
    fig = new_figure(11.0, 2.4 * rows + 0.4)
    axes = fig.subplots(rows, cols, squeeze=False)
    rng = np.random.default_rng(0)
    outside = 0
    for ax, k in zip(axes.flat, keys):
        dev = (np.array(intervals[k]) - k[1]) * 1000
        band = ax.axhspan(-tol, tol, color="#6e7781", alpha=0.25, linewidth=0)
        band.set_gid(f"tolerance-{k[0]}-{k[1] * 1000:g}ms")
        tick = ax.axhline(0, color="#1a7f37", linewidth=1.5)
        tick.set_gid(f"target-{k[0]}-{k[1] * 1000:g}ms")
        off = np.abs(dev) > tol
        outside += int(off.sum())
        x = rng.uniform(-0.3, 0.3, len(dev))
        if len(dev):
            ax.boxplot([dev], positions=[0], whis=(0, 100), widths=0.7, showfliers=False)
            ax.scatter(x[~off], dev[~off], s=6, color="#0969da", alpha=0.35, linewidths=0, rasterized=int((~off).sum()) > 400)
        if off.any():
            pts = ax.scatter(x[off], dev[off], s=10, color="#cf222e", zorder=3, rasterized=int(off.sum()) > 400)
            pts.set_gid(f"outside-{k[0]}-{k[1] * 1000:g}ms")
        ax.set_title(f"{k[0].upper()} {k[1] * 1000:g} ms", fontsize=10)
        ax.set_xticks([0], [f"n={len(dev)}" + (f"\n{int(off.sum())} outside" if off.any() else "")])
        for label in ax.get_xticklabels():
            label.set_color("#cf222e" if off.any() else "#1f2328")
        ax.set_xlim(-0.6, 0.6)
        span = max(tol * 2, float(np.abs(dev).max()) if len(dev) else 0.0, 0.1)
        ax.set_ylim(-span * 1.15, span * 1.15)
        ax.grid(axis="y", alpha=0.3)
    for ax in axes.flat[len(keys):]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel("interval - target (ms)")
    fig.tight_layout()
    return svg(fig), outside


def _comm_loss_plot(timelines: list[tuple[dict[str, Any], dict[str, Any]]]) -> str:
    fig = new_figure(11.0, 0.6 + 0.9 * len(timelines))
    axes = fig.subplots(len(timelines), 1, sharex=True, squeeze=False)[:, 0]
    timeout = cat.COMM_LOSS_TIMEOUT_S * 1000
    for ax, (r, tl) in zip(axes, timelines):
        commands = sorted(tl.get("commands", []))
        msg1 = tl.get("msg1", [])
        last = _last_command(commands)
        ax.set_yticks([])
        ax.set_ylabel(r.name.split("[")[-1].rstrip("]") or r.name, rotation=0, ha="right", va="center")
        if last is None:
            ax.text(0.5, 0.5, "no throttle command recorded", transform=ax.transAxes, ha="center")
            continue
        ax.vlines([(t - last) * 1000 for t in commands], 0.6, 0.9, color="#6e7781", linewidth=0.6)
        for flagged, colour in ((False, "#1a7f37"), (True, "#cf222e")):
            xs = [(t - last) * 1000 for t, f in msg1 if bool(f) is flagged]
            ax.scatter(xs, [0.3] * len(xs), s=14, color=colour, label="bit 13 set" if flagged else "bit 13 clear")
        line = ax.axvline(timeout, color="#cf222e", linestyle="--", linewidth=1)
        line.set_gid("comm-loss-timeout")
        ax.axvline(0, color="#6e7781", linewidth=0.8)
        ax.set_ylim(0, 1)
    axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)  # outside the data
    axes[-1].set_xlim(-150, timeout + 250)
    axes[-1].set_xlabel("time since the last command of the stream (ms)")
    return svg(fig)


def _last_command(commands: list[float]) -> float | None:
    """The last command of the stream: the one before the longest pause (or the last one)."""
    if not commands:
        return None
    gaps = [(b - a, a) for a, b in zip(commands, commands[1:])]
    return max(gaps)[1] if gaps and max(gaps)[0] > cat.COMM_LOSS_TIMEOUT_S / 2 else commands[-1]
