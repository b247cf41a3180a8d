"""The soak's reset watch (R19, R17): no reset, as the bus reader reads one (its bookkeeping,
:class:`ckesc.evidence.resets.ResetSigns`, kept by :class:`~ckesc.evidence.rules.BusRules`, whose events this takes):
241's power-up count does not move across a silence of the ESC, its run time neither goes back nor jumps, no report
gap longer than a restart may take with the report's transfer id starting again. One reset is one event and one
finding, however many signs show it (each report type's gap, the power-up count, the run time): the others are
counted with it (``signs_of_resets_found``)."""

from __future__ import annotations

from typing import Any

from ..evidence.resets import POWER_UPS, RUN_TIME, ResetSigns
from ..protocol.judgements import Reset
from .watch import Monitoring, Watch


class ResetWatch(Watch):
    name = "resets"
    rules = ("R19", "R17")
    what = "resets"
    one = "reset"

    def __init__(self, monitor: Monitoring) -> None:
        super().__init__(monitor)
        self.reads = {POWER_UPS: 0, RUN_TIME: 0}
        self.more_signs = 0  # signs of a reset already found

    def read(self, counter: str) -> None:
        """A 241 answer read as ``counter``: a trial (the reader judges it, :meth:`sign` when it shows a reset)."""
        self.reads[counter] += 1
        self.trials += 1

    def sign(self, t: float, sign: Reset, signs: ResetSigns) -> None:
        """The reader saw a sign of a reset at ``t``: a finding, unless it shows one already found. A report's sign
        restarts every report with it (R9a), its counter showing it or not."""
        if signs.same:
            self.more_signs += 1
            return
        if sign.what not in self.reads:
            self.monitor.intervals.reset(signs.since)
        self.find(t, sign.text, (sign.rule, "R17"))

    def statistics(self) -> dict[str, Any]:
        signs = self.monitor.rules.reset_signs(self.cfg.node_id)
        ups, run_time = (signs.last(POWER_UPS), signs.last(RUN_TIME)) if signs is not None else (None, None)
        return {"reads_241": self.reads, "power_ups": ups.value if ups else None,
                "run_time_s": run_time.value if run_time else None, "signs_of_resets_found": self.more_signs}
