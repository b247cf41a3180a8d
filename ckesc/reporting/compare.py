"""Comparing runs of the suite (``ckesc compare``): what changed from one firmware release, ESC model or
bench to the next.

Runs are given oldest first; each is compared with the one before it. For each such pair:

* **regressed**: a test or requirement that passed (PASS, OBSERVED) and now FAILs, ERRORs or is
  INCONCLUSIVE; **fixed**: the other way; other verdict changes (PASS -> SKIPPED, FAIL -> ERROR, a
  requirement first checked, ...) are listed apart; a requirement's verdict is its evidence's
  (:func:`requirement_results`: a FAIL counts against the requirements it broke, not every one its test cites);
* tests **added** or **removed** (in neither the results nor the not-run list of the other run), and tests
  one of the two runs did not run (a subset, an aborted run);
* timing **margins that shrank**: per timing measurement (unit ms or s) of a test, both margins and values, when the
  margin fell by more than the threshold (a fraction of the earlier margin) and by more than the runs'
  stated timing error.

Over all runs: the DUT's identity side by side, a requirement x run matrix (the model is the Autobahn
Testsuite's report over several implementations) and each timing measurement's margin in every run, so
that a margin shrinking release after release shows before it fails. Runs from different profiles, lanes or
suite revisions, and incomplete runs, are flagged, never refused.

:func:`compare` takes parsed ``results.json`` documents (:func:`parse_run`) and returns one JSON-ready
dict; :func:`text` and :func:`page` render it. Only :func:`read_run` touches the file system. The skeleton it shares
with the soak's comparison (reading a record, the letters, the pairs, the flags' form, the page's frame) is
:mod:`.comparing`'s.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..protocol.catalogue import firmware_date
from ..protocol.requirements import REQUIREMENTS, SECTION_TITLES, VERDICT_LEGEND, VERDICT_SHORT, VERDICTS, Verdict, section_key
from .comparing import RunError, comparison, differs, first_line, is_soak, last_line, letter, pair_name, read_doc
from .comparing import page as page_frame
from .htmlkit import badge, e, new_figure, svg
from .results import NotRun, Result, RunInfo, RunRecord, broken_requirements, firmware_rows, incomplete_banner, requirement_result

GOOD = (Verdict.PASS, Verdict.OBSERVED)
BAD = (Verdict.FAIL, Verdict.ERROR, Verdict.INCONCLUSIVE)
NOT_CHECKED = "NOT CHECKED"
NOT_RUN = "NOT RUN"
#: the units of a timing measurement, to ms
TIMING_UNITS = {"ms": 1.0, "s": 1000.0}
DEFAULT_THRESHOLD = 0.10
_NOISE_MS = 1e-6  # float noise of the simulated clock: never a shrink


@dataclass
class Run:
    """One run as the comparison needs it, from its ``results.json``."""

    label: str  # the run's id (its directory's name)
    path: str
    info: RunInfo
    results: dict[str, Result]  # by nodeid
    not_run: dict[str, NotRun] = field(default_factory=dict)


# ------------------------------------------------------------------------------------------ reading
def read_run(path: str | Path) -> Run:
    """The run at ``path``: a report directory (``reports/<timestamp>``, ``reports/latest``) or its
    ``results.json``. Raises :class:`RunError`."""
    label, doc = read_doc(path)
    return parse_run(doc, label=label, path=str(path))


def parse_run(doc: Any, *, label: str = "", path: str = "") -> Run:
    """A :class:`Run` from a :class:`~.results.RunRecord` or a parsed ``results.json``; :class:`RunError` when it
    is not one."""
    where = path or label or "run"
    if not isinstance(doc, RunRecord):
        if is_soak(doc):
            raise RunError(f"{where}: a soak run (`ckesc soak`), not a conformance run: compare it with soak runs")
        if not isinstance(doc, dict) or not isinstance(doc.get("results"), list) or not isinstance(doc.get("info"), dict):
            raise RunError(f"{where}: not a results record of `ckesc run` (an object with 'info' and 'results')")
        for n, r in enumerate(doc["results"]):
            if not isinstance(r, dict) or not isinstance(r.get("nodeid"), str) or r.get("outcome") not in VERDICTS:
                raise RunError(f"{where}: result {n} has no nodeid or no verdict this version knows ({', '.join(VERDICTS)})")
        try:
            doc = RunRecord.from_json(doc)
        except (KeyError, TypeError, ValueError) as exc:
            raise RunError(f"{where}: not a results record this version reads: {exc!r}") from None
    results = {r.nodeid: r for r in doc.results}
    not_run = {n["nodeid"]: n for n in doc.not_run if isinstance(n.get("nodeid"), str)}
    return Run(label=str(doc.info.get("run_id") or label or where), path=path, info=doc.info, results=results,
               not_run=not_run)


# ------------------------------------------------------------------------------------------ facts of one run
def identity(info: dict[str, Any], label: str = "") -> dict[str, str]:
    """What the run was made against, as rows to show side by side (absent facts are left out)."""
    rows: dict[str, Any] = {"run id": info.get("run_id") or label}
    if info.get("suite_version"):
        rows["suite"] = f"ckesc {info['suite_version']}" + (f" ({info['git_revision']})" if info.get("git_revision") else "")
    esc = info.get("esc_information")
    if isinstance(esc, dict):
        rows["firmware date"] = firmware_date(esc)
        rows.update({k.replace("_", " "): v for k, v in esc.items() if not k.startswith("firmware_")})
    elif "esc_information" in info:
        rows["ESC information (240)"] = "no answer"
    rows.update(firmware_rows(info))
    rows.update({"DUT": info.get("dut"), "node id": info.get("node_id"), "profile": info.get("profile"),
                 "lane": info.get("lane"), "clock": info.get("clock"),
                 "bit rate": f"{info['bitrate']} bit/s" if info.get("bitrate") else None, "power": info.get("power"),
                 "timing error": f"{info['timing_error_s'] * 1000:g} ms" if info.get("timing_error_s") is not None else None,
                 "emulator faults": info.get("faults") or None,
                 "complete": {True: "yes", False: f"no: {info.get('incomplete') or '?'}"}.get(info.get("complete"))})
    return {k: str(v) for k, v in rows.items() if v not in (None, "")}


def requirement_results(run: Run) -> dict[str, str]:
    """Each requirement's result in the run: the worst verdict of its evidence, or NOT CHECKED. A test's verdict is
    the evidence for every requirement it cites, except a FAIL's: that is a FAIL of the requirements it broke
    (:func:`~ckesc.reporting.results.broken_requirements`) and no verdict on the others it cites (it may have
    stopped before their checks), so a requirement never FAILs for sharing a test with a broken one. A bus rule
    broken while a test ran is a FAIL of that rule."""
    by_req: dict[str, list[str]] = defaultdict(list)
    for r in run.results.values():
        broken = broken_requirements(r)
        for rid in broken:
            by_req[rid].append(Verdict.FAIL)
        if r.outcome != Verdict.FAIL:
            for rid in r.requirements:
                by_req[rid].append(r.outcome)
    return {rid: requirement_result(outcomes) for rid, outcomes in by_req.items()}


def _old_quantity(text: str | None) -> tuple[float, str] | None:
    """(number, unit) of a quantity as a record from before ``measured`` rendered it (``80.2 ms``, ``3``:
    :meth:`~ckesc.bench.outcomes.Measurement.as_properties`), None when it is none."""
    number, _, unit = (text or "").strip().partition(" ")
    try:
        return float(number), unit.strip()
    except ValueError:
        return None


def _measured(r: Result) -> list[dict[str, Any]]:
    """A result's measurements as numbers: as recorded (``measured``), or for a record from before they were, from
    their rendering (``measurements``), each with its value, margin and unit and its limit as text."""
    if r.measured:
        return [{**m, "limit": f"{m['op']} {m['limit']:.6g} {m['unit']}".strip() if m.get("limit") is not None else ""}
                for m in r.measured]
    out = []
    for m in r.measurements:
        value, margin = _old_quantity(m.get("value")), _old_quantity(m.get("margin"))
        out.append({**m, "value": value and value[0], "margin": margin and margin[0],
                    "unit": margin[1] if margin else value[1] if value else ""})
    return out


def timing_margins(run: Run) -> dict[str, dict[str, Any]]:
    """Every timing measurement with a limit (unit ms or s), keyed ``nodeid :: name`` (``#2``, ... for a
    name measured again in the same test): its value, margin (ms), limit and verdict."""
    out: dict[str, dict[str, Any]] = {}
    for nodeid, r in run.results.items():
        seen: Counter = Counter()
        for m in _measured(r):
            if m["margin"] is None or m["value"] is None or m["unit"] not in TIMING_UNITS:
                continue
            name = m.get("name", "?")
            seen[name] += 1
            key = f"{nodeid} :: {name}" + (f" #{seen[name]}" if seen[name] > 1 else "")
            scale = TIMING_UNITS[m["unit"]]
            out[key] = {"test": nodeid, "name": name, "margin_ms": m["margin"] * scale, "value_ms": m["value"] * scale,
                        "limit": m.get("limit", ""), "verdict": m.get("verdict", ""), "requirement": m.get("requirement")}
    return out


def _error_ms(run: Run) -> float:
    return float(run.info.get("timing_error_s") or 0.0) * 1000


def shrank(before: float, after: float, *, threshold: float, error_ms: float = 0.0) -> bool:
    """A margin fell from ``before`` to ``after`` (ms) by more than ``threshold`` of ``before`` and by
    more than the timing error the runs stated (a smaller change is inside what the clock can tell)."""
    drop = before - after
    return drop > max(threshold * abs(before), error_ms, _NOISE_MS)


# ------------------------------------------------------------------------------------------ comparing
def diff(a: Run, b: Run, *, threshold: float = DEFAULT_THRESHOLD) -> dict[str, Any]:
    """What changed from run ``a`` to run ``b``."""
    tests: dict[str, list[dict[str, Any]]] = {k: [] for k in ("regressed", "fixed", "changed", "added", "removed",
                                                             "not_run")}
    known_a, known_b = a.results.keys() | a.not_run.keys(), b.results.keys() | b.not_run.keys()
    for nodeid in sorted(known_a | known_b, key=lambda n: (_section(a, b, n), n)):
        before = a.results[nodeid].outcome if nodeid in a.results else NOT_RUN
        after = b.results[nodeid].outcome if nodeid in b.results else NOT_RUN
        row = {"test": nodeid, "section": _section(a, b, nodeid), "before": str(before), "after": str(after),
               "message": b.results[nodeid].message.split("\n")[0][:300] if nodeid in b.results else "",
               "broke": broken_requirements(b.results[nodeid]) if nodeid in b.results else []}
        if nodeid not in known_a:
            tests["added"].append(row)
        elif nodeid not in known_b:
            tests["removed"].append(row)
        elif before in GOOD and after in BAD:
            tests["regressed"].append(row)
        elif before in BAD and after in GOOD:
            tests["fixed"].append(row)
        elif NOT_RUN in (before, after) and before != after:
            tests["not_run"].append(row)
        elif before != after:
            tests["changed"].append(row)
    reqs: dict[str, list[dict[str, Any]]] = {k: [] for k in ("regressed", "fixed", "changed")}
    ra, rb = requirement_results(a), requirement_results(b)
    for rid in sorted(ra.keys() | rb.keys(), key=_req_key):
        before, after = ra.get(rid, NOT_CHECKED), rb.get(rid, NOT_CHECKED)
        req = REQUIREMENTS.get(rid)
        row = {"requirement": rid, "strength": req.strength if req else "", "section": req.section if req else "",
               "before": before, "after": after}
        if before in GOOD and after in BAD:
            reqs["regressed"].append(row)
        elif before in BAD and after in GOOD:
            reqs["fixed"].append(row)
        elif before != after:
            reqs["changed"].append(row)
    ma, mb = timing_margins(a), timing_margins(b)
    error = max(_error_ms(a), _error_ms(b))
    margins = [{"measurement": key, "test": mb[key]["test"], "name": mb[key]["name"],
                "before_ms": ma[key]["margin_ms"], "after_ms": mb[key]["margin_ms"],
                "value_before_ms": ma[key]["value_ms"], "value_after_ms": mb[key]["value_ms"],
                "limit_before": ma[key]["limit"], "limit_after": mb[key]["limit"], "verdict_after": mb[key]["verdict"]}
               for key in ma.keys() & mb.keys()
               if shrank(ma[key]["margin_ms"], mb[key]["margin_ms"], threshold=threshold, error_ms=error)]
    margins.sort(key=lambda m: m["after_ms"] - m["before_ms"])
    return {"from": a.label, "to": b.label, "tests": tests, "requirements": reqs, "margins_shrank": margins,
            "regressed": bool(tests["regressed"] or reqs["regressed"])}


def _section(a: Run, b: Run, nodeid: str) -> str:
    for r in (b.results.get(nodeid), a.results.get(nodeid)):
        if r is not None and r.section:
            return r.section
    for n in (b.not_run.get(nodeid), a.not_run.get(nodeid)):
        if n and n.get("section"):
            return n["section"]
    return ""


def _req_key(rid: str) -> tuple:
    req = REQUIREMENTS.get(rid)
    return (section_key(req.section) if req else (999,), rid)


def flags(runs: list[Run]) -> list[str]:
    """What makes the comparison less than like for like, one line each."""
    out = []
    for key, what in (("profile", "DUT profiles"), ("lane", "lanes"), ("dut", "kinds of DUT"),
                      ("timing_error_s", "stated timing errors"), ("bitrate", "bit rates")):
        out += differs(what, [r.info.get(key) for r in runs])  # a run that does not say is not flagged for it
    suites = [(r.info.get("suite_version"), r.info.get("git_revision")) for r in runs]
    if all(v for v, _ in suites) and len(set(suites)) > 1:  # runs older than these fields: nothing to tell
        out.append("different suite revisions (a verdict may have changed with the suite, not the DUT): "
                   + ", ".join(f"{letter(i)} {v or '?'} {g or ''}".rstrip() for i, (v, g) in enumerate(suites)))
    for i, r in enumerate(runs):
        if r.info.get("complete") is not True:
            out.append(f"{letter(i)} ({r.label}) is incomplete: "
                       + (incomplete_banner(r.info) or "the record does not say it was complete"))
    return out


def compare(runs: list[Run], *, threshold: float = DEFAULT_THRESHOLD) -> dict[str, Any]:
    """The comparison of two or more runs, oldest first, as one JSON-ready dict."""
    req_results = [requirement_results(r) for r in runs]
    rids = sorted(set().union(*req_results), key=_req_key)
    matrix = [{"requirement": rid, "strength": REQUIREMENTS[rid].strength if rid in REQUIREMENTS else "",
               "section": REQUIREMENTS[rid].section if rid in REQUIREMENTS else "",
               "results": [rr.get(rid, NOT_CHECKED) for rr in req_results]} for rid in rids]
    margins = [timing_margins(r) for r in runs]
    errors = [_error_ms(r) for r in runs]
    trends = []
    for key in sorted(set().union(*margins)):
        series = [m[key]["margin_ms"] if key in m else None for m in margins]
        first = next(m[key] for m in margins if key in m)
        steps = [i for i in range(1, len(runs)) if series[i - 1] is not None and series[i] is not None
                 and shrank(series[i - 1], series[i], threshold=threshold, error_ms=max(errors[i - 1], errors[i]))]
        known = [s for s in series if s is not None]
        trends.append({"measurement": key, "test": first["test"], "name": first["name"], "limit": first["limit"],
                       "margins_ms": series, "shrank_at": [letter(i) for i in steps],
                       "change_ms": known[-1] - known[0] if len(known) > 1 else 0.0})
    trends.sort(key=lambda t: (not t["shrank_at"], t["change_ms"], t["measurement"]))
    return comparison(runs, lambda a, b: diff(a, b, threshold=threshold), _run_row, flags(runs), threshold=threshold,
                      matrix=matrix, trends=trends)


def _run_row(r: Run) -> dict[str, Any]:
    return {"label": r.label, "path": r.path, "identity": identity(r.info, r.label), "complete": r.info.get("complete") is True,
            "incomplete": r.info.get("incomplete") or "",
            "counts": {str(v): n for v, n in Counter(x.outcome for x in r.results.values()).items()}, "not_run": len(r.not_run)}


# ------------------------------------------------------------------------------------------ text
_SHORT = {**VERDICT_SHORT, NOT_CHECKED: "-", NOT_RUN: "-"}
_LISTED = 40  # rows per list on the console; --json and --html have them all


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.4g} ms"


def text(doc: dict[str, Any]) -> str:
    """The comparison for the console."""
    runs = doc["runs"]
    letters = [r["letter"] for r in runs]
    lines = [first_line(doc)]
    for r in runs:
        ident = r["identity"]
        lines.append(f"  {r['letter']}  {r['label']}  {r['path']}  " + ", ".join(
            f"{k} {ident[k]}" for k in ("firmware date", "hardware version", "profile", "lane") if k in ident)
            + ("" if r["complete"] else "  [INCOMPLETE]"))
    for f in doc["flags"]:
        lines.append(f"! {f}")
    keys = _identity_keys(runs)
    width = max(map(len, keys), default=10)
    col = max([12, *(min(28, len(r["identity"].get(k, ""))) for r in runs for k in keys)])
    lines += ["", "identity (* differs)", f"  {'':<{width}}   " + "".join(f"{x:<{col + 2}}" for x in letters)]
    for k in keys:
        values = [r["identity"].get(k, "-") for r in runs]
        mark = "*" if k != "run id" and len(set(values)) > 1 else " "
        lines.append(f"{mark} {k:<{width}}   " + "".join(f"{v[:col]:<{col + 2}}" for v in values).rstrip())
    for p in doc["pairs"]:
        lines += ["", f"{_pair_name(doc, p)}: " + _pair_counts(p)]
        for title, key in (("REGRESSED", "regressed"), ("fixed", "fixed"), ("other changes", "changed")):
            rows = p["requirements"][key]
            if rows:
                lines.append(f"  {title} requirements ({len(rows)}):")
                lines += [f"    {r['requirement']} ({r['strength']}): {r['before']} -> {r['after']}" for r in rows[:_LISTED]]
            rows = p["tests"][key]
            if rows:
                lines.append(f"  {title} tests ({len(rows)}):")
                lines += [f"    {r['test']}: {r['before']} -> {r['after']}"
                          + (f" (broke {' '.join(r['broke'])})" if r.get("broke") and r["after"] == Verdict.FAIL else "")
                          + (f": {r['message'][:160]}" if r["message"] and r["after"] in BAD else "")
                          for r in rows[:_LISTED]]
                if len(rows) > _LISTED:
                    lines.append(f"    ... {len(rows) - _LISTED} more")
        for title, key in (("tests added", "added"), ("tests removed", "removed"), ("run in one of the two only", "not_run")):
            rows = p["tests"][key]
            if rows:
                lines.append(f"  {title} ({len(rows)}):")
                lines += [f"    {r['test']}: " + {"added": r["after"], "removed": f"(was {r['before']})"}.get(
                    key, f"{r['before']} -> {r['after']}") for r in rows[:_LISTED]]
                if len(rows) > _LISTED:
                    lines.append(f"    ... {len(rows) - _LISTED} more")
        if p["margins_shrank"]:
            lines.append(f"  timing margins that shrank by more than {doc['threshold'] * 100:g} % ({len(p['margins_shrank'])}):")
            lines += [f"    {m['measurement']}: margin {_ms(m['before_ms'])} -> {_ms(m['after_ms'])} (measured "
                      f"{_ms(m['value_before_ms'])} -> {_ms(m['value_after_ms'])}, limit {m['limit_after']})"
                      for m in p["margins_shrank"][:_LISTED]]
    if len(runs) > 2:
        differing = [row for row in doc["matrix"] if len(set(row["results"])) > 1]
        lines += ["", f"requirements x runs: {len(doc['matrix'])} requirements, {len(differing)} differ between runs"
                  + (" (those below; --html for all)" if differing else "")]
        if differing:
            lines.append(f"  {'requirement':<14}{'':<9}" + "".join(f"{x:<8}" for x in letters))
            lines += [f"  {row['requirement']:<14}{row['strength']:<9}" + "".join(f"{_SHORT.get(v, v):<8}" for v in row["results"])
                      for row in differing]
            lines.append(f"  verdicts: {VERDICT_LEGEND}, - not run")
        moving = [t for t in doc["trends"] if t["shrank_at"]]
        if moving:
            lines += ["", f"timing margins that shrank from one run to the next ({len(moving)}):"]
            lines += [f"  {t['measurement']}: " + " -> ".join(_ms(v) for v in t["margins_ms"]) for t in moving[:_LISTED]]
    lines += ["", last_line(doc, _pair_counts)]
    return "\n".join(lines)


def _identity_keys(runs: list[dict[str, Any]]) -> list[str]:
    """The identity rows of all runs, each where it stands in the runs that have it."""
    keys = list(dict.fromkeys(k for r in runs for k in r["identity"]))
    return sorted(keys, key=lambda k: min(list(r["identity"]).index(k) for r in runs if k in r["identity"]))


def _pair_name(doc: dict[str, Any], pair: dict[str, Any]) -> str:
    return pair_name(doc, next(n for n, p in enumerate(doc["pairs"]) if p is pair))


def _pair_counts(p: dict[str, Any]) -> str:
    t, r = p["tests"], p["requirements"]
    return (f"{len(r['regressed'])} requirements and {len(t['regressed'])} tests regressed, {len(r['fixed'])} requirements and "
            f"{len(t['fixed'])} tests fixed, {len(t['added'])} tests added, {len(t['removed'])} removed, "
            f"{len(p['margins_shrank'])} timing margins shrank")


# ------------------------------------------------------------------------------------------ HTML
def page(doc: dict[str, Any]) -> str:
    """The comparison as one self-contained HTML page, in report.html's style."""
    runs = doc["runs"]
    parts = [identity_table(runs), *(_pair_section(doc, p) for p in doc["pairs"]), matrix_table(doc), _trend_section(doc)]
    return page_frame(doc, heading="CKESC run comparison", lead=f"{len(runs)} runs, oldest first; each compared with the "
                      "one before it", body=parts, title="CKESC run comparison " + " / ".join(r["label"] for r in runs))


