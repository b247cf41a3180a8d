"""The bus rules: what holds on a CKESC bus at all times, judged one frame at a time, sans-IO.

    rules = BusRules(tolerance=0.0, bitrate=500_000, complete=True)
    for violation in rules.feed(can_id, data, timestamp, own=False):   # every frame on the bus, in order
        ...
    rules.summary()                                                     # per-node statistics, JSON-able

The rules (ids from ``spec/INTERPRETATIONS.md`` / ``ckesc/protocol/requirements.toml``):

* F1  an ESC's frames are 29-bit data frames; its service frames are responses (request bit 0);
* F2  every ESC frame with a tail byte is a single-frame transfer (start=1, end=1, toggle=0);
* F3  an ESC's transfer ids count +1 modulo 32 per message type;
* F4  a response goes to a node that asked, with the request's transfer id;
* F5  an ESC sends each frame at the table's priority (240..242 list none: recorded, F5-unlisted);
* F7  no frame of an ESC from node 0 or the reserved ids 0x7E/0x7F; nothing reported on its own at 0x7D;
* R9  MSG1/MSG2/MSG3 come every N x 2 ms, N as the node itself last said in a Set/Get Freq answer
  (when no answer was heard: never closer than the shortest legal interval);
* R19 (and R17) no reset the host did not make: a 241 option 2 answer whose power-up count grew across a silence of
  the node (a reset boots first), or an option 1 answer whose run time went back (or jumped), since the node's
  previous answer of that option; a report gap with a transfer id restart (:func:`~ckesc.protocol.judgements.r19_report_restart`). Never across what the host did that restarts
  transfer ids or reporting: a power switch it reported (:meth:`BusRules.power_switched`), MSG Control, CAN Test, a Set
  Freq write, Set ID. Where power switches are not reported (a capture: ``power_known`` False) a reset is recorded.

"At all times" means no false alarm on legal traffic, so the engine follows what the traffic says and
judges only what it can tell:

* **Who is who.** The catalogue says which side sends each frame (layout ``sender``). A node that sent an
  ESC-side frame (a report, a response) is an ESC; node 0 and any node that sent a host-side frame
  (a request, a throttle command) or whose frames come back as the host's own (``own=True``, the echo
  of what this host sent) is a host. Only ESC frames are judged; host frames move the state (below).
  Frames outside the CKESC vendor ranges (DroneCAN, ArduPilot's own 20000/20010 traffic from its
  node) are counted, never judged as CKESC; frames whose type serves both sides (CAN Test, MSG Control,
  20013) are judged only from a node already known to be an ESC.
* **Restarts.** A node silent for longer than two shortest report intervals (40 ms) may have been power
  cycled (transfer ids and cadence restart, R13 keeps the settings): F3 and R9 compare only frames of
  one unbroken stretch of the node's traffic. A power cycle within 40 ms is assumed impossible (an ESC
  boots and self-tests first). Where every power switch is reported (``power_known``) and none came, the
  silence is the node's own: a report that comes back counting on (+1) is a late one, judged across it (R9).
* **Cadence.** MSG Control (suspend, resume, MSG_EXP), CAN Test on/off and Set/Get Freq writes restart
  the cadence they concern; Set ID (a pseudo-broadcast) makes every node's intervals unknown again.
* **R9a restarts.** After a resume (MSG Control 0xAAAAAAAA, which also leaves MSG_EXP mode) or CAN Test off,
  the first report of each type must come within one interval plus a slack of max(3 ms, a quarter interval) of
  the command; after a Set Freq write, within the longer of its old and new interval plus that slack (R9a,
  READING: measured from the command's timestamp to the earliest the report can have been due; the old
  interval is the one the node last stated, the longest legal one when it stated none);
  the gaps up to and including the second report after such an event, or after a power cycle the host
  reports (:meth:`BusRules.power_switched`), are not judged (R9a-gaps, OBSERVE): whether the ESC restarts its timer or keeps
  its grid is not written. From the third report on R9 holds. A power cycle voids the pending event. (A
  capture does not show power cycles: there, a first report more than two intervals late is only recorded,
  and the gaps after a power-up are judged as after any silence.)
  A report's due time is known only up to bus queueing: a frame that started right when the previous
  one ended may have waited since the start of that busy stretch, so an interval is judged on the
  widest bounds the bus allows (frame lengths from the bit rate), with ``tolerance`` (the lane's stated
  timing error; 0 in the simulated lane) on top.
* **Lost frames.** A capture may miss frames (``complete=False``, the default for files): a transfer id
  jump or a report gap that a whole number of missing frames explains is recorded as an observation,
  not a violation. The simulated lane hears every frame (``complete=True``).

What the traffic says (who is who, requests and their answers, the intervals each node stated, the events
that restart a cadence) is worked out by the tracker this engine is (:mod:`.tracker`), its resets (R19) judged by
its base :class:`~.reset_rules.ResetRules`; the report's plots draw
what the same tracker pairs (:mod:`.timing`). Findings are kept by :mod:`.findings`.

Everything kept per node is bounded: counters, running sums, fixed-bin interval histograms, the first
few events and findings of each kind (the rest counted).
"""

