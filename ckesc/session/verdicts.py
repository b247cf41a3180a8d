"""Verdicts: each phase report of a conformance test made into the test's one :class:`~ckesc.reporting.results.Result`
(PASS, FAIL, OBSERVED, INCONCLUSIVE, SKIPPED, ERROR), its message saying what the DUT did, the bus rules' say in it,
and the console counting each test once by that verdict. Also the run's stop when the bench goes away or the DUT
falls silent.

A phase's verdict is decided in one place, :func:`_outcome`, from the type of what ended it (as pytest decides
passed, failed or skipped from the exception's type in one hook): :class:`~ckesc.bench.outcomes.Inconclusive` is
INCONCLUSIVE (a measurement inside the bench's error is one too), any other skip SKIPPED, a harness or bus error
(:class:`~ckesc.bench.errors.HarnessError`, ``BusFault``, ``BenchGone``) ERROR whatever the requirement's strength;
never a word in the message. The DUT not answering what a test needed (``DutError``) is no verdict on the DUT
(ERROR), but in an OBSERVE test, where it is what the DUT did (OBSERVED); a bench the harness could not put back
afterwards (:class:`~ckesc.bench.errors.RestoreFailed`, a HarnessError, even where the DUT's silence was why) is
ERROR in an OBSERVE test too."""

from __future__ import annotations

import pytest

from ..bench.dut import Dut, DutError
from ..bench.errors import HarnessError
from ..bench.lanes import BenchGone, BusFault
from ..bench.outcomes import Broken, Inconclusive, NotClaimed, failure_text
from ..evidence.timing import evidence
from ..protocol.requirements import Verdict, requirement, strongest
from ..reporting.results import Result
from . import bus_rules
from .collection import is_conformance, item_requirements, section_of
from .fixtures import dut_of
from .state import state

#: a DUT that did not send one frame in this many tests in a row, each of which ERRORed, has stopped
#: answering: the run is aborted rather than every remaining test ERRORing the same way
SILENT_TESTS_TO_ABORT = 3

_DECISIVE = pytest.StashKey[pytest.TestReport]()  # the phase report that decided a test's verdict
_MESSAGE = pytest.StashKey[str]()  # the test's failure message: what the DUT did (or the harness problem)
_BROKEN = pytest.StashKey[list[Broken]]()  # what the test broke, typed: the message is its rendering
_SILENT = pytest.StashKey[int]()  # tests in a row that ERRORed without a frame from the DUT


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    rep: pytest.TestReport = yield
    if not is_conformance(item):
        return rep
    ids = item_requirements(item)
    strength = strongest(ids)
    d = dut_of(item)
    raised = call.excinfo.value if call.excinfo is not None else None  # what ended the phase: decides its verdict
    # the suite, the bus or the bench (its power control) failed under the test, not the DUT: an ERROR whatever the
    # requirement's strength
    if rep.when == "call" and isinstance(raised, HarnessError):
        _harness_failed(item, rep, raised, d)
    elif rep.when == "call" and not isinstance(raised, BENCH_FAILED):
        asserted = call.excinfo is not None and isinstance(call.excinfo.value, AssertionError)
        if rep.failed and strength == "OBSERVE":  # what the DUT did (an assert, or no answer: DutError) is observed
            rep.outcome = "passed"
            msg = str(call.excinfo.value) if call.excinfo else ""
            if d is not None:
                d.record.observe("observed deviation", msg)
        elif (rep.failed and asserted) or (not rep.failed and d is not None and d.record.failed):  # INCONCLUSIVE after a failed limit: FAIL
            _judged(item, rep, call, ids, strength, d)
        elif rep.passed and d is not None and d.record.inconclusive:  # a margin inside the bench's error
            raised = Inconclusive("; ".join(d.record.inconclusive))
            rep.outcome = "skipped"
            rep.longrepr = (str(item.path), item.location[1] or 0, raised.msg)
    bus_rules.judge(item, rep, skipped=_skipped(item, rep, raised))
    if not rep.passed and _DECISIVE not in item.stash:
        item.stash[_DECISIVE] = rep
    _collect(item, rep, raised, ids, strength, d)
    if call.excinfo is not None and isinstance(call.excinfo.value, BenchGone):
        _stop(item, f"aborted: {call.excinfo.value}")
    if rep.when == "teardown":
        state(item.config).finished.add(item.nodeid)
        _watch_silence(item, d)
        _final_report(item, rep)
    return rep


def _skipped(item: pytest.Item, rep: pytest.TestReport, raised: BaseException | None) -> bool:
    """Whether the test's own verdict is SKIPPED (not INCONCLUSIVE): as this phase's outcome says, or (at
    teardown) as an earlier phase decided."""
    if rep.when == "call":
        return _outcome(rep, raised, "SHALL") == Verdict.SKIPPED
    res = state(item.config).results.get(item.nodeid)
    return res is not None and res.outcome == Verdict.SKIPPED


