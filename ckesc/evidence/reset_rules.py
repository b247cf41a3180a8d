"""The bus rules' resets (R19, and R17): a reset the host did not make, shown by a report gap with a transfer id
restart or by a 241 answer's counters, kept per node in :class:`~.resets.ResetSigns` (which the soak's reset watch
reads) and judged by :class:`ResetRules`, the base of :class:`~.rules.BusRules`, whose module docstring says when
they are judged."""

from __future__ import annotations

import math
from typing import Any

from ..protocol.judgements import Reset
from ..protocol.transfer import tail_transfer_id
from .findings import quote
from .resets import POWER_UPS, ResetSigns
from .tracker import RESET_FIELDS, EscStream, FrameId, Node, Tracker, field_value


class ResetRules(Tracker):
    """The tracker with R19's bookkeeping and judgements (:class:`~.rules.BusRules` is one: see it)."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        #: R19's bookkeeping per node (:mod:`.resets`, the soak's too): its streams' last reports, its 241 counters
        self._resets: dict[int, ResetSigns] = {}

    def _signs(self, node: Node) -> ResetSigns:
        signs = self._resets.get(node.id)
        if signs is None:
            signs = self._resets[node.id] = ResetSigns(error=self.tolerance, jitter=self.jitter)
        return signs

    def reset_signs(self, node_id: int) -> ResetSigns | None:
        """Node ``node_id``'s reset bookkeeping (its resets counted, its 241 counters' last readings), None: none yet."""
        return self._resets.get(node_id)

    def _pair(self, st: EscStream, info: FrameId, data, ts: float) -> tuple[str, str]:
        return (quote(st.can_id, st.data, st.ts, note=f"{st.name} tid {st.tid}"),  # type: ignore[arg-type]
                quote(info.can_id, data, ts, note=f"{st.name} tid {tail_transfer_id(data[-1])}"))

    # ------------------------------------------------------------------------------------- R19 (R17): resets
    def _reset(self, out, sign: Reset, ts: float, node: Node, frames: tuple[str, ...]):
        """A reset shown (:class:`~ckesc.protocol.judgements.Reset`). It breaks R19 ("no reset" for as long as the test
        runs: the rule these signs are written for, its judgement's own id) and R17 ("such a frame never resets the
        ESC"): the bus cannot tell what set it off (a malformed frame, a long stream, nothing), and a reset in the middle
        of a test that asked for none breaks both, so it cites both, as the soak's reset watch does; the selftest then
        takes it as a test failing for the fault's rule whichever of the two a reset fault names. Where power cycles
        are not reported (a capture, ``power_known`` False) the bench may have switched the power meanwhile: recorded.
        Told to the consumer (:meth:`.events.ReaderEvents.reset`) either way."""
        if self.events is not None:
            self.events.reset(ts, node.id, sign, self._signs(node))
        if self.power_known:
            return self._violation(out, (sign.rule, "R17"), ts, node.id, "reset",
                                   f"a reset the host did not make: {sign.text}", frames,
                                   subject=f"a reset the host did not make ({sign.what})", expected="no reset")
        self._observe((sign.rule, "R17"), ts, node.id, "reset-unjudged",
                      f"a reset, unless the power was switched (a capture does not show it): {sign.text}", frames)
        return out

    def _report_restart(self, out, st: EscStream, info: FrameId, node: Node, data, ts: float, start: float, tid: int):
        """R19: a report gap with a transfer id restart (every report of a periodic stream kept in its node's
        :class:`~.resets.ResetSigns`), judged between two reports of one stream with no host event between them that
        restarts reporting or may re-address the node (MSG Control, CAN Test, a Set Freq write or answer, Set ID: the
        node's ``reset`` and ``moved`` counts) and no power switch the host reported. The interval is the one the node
        stated, else the shortest gap seen (none: not judged)."""
        judge = (st.ts is not None and st.power == self.power_switches and self.last_switch_ts < st.ts
                 and st.moved == node.moved and st.reset == node.reset and not node.shared and ts > node.unsure_until)
        period = node.periods[st.interval] if st.interval is not None else None
        if period is None and st.min_gap < math.inf:
            period = st.min_gap
        signs = self._signs(node)
        sign = signs.report(info.type_id, start, tid, period, what=st.name, judge=judge)
        if sign is not None:
            out = self._reset(out, sign, ts, node, self._pair(st, info, data, ts))
        if self.events is not None:
            self.events.report(ts, node.id, st.name, signs.restarted)
        return out

    def _counters(self, out, info: FrameId, node: Node, data, ts: float, asked: float):
        """R19: a 241 answer (option 2: the power-up count; option 1: the run time) against the node's last one of that
        option, when no power switch the host reported and no Set ID came between them. A power-up count is judged only
        across a silence of the node as long as a power cycle may take (:data:`RESTART_SILENCE_S`: a reset boots first).
        The run time's elapsed time is the widest the two readings can be apart: from the earlier one's request to this
        answer."""
        option = self._maintenance.get((info.dest, info.source, tail_transfer_id(data[-1])))  # type: ignore[arg-type]
        f = RESET_FIELDS.get(option)  # type: ignore[arg-type]
        if f is None or len(data) <= f.offset + f.size or node.shared:
            return out
        value = field_value(data, f)
        if self.events is not None:
            self.events.counter(ts, node.id, f.name, value)
        # each reading kept with its request's time, the tracker's power switches, the node's Set ID count and chain
        signs = self._signs(node)
        before = signs.last(f.name)
        judge = (before is not None and before.tag[:2] == (self.power_switches, node.moved)  # type: ignore[index]
                 and self.last_switch_ts < before.t
                 # a power-up count is judged only across a silence as long as a boot takes: one that grew with the
                 # node never silent counts something else (4.4.27-T's tests judge what it counts)
                 and (f.name != POWER_UPS or before.tag[2] != node.chain))  # type: ignore[index]
        sign = signs.counter(f.name, value, ts, since=asked, judge=judge, tag=(self.power_switches, node.moved, node.chain))
        if sign is None:
            return out
        return self._reset(out, sign, ts, node, (quote(info.can_id, data, ts, note=f"{info.label}, {f.name} {value}"),))