from __future__ import annotations

import math
from typing import Any

from ..protocol.ids import DEFAULT_ESC_NODE_ID, Kind, priority_name
from ..protocol.judgements import F3Step, f3_holds, f3_step, r9_gap, r9a_first, r9a_limit_s
from ..protocol.transfer import SINGLE_FRAME, parse_tail, tail_transfer_id
from .findings import Intervals, Violation, ms, quote
from .pairing import RESPONSE_WINDOW_S
from .reset_rules import ResetRules
from .tracker import (
    COMM_BYTE,
    COMM_MASK,
    ESC_VALUE,
    MAINTENANCE,
    MSG1,
    MSG_CONTROL,
    PSEUDO_BROADCAST,
    RESTART_SILENCE_S,
    SET_FREQ,
    SHORTEST_S,
    SIDE_EITHER,
    SIDE_ESC,
    SIDE_FOREIGN,
    SIDE_HOST,
    EscStream,
    FrameId,
    Node,
)

__all__ = ["BusRules", "Intervals", "RESTART_SILENCE_S", "SHORTEST_S", "Violation", "quote"]

_TAIL_RULES = (("start", 0x80, "4.1.3-start"), ("end", 0x40, "4.1.3-end"))
_NONE: tuple = ()


class BusRules(ResetRules):
    """The rule engine. Feed every frame of one bus in time order; see the module docstring.

    ``tolerance``: the timing error of the timestamps (seconds; the lane's stated error). ``bitrate``: the
    bus's, for frame durations (a lower one than the real one only makes the engine more careful).
    ``complete``: the capture holds every frame on the bus (the simulated lane), so a missing frame is
    the sender's. ``power_known``: every power cycle is reported with :meth:`power_switched` (a suite's
    lane); otherwise a first report more than two intervals after an R9a event may follow an unseen
    power cycle and is only recorded. ``host_nodes``: nodes known to be hosts from the start (node 0, 4.4.18 note 8).
    ``jitter``: the DUT's report-interval jitter allowance (seconds; a DUT profile's ``jitter_s``),
    added to ``tolerance`` in the R9 interval check only.
    """

    # ------------------------------------------------------------------------------------- the hot path
    def feed(self, can_id: int, data, ts: float, extended: bool = True, remote: bool = False, error: bool = False,
             own: bool = False) -> list[Violation] | tuple:
        """One frame as it was on the bus: its timestamp is when it ended (SocketCAN, the simulated lane).
        ``own``: the host's own frame (its echo). Returns the violations it shows (usually none)."""
        self.frames += 1
        if own:  # the host's own frame moves no clock: by its echo it is in order; without echo it is timed by its
            pass  # send, ahead of the bus's frames the host has not read yet (by its read latency, not the stamps' error)
        elif ts >= self.last_ts:
            self.last_ts = ts
        elif ts < self.last_ts - self.tolerance:  # back by more than the stamps' error: the clock went back
            self._time_jump(ts)
            self.last_ts = ts
        # (back by less: two frames stamped in the other order within their error, e.g. by two handles; no jump)
        if self.first_ts is None:
            self.first_ts = ts
        n = len(data)
        dur = self._dur[0 if remote else (n if n < 9 else 8)]
        start = ts - dur
        if start > self._bus_end + self._slack[n if n < 9 else 8]:
            self._busy_from = start  # the bus was idle before this frame: it did not wait
        busy_from = self._busy_from
        if ts > self._bus_end:  # (one stamped earlier, within the error: the host's own by its clock, without echo)
            self._bus_end = ts
        if error:
            self._error_frame(ts, can_id, data)
            return _NONE
        if not extended:
            self.standard += 1
            return _NONE
        info = self._ids.get(can_id)
        if info is None:
            info = self._new_id(can_id)
        info.count += 1
        node = info.node
        side = info.side
        if self._held is not None:
            self.held(node, ts, busy_from, own)
        # its queueing began no later than its own start: a stretch heard first may start later (the host's own
        # frames without echo are timed by their send, ahead of the bus's frames not read yet)
        busy_from = min(busy_from, start)
        if node.first_ts is None:
            node.first_ts = ts
        if own:
            if not node.host:
                node.host = True
            if info.throttle:  # the host's stream: most frames (what _host_frame does with one, without its tests)
                self._throttle(info, data, ts)
            elif side == SIDE_HOST or side == SIDE_EITHER:
                self._host_frame(info, data, ts)
            return _NONE
        if side == SIDE_ESC:
            if not node.esc:
                node.esc = True
            return self._esc_frame(info, node, data, ts, start, busy_from, remote)
        if side == SIDE_HOST:
            if node.esc and not node.host:
                return self._host_frame_from_esc(info, data, ts, remote)
            if not node.host:
                node.host = True
            self._host_frame(info, data, ts)
            return _NONE
        if side == SIDE_EITHER:
            return self._either_frame(info, node, data, ts, start, busy_from, remote)
        if side == SIDE_FOREIGN and node.esc and (info.type_id, 0) not in node.noted:
            node.noted.add((info.type_id, 0))
            which = "4.3.1-2" if info.kind is not Kind.MESSAGE else "4.3.1-1"
            self._observe((which,), ts, node.id, "foreign-id",
                          f"node {node.id}, an ESC, sent {info.label} (outside the CKESC vendor ranges, 4.3.1)",
                          (quote(can_id, data, ts),))
        return _NONE

    def feed_message(self, msg: Any) -> list[Violation] | tuple:
        """A ``can.Message`` (or anything shaped like one); ``is_rx=False`` marks the host's own frame."""
        return self.feed(msg.arbitration_id, msg.data, msg.timestamp, msg.is_extended_id, msg.is_remote_frame,
                         msg.is_error_frame, not getattr(msg, "is_rx", True))

    # ------------------------------------------------------------------------------------- ESC frames
    def _either_frame(self, info: FrameId, node: Node, data, ts: float, start: float, busy_from: float, remote: bool):
        esc_value = ESC_VALUE.get(info.type_id)
        spec = info.spec
        if esc_value is not None:
            off, size, value = esc_value
            looks_esc = len(data) > off + size and int.from_bytes(data[off:off + size], "little") == value
            if looks_esc and info.type_id == MSG_CONTROL.type_id and not node.host and info.source not in self._host_nodes:
                self._command_answer(info, node, data, ts)  # (an ESC's answer to MSG Control: which command it answers)
        else:  # 20013: the query and the reply differ in length
            layout = spec.message_layout(len(data) - 1) if data else None
            looks_esc = layout is not None and layout.sender == "esc"
            if looks_esc and info.source not in self._host_nodes and not node.host:
                node.esc = True
                self._query_reply(info, node, data, ts)
        if node.esc and not node.host:
            return self._esc_frame(info, node, data, ts, start, busy_from, remote)
        if not looks_esc:
            self._host_frame(info, data, ts)  # a host's command (from a foreign node it at most restarts cadence)
        return _NONE

    def _esc_frame(self, info: FrameId, node: Node, data, ts: float, start: float, busy_from: float, remote: bool):
        out = None
        if ts - node.last_ts > RESTART_SILENCE_S + self.tolerance:
            self._silence(node, ts)
        node.last_ts = ts
        if remote:
            return self._violation(out, ("F1",), ts, node.id, "frame-layout",
                                   f"remote frame with {info.label}'s id: all data goes in data frames (4.1.2)",
                                   (quote(info.can_id, data, ts, remote=True),), subject=f"{info.label} remote frame",
                                   expected="all data in data frames")
        if info.bad_source:
            what = "the host's / unknown node id 0" if info.source == 0 else f"the reserved node id {info.source:#04x}"
            return self._violation(out, ("F7", "4.1.2-N2"), ts, node.id, "reserved-node",
                                   f"{info.label} from {what}: an ESC's node id is 1..0x7D",
                                   (quote(info.can_id, data, ts, note=info.label),), subject=f"{info.label} from {what}",
                                   expected="an ESC's node id is 1..0x7D")
        if info.report and info.source == DEFAULT_ESC_NODE_ID:
            out = self._violation(out, ("F7",), ts, node.id, "default-node-reports",
                                  f"{info.label} from the factory default node id 0x7D: at 0x7D an ESC reports nothing on its own",
                                  (quote(info.can_id, data, ts, note=info.label),),
                                  subject=f"{info.label} from the factory default node id 0x7D",
                                  expected="at 0x7D an ESC reports nothing on its own")
        if info.prio_ok is False:
            out = self._violation(out, ("F5",), ts, node.id, "priority",
                                  f"{info.label} at priority {info.priority} ({priority_name(info.priority)}), the table's "
                                  f"is {int(info.spec.priority)} ({priority_name(info.spec.priority)})",
                                  (quote(info.can_id, data, ts, note=info.label),),
                                  subject=f"{info.label} at priority {info.priority}",
                                  expected=f"the table's priority, {int(info.spec.priority)}")
        elif info.prio_ok is None and info.spec is not None and (info.type_id, 1) not in node.noted:
            node.noted.add((info.type_id, 1))
            self._observe(("F5-unlisted",), ts, node.id, "priority-unlisted",
                          f"{info.label} at priority {info.priority} ({priority_name(info.priority)}); the table lists none",
                          (quote(info.can_id, data, ts),))
        tid = None
        if info.has_tail:
            if not data:
                return self._violation(out, ("F2",), ts, node.id, "tail-byte", f"{info.label} with no data: no tail byte",
                                       (quote(info.can_id, data, ts),), subject=f"{info.label} with no data",
                                       expected="a tail byte")
            tail = data[-1]
            tid = tail_transfer_id(tail)
            if tail & 0xE0 != SINGLE_FRAME:
                out = self._tail(out, info, node, data, ts, tail)
        if info.kind is Kind.RESPONSE:
            return self._response(out, info, node, data, ts, tid)
        if info.stream_key is not None and tid is not None:
            st = self._streams.get(info.stream_key)
            if st is None:
                st = self._streams[info.stream_key] = EscStream(node, info.type_id, info.label, info.periodic)
            out = self._stream(out, st, info, node, data, ts, start, busy_from, tid)
        if info.type_id == MSG1.type_id and len(data) > COMM_BYTE:  # (after its report's events: a restart comes first)
            self._comm_flag(node, bool(data[COMM_BYTE] & COMM_MASK), ts)
            if self.events is not None:
                self.events.msg1(ts, node.id, bool(data[COMM_BYTE] & COMM_MASK), self.clock.last(node.id))
            if self.heard is not None and self.heard.mine(node.id):
                self.heard.msg1.append([ts, bool(data[COMM_BYTE] & COMM_MASK)])
        return out or _NONE

    def _tail(self, out, info: FrameId, node: Node, data, ts: float, tail: int):
        t = parse_tail(tail)
        wrong = [f"{name}=0" for name, bit, _ in _TAIL_RULES if not tail & bit] + (["toggle=1"] if t.toggle else [])
        rules = ("F2",) + tuple(rid for _, bit, rid in _TAIL_RULES if not tail & bit) + (("4.1.3-toggle",) if t.toggle else ())
        return self._violation(out, rules, ts, node.id, "tail-byte",
                               f"{info.label}: tail byte 0x{tail:02X} has {', '.join(wrong)}; a single-frame transfer has "
                               "start=1 end=1 toggle=0", (quote(info.can_id, data, ts, note=info.label),),
                               subject=f"{info.label}'s tail byte with {', '.join(wrong)}",
                               expected="a single-frame transfer's tail: start=1 end=1 toggle=0")

    def _host_frame_from_esc(self, info: FrameId, data, ts: float, remote: bool):
        """A host-side frame from a node known as an ESC: a request means a response sent with the request bit set."""
        if info.kind is not Kind.REQUEST:
            return _NONE
        return self._violation(None, ("F1", "F4"), ts, info.source, "frame-layout",
                               f"{info.label} from node {info.source}, an ESC, to node {info.dest}: an ESC's service frames "
                               "answer requests (request bit 0)", (quote(info.can_id, data, ts, note=info.label),),
                               subject=f"{info.label} from an ESC with the request bit set",
                               expected="an ESC's service frames answer requests (request bit 0)")

    # ------------------------------------------------------------------------------------- F3 and R9
    def _stream(self, out, st: EscStream, info: FrameId, node: Node, data, ts: float, start: float, busy_from: float, tid: int):
        if st.periodic:
            out = self._report_restart(out, st, info, node, data, ts, start, tid)
            if (node.paused and st.chain == node.chain - 1 and st.reset == node.reset and st.moved == node.moved
                    and f3_holds(st.tid, tid)):  # no power cycle, counting on: a late report across the pause (R9)
                st.chain = node.chain
        fresh = st.ts is None or st.chain != node.chain or st.reset != node.reset
        if st.ts is not None and st.chain == node.chain and not node.shared and ts > node.unsure_until:
            gap = start - st.start
            period = None
            if st.interval is not None:
                period = node.periods[st.interval]
            if period is None and st.periodic and st.min_gap < math.inf:
                period = st.min_gap
            if not f3_holds(st.tid, tid) and st.moved == node.moved:  # after a Set ID: maybe another ESC, or one back
                out = self._transfer_ids(out, st, info, node, data, ts, gap, f3_step(st.tid, tid), period)
            if st.reset == node.reset:
                st.nth += 1
                st.stats.add(gap)
                if st.nth > 2 or not st.grace:  # R9a-gaps: up to the second report after a restart, not judged
                    if gap < st.min_gap and gap > 0:
                        st.min_gap = gap
                    if st.interval is not None:
                        out = self._cadence(out, st, info, node, data, ts, start, busy_from)
                        if self.heard is not None:
                            self._heard_interval(st, node, gap)
        if fresh:
            st.nth = 1
            first = node.reset == node.event_reset and st.event != node.event_reset  # the first since an R9a event
            st.grace = first or (st.chain != node.chain and node.chain == node.grace_chain)
            if first:
                st.event = node.event_reset
                if st.interval is not None and node.event_ts is not None:
                    out = self._first_report(out, st, info, node, data, ts, start, busy_from)
        st.ts, st.start, st.busy_from, st.tid, st.data, st.can_id = ts, start, busy_from, tid, data, info.can_id
        st.chain, st.reset, st.moved, st.power = node.chain, node.reset, node.moved, self.power_switches
        return out

    def _transfer_ids(self, out, st: EscStream, info: FrameId, node: Node, data, ts: float, gap: float, step: F3Step,
                      period: float | None):
        if step.advance and not self.complete:
            if period is None or not st.periodic:
                return out  # a frame of an irregular stream may be missing from the capture: cannot tell
            k = round(gap / period)
            if k >= 2 and abs(gap - k * period) <= 0.25 * period + self.tolerance and step.explained_by(k - 1):
                self._observe(("F3",), ts, node.id, "lost-frames",
                              f"{st.name}: transfer id {step.previous} then {step.current} after {ms(gap)}: "
                              f"{k - 1} frame(s) missing from the capture", self._pair(st, info, data, ts))
                return out
        return self._violation(out, ("F3", "4.1.3-tid"), ts, node.id, "transfer-id",
                               f"{st.name}: transfer id {step.current} after {step.previous} ({ms(gap)} earlier), "
                               f"expected {step.expected}", self._pair(st, info, data, ts),
                               subject=f"{st.name}'s transfer id", expected="+1 per transfer (modulo 32)")

    def _cadence(self, out, st: EscStream, info: FrameId, node: Node, data, ts: float, start: float, busy_from: float):
        """R9 between two reports of one stretch (no restart, no reset between them). Without a period the
        node stated, only a report closer than the shortest legal interval is judged. The DUT's jitter
        allowance widens the interval; the bench's error (``tolerance``) is on top of it."""
        tol = self.tolerance + self.jitter
        # due times lie in [start of the busy stretch, start]: the due-to-due gap lies in [lo, hi]
        lo, hi = busy_from - st.start, start - st.busy_from
        period = node.periods[st.interval]  # type: ignore[index]
        gap = r9_gap(lo, hi, SHORTEST_S if period is None else period, tolerance=self.tolerance, jitter=self.jitter)
        if gap.ok:
            return out
        if period is None:
            if not node.floor or gap.op != ">=":
                return out
            rules: tuple[str, ...] = ("R9",)
            expected = f"never closer than the shortest legal interval, {ms(SHORTEST_S)}"
            note = ""
        elif gap.op == ">=":
            rules = ("R9",) + self._period_rules(node)
            expected = f"expected {ms(period)} +- {ms(tol)}"
            note = f" ({node.period_note})"
        else:
            k_lo, k_hi = math.ceil((lo - tol) / period), math.floor((hi + tol) / period)
            if k_hi >= max(k_lo, 2) and not self.complete:
                self._observe(("R9",), ts, node.id, "lost-frames",
                              f"{st.name} {ms(start - st.start)} after the previous one: {k_hi - 1} report(s) at "
                              f"{ms(period)} missing from the capture", self._pair(st, info, data, ts))
                return out
            return self._violation(out, ("R9",) + self._period_rules(node), ts, node.id, "report-interval",
                                   f"{st.name} {ms(start - st.start)} after the previous one (bus queueing allows no less "
                                   f"than {ms(lo)}), expected {ms(period)} +- {ms(tol)} ({node.period_note})",
                                   self._pair(st, info, data, ts), subject=st.name,
                                   expected=f"{ms(period)} +- {ms(tol)}",
                                   measured_s=start - st.start, expected_s=period)
        return self._violation(out, rules, ts, node.id, "report-interval",
                               f"{st.name} {ms(start - st.start)} after the previous one (bus queueing allows up to "
                               f"{ms(hi)}), {expected}{note}", self._pair(st, info, data, ts), subject=st.name,
                               expected=expected.removeprefix("expected "), measured_s=start - st.start,
                               expected_s=period)

    def _first_report(self, out, st: EscStream, info: FrameId, node: Node, data, ts: float, start: float, busy_from: float):
        """R9a: the first report of a type after a resume / CAN Test off comes within one interval plus a slack of
        max(3 ms, a quarter interval) of it; after a Set Freq write, within the longer of its old and new interval
        plus that slack; and never sooner than an earlier event's first report that had not come yet could. Judged
        on the earliest it can have been due (bus queueing), tolerance and the DUT's report-interval jitter
        allowance on top."""
        period, which = self._restart_period(node, st.interval)  # type: ignore[arg-type]
        if period is None:
            return out
        limit = r9a_limit_s(period)
        carried = node.pending[st.interval]  # type: ignore[index]
        if carried is not None and carried - node.event_ts > limit:  # type: ignore[operator]
            limit, which = carried - node.event_ts, "what an earlier restart still allowed"  # type: ignore[operator]
        tol = self.tolerance + self.jitter
        since = busy_from - node.event_ts  # type: ignore[operator]
        if r9a_first(since, limit, error=tol).ok:
            return out
        if not self.power_known and since > limit + period + RESTART_SILENCE_S + self.tolerance:
            self._observe(("R9a",), ts, node.id, "first-report-unjudged",
                          f"the first {st.name} {ms(start - node.event_ts)} after {node.event_what}: not judged, the node "  # type: ignore[operator]
                          "may have been power cycled meanwhile (a capture does not show it)", (quote(info.can_id, data, ts),))
            return out
        return self._violation(out, ("R9a",), ts, node.id, "first-report",
                               f"the first {st.name} {ms(start - node.event_ts)} after {node.event_what} "  # type: ignore[operator]
                               f"(bus queueing allows no less than {ms(since)}), expected within {which} plus a slack, "
                               f"{ms(limit)} +- {ms(tol)} ({node.period_note})",
                               (quote(info.can_id, data, ts, note=st.name),),
                               subject=f"the first {st.name} after {node.event_what}",
                               expected=f"within {which} plus a slack, {ms(limit)} +- {ms(tol)}",
                               measured_s=start - node.event_ts, expected_s=limit)  # type: ignore[operator]

    @staticmethod
    def _period_rules(node: Node) -> tuple[str, ...]:
        """The other clause an interval mismatch may break: the read answer the period came from
        (4.4.22-2), or the persistence of a period stated before the node went silent (R13)."""
        return (("4.4.22-2",) if node.from_read else ()) + (("R13",) if node.before_silence else ())

    def _response(self, out, info: FrameId, node: Node, data, ts: float, tid: int | None):
        """F4: the request it answers (:class:`~.pairing.RequestPairing`, told to the consumer), else a violation."""
        service, requester = info.type_id, info.dest
        p = self.requests.response(ts, info.source, service, tid, requester)  # type: ignore[arg-type]
        if self.events is not None:
            self.events.response(ts, node.id, p, info.can_id, bytes(data))
        if service in PSEUDO_BROADCAST:
            self._answer(node, ts)
        if p.holds or (p.again and p.request.taken):  # type: ignore[union-attr]
            if self.heard is not None:
                self._paired_answer(info, p, ts)
            if not node.shared:  # (two ESCs at one id: whose channel an answer says, the bus cannot tell)
                self.clock.answer(service, node.id, data, p.request.t)  # type: ignore[union-attr]
            if service == SET_FREQ.type_id:
                self._set_freq_answer(node, data, ts)
            elif service == MAINTENANCE.type_id:
                out = self._counters(out, info, node, data, ts, p.request.t)  # type: ignore[union-attr]
            return out or _NONE
        frames = (quote(info.can_id, data, ts, note=info.label),)
        if p.request is not None and not p.request.taken and not p.mismatches:
            return self._violation(out, ("F4",), ts, node.id, "response-match",
                                   f"{info.label} to node {requester} with transfer id {tid}: it answers a request the "
                                   "ESC ignores (R17: malformed), and no other", frames,
                                   subject=f"{info.label} to a node that sent no {info.spec.title} request",  # type: ignore[union-attr]
                                   expected="a response goes to the requester")
        if p.request is not None and self.complete and not any("transfer id" in m for m in p.mismatches):  # not asked
            return self._violation(out, ("F4",), ts, node.id, "response-match",
                                   f"{info.label} to node {requester} with transfer id {tid}: the answer to node "
                                   f"{requester}'s request to node {p.request.asked}, but {'; '.join(p.mismatches)}", frames,
                                   subject=f"{info.label} from a node that was not asked",
                                   expected="a response comes from the node asked")
        if p.asked:
            return self._violation(out, ("F4",), ts, node.id, "response-match",
                                   f"{info.label} to node {requester} with transfer id {tid}; node {requester}'s requests "
                                   f"to node {info.source} in the last {RESPONSE_WINDOW_S:g} s had transfer ids "
                                   f"{sorted(set(p.asked))} (a response keeps its request's)", frames,  # type: ignore[type-var]
                                   subject=f"{info.label}'s transfer id", expected="a response keeps its request's")
        others = self.requests.others(info.source, service, requester, ts)
        text = (f"{info.label} to node {requester}, but node {requester} sent no {info.spec.title} request to node "  # type: ignore[union-attr]
                f"{info.source} in the last {RESPONSE_WINDOW_S:g} s" + (f" (node(s) {others} did)" if others else ""))
        if self.complete:  # every frame since the bus started was heard: the request was not missed
            return self._violation(out, ("F4",), ts, node.id, "response-match", text + ": a response goes to the requester",
                                   frames, subject=f"{info.label} to a node that sent no {info.spec.title} request",  # type: ignore[union-attr]
                                   expected="a response goes to the requester")
        self._observe(("F4",), ts, node.id, "response-unmatched", text + " (the capture may have missed it)", frames)
        return out or _NONE

    # ------------------------------------------------------------------------------------- the summary
    def summary(self) -> dict[str, Any]:
        """Everything the engine kept, JSON-able: per node its role, frames by type, report interval
        statistics, comm-loss events and findings."""
        by_node: dict[int, dict[str, Any]] = {}
        for info in self._ids.values():
            n = by_node.setdefault(info.source, {"by_type": {}})
            n["by_type"][info.label] = n["by_type"].get(info.label, 0) + info.count
        nodes = {}
        for node_id in sorted(self._nodes):
            node = self._nodes[node_id]
            counts = by_node.get(node_id, {"by_type": {}})["by_type"]
            streams = {st.name: {**st.stats.to_json(),
                                 "expected_ms": (None if st.interval is None or node.periods[st.interval] is None
                                                 else round(node.periods[st.interval] * 1000, 3))}  # type: ignore[operator]
                       for (src, _), st in sorted(self._streams.items()) if src == node_id}
            nodes[str(node_id)] = {
                "role": node.role,
                "frames": sum(counts.values()),
                "by_type": dict(sorted(counts.items(), key=lambda kv: -kv[1])),
                "intervals": streams,
                "intervals_from": node.period_note or None,
                "comm_loss": node.comm_events + ([{"more": node.comm_dropped}] if node.comm_dropped else []),
                "silences": node.silences,
                "violations": {check: t.count for (nid, check), t in sorted(self._tallies.items(), key=str) if nid == node_id},
            }
        return {
            "frames": self.frames,
            "first_timestamp": self.first_ts,
            "last_timestamp": self.last_ts if self.frames else None,
            "duration_s": (self.last_ts - self.first_ts) if self.first_ts is not None else 0.0,
            "bitrate": self.bitrate,
            "tolerance_s": self.tolerance if self.tolerance > 1e-9 else 0.0,
            "complete": self.complete,
            "standard_id_frames": self.standard,
            "error_frames": {"count": self.error_frames, "first": self.error_first},
            "time_jumps": self.time_jumps,
            "get_esc_id": self.queries.statistics(),  # its replies by the query they answer (pairing.QueryPairing)
            "violations": {"count": self.violations, "by_rule": dict(sorted(self._by_rule.items())),
                           "first": [v.to_json() for v in self.findings()]},
            "observations": [v.to_json() for v in self.findings(observations=True)],
            "nodes": nodes,
        }