def _judged(item: pytest.Item, rep: pytest.TestReport, call: pytest.CallInfo, ids: list[str], strength: str,
            d: Dut | None) -> None:
    """A test that failed an assert or a limit: its message says what the DUT did, the strongest broken
    requirement first and every other failed limit after it (never the traceback's fixture repr; that
    stays below on the console)."""
    own = None
    if rep.failed and call.excinfo is not None:
        text = str(call.excinfo.value).strip()
        if "\nassert " in text:  # pytest's explanation of the assert follows the test's own message: reprs
            text = text.split("\nassert ", 1)[0].strip()
        own = Broken.of_assertion(text or "assertion failed",
                                  [i for i in ids if requirement(i).strength == strength] or ids, strength)
    broken = d.record.broken(own) if d is not None else [own] if own else []
    message = item.stash[_MESSAGE] = failure_text(broken)
    item.stash[_BROKEN] = broken
    trace = rep.longrepr
    rep.outcome = "failed"
    crash = getattr(trace, "reprcrash", None) if rep.failed else None
    if crash is not None and hasattr(crash, "message"):
        # keep pytest's traceback for the FAILURES section, and make its one-line crash message ours: the
        # short test summary (whole on CI, where pytest does not trim it) then says what the DUT did
        crash.message = message
        rep.sections.append(("ckesc verdict", message))
    elif isinstance(trace, tuple):  # a skip (INCONCLUSIVE) raised after a failed limit: the FAIL, then why it stopped
        rep.longrepr = f"{message}\nthen: {trace[2]}"
    else:
        rep.longrepr = message if trace is None or not rep.failed else f"{message}\n\n{trace}"


def _harness_failed(item: pytest.Item, rep: pytest.TestReport, raised: HarnessError, d: Dut | None) -> None:
    """A test the suite itself could not carry out (:class:`~ckesc.bench.errors.HarnessError`): an ERROR, its message
    the harness's, with the limits the DUT had failed before it listed (they are no verdict now)."""
    limits = d.record.failure_message() if d is not None else ""
    message = str(raised).strip() + (f"\nfailed limits before it:\n{limits}" if limits else "")
    item.stash[_MESSAGE] = message
    crash = getattr(rep.longrepr, "reprcrash", None)
    if crash is not None and hasattr(crash, "message"):
        crash.message = message
        rep.sections.append(("ckesc verdict", message))


def _stop(item: pytest.Item, why: str) -> None:
    """End the run after this test (its teardown still zeroes the throttle)."""
    st = state(item.config)
    st.stopped = st.stopped or why
    item.session.shouldstop = why


def _watch_silence(item: pytest.Item, d: Dut | None) -> None:
    """Abort when the DUT has stopped answering: several tests in a row ERRORed without one frame from it."""
    st = state(item.config)
    res = st.results.get(item.nodeid)
    if res is None:
        return
    heard = d is not None and (any(f.source == d.node_id for f in d.trace)
                               or any(g.msg.arbitration_id & 0x7F == d.node_id for g in d.garbled))
    silent = item.config.stash[_SILENT] = (item.config.stash.get(_SILENT, 0) + 1
                                           if res.outcome == Verdict.ERROR and not heard else 0)
    if silent >= SILENT_TESTS_TO_ABORT:
        _stop(item, f"aborted: the DUT stopped answering: {silent} tests in a row ERRORed and heard no frame "
                    f"from node {st.node_id} (the last: {res.message.splitlines()[0][:200] if res.message else '?'})")


def _final_report(item: pytest.Item, rep: pytest.TestReport) -> None:
    """The teardown report carries the test's one verdict (pytest_report_teststatus): a failure found
    in any phase, the bus rules' at teardown included, is the test's FAIL, counted once."""
    res = state(item.config).results.get(item.nodeid)
    decisive = item.stash.get(_DECISIVE, None)
    if res is None or decisive is None or decisive is rep:
        return
    if res.outcome in (Verdict.FAIL, Verdict.ERROR) and not rep.failed:
        rep.outcome, rep.longrepr = "failed", decisive.longrepr
        rep.sections = decisive.sections + rep.sections
    elif res.outcome in (Verdict.SKIPPED, Verdict.INCONCLUSIVE) and rep.passed:
        rep.outcome, rep.longrepr = "skipped", decisive.longrepr


