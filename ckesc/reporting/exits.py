"""The exit statuses of every ``ckesc`` command, in one table (:class:`ExitStatus`), with the ranking a batch of
benches uses (:data:`WORST_FIRST`, :func:`worst`) and the one place a run's status is decided from its results
(:func:`of_run`). The command line, ``ckesc run``, the session's end, the soak and the rig batches all take their
statuses from here (``tests/test_exit_statuses.py`` finds a number written anywhere else)."""

from __future__ import annotations

from collections.abc import Iterable
from enum import IntEnum

from ..protocol.requirements import Verdict
from .causes import broken_outside_a_fail
from .results import Result


class ExitStatus(IntEnum):
    """What a ``ckesc`` process says to its shell."""

    #: nothing found: every test passed (INCONCLUSIVE and SKIPPED reported), a soak or an exploration found nothing,
    #: the frames decoded, the runs compared without a regression
    OK = 0
    #: something found: a test FAILed or ERRORed (or, ``--strict``, was INCONCLUSIVE), a bus rule was broken while a
    #: test that is not that FAIL ran, a soak's or the explorer's finding, a rule broken in a log, frames that do not
    #: decode, a regression (``ckesc compare``, ``ckesc run --baseline``'s gate), a profile claim the DUT contradicts, an error answer of the emulator's control
    FAILED = 1
    #: a set-up mistake or bad input (one line on stderr, no report)
    USAGE = 2
    #: the bench could not be used: the DUT did not answer or the bench went away (the run ABORTED, its report says
    #: so), no emulator on the control port
    ABORTED = 3
    #: pytest's own usage error (pytest.ExitCode.USAGE_ERROR): a path after ``ckesc run``'s ``--``
    PYTEST_USAGE = 4
    #: Ctrl-C / SIGTERM (128 + SIGINT): stopped with zero throttle, the report written and marked INTERRUPTED
    INTERRUPTED = 130
    #: 128 + SIGPIPE, what a shell reports for a writer whose reader went away (``| head``)
    BROKEN_PIPE = 141


#: a batch's status from its benches': the first of these any bench has (then OK when all are, else ABORTED)
WORST_FIRST = (ExitStatus.INTERRUPTED, ExitStatus.FAILED, ExitStatus.ABORTED, ExitStatus.USAGE)


def worst(statuses: Iterable[int]) -> ExitStatus:
    """The worst of several runs' statuses (:data:`WORST_FIRST`); one that is none of the table's (a process that
    died) counts as a bench that could not be used."""
    statuses = list(statuses)
    found = next((s for s in WORST_FIRST if s in statuses), None)
    if found is not None:
        return found
    return ExitStatus.OK if all(s == ExitStatus.OK for s in statuses) else ExitStatus.ABORTED


def failing_verdicts(*, strict: bool = False) -> tuple[Verdict, ...]:
    """The verdicts that fail a run: FAIL and ERROR, and with ``strict`` INCONCLUSIVE."""
    return (Verdict.FAIL, Verdict.ERROR, *((Verdict.INCONCLUSIVE,) if strict else ()))


def failing(results: Iterable[Result], *, strict: bool = False) -> list[Result]:
    """The results that fail a run: their verdict (:func:`failing_verdicts`), or a bus rule broken while a test that
    is not its FAIL ran."""
    bad = failing_verdicts(strict=strict)
    return [r for r in results if r.outcome in bad or broken_outside_a_fail(r)]


def of_run(results: Iterable[Result], *, stopped: str | None, strict: bool = False, regressed: bool = False) -> ExitStatus:
    """A conformance run's status: ABORTED or INTERRUPTED when it stopped so (``stopped``: "aborted: ...",
    "interrupted ..."), FAILED when a result fails it (:func:`failing`) or the release gate found a regression against
    its baseline (``regressed``: :mod:`.gate`), else OK (``ckesc run`` fails a run in which no test ran; ``pytest
    --collect-only`` runs none)."""
    results = list(results)
    if (stopped or "").startswith("aborted"):
        return ExitStatus.ABORTED
    if (stopped or "").startswith("interrupted"):
        return ExitStatus.INTERRUPTED
    return ExitStatus.FAILED if regressed or failing(results, strict=strict) else ExitStatus.OK
