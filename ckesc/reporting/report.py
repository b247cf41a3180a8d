"""Run reports: JUnit XML (one testsuite per spec section), a JSON record and a text summary,
under ``reports/<timestamp>/`` with ``reports/latest`` pointing at the newest run.

The JUnit file is built with the ``junit-xml`` package. That package has no per-testcase
properties, so each testcase's requirement ids, strength, verdict and measurements are added as
``<properties>`` afterwards (Jenkins shows them) and repeated as ``[[PROPERTY|name=value]]`` lines
in its system-out (GitLab and other readers that drop properties still show them). Every testsuite
carries the run's identity as properties (:func:`suite_properties`), and classnames are one dot deep
(:func:`classname`), so that Jenkins, which splits a classname at its last dot into package and class,
shows one package ``ckesc`` with a class per section.
"""

from __future__ import annotations

import os
import re
import subprocess
import xml.etree.ElementTree as ET
from collections import Counter, defaultdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Mapping

from junit_xml import TestCase, TestSuite, to_xml_report_string

from .. import __version__
from ..protocol import catalogue as cat
from ..protocol.requirements import (
    REQUIREMENTS,
    SECTION_TITLES,
    VERDICT_LEGEND,
    VERDICT_SHORT,
    VERDICTS,
    Verdict,
    section_heading,
    section_key,
)
from . import causes, gate, html_report
from .results import RunRecord, claim_text, firmware_rows, incomplete_banner, profile_warnings


def _properties(r) -> dict[str, str]:
    props = {"nodeid": r.nodeid, "requirements": " ".join(r.requirements), "strength": r.strength, "verdict": r.outcome,
             "section": r.section}
    for lane, path in r.traces.items():
        props[f"trace.{lane}" if lane else "trace"] = path
    props.update(r.properties)
    for n, (what, value) in enumerate(r.observations):
        props[f"observation.{n}"] = f"{what}: {value}"
    return props


def classname(section: str) -> str:
    """The JUnit classname of a section's tests: ``ckesc.s4_4_22_set_get_freq`` for 4.4.22 Set/Get Freq.

    Letters, digits and ``_`` after a single dot: Jenkins splits a classname at its last dot into package
    and class (``ckesc.4.4.22 Set/Get Freq`` would be class ``22 Set/Get Freq`` of a package ``ckesc.4.4``,
    with a slash in its URL), and GitLab keys test cases by classname and name."""
    slug = re.sub(r"[^a-z0-9]+", "_", f"{section or 'unselected'} {SECTION_TITLES.get(section, '')}".lower()).strip("_")
    return f"ckesc.{'s' + slug if slug[:1].isdigit() else slug}"


