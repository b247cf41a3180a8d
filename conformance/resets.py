"""Whether the ESC reset while a robustness test looked (R17: such a frame never resets the ESC), read as the bus rules
and the soak read it (R19's signs, one bookkeeping: :class:`ckesc.evidence.resets.ResetSigns`): a report gap longer
than a restart may take (R9a's limit, with the bench's error and the DUT's declared jitter) across which the report's
transfer id started again, or 241's power-up count moved (modulo its u16 width: 65535 then 0 is a power-up too).

A transfer id that skips without such a gap is not a reset: it is F3's, which the bus rules judge in every test, and
a late report that counts on is R9's. Not a section: no tests here.
"""

from __future__ import annotations

from collections.abc import Iterable

from ckesc.bench.dut import DutError
from ckesc.evidence.resets import POWER_UPS, ResetSigns

from .settings import changes


def reset_signs(dut, reports: Iterable, interval: float, *, ups: tuple[int | None, int | None] = (None, None)) -> list[str]:
    """The resets shown by ``reports`` (one report type's frames from the DUT, in order, at ``interval``) and by the
    power-up count ``ups`` read before and after them (None: not read), each in words."""
    signs = ResetSigns(error=dut.lane.timing_error, jitter=dut.profile.jitter_s)
    found = [sign for f in reports
             if (sign := signs.report(f.name, f.timestamp or 0.0, f.transfer_id, interval)) is not None]
    before, after = ups
    if before is not None and after is not None:
        signs.counter(POWER_UPS, before, 0.0)
        if (sign := signs.counter(POWER_UPS, after, 0.0)) is not None:
            found.append(sign)
    return [f"{sign.text}: the ESC reset" for sign in found]


def afterwards(dut, settings: dict | None, ups: int | None, interval: float) -> list[str]:
    """What a robustness test finds once its disturbance is over, in words: the ESC does not answer, its settings
    differ from ``settings`` (242 read before; None: not compared), or its power-up count moved from ``ups`` (a reset,
    :func:`reset_signs`)."""
    try:
        after, ups_after = (dut.settings() if settings is not None else None), dut.power_up_count()
    except DutError as exc:
        return [f"afterwards it did not answer: {exc}"]
    problems = [f"its settings changed: {changed}"] if settings is not None and (changed := changes(settings, after)) else []
    return problems + reset_signs(dut, [], interval, ups=(ups, ups_after))