def _run_heads(runs: list[dict[str, Any]]) -> str:
    return "".join(f'<th data-run="{e(r["letter"])}">{e(r["letter"])}<div class=note>{e(r["label"])}</div></th>' for r in runs)


def identity_table(runs: list[dict[str, Any]]) -> str:
    keys = _identity_keys(runs)
    rows = []
    for k in keys[1:] if keys[:1] == ["run id"] else keys:  # the run id heads its column
        values = [r["identity"].get(k, "") for r in runs]
        differs = k != "run id" and len(set(values)) > 1
        rows.append(f'<tr data-field="{e(k)}"{" class=diff" if differs else ""}><th>{e(k)}</th>'
                    + "".join(f"<td>{e(v)}</td>" for v in values) + "</tr>")
    return (f"<section id=identity><h2>Devices under test</h2><table class=kv><tr><th></th>{_run_heads(runs)}</tr>"
            f"{''.join(rows)}</table><p class=note>Highlighted: differs between runs.</p></section>")


def _change_rows(rows: list[dict[str, Any]], key: str) -> str:
    return "".join(f'<tr data-{key}="{e(r[key])}"><td>{e(r[key])}</td>'
                   + (f"<td>{e(r.get('strength', ''))}</td>" if key == "requirement" else f"<td>{e(r['section'])}</td>")
                   + f"<td class=vv>{badge(r['before'])} &rarr; {badge(r['after'])}</td>"
                   + (f"<td>{_broke(r)}{e(r.get('message', ''))}</td>" if key == "test" else "") + "</tr>" for r in rows)


