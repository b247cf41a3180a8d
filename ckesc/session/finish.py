"""The session's end: whether the run was the whole suite run to its end (or why not, and which tests it did not
run), the release gate's verdict against ``--baseline`` (:mod:`.baseline`), its exit status (decided here, once, from
both: :func:`~ckesc.reporting.exits.of_run`; ``ckesc run`` returns it), and its
reports written (``ckesc/reporting``) and summarised on the console."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from ..protocol.requirements import Verdict
from ..reporting import report
from ..reporting.exits import ExitStatus, of_run
from ..reporting.gate import REGRESSED
from ..reporting.results import profile_warnings
from . import baseline, trace_hooks
from .collection import conformance_dir, item_requirements, section_of
from .state import RunState, report_dir, state


def _module_name(nodeid_or_item) -> str:
    mod = getattr(nodeid_or_item, "module", None)
    if mod is not None:
        return mod.__name__.rsplit(".", 1)[-1]
    return Path(str(nodeid_or_item).split("::")[0]).stem


#: the verdicts a test has only once it ran to its end (its teardown judges the bus rules that ran under it)
NEEDS_THE_END = (Verdict.PASS, Verdict.OBSERVED)


def cut_short(st: RunState) -> list[str]:
    """The tests the run's end cut (an interrupt, an abort) before their teardown reported, with no finding yet: a
    test whose phase did not finish is never a PASS (pytest counts it in no outcome either); it is "not run to its
    end". A FAIL, ERROR, INCONCLUSIVE or SKIPPED decided before the cut stands."""
    return [n for n, r in st.results.items() if n not in st.finished and r.outcome in NEEDS_THE_END]


def _completeness(session: pytest.Session, exitstatus: int) -> tuple[str | None, list[dict[str, Any]]]:
    """Why this run is less than the whole suite ("aborted: ...", "interrupted", "stopped: ...",
    "subset: ..."; None: it is the whole suite, run to its end), and the tests it did not run."""
    st = state(session.config)
    reason = st.stopped
    if reason is None and exitstatus == pytest.ExitCode.INTERRUPTED:
        reason = f"stopped: {session.shouldstop}" if isinstance(session.shouldstop, str) else "interrupted"
    if reason is None and session.shouldfail:
        reason = f"stopped: {session.shouldfail} (-x / --maxfail)"
    why = {"aborted": "the run was aborted", "interrupted": "the run was interrupted",
           "stopped": "the run stopped early"}.get((reason or "").split(":")[0].split(" ")[0])
    cut = set(cut_short(st))
    for nodeid in cut:
        del st.results[nodeid]
    not_run = [{"nodeid": it.nodeid, "name": it.name, "section": section_of(it), "requirements": item_requirements(it),
                "reason": (f"not run to its end: {why} while it ran" if why else "not run to its end") if it.nodeid in cut
                else (f"not run: {why}" if why else "not run")}
               for it in st.selected if it.nodeid not in st.results]
    not_run += [{"nodeid": n, "name": n.split("::")[-1], "section": "", "requirements": [], "reason": "not run: deselected"}
                for n in st.deselected]
    where = conformance_dir()
    suite = {p.stem for p in where.glob("test_*.py")} if where else set()
    ran = {_module_name(it) for it in st.selected} | {_module_name(n) for n in st.deselected}
    left_out = sorted(suite - ran)
    if reason is None and (st.deselected or left_out or any("::" in a for a in session.config.args)):
        parts = []
        if left_out:
            parts.append(f"{len(suite) - len(left_out)} of {len(suite)} section modules selected")
        if st.deselected:
            parts.append(f"{len(st.deselected)} tests deselected")
        reason = "subset: " + ("; ".join(parts) or "single tests selected")
    return reason, not_run


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    st = state(session.config)
    traces = trace_hooks.writer(session.config)
    if traces is not None:
        traces.end()
    if not st.conformance or not st.selected or exitstatus == pytest.ExitCode.USAGE_ERROR:
        return  # a set-up mistake (the preflight, the bench proof): one line, no report
    reason, not_run = _completeness(session, exitstatus)
    st.info["complete"] = reason is None
    st.info["incomplete"] = reason or ""
    st.info["not_run"] = len(not_run)
    gate = baseline.judged(session.config, st, reason, not_run)  # (--baseline: the release gate, into st.info)
    st.exit_status = of_run(st.results.values(), stopped=reason, strict=session.config.getoption("ckesc_strict"),
                            regressed=bool(gate and gate["verdict"] == REGRESSED))
    if st.exit_status in (ExitStatus.ABORTED, ExitStatus.FAILED):  # (a bus rule broken while a SKIPPED test ran)
        session.exitstatus = st.exit_status  # pytest's own statuses otherwise: its INTERRUPTED is 2
    out = report_dir(session.config)
    if out is not None:
        report.write_reports(out, list(st.results.values()), st.info, not_run=not_run,
                             html=not session.config.getoption("ckesc_no_html"))
        st.info["report_dir"] = str(out)
    if session.exitstatus == ExitStatus.ABORTED:  # pytest prints no terminal summary for this status: ours, then
        tr = session.config.pluginmanager.get_plugin("terminalreporter")
        if tr is not None:
            pytest_terminal_summary(tr, ExitStatus.ABORTED, session.config)


def pytest_terminal_summary(terminalreporter, exitstatus: int, config: pytest.Config) -> None:
    st = state(config)
    for left in st.info.get("not_restored", []):  # always said, summary or not: the bench needs a look
        terminalreporter.write_line(f"WARNING: the DUT's settings were not restored after {left['test']}: {left['why']}")
    if exitstatus == pytest.ExitCode.USAGE_ERROR:
        return
    if not st.conformance or not st.selected or not config.getoption("ckesc_summary"):
        for line in profile_warnings(st.info):  # (the summary says them otherwise)
            terminalreporter.write_line(line)
        return
    terminalreporter.write_sep("=", "CKESC conformance summary")
    terminalreporter.write_line(report.summary_text(list(st.results.values()), st.info))
    if "report_dir" in st.info:
        terminalreporter.write_line(f"reports: {st.info['report_dir']}")