def git_revision(source: Path | None = None) -> str | None:
    """The commit of the checkout the suite runs from (``<sha>-dirty`` with uncommitted changes), or None
    when it is installed from a wheel, git is missing or anything else goes wrong (never an error)."""
    source = source or Path(__file__).resolve().parents[2]
    if not (source / ".git").exists():  # the package directory is not at the top of a checkout
        return None
    try:
        head = subprocess.run(["git", "-C", str(source), "rev-parse", "--verify", "HEAD"], capture_output=True,
                              text=True, timeout=20)
        if head.returncode != 0 or not re.fullmatch(r"[0-9a-f]{40,64}", head.stdout.strip()):
            return None
        dirty = subprocess.run(["git", "-C", str(source), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError, ValueError):
        return None
    return head.stdout.strip() + ("-dirty" if dirty.returncode == 0 and dirty.stdout.strip() else "")


def suite_properties(info: dict[str, Any]) -> dict[str, str]:
    """The run's info as JUnit testsuite properties: every plain value as it is (``complete``, ``lane``,
    ``node_id``, ``timing_error_s``, ...), ESC Information 240 as ``esc_information.<field>`` and
    ``firmware_date`` (``esc_information`` = ``no answer`` when the DUT gave none), and ``none`` for an
    unknown value (``git_revision`` outside a checkout); the release gate as ``gate.verdict``, ``gate.baseline`` and
    ``gate.reason.<n>``."""
    props: dict[str, str] = {}
    for key, value in info.items():
        if key == "gate":  # the release gate (--baseline): its verdict and one property per reason
            props.update(gate.properties(value))
        elif isinstance(value, dict):
            props.update({f"{key}.{k}": "none" if v is None else str(v) for k, v in value.items()})
        else:
            props[key] = "none" if value is None else str(value)
    esc = info.get("esc_information")
    if isinstance(esc, dict):
        if date := cat.firmware_date(esc):
            props["firmware_date"] = date
    elif "esc_information" in info:
        props["esc_information"] = "no answer"
    return props


def junit_xml(results: list, info: dict[str, Any], out: Path | None = None, not_run: list[dict[str, Any]] = ()) -> str:
    """The JUnit document; with ``out`` (the run's directory) each of a test's traces is also an
    ``[[ATTACHMENT|/absolute/path]]`` line (Jenkins' JUnit attachments plugin wants it absolute).
    Every testsuite carries the run's info (``complete``, ``incomplete``: why not); the tests the run
    did not get to (``not_run``) are skipped testcases saying why."""
    by_section: dict[str, list] = defaultdict(list)
    for r in results:
        by_section[r.section].append(r)
    skipped_cases: dict[str, list[TestCase]] = defaultdict(list)
    for n in not_run:
        section = n.get("section") or "unselected"
        tc = TestCase(f"{n['name']} [{' '.join(n.get('requirements', []))}]".replace(" []", ""),
                      classname=classname(section), status="NOT RUN")
        tc.add_skipped_info(message=n.get("reason") or "not run")
        skipped_cases[section].append(tc)
        by_section.setdefault(section, [])
    suites = []
    suite_props = suite_properties(info)
    cases_props: list[dict[str, str]] = []
    for section in sorted(by_section, key=section_key):
        cases = []
        for r in by_section[section]:
            props = _properties(r)
            lines = "\n".join(f"[[PROPERTY|{k}={v}]]" for k, v in props.items())
            if out is not None:
                lines += "".join(f"\n[[ATTACHMENT|{(out / path).resolve()}]]" for path in r.traces.values())
            tc = TestCase(f"{r.name} [{' '.join(r.requirements)}]", classname=classname(section),
                          elapsed_sec=round(r.duration, 6), stdout=lines, status=r.outcome)
            if r.outcome == Verdict.FAIL:
                tc.add_failure_info(message=r.message[:500], output=r.message, failure_type=r.strength)
            elif r.outcome == Verdict.ERROR:
                tc.add_error_info(message=r.message[:500], output=r.message)
            elif r.outcome in (Verdict.INCONCLUSIVE, Verdict.SKIPPED):
                tc.add_skipped_info(message=r.message[:500] or r.outcome)
            cases.append(tc)
            cases_props.append(props)
        cases += skipped_cases.get(section, [])
        cases_props += [{"verdict": "NOT RUN"}] * len(skipped_cases.get(section, []))
        suites.append(TestSuite(section_heading(section), cases, properties=suite_props))
    if unjudged := causes.rule_failures(results):  # the rules' failures, each where it was seen
        cases = []
        for u in unjudged:
            text = "\n".join(c["first"] for c in u["causes"]) or " ".join(u["rules"])
            tc = TestCase(f"{' '.join(u['rules'])} while {u['test'].split('::', 1)[-1]} ran ({u['outcome']})",
                          classname="ckesc.bus_rules", status=Verdict.FAIL)
            tc.add_failure_info(message=f"[bus rules {' '.join(u['rules'])}] broken while {u['test']} ran; its own "
                                        f"verdict: {u['outcome']}"[:500], output=text, failure_type="bus rule")
            cases.append(tc)
            cases_props.append({"requirements": " ".join(u["rules"]), "verdict": Verdict.FAIL, "seen_in": u["test"]})
        suites.append(TestSuite("bus rules broken outside a test's FAIL", cases, properties=suite_props))
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


def _counts(per_verdict: Mapping) -> str:
    """A row's cells, one per verdict, each as wide as its column's head (:data:`VERDICT_SHORT`) and at least 5."""
    return " ".join(f"{per_verdict[v]:>{max(5, len(VERDICT_SHORT[v]))}}" for v in VERDICTS)


def summary_text(results: list, info: dict[str, Any]) -> str:
    rows = defaultdict(Counter)
    for r in results:
        rows[r.section][r.outcome] += 1
    # the counts first and the title last, whole: no word of either is cut (the verdicts abbreviated, with a legend)
    head = f"{'section':<10} " + _counts(VERDICT_SHORT) + "  title"
    rule = "-" * max(len(head), len(head) - len("title") + max((len(SECTION_TITLES.get(s, "")) for s in rows), default=0))
    lines = [head, rule]
    total = Counter()
    for section in sorted(rows, key=section_key):
        c = rows[section]
        total.update(c)
        lines.append(f"{section:<10} {_counts(c)}  {SECTION_TITLES.get(section, '')}".rstrip())
    lines.append(rule)
    lines.append(f"{'all':<10} {_counts(total)}")
    lines.append(f"verdicts: {VERDICT_LEGEND}")
    cov = coverage(results)
    lines.append(f"requirements: {len(cov['covered'])} of {cov['total']} checked; "
                 f"SHALL/READING not checked in this run: {len(cov['uncovered'])}"
                 + (f" ({', '.join(cov['uncovered'][:12])}{' ...' if len(cov['uncovered']) > 12 else ''})" if cov["uncovered"] else ""))
    dut = ", ".join(f"{k}={info[k]}" for k in ("dut", "lane", "profile", "node_id", "bitrate", "power", "faults") if info.get(k) not in (None, ""))
    lines.append(f"DUT: {dut}")
    lines += [f"{label}: {value}" for label, value in firmware_rows(info)]
    if info.get("emulator_variants") not in (None, "", "defaults"):  # a conforming variant: replayable from these
        seed = info.get("emulator_variants_seed")
        lines.append(f"variant: {info['emulator_variants']}" + (f" (drawn from --emulator-variants {seed})" if seed is not None else ""))
    if info.get("clock"):  # the bench's stated error: timing margins inside it are INCONCLUSIVE
        lines.append(f"timing: {info['clock']} clock, stated error +-{(info.get('timing_error_s') or 0.0) * 1000:g} ms "
                     f"(the bench's), report-interval jitter allowance {(info.get('jitter_s') or 0.0) * 1000:g} ms (the DUT's)")
    if "not_claimed" in info:
        lines.append(claim_text(info))
    lines += profile_warnings(info)
    if info.get("echo") is not None:  # whether the bench echoes the host's own frames, and so what times them
        own = f"{info.get('own_frames_clock')}, error +-{(info.get('own_frames_error_s') or 0.0) * 1000:g} ms"
        lines.append(f"echo: {'yes' if info['echo'] else 'NO'} ({info.get('echo_note', '')}); the host's own frames "
                     f"timed by: {own}")
    if info.get("run_frames_not_kept"):
        lines.append(f"run-wide checks (4.1): {info['run_frames_not_kept']} of the DUT's frames were not kept (more than "
                     "the run keeps: a flooding DUT); those checks judged the frames kept")
    if ft := info.get("foreign_traffic"):
        lines.append(foreign_traffic_text(ft))
    if info.get("bus_recoveries"):
        lines.append(f"bus failures recovered from (the lane reopened the bus): {'; '.join(info['bus_recoveries'])}")
    if banner := incomplete_banner(info):
        lines.insert(0, banner)
        lines.append(banner)
    if unjudged := causes.rule_failures(results):
        rules = " ".join(dict.fromkeys(i for u in unjudged for i in u["rules"]))
        lines.append(f"bus rules broken while {len(unjudged)} test(s) without a FAIL of their own ran ({rules}): "
                     "the rules' failures (below), not those tests'; the run fails")
    lines += causes.summary_lines(results)
    return "\n".join(lines)


def run_dir(base: Path, started: float, kind: str = "") -> Path:
    """A new directory ``base/<UTC timestamp>[-kind][-n]/`` for a run that started at ``started`` (``kind``: another
    command's run than the suite's, ``soak``)."""
    stamp = datetime.fromtimestamp(started, UTC).strftime("%Y%m%dT%H%M%SZ") + (f"-{kind}" if kind else "")
    out = base / stamp
    n = 1
    while True:
        try:
            out.mkdir(parents=True)
            return out
        except FileExistsError:
            n += 1
            out = base / f"{stamp}-{n}"


def point_latest(out: Path) -> None:
    """``out.parent/latest`` -> ``out`` (replaced at once; a text file ``LATEST`` where there are no symlinks)."""
    base = out.parent
    latest = base / "latest"
    tmp = base / f".latest-{os.getpid()}"
    try:
        if tmp.is_symlink() or tmp.exists():
            tmp.unlink()
        tmp.symlink_to(out.name)
        os.replace(tmp, latest)
    except OSError:  # no symlinks here: a text pointer instead
        (base / "LATEST").write_text(out.name + "\n")


def write_reports(out: Path, results: list, info: dict[str, Any], *, not_run: list[dict[str, Any]] = (),
                  html: bool = True) -> Path:
    """Write the run's reports into ``out`` (from :func:`run_dir`), ``report.html`` last (built from
    ``results.json``; ``html=False``: not at all), and point ``latest`` at it. ``info`` gains the run's
    id (the directory's name), the suite's version and its git revision (None outside a checkout)."""
    info.setdefault("run_id", out.name)
    info.setdefault("suite_version", __version__)
    info.setdefault("git_revision", git_revision())
    (out / "junit.xml").write_text(junit_xml(results, info, out, not_run), encoding="utf-8")
    RunRecord(info, list(results), list(not_run), coverage(results), causes.rule_failures(results)).write(out / "results.json")  # type: ignore[arg-type]
    (out / "summary.txt").write_text("\n".join([*gate.lines(info.get("gate")), summary_text(results, info)]) + "\n",
                                     encoding="utf-8")  # the release gate's verdict and reasons first (--baseline)
    point_latest(out)
    if html:
        html_report.build(out)
    return out


def foreign_traffic_text(ft: Mapping[str, Any]) -> str:
    """The summary's line on the foreign traffic a run played (``--foreign-traffic``): what, from which nodes, the
    frames and load it reached and how late it was."""
    nodes = sorted({s["node"] for s in ft.get("streams", [])})
    late = (f", late by {ft.get('late_mean_ms', 0):g} ms on average, {ft.get('late_max_ms', 0):g} ms at most"
            if ft.get("late_max_ms") else "")
    errors = f", {ft['send_errors']} sends failed" if ft.get("send_errors") else ""
    return (f"foreign traffic: {ft.get('profile')} from nodes {', '.join(map(str, nodes))} played during the run: "
            f"{ft.get('frames', 0)} frames in {ft.get('seconds', 0):g} s, {ft.get('load', 0) * 100:.2f} % of the bus"
            f"{late}{errors}")
