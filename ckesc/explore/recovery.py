"""The explorer's judge of a bus short (R20, issue #36), sans-IO: what the ESC must do once the bus is freed.

After each short of a program (:attr:`~.oracle.Oracle.shorts`) the ESC's reports go on by themselves within R20's
bound (:func:`~ckesc.protocol.judgements.r20_back`: its controller's bus-off recovery, two MSG1 intervals and the
bench's error), where the model's ESC reports MSG1 then. From the short's start until each report is back on its grid
(the ``bus settled`` mark) nothing of the reports is judged but that: what an ESC sends while error-passive, the
reports it held through bus-off and sends back to back, their transfer-id sequence are OBSERVE (the live reader leaves
its R9, R9a and F3 unjudged meanwhile, :data:`~ckesc.protocol.judgements.R20_UNJUDGED`). From then on everything is
judged as anywhere: the comm flag the lost commands raised (R8) and the next command clearing it, the reports'
intervals, and at the program's end the settings read back and 241's counters (no reset): every finding after a
short also cites R20-recovery (:func:`cite_r20`), as a reset the reader finds across it (R19).
"""

from __future__ import annotations

import bisect
import math

from ..protocol.frame import Frame
from ..protocol.ids import Kind
from ..protocol.judgements import r20_back
from .finding import ExploreFinding, Params
from .oracle import SHORT_MARKS, Oracle

#: the stretches the stream judge leaves to this module: a short's, and the one after it until the reports settle
UNJUDGED_STRETCHES = SHORT_MARKS[:2]


def in_short(oracle: Oracle, t: float) -> bool:
    """Whether lane time ``t`` is within a short or before the reports settled after it (OBSERVE but R20's bound)."""
    return any(start <= t < settled for start, _, settled, _ in oracle.shorts)


def recovery(oracle: Oracle, dut: list[Frame], t0: float, p: Params) -> list[ExploreFinding]:
    """R20-recovery after each short: the DUT's first MSG1 after the bus was freed, within R20's bound, where the
    model's ESC reports MSG1 then (reporting normally; suspended, in CAN Test or MSG_EXP mode the stream judge holds it
    to what flows once the reports settle)."""
    msg1 = [f.timestamp for f in dut if f.name == "msg1" and f.kind is Kind.MESSAGE and f.source != p.host_node]
    out = []
    for start, end, _settled, step in oracle.shorts:
        state = oracle.state_at(end)
        if state.mode != "normal":
            continue
        interval = state.intervals["msg1"]
        k = bisect.bisect_right(msg1, end)
        first = msg1[k] if k < len(msg1) else None
        j = r20_back(math.inf if first is None else first - end, interval, bitrate=state.bitrate, error=p.error)
        if j.ok:
            continue
        seen = "none" if first is None else f"the first {j.measured * 1000:.1f} ms after"
        out.append(ExploreFinding(
            "recovery", ["R20-recovery"], f"no MSG1 within {(j.limit + j.error) * 1000:.1f} ms of the bus being freed "
            f"after a {end - start:g} s short", f"MSG1 after the short: {seen}",
            f"MSG1 within {j.limit * 1000:.1f} ms (+-{j.error * 1000:g}) (R20: bus-off recovery + 2 MSG1 intervals)",
            end - t0, step, subject="no MSG1 after a bus short"))
    return out


def cite_r20(findings: list[ExploreFinding], oracle: Oracle, t0: float) -> list[ExploreFinding]:
    """Every finding after a bus short of the program also cites R20-recovery (the ESC recovers without a reset and with
    its settings kept: a reset, a changed setting or mode shows as its own finding later), and says which short."""
    shorts = oracle.shorts
    for f in findings:
        before = [(start, step) for start, _, _, step in shorts if start - t0 <= f.at]
        if before and "R20-recovery" not in f.requirements:
            f.requirements.append("R20-recovery")
            where = f" at step {before[-1][1] + 1}" if before[-1][1] is not None else ""
            f.model += f" (R20: after the bus short{where})"
    return findings
