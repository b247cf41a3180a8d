"""What the traffic on a CKESC bus says, one frame at a time, sans-IO: the state the bus rules
(:mod:`.rules`) judge against and the report's plots draw (:mod:`.timing`), worked out once.

* **who is who**: which node is an ESC, which a host (:class:`FrameId` works out each CAN id once);
* **request/answer pairing**: which requests each node made, so that an answer is matched with the request it
  answers by F4 (same requester, service and transfer id, within :data:`RESPONSE_WINDOW_S`; Set ID, a
  pseudo-broadcast, from any node), and which GET_ESC_ID query (the host's, another node's) each reply answers
  (:class:`.pairing.QueryPairing`, the one owner of that decision: a reply from a node id that answers none while
  queries were open is a second ESC at that id);
* **report-interval targets**: per node the MSG1..MSG3 intervals it last stated in a Set/Get Freq answer, and
  the events after which a report's cadence restarts (MSG Control, CAN Test, Set ID, Set Freq writes, R9a
  restarts, silences long enough for a power cycle);
* with :attr:`Tracker.heard` set, a record of what it paired (:class:`TimingEvidence`: answer delays, the report
  intervals the rules judged against a stated target, the R8 timeline).

The rules' docstring (:mod:`.rules`) says what each of these means for a verdict.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.frame import classify, frame_bits
from ..protocol.ids import ESC_NODE_IDS, HOST_NODE_ID, MESSAGE_VENDOR_RANGE, SERVICE_VENDOR_RANGE, Kind
from ..protocol.transfer import tail_transfer_id
from .commands import CommandClock
from .events import ReaderEvents
from .findings import KEEP, Findings, Intervals, quote
from .pairing import QueryPairing, RequestPairing, ResponsePairing
from .rejoin import Rejoin
from .taken import taken

# ------------------------------------------------------------------------------------------ facts, derived
#: The reports whose interval Set/Get Freq sets (R9), by type id, with their interval field.
INTERVAL_FIELDS = cat.INTERVAL_FIELDS
REPORT_INTERVAL = {cat.BY_NAME[k.removesuffix("_interval")].type_id: i for i, k in enumerate(INTERVAL_FIELDS)}
SHORTEST_S = cat.REPORT_INTERVAL_RANGE[0] * cat.INTERVAL_UNIT_S
LONGEST_S = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
#: A node silent for longer than this may have been power cycled: its frames before and after are not compared.
RESTART_SILENCE_S = 2 * SHORTEST_S

SET_FREQ = cat.spec("set_freq")
SET_FREQ_OPTION = SET_FREQ.request.field("option")  # type: ignore[union-attr]
SET_FREQ_WRITE = next(k for k, v in (SET_FREQ_OPTION.codes or {}).items() if v == "write")
SET_ID_NODE = cat.spec("set_id").request.field("node_id")  # type: ignore[union-attr]
PSEUDO_BROADCAST = frozenset({cat.spec("set_id").type_id})  # R11: answered by every ESC, from its (new) node id
MSG1 = cat.spec("msg1")
STATUS = MSG1.layouts[0].field("status")
COMM_BIT = int(cat.Status.COMM_FAULT).bit_length() - 1
COMM_BYTE, COMM_MASK = STATUS.offset + COMM_BIT // 8, 1 << (COMM_BIT % 8)
THROTTLE = frozenset(cat.spec(name).type_id for name in cat.THROTTLE_FRAMES)
#: Periodic ESC reports (they come on their own; F7: none at 0x7D): the catalogue's "report" layouts,
#: except MSG_EXP12 (one per Get Rec, its transfer id names the record, R15).
REPORTS = frozenset(s.type_id for s in cat.CATALOGUE if not s.service and s.layouts[0].name == "report" and s.tail_tag is None)

#: Frames that either side sends: which payload value marks the ESC's (CAN Test report, MSG Control answer).
ESC_VALUE: dict[int, tuple[int, int, int]] = {}
for _name, _field, _value in (("can_test", "option", cat.CAN_TEST_REPORT), ("msg_control", "command", cat.MSG_CONTROL_ANSWER)):
    _f = cat.spec(_name).layouts[0].field(_field)
    ESC_VALUE[cat.spec(_name).type_id] = (_f.offset, _f.size, _value)
MSG_CONTROL = cat.spec("msg_control")
GET_ESC_ID = cat.spec("get_esc_id")
MSG_CONTROL_COMMAND = MSG_CONTROL.layouts[0].field("command")
CAN_TEST = cat.spec("can_test")
CAN_TEST_OPTION = CAN_TEST.layouts[0].field("option")
#: 241's answers that show a reset (R19): option 2's power-up count, option 1's run time (the layout is the request's
#: option's: the answer does not carry it)
MAINTENANCE = cat.spec("maintenance_information")
MAINTENANCE_OPTION = MAINTENANCE.request.field("option")  # type: ignore[union-attr]
RESET_FIELDS = {option: MAINTENANCE.response_for({"option": option}).field(name)  # type: ignore[union-attr]
                for option, name in ((1, "run_time"), (2, "power_ups"))}
#: Host broadcasts that start, stop or switch active reporting on every ESC (4.4.1, 4.4.2).
REPORTING_SWITCHES = {
    MSG_CONTROL.type_id: (MSG_CONTROL_COMMAND, {cat.MSG_CONTROL_SUSPEND, cat.MSG_CONTROL_RESUME, cat.MSG_CONTROL_RESUME_EXP}),
    CAN_TEST.type_id: (CAN_TEST_OPTION, {cat.CAN_TEST_ON, cat.CAN_TEST_OFF}),
}
#: ... and the values among them after which MSG1..MSG3 come back (R9a: the first within one interval)
RESTARTS = {MSG_CONTROL.type_id: cat.MSG_CONTROL_RESUME, CAN_TEST.type_id: cat.CAN_TEST_OFF}

# which side sends a frame
SIDE_FOREIGN, SIDE_HOST, SIDE_ESC, SIDE_EITHER, SIDE_UNKNOWN = range(5)
_SIDE_NAMES = ("foreign", "host", "esc", "either", "unknown")

ID_CACHE = 65536  # distinct CAN ids remembered; a capture of random ids must not grow memory without bound


def field_value(data, f) -> int:
    return int.from_bytes(data[f.offset:f.offset + f.size], "little")


@dataclass
class TimingEvidence:
    """What the tracker paired while :attr:`Tracker.heard` was set, as the report's plots draw it (seconds):

    * ``answers``: ``{node: {request: [delay]}}``: each answer matched with the request it answers (its first
      answer from each node), and each GET_ESC_ID reply that answers one query only (:class:`.pairing.QueryPairing`),
      from the request's timestamp (its end on the bus, the host's own frame by its echo) to the answer's;
    * ``intervals``: ``{report: {target: [interval]}}``: the MSG1..MSG3 intervals of ``node`` the rules judged
      against the interval the node last stated (start to start of the two frames, as judged; none before
      a stated target, none across a restart of the cadence or within the two reports after an R9a event);
    * ``commands`` and ``msg1`` (R8's timeline): the throttle commands' timestamps, and ``[t, comm fault bit]``
      per MSG1 of ``node``.
    """

    node: int | None = None  # None: every node's intervals and MSG1
    answers: dict[str, dict[str, list[float]]] = field(default_factory=lambda: defaultdict(lambda: defaultdict(list)))
    intervals: dict[str, dict[str, list[float]]] = field(default_factory=lambda: defaultdict(lambda: defaultdict(list)))
    commands: list[float] = field(default_factory=list)
    msg1: list[list] = field(default_factory=list)

    def mine(self, node: int) -> bool:
        return self.node is None or node == self.node

    def answer(self, node: int, request: str, delay: float) -> None:
        self.answers[str(node)][request].append(round(delay, 9))

    def to_json(self, *, comm_loss: bool = False) -> dict[str, Any]:
        """As a test's ``evidence`` in results.json (``comm_loss``: with R8's timeline)."""
        out: dict[str, Any] = {"answers": {k: dict(v) for k, v in self.answers.items()},
                               "intervals": {k: dict(v) for k, v in self.intervals.items()}}
        if comm_loss:
            out["comm_loss"] = {"commands": list(self.commands), "msg1": [list(m) for m in self.msg1]}
        return out


class Node:
    __slots__ = ("id", "esc", "host", "first_ts", "last_ts", "chain", "reset", "periods", "period_note", "floor",
                 "from_read", "before_silence", "shared", "comm_fault", "comm_events", "comm_dropped", "silences", "noted",
                 "event_reset", "event_ts", "event_what", "event_old", "pending", "grace_chain", "unsure_until", "moved",
                 "paused")

    def __init__(self, node_id: int, host: bool) -> None:
        self.id = node_id
        self.esc = False
        self.host = host
        self.first_ts: float | None = None
        self.last_ts = -math.inf
        self.chain = 0  # +1 at every silence long enough for a power cycle
        #: the last silence came with every power switch reported and none since the node's frame before it: the
        #: node's own pause (R9 judges its gap where a report counts on) or a reset (its counter starts again, R19)
        self.paused = False
        self.reset = 0  # +1 whenever this node's report cadence may restart (suspend/resume, Set Freq, ...)
        #: +1 at every Set ID (it may re-address any ESC): the ESC sending from this id next may have sent from
        #: another id meanwhile, its transfer ids counting on there (F3 counts at the sender), so the first frame
        #: of each stream after it is not held to the one before
        self.moved = 0
        # R9a: the reset an event started after which the reports come back (a resume, CAN Test off, a Set Freq
        # write), its time and name (None: the first report's delay cannot be judged, e.g. after a power cycle)
        self.event_reset = -1
        self.event_ts: float | None = None
        self.event_what = ""
        self.event_old: list[float | None] | None = None  # a Set Freq write's: the periods before it (R9a)
        # per report: the latest an earlier event's first report may still come, when a new event came before it
        # (a resume right after a Set Freq write: the report due on the old interval may still go first)
        self.pending: list[float | None] = [None] * len(INTERVAL_FIELDS)
        self.grace_chain = -1  # the stretch after a power cycle the host made (power_switched): R9a-gaps too
        self.periods: list[float | None] = [None] * len(INTERVAL_FIELDS)  # seconds, as the node last said
        self.period_note = ""  # where the periods come from (for messages)
        self.from_read = False  # the periods come from a read answer (4.4.22-2 says it tells the settings)
        self.before_silence = False  # ... stated before a silence that may have been a power cycle (R13 keeps them)
        self.shared = False  # two ESCs answered one broadcast from this node id: its frames are two ESCs' (4.4.18-2)
        #: a Set ID to this node id went out when no ESC had been heard (how many ESCs may take it is not known) and
        #: its answers may still come: until then (the longest answer delay and a service's) its frames are not compared
        self.unsure_until = -math.inf
        self.floor = True  # judge reports against the shortest legal interval while the periods are unknown
        self.comm_fault: bool | None = None
        self.comm_events: list[dict[str, Any]] = []
        self.comm_dropped = 0
        self.silences = 0
        self.noted: set[tuple] = set()  # observations made once per node

    @property
    def role(self) -> str:
        return "+".join(r for r, on in (("esc", self.esc), ("host", self.host)) if on) or "foreign"


class EscStream:
    """One (node, message type) of an ESC: transfer ids (F3) and intervals (R9)."""

    __slots__ = ("node", "type_id", "name", "interval", "periodic", "ts", "start", "busy_from", "tid", "data", "can_id",
                 "chain", "reset", "min_gap", "stats", "nth", "grace", "event", "moved", "power")

    def __init__(self, node: Node, type_id: int, name: str, periodic: bool) -> None:
        self.node = node
        self.type_id = type_id
        self.name = name
        self.interval = REPORT_INTERVAL.get(type_id)  # index into node.periods, for MSG1..MSG3
        self.periodic = periodic
        self.ts: float | None = None
        self.start = self.busy_from = 0.0
        self.tid = 0
        self.data = b""
        self.can_id = 0
        self.chain = self.reset = -1
        self.moved = 0  # the node's Set ID count at this stream's last frame
        self.power = 0  # the tracker's power switches at this stream's last frame (R19: a restart the host made)
        self.min_gap = math.inf
        self.stats = Intervals()
        self.nth = 0  # reports in this stretch (since the chain or the reset changed)
        self.grace = False  # the stretch began at an R9a event: its first two gaps are not judged
        self.event = -1  # the node's R9a event (event_reset) whose first report this stream has had


class FrameId:
    """What one CAN id is, worked out once (the hot path looks it up)."""

    __slots__ = ("can_id", "kind", "type_id", "source", "dest", "spec", "side", "node", "label", "count", "priority",
                 "prio_ok", "bad_source", "report", "stream_key", "periodic", "has_tail", "throttle")

    def __init__(self, can_id: int, node: Node) -> None:
        kind, type_id, source, dest, spec = classify(can_id)
        self.can_id, self.kind, self.type_id, self.source, self.dest, self.spec = can_id, kind, type_id, source, dest, spec
        self.node = node
        self.count = 0
        self.priority = (can_id >> 24) & 0x1F
        vendor = SERVICE_VENDOR_RANGE if kind is not Kind.MESSAGE else MESSAGE_VENDOR_RANGE
        if spec is None:
            self.side = SIDE_UNKNOWN if type_id in vendor else SIDE_FOREIGN
            what = "service " + kind.label if kind is not Kind.MESSAGE else "message"
            self.label = f"{'unknown' if self.side == SIDE_UNKNOWN else 'foreign'} {what} {type_id}"
        elif kind is Kind.MESSAGE:
            senders = {lay.sender for lay in spec.layouts}
            self.side = SIDE_ESC if senders == {"esc"} else SIDE_HOST if senders == {"host"} else SIDE_EITHER
            self.label = spec.name
        else:
            self.side = SIDE_HOST if kind is Kind.REQUEST else SIDE_ESC
            self.label = f"{spec.name} {kind.label}"
        expected = spec.priority if spec is not None else None
        self.prio_ok = None if expected is None else self.priority == expected
        self.bad_source = source not in ESC_NODE_IDS  # 0 (the host's / unknown) or reserved (F7)
        self.report = type_id in REPORTS and kind is Kind.MESSAGE
        self.has_tail = spec is None or spec.has_tail
        # F3 counts per message type; a response carries its request's id (F4), MSG_EXP12 names its record (R15)
        counted = kind is Kind.MESSAGE and spec is not None and spec.has_tail and spec.tail_tag is None
        self.stream_key = (source, type_id) if counted else None
        self.periodic = self.report or type_id == CAN_TEST.type_id
        self.throttle = kind is Kind.MESSAGE and type_id in THROTTLE  # a host's throttle command (the stream: the hot path)



class Tracker(Findings, Rejoin):
    """The traffic's state, fed by :class:`.rules.BusRules` (which judges it); see the module docstring."""

    def __init__(self, *, tolerance: float = 0.0, bitrate: int = cat.DEFAULT_BITRATE, complete: bool = False,
                 host_nodes=(HOST_NODE_ID,), jitter: float = 0.0, power_known: bool = False, own_error: float = 0.0) -> None:
        self.tolerance = max(float(tolerance), 1e-9)
        self.own_error = max(self.tolerance, own_error)  #: the error of the stamps on the host's own frames
        self.jitter = max(float(jitter), 0.0)
        self.complete = complete
        self.power_known = power_known
        self._host_nodes = frozenset(host_nodes)
        self.frames = 0
        self.standard = 0
        self.error_frames = 0
        self.error_first: list[float] = []
        self.time_jumps = 0
        self.first_ts: float | None = None
        self.last_ts = -math.inf
        self._nodes: dict[int, Node] = {}
        self._ids: dict[int, FrameId] = {}
        self._streams: dict[tuple[int, int], EscStream] = {}
        #: which request each answer answers (F4), every node's (the one owner of that decision)
        self.requests = RequestPairing(error=self.own_error)
        super().__init__()
        self._last_throttle: tuple[float, str, int] | None = None
        #: answers per node to the last Set ID (more than one: a shared id)
        self._answered: dict[int, int] = {}
        #: which GET_ESC_ID query each reply answers, from any node: another host on the bus (a flight controller, F6)
        #: queries too, and the ESC may answer both (the one owner of that decision)
        #: ``own_error``: the error of the stamps on the host's own frames (a query's), where larger than ``tolerance``
        self.queries = QueryPairing(error=self.own_error, host=min(self._host_nodes, default=HOST_NODE_ID))
        #: the throttle commands heard (any host's), the longest gap between two, and the gaps longer than the comm-loss
        #: time (R8: the ESC may then flag it)
        self.commands = 0
        self.longest_command_gap = 0.0
        self.command_gaps = 0
        self._set_id_ts = -math.inf  # the last Set ID: a node id not heard since may have been left by its ESC
        self._bus_end = -math.inf
        self._busy_from = -math.inf
        self._held: bool | float | None = None  # (Rejoin.held) True: the host reopened; then the stretch's start
        self.set_bitrate(bitrate)
        #: the host's last MSG Control switch suspended reporting, and no resume nor power switch since: a parameter
        #: write then does not take effect (R12) and its answer is free (R10-R12: the current values, none, or the
        #: request's echoed), so a Set Freq write's answer does not say the intervals in force
        self._suspended = False
        #: how many times the host switched the DUT's power (:meth:`power_switched`): a reset across one is the host's
        self.power_switches = 0
        self.last_switch_ts = -math.inf  #: the lane time of the latest power switch the host reported
        #: 241 requests' options by (requester, node asked, transfer id): their answers' layout (R19's counters)
        self._maintenance: dict[tuple[int, int | None, int], int] = {}
        #: what the tracker paired, for the report's plots: None (the default) records nothing
        self.heard: TimingEvidence | None = None
        #: R8's clock: per ESC node, the last command that addresses its throttle channel (:mod:`.commands`); a
        #: channel read where the reader was not fed the answer (the explorer's baseline) is told to it (``clock.read``)
        self.clock = CommandClock()
        self.events = None

    @property
    def events(self) -> ReaderEvents | None:
        """A consumer of the reader's events (:class:`.events.ReaderEvents`): None (the default) tells none."""
        return self._events

    @events.setter
    def events(self, sink: ReaderEvents | None) -> None:
        self._events = sink
        self.clock.sink = sink.command if sink is not None and sink.wants_commands else None

    # ------------------------------------------------------------------------------------- setup
    def set_bitrate(self, bitrate: int) -> None:
        """The bus's bit rate from now on."""
        self.bitrate = int(bitrate)
        self._dur = [frame_bits(n) / self.bitrate for n in range(9)]
        # a real frame is up to ~20 % longer than its unstuffed length: a frame that starts within that of
        # the previous one's end may have waited for it
        self._slack = [0.25 * d + self.tolerance for d in self._dur]
        self._bus_end = self._busy_from = -math.inf

    def _node(self, node_id: int) -> Node:
        node = self._nodes.get(node_id)
        if node is None:
            node = self._nodes[node_id] = Node(node_id, node_id in self._host_nodes)
        return node

    def frame_id(self, can_id: int) -> FrameId:
        """What the extended CAN id ``can_id`` is, from the reader's table (worked out once): a consumer reading the same
        frames (the soak's monitor) takes it from here instead of classifying the id again. The id's node is the
        reader's from then on, as :meth:`~.rules.BusRules.feed` makes it: ask only for a frame it is fed."""
        info = self._ids.get(can_id)
        return info if info is not None else self._new_id(can_id)

    def _new_id(self, can_id: int) -> FrameId:
        info = FrameId(can_id, self._node(can_id & 0x7F))
        if len(self._ids) < ID_CACHE:
            self._ids[can_id] = info
        return info

    @staticmethod
    def _restart_period(node: Node, i: int) -> tuple[float | None, str]:
        """R9a: the interval the first report of report ``i`` after the node's event counts (None: unknown), and
        which: one interval, or after a Set Freq write the longer of its old and new one (the longest legal one
        when the node had stated none)."""
        period = node.periods[i]
        if period is None or node.event_old is None:
            return period, "one interval"
        old = node.event_old[i]
        return max(period, LONGEST_S if old is None else old), "the longer of its old and new interval"

    def _event(self, node: Node, ts: float, what: str, old: list[float | None] | None = None) -> None:
        """An R9a event for ``node``: its reports (come back and) count from ``ts``; ``old``: a Set Freq write's
        periods before it. A report whose first since the previous event has not come keeps that event's limit."""
        if node.event_ts is None:
            node.pending = [None] * len(INTERVAL_FIELDS)
        else:
            for type_id, i in REPORT_INTERVAL.items():
                st = self._streams.get((node.id, type_id))
                if st is not None and st.event == node.event_reset:  # it came: nothing of before is pending
                    node.pending[i] = None
                    continue
                period = self._restart_period(node, i)[0]
                due = node.event_ts + cat.restart_limit_s(LONGEST_S if period is None else period)
                node.pending[i] = due if node.pending[i] is None else max(node.pending[i], due)  # type: ignore[type-var]
        node.reset += 1
        node.event_reset, node.event_ts, node.event_what, node.event_old = node.reset, ts, what, old

    def stated(self, node_id: int, periods: dict[str, float], what: str) -> None:
        """Node ``node_id`` stated its MSG1..MSG3 intervals (seconds, by report name: ``msg1``) in a read answer the
        reader was not fed (the soak's settings, read before its run): taken as if it had heard it (``what`` says where
        from, for messages)."""
        node = self._node(node_id)
        node.periods = [periods.get(k.removesuffix("_interval")) for k in INTERVAL_FIELDS]
        node.floor, node.from_read, node.before_silence = True, True, False
        node.period_note = what

    def power_switched(self, ts: float) -> None:
        """The host switched the DUT's power (off or on) at ``ts``: a pending R9a event is void (the first
        report after a power-up is the boot's, not the command's); the next stretch has R9a-gaps grace."""
        self._suspended = False  # a suspension is not kept across a power cycle (R13)
        self.power_switches += 1
        # when: frames are handed over as the host reads them, maybe after the switch was noted (a lane that let
        # time pass unread): a report stamped before it and read after it still lies before the switch
        self.last_switch_ts = max(self.last_switch_ts, ts)
        for node in self._nodes.values():
            node.event_ts = None
            node.grace_chain = node.chain + 1  # the stretch after the silence it makes

    # ------------------------------------------------------------------------------------- state the traffic sets
    def _silence(self, node: Node, ts: float) -> None:
        node.paused = self.power_known and node.last_ts >= self.last_switch_ts
        if node.last_ts > -math.inf:
            node.silences += 1
            if any(p is not None for p in node.periods) and not node.before_silence:
                node.before_silence = True
                node.period_note += ", before a silence (a power cycle?)"
        node.chain += 1

    def _time_jump(self, ts: float) -> None:
        self.time_jumps += 1
        self._observe((), ts, None, "time-jump", f"timestamps go back from {self.last_ts:.6f} to {ts:.6f}: "
                      "everything before is not compared with what follows")
        for node in self._nodes.values():
            node.chain += 1
            node.last_ts = -math.inf
        self._bus_end = self._busy_from = -math.inf
        self.queries.forget()

    def _reset_all(self) -> None:
        for node in self._nodes.values():
            node.reset += 1

    def _throttle(self, info: FrameId, data, ts: float) -> None:
        """A host's throttle command (R8: the comm flag's clock per ESC, the stream's gaps)."""
        self.clock.command(info.can_id, info.type_id, data, ts)
        if self.heard is not None:
            self.heard.commands.append(ts)
        last = self._last_throttle
        if last is not None:
            gap = ts - last[0]
            if gap > self.longest_command_gap:
                self.longest_command_gap = gap
            if gap > cat.COMM_LOSS_TIMEOUT_S:
                self.command_gaps += 1
        self.commands += 1
        self._last_throttle = (ts, info.label, info.type_id)

    def _host_frame(self, info: FrameId, data, ts: float) -> None:
        type_id = info.type_id
        if info.kind is Kind.MESSAGE:
            if info.throttle:
                self._throttle(info, data, ts)
                return
            if not taken(info.can_id, data):
                return  # R17: an ESC ignores it (a multi-frame part, a wrong length): it switches nothing
            if type_id == GET_ESC_ID.type_id:  # a query: every ESC answers it once
                self.queries.query(ts, info.source)
                if self.events is not None:
                    self.events.query(ts, info.source)
            switch = REPORTING_SWITCHES.get(type_id)
            if switch is not None and len(data) > switch[0].offset + switch[0].size and field_value(data, switch[0]) in switch[1]:
                value = field_value(data, switch[0])
                if type_id == MSG_CONTROL.type_id:  # a command every ESC answers (its answer: command_answer)
                    self._suspended = value == cat.MSG_CONTROL_SUSPEND
                    self.requests.request(ts, Kind.MESSAGE, type_id, tail_transfer_id(data[-1]), info.source, None)
                if RESTARTS.get(type_id) == value:  # reporting comes back on every ESC (R9a)
                    what = f"{info.label} {value:#x}"
                    for node in self._nodes.values():
                        self._event(node, ts, what)
                else:
                    self._reset_all()  # reporting stops or switches on every ESC: cadence restarts
            return
        if info.kind is not Kind.REQUEST or not data:
            return
        tid = tail_transfer_id(data[-1])
        asked = None if type_id in PSEUDO_BROADCAST else info.dest
        if not taken(info.can_id, data):  # R17: a malformed request is ignored: an answer to it is one too many
            self.requests.request(ts, Kind.REQUEST, type_id, tid, info.source, asked, taken=False)
            return
        if type_id in PSEUDO_BROADCAST:
            self._answered.clear()
            for node in self._nodes.values():  # may re-address any ESC: nobody's intervals are known now
                node.periods = [None] * len(INTERVAL_FIELDS)
                node.reset += 1
                node.moved += 1
                node.shared = False  # ... nor whether two of them share an id
            self._set_id_shared(data, ts)
            self.clock.set_id(ts, data, suspended=self._suspended,
                              up_for=ts - self.last_switch_ts if self.power_known and self.power_switches else None)
        else:
            if type_id == MAINTENANCE.type_id and len(data) > MAINTENANCE_OPTION.offset + MAINTENANCE_OPTION.size:
                if len(self._maintenance) > 4096:
                    self._maintenance.clear()
                self._maintenance[(info.source, info.dest, tid)] = field_value(data, MAINTENANCE_OPTION)
            if type_id == SET_FREQ.type_id and field_value(data, SET_FREQ_OPTION) == SET_FREQ_WRITE:
                dest = self._node(info.dest)  # type: ignore[arg-type]
                # the new intervals count from the write (its answer tells them), the old ones as the node last said
                self._event(dest, ts, "a Set Freq write", list(dest.periods))
                dest.periods = [None] * len(INTERVAL_FIELDS)  # unknown until that answer: it may come after reports
        self.requests.request(ts, Kind.REQUEST, type_id, tid, info.source, asked)

    def _set_id_shared(self, data, ts: float) -> None:
        """Set ID while more than one ESC reports: any of them may take the id (R11: it ignores the destination), and
        their answers from it, alike and in the same slot, may reach the bus as one frame; so the id is taken as
        shared (4.4.18-2): its reports are not compared with one another. An ESC reports if heard lately and since
        the Set ID before (a node id an ESC left then is heard no more)."""
        since = max(self._set_id_ts, ts - LONGEST_S - RESTART_SILENCE_S)
        self._set_id_ts = ts
        escs = sum(1 for n in self._nodes.values() if n.esc and n.last_ts > since)
        if len(data) <= SET_ID_NODE.offset + SET_ID_NODE.size:
            return
        if escs == 0:  # none heard: several may take it, and answer up to 64 ms later (their answers tell then)
            self._node(field_value(data, SET_ID_NODE)).unsure_until = ts + 2 * cat.ANSWER_DELAY_MAX_S
        if escs > 1:
            node = self._node(field_value(data, SET_ID_NODE))
            node.shared = True
            self._observe(("4.4.18-2",), ts, node.id, "shared-node-id",
                          f"Set ID {node.id} while {escs} ESCs report: any of them may take it, their reports from it are "
                          "not compared with one another")

    def _answer(self, node: Node, ts: float) -> None:
        """An answer to Set ID, which every ESC answers once: a second one from the same node id means two ESCs
        share it (Set ID sets every ESC on the bus, 4.4.18-2)."""
        count = self._answered[node.id] = self._answered.get(node.id, 0) + 1
        if count > 1:
            self._shared(node, ts)

    def _shared(self, node: Node, ts: float) -> None:
        if not node.shared:
            node.shared = True
            self._observe(("4.4.18-2",), ts, node.id, "shared-node-id",
                          f"two ESCs answer from node id {node.id}: its reports are not compared with one another")

    def _paired_answer(self, info: FrameId, p: ResponsePairing, ts: float) -> None:
        """The answer ``info`` at ``ts`` to ``p``'s request: its delay, once (a repeat is not recorded)."""
        if not p.again and p.request is not None:
            self.heard.answer(info.source, info.spec.name, ts - p.request.t)  # type: ignore[union-attr]

    def _command_answer(self, info: FrameId, node: Node, data, ts: float) -> None:
        """An ESC's answer to a broadcast command (MSG Control's): the command it answers (:class:`.pairing.RequestPairing`),
        told to the consumer."""
        p = self.requests.command_answer(ts, node.id, info.type_id)
        if self.events is not None:
            self.events.response(ts, node.id, p, info.can_id, bytes(data))

    def _query_reply(self, info: FrameId, node: Node, data, ts: float) -> None:
        """An ESC's GET_ESC_ID reply: the query it answers (:class:`.pairing.QueryPairing`). None while queries it
        could have answered by time were open: this node id answered them all already, so a second ESC shares it
        (4.4.18-2); none with no query open (one the capture missed, or nobody's) says nothing of the id. Its delay
        when it answers one query only."""
        open_ = bool(self.queries.open(ts))
        p = self.queries.reply(ts, node.id)
        if not node.shared:
            self.clock.reply(node.id, data)
        if self.events is not None:
            self.events.reply(ts, node.id, p, info.can_id, bytes(data))
        if p.none:
            if open_:
                self._shared(node, ts)
            return
        delay = p.delay()
        if self.heard is not None and delay is not None:
            self.heard.answer(node.id, info.spec.name, delay)  # type: ignore[union-attr]

    def _heard_interval(self, st: EscStream, node: Node, gap: float) -> None:
        """Report interval ``gap`` of ``st``, judged against the interval ``node`` stated (R9), for the plots."""
        period = node.periods[st.interval]  # type: ignore[index]
        if period is not None and self.heard.mine(node.id):  # type: ignore[union-attr]
            self.heard.intervals[st.name][f"{period:g}"].append(round(gap, 9))  # type: ignore[union-attr]

    def _set_freq_answer(self, node: Node, data, ts: float) -> None:
        layout = SET_FREQ.response
        values = [field_value(data, layout.field(k)) for k in INTERVAL_FIELDS]  # type: ignore[union-attr]
        legal = all(layout.field(k).is_legal(v) for k, v in zip(INTERVAL_FIELDS, values))  # type: ignore[union-attr]
        write = field_value(data, SET_FREQ_OPTION) == SET_FREQ_WRITE
        if not legal or (write and self._suspended):
            # what an answer to an illegal write says is OBSERVE (R10-answer), and so is the answer to a write while
            # reporting is suspended, which does not take effect (R12: it may echo the request, rejected_answer=echo);
            # whether either was applied is R10's and R12's tests' (read back)
            node.periods = [None] * len(INTERVAL_FIELDS)
            node.floor = False
            node.reset += 1
            return
        periods = [round(v * cat.INTERVAL_UNIT_S, 9) for v in values]
        if periods != node.periods and not (node.event_reset == node.reset and node.event_what == "a Set Freq write"):
            node.reset += 1  # (the answer to a write: the write restarted the cadence already, R9a counts from it)
        node.periods = periods
        node.floor = True
        option = "write" if write else "read"
        node.from_read, node.before_silence = option == "read", False
        node.period_note = f"its Set/Get Freq {option} answer at {ts:.6f} says {'/'.join(map(str, values))}"

    def _comm_flag(self, node: Node, on: bool, ts: float) -> None:
        if node.comm_fault is on:
            return
        first = node.comm_fault is None
        node.comm_fault = on
        if first and not on:
            return
        if len(node.comm_events) >= KEEP * 5:
            node.comm_dropped += 1
            return
        event: dict[str, Any] = {"timestamp": ts, "event": "set" if on else "cleared"}
        if first:
            event["event"] = "set at the first MSG1 heard"
        if self._last_throttle is not None:
            event["since_last_throttle_ms"] = round((ts - self._last_throttle[0]) * 1000, 3)
        if (last := self.clock.last(node.id)) is not None:  # R8's clock: the last that carried the node's channel
            event["since_last_command_ms"] = round((ts - last) * 1000, 3)
        node.comm_events.append(event)

    def _error_frame(self, ts: float, can_id: int, data) -> None:
        self.error_frames += 1
        if len(self.error_first) < KEEP:
            self.error_first.append(ts)
        if self.error_frames == 1:
            self._observe((), ts, None, "error-frames", "error frames on the bus (bus errors: wiring, termination, a node at "
                          "another bit rate)", (quote(can_id, data, ts),))

