"""The soak's report-interval watch (R9 over every minute, R19), per report (MSG1..3): the mean of that minute's gaps
(:func:`~ckesc.protocol.judgements.r9_mean`), less those R9a leaves unjudged after a restart; the trend is one mean
per minute and report."""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from ..protocol import judgements as jd
from .watch import REPORTS, Monitoring, Watch

#: the R9 minute
MINUTE_S = 60.0
#: report times kept of each report's open stretch, to cut it where another report showed a reset (a reset shows
#: within a boot's time and a slower report's interval: a few of the fastest report's)
RECENT = 64


class _Span:
    """One report's gaps in the minute being read, without keeping them: the stretch open now (its first and last
    report, how many, and the times of its last :data:`RECENT`) and the stretches a restart closed in this minute
    (their spans summed, their gaps, how many). A restart closes the open stretch, and the reports whose gaps R9a
    leaves unjudged open none (:func:`~ckesc.protocol.judgements.r9_judged`: the gaps up to and including the second
    report after the restart), so the minute's mean is that of the gaps R9 judges.

    A restart shows in the report's own counter starting again (:meth:`add`), or in another report's reset
    (:meth:`reset`): a counter that by chance goes on by one across a reset (one time in 32) shows none of its own."""

    __slots__ = ("first", "last", "n", "recent", "spanned", "gaps", "stretches", "skip", "pending", "heard", "seen",
                 "restarted_at", "latest", "found_silent")

    def __init__(self) -> None:
        self.first = self.last = self.spanned = 0.0
        self.n = self.gaps = self.stretches = self.skip = self.heard = 0
        self.recent: deque[float] = deque(maxlen=RECENT)
        self.pending = False  # the next report is the first after a restart
        self.seen = False  # a report heard in an earlier minute
        self.restarted_at = -math.inf  # the first report after the last restart
        self.latest = -math.inf  # the last report heard
        self.found_silent = False  # a silent minute since it was found

    def add(self, t: float, restarted: bool) -> None:
        self.heard += 1
        self.latest = t
        self.found_silent = False
        if restarted or self.pending:
            self.pending = False
            self.restarted_at = t
            self._close()
            self.skip = jd.R9A_UNJUDGED - 1  # these open no stretch (this one among them): the next report does
        if self.skip:
            self.skip -= 1
        elif self.n:  # (_extend inline: once per report)
            self.last = t
            self.n += 1
            self.recent.append(t)
        else:
            self._extend(t)

    def _extend(self, t: float) -> None:
        if self.n:
            self.last = t
            self.n += 1
        else:
            self.first = self.last = t
            self.n = 1
        self.recent.append(t)

    def reset(self, since: float) -> None:
        """The ESC reset after ``since`` (another report's last before its gap): this report's first after ``since``
        is the first after the restart, unless its own counter said so later. The open stretch is cut there as
        :meth:`add` would have cut it (or at this report's next one); one with more than :data:`RECENT` reports since
        then is left as heard."""
        if self.restarted_at > since:
            return
        recent = list(self.recent)
        after = [t for t in recent if t > since]
        if not after:
            self.pending = True
            return
        if len(after) == len(recent) < self.n:
            return
        self.last, self.n = (recent[-len(after) - 1], self.n - len(after)) if len(after) < len(recent) else (0.0, 0)
        self._close()
        self.restarted_at = after[0]
        self.skip = jd.R9A_UNJUDGED - 1
        for t in after:  # again, as add() would have taken them
            if self.skip:
                self.skip -= 1
            else:
                self._extend(t)

    def _close(self) -> None:
        if self.n >= 2:
            self.spanned += self.last - self.first
            self.gaps += self.n - 1
            self.stretches += 1
        self.n = 0
        self.recent.clear()

    def minute(self) -> tuple[_Joined, int]:
        """The minute's judged stretches joined end to end, and how many they are; the open stretch then goes on from
        its last report (the gap across the minute's end is the next minute's)."""
        going_on = self.n > 0
        self._close()
        joined, stretches = _Joined(self.spanned, self.gaps), self.stretches
        self.seen = self.seen or self.heard > 0
        self.spanned, self.gaps, self.stretches, self.heard = 0.0, 0, 0, 0
        if going_on:
            self._extend(self.last)
        return joined, stretches


class _Joined:
    """A minute's judged stretches joined end to end, as :func:`~ckesc.protocol.judgements.r9_mean` reads a sequence
    of report starts (the first, the last, how many): from 0 to the sum of their spans, over the sum of their gaps."""

    __slots__ = ("span", "gaps")

    def __init__(self, span: float, gaps: int) -> None:
        self.span, self.gaps = span, gaps

    def __len__(self) -> int:
        return self.gaps + 1

    def __getitem__(self, i: int) -> float:
        if i in (0, -self.gaps - 1):
            return 0.0
        if i in (-1, self.gaps):
            return self.span
        raise IndexError("joined stretches keep their ends only")


