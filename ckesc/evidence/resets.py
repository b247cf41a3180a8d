"""R19 (and R17's "never resets") over a stream of observations, sans-IO: the one keeper of what a reset shows against.

    signs = ResetSigns(error=0.0, jitter=0.0)        # the bench's timing error, the DUT's declared jitter (s)
    signs.report("msg1", t, transfer_id, interval)   # each report of the ESC, in order: a Reset or None
    signs.restarted                                  # ... and whether that report's counter started again (R9a)
    signs.counter("power_ups", value, t)             # each 241 answer (option 2; option 1: "run_time")

Each call keeps the observation (the last report of each type: its time and transfer id; the last reading of each
241 counter: its value, its time and the caller's ``tag``) and judges it against the one before with the rule's
judgement in :mod:`ckesc.protocol.judgements` (:func:`~ckesc.protocol.judgements.r19_report_restart`,
:func:`~ckesc.protocol.judgements.r19_power_ups`, :func:`~ckesc.protocol.judgements.r19_run_time`): it adds no
tolerance of its own, and the bench's error is given here once (the run time's two readings, each stamped with it).

Which observations may be compared at all is the consumer's to know and to say with ``judge`` (a power switch or a
Set ID between them, the host's own restart of reporting): the soak and the R17 tests compare every one, the bus
rules (:mod:`.rules`) only those with nothing of the host's between them (a reading's ``tag`` keeps what it needs).
Memory: one entry per report type and per counter.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass

from ..protocol.judgements import Reset, f3_holds, f3_step, r19_counter_restarted, r19_power_ups, r19_report_restart, r19_run_time

#: the 241 counters a reset shows in (option 2's and option 1's field)
POWER_UPS = "power_ups"
RUN_TIME = "run_time"


@dataclass(frozen=True, slots=True)
class Reading:
    """A 241 counter's last reading: its value, when (the run time's elapsed time counts from it), the caller's tag."""

    value: int
    t: float
    tag: Hashable = None


class ResetSigns:
    """The reset bookkeeping (module docstring). ``error``: the bench's timing error of a stamp (s); ``jitter``: the
    DUT's declared report jitter (s)."""

    __slots__ = ("error", "jitter", "restarted", "_reports", "_readings")

    def __init__(self, *, error: float = 0.0, jitter: float = 0.0) -> None:
        self.error = error
        self.jitter = jitter
        #: the last report fed: its counter started again (the first report after a restart, R9a), a reset or not
        self.restarted = False
        self._reports: dict[Hashable, tuple[float, int | None]] = {}
        self._readings: dict[Hashable, Reading] = {}

    def report(self, key: Hashable, t: float, tid: int | None, interval: float | None, *, what: str | None = None,
               judge: bool = True) -> Reset | None:
        """One report of type ``key`` at ``t`` with transfer id ``tid`` (None: the frame has none), the type's
        ``interval`` (None: unknown): a :class:`~ckesc.protocol.judgements.Reset` when the gap since the type's last
        report is one with a transfer id restart, and ``judge`` (else None). ``restarted`` says whether its counter
        started again (:func:`~ckesc.protocol.judgements.r19_counter_restarted`)."""
        reports = self._reports
        prev = reports.get(key)
        reports[key] = (t, tid)
        if prev is None or tid is None or prev[1] is None or f3_holds(prev[1], tid):  # counting on (the hot path)
            self.restarted = False
            return None
        gap, step = t - prev[0], f3_step(prev[1], tid)
        self.restarted = r19_counter_restarted(gap, interval, step)
        if not self.restarted or not judge or interval is None:
            return None
        return r19_report_restart(gap, interval, step, error=self.error, jitter=self.jitter,
                                  what=str(key) if what is None else what)

    def counter(self, name: str, value: int, t: float, *, key: Hashable = None, since: float | None = None,
                judge: bool = True, tag: Hashable = None) -> Reset | None:
        """A reading of 241's counter ``name`` (:data:`POWER_UPS` or :data:`RUN_TIME`) of ``value``, answered at ``t``:
        a :class:`~ckesc.protocol.judgements.Reset` when it shows one against the last reading (under ``key``: one per
        node where several are watched) and ``judge`` (else None). ``since``: the time this reading is kept with
        (default ``t``; the bus rules keep its request's, the earliest it can have been read, so that the run time's
        elapsed time between two readings is the widest it can be); ``tag``: kept with it (:meth:`last`)."""
        slot = (key, name)
        before = self._readings.get(slot)
        self._readings[slot] = Reading(value, t if since is None else since, tag)
        if before is None or not judge:
            return None
        if name == POWER_UPS:
            return r19_power_ups(before.value, value)
        if name == RUN_TIME:  # two stamped readings: each stamp's error
            return r19_run_time(before.value, value, t - before.t, error=2 * self.error)
        raise ValueError(f"241 counter {name!r}: not one a reset shows in ({POWER_UPS}, {RUN_TIME})")

    def last(self, name: str, key: Hashable = None) -> Reading | None:
        """The last reading of counter ``name`` under ``key`` (None: none yet)."""
        return self._readings.get((key, name))
