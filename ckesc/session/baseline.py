"""The release gate in the session (``--ckesc-baseline``, ``ckesc run --baseline``): the baseline read once the tests
are collected, before the bench is proven (one that is not a run, or shares no selected test, ends the run there: a
usage error, exit 2); the gate judged at the session's end from the run's results (:func:`judged`, which the
session's end calls before it decides the exit status); its lines at the console's end. The judging is
:mod:`ckesc.reporting.gate`'s."""

from __future__ import annotations

from typing import Any

import pytest

from ..reporting import gate
from ..reporting.compare import parse_run
from ..reporting.results import RunRecord
from .collection import is_conformance
from .state import RunState, state

_BASELINE = pytest.StashKey[gate.Run]()


@pytest.hookimpl(tryfirst=True)  # before the bench proof: a baseline that cannot gate is refused before any work
def pytest_collection_finish(session: pytest.Session) -> None:
    config = session.config
    path = config.getoption("ckesc_baseline")
    selected = [it.nodeid for it in session.items if is_conformance(it)]
    if not path or not selected or _BASELINE in config.stash:
        return
    try:
        baseline = gate.load(path)
    except gate.RunError as exc:
        raise pytest.UsageError(f"--baseline {exc}") from None
    if not gate.shared_tests(baseline, selected):
        sections = sorted({r.section for r in baseline.results.values() if r.section})
        raise pytest.UsageError(f"--baseline {path}: that run has no verdict of any of the {len(selected)} tests selected "
                                f"here (it ran {len(baseline.results)} tests, sections {', '.join(sections) or 'none'}): the "
                                "gate compares the tests both runs ran; select some of them")
    config.stash[_BASELINE] = baseline


def judged(config: pytest.Config, st: RunState, stopped: str | None, not_run: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The gate's record for this run (None without a baseline), kept in the run's info (``info["gate"]``):
    judged over the run's results, or NOT JUDGED when the run did not end (``stopped``: aborted, interrupted)."""
    path = config.getoption("ckesc_baseline")
    baseline = config.stash.get(_BASELINE, None)
    if not path or baseline is None:
        return None
    if (stopped or "").startswith(("aborted", "interrupted")):
        record = gate.not_judged(str(path), f"the run {stopped.split(':')[0]}")  # type: ignore[union-attr]
    else:
        current = parse_run(RunRecord(st.info, list(st.results.values()), not_run), label="this run")  # type: ignore[arg-type]
        record = gate.judge(baseline, current, threshold=config.getoption("ckesc_baseline_threshold") / 100)
    st.info["gate"] = record
    return record


@pytest.hookimpl(trylast=True)  # after the summary and the reports' line: the console's last words
def pytest_terminal_summary(terminalreporter, exitstatus: int, config: pytest.Config) -> None:
    for line in gate.lines(state(config).info.get("gate")):
        terminalreporter.write_line(line)
