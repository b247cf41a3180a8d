"""R19 (and R17's "never resets") over a stream of observations, sans-IO: the one keeper of what a reset shows against.

    signs = ResetSigns(error=0.0, jitter=0.0)        # the bench's timing error, the DUT's declared jitter (s)
    signs.report("msg1", t, transfer_id, interval)   # each report of the ESC, in order: a Reset or None
    signs.restarted                                  # ... and whether that report's counter started again (R9a)
    signs.counter("power_ups", value, t)             # each 241 answer (option 2; option 1: "run_time")

One per ESC. Each call keeps the observation (the last report of each type: its time and transfer id; the last
reading of each 241 counter: its value, its time and the caller's ``tag``) and judges it against the one before with
the rule's judgement in :mod:`ckesc.protocol.judgements` (:func:`~ckesc.protocol.judgements.r19_report_restart`,
:func:`~ckesc.protocol.judgements.r19_power_ups`, :func:`~ckesc.protocol.judgements.r19_run_time`): it adds no
tolerance of its own, and the bench's error is given here once (the run time's two readings, each stamped with it).

One reset shows several signs (each report type's gap, the power-up count, the run time): ``resets`` counts the
resets, and ``same`` says whether the sign just returned shows one already counted (a report gap overlapping the
last reset's, a power-up count grown by no more than the resets shown since its last reading, a run time gone back
after one). The soak counts resets so; the bus rules report every sign, each a frame that shows one.

Which observations may be compared at all is the consumer's to know and to say with ``judge`` (a power switch or a
Set ID between them, the host's own restart of reporting): the soak and the R17 tests compare every one, the bus
rules (:mod:`.rules`) only those with nothing of the host's between them (a reading's ``tag`` keeps what it needs).
Memory: one entry per report type and per counter.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass

from ..protocol.judgements import (
    POWER_UPS_MODULO,
    Reset,
    f3_holds,
    f3_step,
    r19_counter_restarted,
    r19_power_ups,
    r19_report_restart,
    r19_run_time,
)

#: the 241 counters a reset shows in (option 2's and option 1's field)
POWER_UPS = "power_ups"
RUN_TIME = "run_time"


@dataclass(frozen=True, slots=True)
class Reading:
    """A 241 counter's last reading: its value, when (the run time's elapsed time counts from it), the caller's tag."""

    value: int
    t: float
    tag: Hashable = None
    resets: int = 0  # the resets shown up to this reading


class ResetSigns:
    """The reset bookkeeping (module docstring). ``error``: the bench's timing error of a stamp (s); ``jitter``: the
    DUT's declared report jitter (s)."""

    __slots__ = ("error", "jitter", "restarted", "resets", "same", "_last", "_reports", "_readings")

    def __init__(self, *, error: float = 0.0, jitter: float = 0.0) -> None:
        self.error = error
        self.jitter = jitter
        #: the last report fed: its counter started again (the first report after a restart, R9a), a reset or not
        self.restarted = False
        #: the resets shown so far, and whether the last sign returned shows one already counted
        self.resets = 0
        self.same = False
        self._last: tuple[float, float] | None = None  # the last reset's window: between these it happened
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
        sign = r19_report_restart(gap, interval, step, error=self.error, jitter=self.jitter,
                                  what=str(key) if what is None else what)
        if sign is not None:
            last = self._last
            self.same = last is not None and prev[0] < last[1] and t > last[0]  # the silences overlap: one reset
            if self.same:
                self._last = (min(last[0], prev[0]), max(last[1], t))  # type: ignore[index]
            else:
                self.resets += 1
                self._last = (prev[0], t)
        return sign

    def counter(self, name: str, value: int, t: float, *, since: float | None = None, judge: bool = True,
                tag: Hashable = None) -> Reset | None:
        """A reading of 241's counter ``name`` (:data:`POWER_UPS` or :data:`RUN_TIME`) of ``value``, answered at ``t``:
        a :class:`~ckesc.protocol.judgements.Reset` when it shows one against the last reading and ``judge`` (else
        None). ``since``: the time this reading is kept with (default ``t``; the bus rules keep its request's, the
        earliest it can have been read, so that the run time's elapsed time between two readings is the widest it can
        be); ``tag``: kept with it (:meth:`last`)."""
        if name not in (POWER_UPS, RUN_TIME):
            raise ValueError(f"241 counter {name!r}: not one a reset shows in ({POWER_UPS}, {RUN_TIME})")
        before = self._readings.get(name)
        sign = None
        if before is not None and judge:
            if name == POWER_UPS:
                sign = r19_power_ups(before.value, value)
                new = (value - before.value) % POWER_UPS_MODULO - (self.resets - before.resets)
            else:  # two stamped readings: each stamp's error
                sign = r19_run_time(before.value, value, t - before.t, error=2 * self.error)
                new = 1 - (self.resets - before.resets)
            if sign is not None:
                self.same = new <= 0  # no more than the resets shown since the last reading
                if not self.same:  # it happened between the two readings
                    self.resets += new
                    self._last = (before.t, t)
        self._readings[name] = Reading(value, t if since is None else since, tag, self.resets)
        return sign

    @property
    def since(self) -> float | None:
        """When the last reset shown began at the latest: the last observation before it (None: none shown)."""
        return None if self._last is None else self._last[0]

    def last(self, name: str) -> Reading | None:
        """The last reading of counter ``name`` (None: none yet)."""
        return self._readings.get(name)
