"""The soak's comm-flag watch (R8, R19): MSG1's comm-loss flag set only when the host's stream stops
(:func:`~ckesc.protocol.judgements.r8_flag_due`), each MSG1's flag and the last throttle command that carries the ESC's
throttle channel as the bus reader tells them (:meth:`~ckesc.evidence.events.ReaderEvents.msg1`, R8's clock: none
before the reader knows the channel, from the ESC's first GET_ESC_ID answer); the stream's gaps are the reader's
statistics."""

from __future__ import annotations

from typing import Any

from ..protocol import judgements as jd
from .watch import Monitoring, Watch


class CommFlagWatch(Watch):
    name = "comm flag"
    rules = ("R8", "R19")
    what = "comm flag glitches"
    one = "comm flag glitch"

    def __init__(self, monitor: Monitoring) -> None:
        super().__init__(monitor)
        self.msg1_since_stream = 0
        self.flagged = False  # inside an episode already found
        self.flag_set = 0
        interval = self.cfg.intervals.get("msg1")
        #: R8's window opens here after the last command (its judgement's: r8_window_s)
        self._early = jd.r8_window_s(interval, jitter=self.cfg.jitter)[0] if interval else 0.0
        self._interval = interval
        self._error = self.cfg.error + self.cfg.own_error
        self._up = -float("inf")  # the ESC's first report after its latest restart

    def restarted(self, t: float) -> None:
        """The ESC restarted (a report's transfer id started again, the reader's ``report`` event): its comm watchdog
        with it, so R8's window counts from no earlier than ``t``. On a bench where the host is then alone, its
        commands wait in its queue through the ESC's boot and the bus carries none: that is no stopped stream."""
        self._up = t

    def msg1(self, t: float, flag: bool, last_command: float | None) -> None:
        if last_command is None:
            return
        if last_command < self._up:
            last_command = self._up
        self.msg1_since_stream += 1
        if self.msg1_since_stream < 2:  # the MSG1 due as the stream began may still show the flag of before it
            return
        interval = self._interval
        if interval is None:
            return
        self.flag_set += flag
        since = t - last_command
        error = self._error
        if not flag and since < self._early - error:  # well before R8's window, clear: as r8_flag_due wants (hot path)
            self.trials += 1
            self.flagged = False
            return
        due = jd.r8_flag_due(since, interval, jitter=self.cfg.jitter, error=error)
        if due is None:
            return
        self.trials += 1
        if flag == due:
            self.flagged = False
            return
        if not self.flagged:
            self.flagged = True
            self.find(t, f"MSG1 {'shows' if flag else 'lacks'} the comm-loss flag {since * 1000:.1f} ms after the last command "
                      f"({'the stream runs' if not due else 'the stream stopped'})")

    def statistics(self) -> dict[str, Any]:
        rules = self.monitor.rules
        return {"msg1_judged": self.trials, "msg1_with_flag": self.flag_set,
                "host_stream_gaps_over_200ms": rules.command_gaps,
                "longest_command_gap_ms": round(rules.longest_command_gap * 1000, 3)}
