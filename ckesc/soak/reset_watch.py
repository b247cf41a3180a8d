"""The soak's reset watch (R19, R17): no reset, as the bus rules and the R17 tests read one (the one bookkeeping,
:class:`ckesc.evidence.resets.ResetSigns`): 241's power-up count does not move, its run time neither goes back nor
jumps, no report gap longer than a restart may take with the report's transfer id starting again. One reset is one
event and one finding, however many signs show it (each report type's gap, the power-up count, the run time): the
others are counted with it (``signs_of_resets_found``)."""

from __future__ import annotations

from typing import Any

from ..evidence.resets import POWER_UPS, RUN_TIME, ResetSigns
from ..protocol.frame import Frame
from ..protocol.judgements import Reset
from .watch import Monitoring, Watch


class ResetWatch(Watch):
    name = "resets"
    rules = ("R19", "R17")
    what = "resets"
    one = "reset"

    def __init__(self, monitor: Monitoring) -> None:
        super().__init__(monitor)
        #: the reset bookkeeping the bus rules keep too: the last report of each type, the last 241 readings
        self.signs = ResetSigns(error=self.cfg.error, jitter=self.cfg.jitter)
        self.reads = {POWER_UPS: 0, RUN_TIME: 0}
        self.more_signs = 0  # signs of a reset already found
        self._intervals = self.cfg.intervals

    def _sign(self, sign: Reset | None, t: float) -> None:
        if sign is None:
            return
        if self.signs.same:
            self.more_signs += 1
        else:
            self.find(t, sign.text, (sign.rule, "R17"))

    def report(self, name: str, t: float, tid: int | None) -> bool:
        """A report of the ESC: whether its counter started again (the first report after a restart, R9a)."""
        signs = self.signs
        sign = signs.report(name, t, tid, self._intervals.get(name))
        if sign is not None:
            if not signs.same:  # every report restarted with it (R9a), its counter showing it or not
                self.monitor.intervals.reset(signs.since)  # type: ignore[arg-type]
            self._sign(sign, t)
        return signs.restarted

    def maintenance(self, frame: Frame, t: float) -> None:
        f = frame.fields
        for counter in (POWER_UPS, RUN_TIME):
            if counter in f:
                self.reads[counter] += 1
                self.trials += 1
                self._sign(self.signs.counter(counter, f[counter], t), t)
                return

    def statistics(self) -> dict[str, Any]:
        ups, run_time = self.signs.last(POWER_UPS), self.signs.last(RUN_TIME)
        return {"reads_241": self.reads, "power_ups": ups.value if ups else None,
                "run_time_s": run_time.value if run_time else None, "signs_of_resets_found": self.more_signs}