class IntervalWatch(Watch):
    name = "report intervals"
    rules = ("R9", "R19")
    statement_unit = "report-minute"
    what = "report-minutes out of R9"
    one = "report-minute out of R9"

    def __init__(self, monitor: Monitoring) -> None:
        super().__init__(monitor)
        self.t0 = monitor.t0
        self.minute = 0
        self.spans = {r: _Span() for r in REPORTS}
        #: the trend: per report, the mean interval (ms) of each minute (None: not judged)
        self.series: dict[str, list[float | None]] = {r: [] for r in REPORTS}
        self.worst: dict[str, float] = {}

    def report(self, name: str, t: float, restarted: bool = False) -> None:
        """A report of the ESC at ``t``; ``restarted``: its counter started again (the first after a restart, R9a)."""
        minute = int((t - self.t0) // MINUTE_S)
        while minute > self.minute:
            self._close_minute(self.t0 + (self.minute + 1) * MINUTE_S)
        self.spans[name].add(t, restarted)

    def reset(self, since: float) -> None:
        """The ESC reset after ``since`` (another report's gap showed it, :class:`~.reset_watch.ResetWatch`): every
        report restarted there (R9a), whether its own counter shows it or not."""
        for span in self.spans.values():
            span.reset(since)

    def _close_minute(self, end: float, *, partial: bool = False, stopped: dict[str, jd.Judgement] | None = None) -> None:
        for name in REPORTS:
            interval = self.cfg.intervals.get(name)
            span = self.spans[name]
            silent = not span.heard and span.seen
            joined, stretches = span.minute()
            if interval is None:
                self.series[name].append(None)
                continue
            if stopped and name in stopped:  # it stopped before the run's end: the last minute's judgement of it
                self.series[name].append(round(joined.span / joined.gaps * 1000, 4) if joined.gaps else None)
                self.trials += 1
                self.find(min(end, self.monitor.last_t), f"minute {self.minute + 1}: {stopped.pop(name)}")
                continue
            if joined.gaps < 1:
                self.series[name].append(None)
                if silent and not partial:
                    self.trials += 1
                    span.found_silent = True
                    self.find(end, f"no {name} in minute {self.minute + 1} (interval {interval * 1000:g} ms)")
                continue
            if partial and joined.gaps < jd.R9_GAPS:
                self.series[name].append(None)
                continue
            # each stretch's two ends carry the bench's error and the DUT's declared jitter, as one span's do (R9)
            judged = jd.r9_mean(joined, interval, error=stretches * self.cfg.error, jitter=stretches * self.cfg.jitter,
                                what=name)
            assert judged is not None
            if not judged.judged:  # too few gaps in this minute for the ends' error and jitter (R9: OBSERVE)
                self.series[name].append(None)
                continue
            self.series[name].append(round(joined.span / joined.gaps * 1000, 4))
            self.worst[name] = max(self.worst.get(name, 0.0), judged.measured)
            self.trials += 1
            if not judged.ok:
                self.find(end, f"minute {self.minute + 1}: {judged}")
        self.minute += 1

    def close(self, now: float) -> None:
        """The run ended at ``now``: the minutes left closed, the last one maybe partial (its mean judged over enough
        gaps only), and each report's silence at the end judged (:meth:`_stopped`) as that last minute's."""
        minute = int((now - self.t0) // MINUTE_S)
        while minute > self.minute:
            self._close_minute(self.t0 + (self.minute + 1) * MINUTE_S)
        stopped = self._stopped(min(now, self.monitor.last_t))
        if now - self.t0 > self.minute * MINUTE_S:  # a part of a minute left
            self._close_minute(now, partial=True, stopped=stopped)
        for judged in stopped.values():  # the run ended as its last minute did, which was judged without them
            self.trials += 1
            self.find(min(now, self.monitor.last_t), f"minute {self.minute}: {judged}")

    def _stopped(self, heard: float) -> dict[str, jd.Judgement]:
        """The reports silent at the end longer than a report may be absent (:func:`~ckesc.protocol.judgements.
        r9_stopped`), no minute having found their silence already. The silence is measured to ``heard``, the last
        frame heard, not to the run's end: what the host did not read (its own stop, a bench that delivered nothing
        more before it failed) is not the ESC's silence."""
        cfg = self.cfg
        error = cfg.error + max(cfg.error, cfg.own_error)  # the report's stamp, and the last frame's (maybe the host's)
        out = {}
        for name in REPORTS:
            interval, span = cfg.intervals.get(name), self.spans[name]
            if interval is None or span.found_silent or span.latest == -math.inf:
                continue
            judged = jd.r9_stopped(heard - span.latest, interval, error=error, jitter=cfg.jitter, what=name)
            if not judged.ok:
                out[name] = judged
        return out

    def statistics(self) -> dict[str, Any]:
        return {"minutes_judged": self.trials, "worst_mean_error_ms": {k: round(v * 1000, 4) for k, v in self.worst.items()},
                "intervals_ms": {k: v * 1000 for k, v in self.cfg.intervals.items()}}