def _broke(row: dict[str, Any]) -> str:
    """A test row's requirements its FAIL broke, as HTML (none for another verdict)."""
    if not row.get("broke") or row["after"] != Verdict.FAIL:
        return ""
    return f"<span class=broke>broke {e(' '.join(row['broke']))}</span> "


def _pair_section(doc: dict[str, Any], p: dict[str, Any]) -> str:
    name = _pair_name(doc, p)
    sid = "pair-" + name.replace(" -> ", "-")
    out = [f'<section id="{sid}" class=pair data-regressed="{str(p["regressed"]).lower()}"><h2>{e(name)}: '
           f'{badge("REGRESSED" if p["regressed"] else "NO REGRESSION")}</h2><p>{e(_pair_counts(p))}</p>']
    for title, key in (("Regressed", "regressed"), ("Fixed", "fixed"), ("Other verdict changes", "changed")):
        reqs, tests = p["requirements"][key], p["tests"][key]
        if reqs:
            out.append(f'<h3>{title}: requirements ({len(reqs)})</h3><table class="chg req-{key}"><tr><th>requirement</th>'
                       f"<th>strength</th><th>verdict</th></tr>{_change_rows(reqs, 'requirement')}</table>")
        if tests:
            out.append(f'<h3>{title}: tests ({len(tests)})</h3><table class="chg test-{key}"><tr><th>test</th><th>section</th>'
                       f"<th>verdict</th><th>message</th></tr>{_change_rows(tests, 'test')}</table>")
    for title, key in (("Tests added", "added"), ("Tests removed", "removed"), ("Run in one of the two only", "not_run")):
        tests = p["tests"][key]
        if tests:
            out.append(f'<details class="test-{key}"><summary>{title} ({len(tests)})</summary><table class=chg><tr><th>test</th>'
                       f"<th>section</th><th>verdict</th><th>message</th></tr>{_change_rows(tests, 'test')}</table></details>")
    if p["margins_shrank"]:
        rows = "".join(f'<tr data-measurement="{e(m["measurement"])}">{_what(m)}<td class=lim>{e(m["limit_after"])}</td>'
                       f'<td class=num>{_ms(m["value_before_ms"])}</td><td class=num>{_ms(m["value_after_ms"])}</td>'
                       f'<td class=num>{_ms(m["before_ms"])}</td><td class=num>{_ms(m["after_ms"])}</td>'
                       f'<td>{badge(m["verdict_after"])}</td></tr>' for m in p["margins_shrank"])
        out.append(f"<h3>Timing margins that shrank by more than {doc['threshold'] * 100:g} % ({len(p['margins_shrank'])})</h3>"
                   "<table class=margins-shrank><tr><th>measurement and test</th><th>limit</th><th>measured before</th><th>after</th><th>margin before</th>"
                   f"<th>margin after</th><th></th></tr>{rows}</table>")
    out.append("</section>")
    return "".join(out)