#: how the console counts and prints each verdict (category, letter, word): the same verdicts as
#: summary.txt, JUnit and report.html
_CONSOLE = {Verdict.PASS: ("passed", ".", "PASSED"), Verdict.FAIL: ("failed", "F", "FAILED"), Verdict.ERROR: ("error", "E", "ERROR"),
            Verdict.OBSERVED: ("observed", "o", ("OBSERVED", {"blue": True})),
            Verdict.INCONCLUSIVE: ("inconclusive", "i", ("INCONCLUSIVE", {"yellow": True})),
            Verdict.SKIPPED: ("skipped", "s", "SKIPPED")}


@pytest.hookimpl(tryfirst=True)
def pytest_report_teststatus(report: pytest.TestReport, config: pytest.Config):
    """A conformance test is counted once, at its teardown, by its verdict (setup and call are not
    counted on their own): pytest's closing line and progress words say what summary.txt says."""
    if getattr(report, "when", None) is None:
        return None
    res = state(config).results.get(report.nodeid)
    if res is None:
        return None
    if report.when != "teardown":
        return "", "", ""
    return _CONSOLE.get(res.outcome)


def _collect(item: pytest.Item, rep: pytest.TestReport, raised: BaseException | None, ids: list[str], strength: str,
             d: Dut | None) -> None:
    st = state(item.config)
    res = st.results.get(item.nodeid)
    if res is None:
        res = st.results[item.nodeid] = Result(item.nodeid, item.name, section_of(item), ids, strength)
    res.duration += rep.duration
    if rep.when == "call" or (rep.when == "setup" and not rep.passed) or (rep.when == "teardown" and rep.failed):
        outcome, message = _outcome(rep, raised, strength), "" if rep.passed else _longrepr_text(rep, raised)
        if rep.when == "call" and _MESSAGE in item.stash:
            message = item.stash[_MESSAGE]
            res.broken = [b.as_json() for b in item.stash.get(_BROKEN, [])]
        if rep.when == "teardown" and res.outcome not in (Verdict.FAIL,) and not bus_rules.failed_at_teardown(item):
            outcome = Verdict.ERROR
        if rep.when != "teardown" or res.outcome != Verdict.FAIL:
            res.outcome, res.message = outcome, message
    res.bus_rules = bus_rules.rules_of(item)
    res.bus_causes = bus_rules.causes_of(item)
    if d is not None and rep.when in ("call", "teardown"):
        res.lane_seconds = d.lane_seconds  # set when the dut fixture is torn down
        res.properties = {}
        for n, m in enumerate(d.record.measurements):
            res.properties.update(m.as_properties(n))
        res.measured = [m.as_json() for m in d.record.measurements]
        res.observations = [(w, str(v)) for w, v in d.record.observations]
    if d is not None and rep.when == "teardown":
        res.evidence = evidence(d.trace, host=d.host_node, node=d.node_id, comm_loss="R8" in ids)
        st.info.setdefault("interval_tolerance_ms", d.interval_tolerance_ms)


#: what, raised under a test, says the suite itself, the bus or the bench (its power control) failed under it, not
#: the DUT: an ERROR whatever the requirement's strength (:mod:`ckesc.bench.errors`, :mod:`ckesc.bench.lanes`)
BENCH_FAILED = (BusFault, BenchGone, HarnessError)
#: ... and with the DUT that did not answer what the test needed (:class:`~ckesc.bench.dut.DutError`): no verdict on
#: the DUT, but where the test only observes (an OBSERVE test: what the DUT did)
NOT_THE_DUT = (DutError, *BENCH_FAILED)


def _outcome(rep: pytest.TestReport, raised: BaseException | None, strength: str) -> str:
    """The verdict of one phase: from its report's outcome and the type of what ended it (``raised``), never from
    its message's words."""
    if rep.failed and isinstance(raised, NOT_THE_DUT):
        # the harness could not do what the test needed, or the bus failed under it: no verdict on the DUT
        return Verdict.ERROR
    if rep.passed:
        return Verdict.OBSERVED if strength == "OBSERVE" else Verdict.PASS
    if rep.skipped:
        return Verdict.INCONCLUSIVE if isinstance(raised, Inconclusive) else Verdict.SKIPPED
    if rep.when == "setup":
        return Verdict.ERROR
    return Verdict.FAIL


def _longrepr_text(rep: pytest.TestReport, raised: BaseException | None = None) -> str:
    lr = rep.longrepr
    if lr is None:
        return ""
    if isinstance(lr, tuple):
        text = str(lr[2])
    else:
        crash = getattr(getattr(lr, "reprcrash", None), "message", None)
        text = crash if crash else str(lr)
    kinds = (Inconclusive, NotClaimed) + ((type(raised),) if isinstance(raised, (pytest.skip.Exception, HarnessError))
                                          else ())
    for verdict in kinds:  # raised below the test (a helper, a fixture): pytest names the class
        text = text.removeprefix(f"{verdict.__module__}.{verdict.__qualname__}: ")
    return text