def matrix_table(doc: dict[str, Any]) -> str:
    runs = doc["runs"]
    rows, section = [], None
    for row in doc["matrix"]:
        if row["section"] != section:
            section = row["section"]
            rows.append(f'<tr class=group><th colspan="{len(runs) + 2}">{e(section)} {e(SECTION_TITLES.get(section, ""))}</th></tr>')
        differs = " class=diff" if len(set(row["results"])) > 1 else ""
        rows.append(f'<tr data-requirement="{e(row["requirement"])}" data-results="{e(" ".join(row["results"]))}"{differs}>'
                    f'<td>{e(row["requirement"])}</td><td>{e(row["strength"])}</td>'
                    + "".join(f'<td class="cell c-{v.replace(" ", "-")}">{e(_SHORT.get(v, v))}</td>' for v in row["results"])
                    + "</tr>")
    return (f"<section id=matrix><h2>Requirements x runs</h2><table class=matrix><tr><th>requirement</th><th>strength</th>"
            f"{_run_heads(runs)}</tr>{''.join(rows)}</table></section>")


def _trend_section(doc: dict[str, Any]) -> str:
    runs = doc["runs"]
    trends = doc["trends"]
    if not trends:
        return "<section id=trends><h2>Timing margins</h2><p>No timing measurement with a limit in these runs.</p></section>"
    rows = []
    for t in trends:
        cells = "".join(f"<td class=num>{_ms(v)}</td>" for v in t["margins_ms"])
        rows.append(f'<tr data-measurement="{e(t["measurement"])}" data-shrank="{e(" ".join(t["shrank_at"]))}"'
                    f'{" class=diff" if t["shrank_at"] else ""}>{_what(t)}<td class=lim>{e(t["limit"])}</td>{cells}'
                    f'<td class=spark>{_sparkline(t["margins_ms"])}</td></tr>')
    shrinking = sum(1 for t in trends if t["shrank_at"])
    return (f"<section id=trends><h2>Timing margins in every run</h2><p>{len(trends)} timing measurements; {shrinking} shrank "
            f"by more than {doc['threshold'] * 100:g} % (and more than the stated timing error) from one run to the next: "
            "listed first and highlighted. The line is the margin in each run, oldest left; red below zero (a failure).</p>"
            f"<table class=trend><tr><th>measurement and test</th><th>limit</th>{_run_heads(runs)}<th>margin</th></tr>"
            f"{''.join(rows)}</table></section>")


def _what(m: dict[str, Any]) -> str:
    """A measurement's cell: its name, and the test that made it."""
    return f'<td class=what><b>{e(m["name"])}</b><div class=note>{e(m["test"].removeprefix("conformance/"))}</div></td>'


def _sparkline(series: list[float | None]) -> str:
    """The margin in each run (a small matplotlib SVG): a line, the zero line, red points below zero."""
    points = [(i, v) for i, v in enumerate(series) if v is not None]
    if len(points) < 2:
        return ""
    fig = new_figure(1.6, 0.42)
    fig.set_facecolor("none")  # the row's colour shows through
    ax = fig.add_axes((0.02, 0.08, 0.96, 0.84))
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    ax.plot(xs, ys, color="#0969da", linewidth=1.2)
    ax.scatter(xs, ys, s=8, color=["#cf222e" if y < 0 else "#0969da" for y in ys], zorder=3)
    ax.axhline(0, color="#cf222e", linewidth=0.6, linestyle=":")
    lo, hi = min(0.0, *ys), max(0.0, *ys)
    pad = (hi - lo) * 0.15 or 1.0
    ax.set_ylim(lo - pad, hi + pad)
    ax.set_xlim(-0.3, len(series) - 0.7)
    ax.set_axis_off()
    return svg(fig)
