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
  (when no answer was heard: never closer than the shortest legal interval).

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
  boots and self-tests first).
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

Everything kept per node is bounded: counters, running sums, fixed-bin interval histograms, the first
few events and findings of each kind (the rest counted).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.frame import classify, frame_bits
from ..protocol.ids import (
    DEFAULT_ESC_NODE_ID,
    ESC_NODE_IDS,
    HOST_NODE_ID,
    MESSAGE_VENDOR_RANGE,
    SERVICE_VENDOR_RANGE,
    Kind,
    priority_name,
)
from ..protocol.requirements import strongest
from ..protocol.transfer import SINGLE_FRAME, TRANSFER_ID_MODULO, parse_tail

# ------------------------------------------------------------------------------------------ facts, derived
#: The reports whose interval Set/Get Freq sets (R9), by type id, with their interval field.
_INTERVAL_FIELDS = tuple(cat.DEFAULT_REPORT_INTERVALS)  # msg1_interval, msg2_interval, msg3_interval
REPORT_INTERVAL = {cat.BY_NAME[k.removesuffix("_interval")].type_id: i for i, k in enumerate(_INTERVAL_FIELDS)}
SHORTEST_S = cat.REPORT_INTERVAL_RANGE[0] * cat.INTERVAL_UNIT_S
LONGEST_S = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
#: A node silent for longer than this may have been power cycled: its frames before and after are not compared.
RESTART_SILENCE_S = 2 * SHORTEST_S
#: How long after a request its response may still come (the document sets no bound for services; 64 ms for
#: broadcasts): generous, so that a slow answer is never taken for an unasked one.
RESPONSE_WINDOW_S = 5.0

_SET_FREQ = cat.spec("set_freq")
_SET_FREQ_OPTION = _SET_FREQ.request.field("option")  # type: ignore[union-attr]
_SET_FREQ_WRITE = next(k for k, v in (_SET_FREQ_OPTION.codes or {}).items() if v == "write")
_SET_ID_NODE = cat.spec("set_id").request.field("node_id")  # type: ignore[union-attr]
_PSEUDO_BROADCAST = frozenset({cat.spec("set_id").type_id})  # R11: answered by every ESC, from its (new) node id
_MSG1 = cat.spec("msg1")
_STATUS = _MSG1.layouts[0].field("status")
_COMM_BIT = int(cat.Status.COMM_FAULT).bit_length() - 1
_COMM_BYTE, _COMM_MASK = _STATUS.offset + _COMM_BIT // 8, 1 << (_COMM_BIT % 8)
_THROTTLE = frozenset(s.type_id for s in cat.CATALOGUE if not s.service and s.layouts[0].codec.startswith("throttle"))
#: Periodic ESC reports (they come on their own; F7: none at 0x7D): the catalogue's "report" layouts,
#: except MSG_EXP12 (one per Get Rec, its transfer id names the record, R15).
_REPORTS = frozenset(s.type_id for s in cat.CATALOGUE if not s.service and s.layouts[0].name == "report" and s.tail_tag is None)

#: Frames that either side sends: which payload value marks the ESC's (CAN Test report, MSG Control answer).
_ESC_VALUE: dict[int, tuple[int, int, int]] = {}
for _name, _field, _value in (("can_test", "option", cat.CAN_TEST_REPORT), ("msg_control", "command", cat.MSG_CONTROL_ANSWER)):
    _f = cat.spec(_name).layouts[0].field(_field)
    _ESC_VALUE[cat.spec(_name).type_id] = (_f.offset, _f.size, _value)
_MSG_CONTROL = cat.spec("msg_control")
_GET_ESC_ID = cat.spec("get_esc_id")
_MSG_CONTROL_COMMAND = _MSG_CONTROL.layouts[0].field("command")
_CAN_TEST = cat.spec("can_test")
_CAN_TEST_OPTION = _CAN_TEST.layouts[0].field("option")
#: Host broadcasts that start, stop or switch active reporting on every ESC (4.4.1, 4.4.2).
_REPORTING_SWITCHES = {
    _MSG_CONTROL.type_id: (_MSG_CONTROL_COMMAND, {cat.MSG_CONTROL_SUSPEND, cat.MSG_CONTROL_RESUME, cat.MSG_CONTROL_RESUME_EXP}),
    _CAN_TEST.type_id: (_CAN_TEST_OPTION, {cat.CAN_TEST_ON, cat.CAN_TEST_OFF}),
}
#: ... and the values among them after which MSG1..MSG3 come back (R9a: the first within one interval)
_RESTARTS = {_MSG_CONTROL.type_id: cat.MSG_CONTROL_RESUME, _CAN_TEST.type_id: cat.CAN_TEST_OFF}

# which side sends a frame
_FOREIGN, _HOST, _ESC, _EITHER, _UNKNOWN = range(5)
_SIDE_NAMES = ("foreign", "host", "esc", "either", "unknown")

_TAIL_RULES = (("start", 0x80, "4.1.3-start"), ("end", 0x40, "4.1.3-end"))

_KEEP = 20  # findings and events kept per (node, check); the rest are counted
_HIST_BIN_S = 0.0005
_HIST_BINS = 1200  # 0 .. 600 ms, then one overflow bin
_ID_CACHE = 65536  # distinct CAN ids remembered; a capture of random ids must not grow memory without bound
_NONE: tuple = ()


def _field(data, f) -> int:
    return int.from_bytes(data[f.offset:f.offset + f.size], "little")


def quote(can_id: int, data, timestamp: float, *, remote: bool = False, own: bool = False, note: str = "") -> str:
    """One frame in candump -L style: ``(12.345678) 1F4E5201#3412E8030181C3``, with a note."""
    body = "R" if remote else bytes(data).hex().upper()
    text = f"({timestamp:.6f}) {can_id:08X}#{body}{' T' if own else ''}"
    return f"{text}  {note}" if note else text


def _ms(seconds: float) -> str:
    return f"{seconds * 1000:.3f} ms"


@dataclass(frozen=True)
class Violation:
    """A rule the bus broke (or, with strength OBSERVE, something recorded that is never a failure).

    ``rules``: requirement ids; ``check``: a short stable name of the check; ``message``: what was
    expected and what was seen; ``frames``: the offending frame(s) in candump -L style."""

    rules: tuple[str, ...]
    strength: str
    timestamp: float
    node: int | None
    check: str
    message: str
    frames: tuple[str, ...] = ()

    @property
    def fails(self) -> bool:
        return self.strength != "OBSERVE"

    def __str__(self) -> str:
        where = f"node {self.node}" if self.node is not None else "bus"
        head = f"[{' '.join(self.rules)} {self.strength}] t={self.timestamp:.6f} {where}: {self.message}"
        return "\n    ".join((head, *self.frames))

    def to_json(self) -> dict[str, Any]:
        return {"rules": list(self.rules), "strength": self.strength, "timestamp": self.timestamp, "node": self.node,
                "check": self.check, "message": self.message, "frames": list(self.frames)}


class _Tally:
    """Findings of one kind: a count and the first few."""

    __slots__ = ("count", "first")

    def __init__(self) -> None:
        self.count = 0
        self.first: list[Violation] = []

    def add(self, v: Violation) -> None:
        self.count += 1
        if len(self.first) < _KEEP:
            self.first.append(v)


class Intervals:
    """Running statistics of one stream's intervals, in bounded memory: count, mean, stdev, min,
    max and a fixed-bin histogram (0.5 ms bins up to 600 ms, then an overflow bin)."""

    __slots__ = ("n", "total", "squares", "lo", "hi", "hist")

    def __init__(self) -> None:
        self.n = 0
        self.total = self.squares = 0.0
        self.lo = math.inf
        self.hi = -math.inf
        self.hist = [0] * (_HIST_BINS + 1)

    def add(self, gap: float) -> None:
        self.n += 1
        self.total += gap
        self.squares += gap * gap
        if gap < self.lo:
            self.lo = gap
        if gap > self.hi:
            self.hi = gap
        i = int(gap / _HIST_BIN_S + 1e-6)  # a gap of exactly 20 ms goes in the 20.0 bin, not 19.5
        self.hist[i if 0 <= i < _HIST_BINS else (_HIST_BINS if i > 0 else 0)] += 1

    def quantile(self, q: float) -> float | None:
        """From the histogram: the middle of the bin holding the q-quantile (0.5 ms resolution), within [min, max]."""
        if not self.n:
            return None
        target, seen = q * self.n, 0
        for i, c in enumerate(self.hist):
            seen += c
            if seen >= target and c:
                return self.hi if i == _HIST_BINS else min(max((i + 0.5) * _HIST_BIN_S, self.lo), self.hi)
        return self.hi

    def to_json(self) -> dict[str, Any]:
        if not self.n:
            return {"count": 0}
        mean = self.total / self.n
        var = max(self.squares / self.n - mean * mean, 0.0)
        ms = lambda s: None if s is None else round(s * 1000, 4)  # noqa: E731
        return {"count": self.n, "mean_ms": ms(mean), "stdev_ms": ms(math.sqrt(var)), "min_ms": ms(self.lo),
                "p50_ms": ms(self.quantile(0.5)), "p99_ms": ms(self.quantile(0.99)), "max_ms": ms(self.hi),
                "histogram_bin_ms": _HIST_BIN_S * 1000,
                "histogram": {str(round(i * _HIST_BIN_S * 1000, 1)) if i < _HIST_BINS else "overflow": c
                              for i, c in enumerate(self.hist) if c}}


class _Node:
    __slots__ = ("id", "esc", "host", "first_ts", "last_ts", "chain", "reset", "periods", "period_note", "floor",
                 "from_read", "before_silence", "shared", "comm_fault", "comm_events", "comm_dropped", "silences", "noted",
                 "event_reset", "event_ts", "event_what", "event_old", "pending", "grace_chain", "unsure_until")

    def __init__(self, node_id: int, host: bool) -> None:
        self.id = node_id
        self.esc = False
        self.host = host
        self.first_ts: float | None = None
        self.last_ts = -math.inf
        self.chain = 0  # +1 at every silence long enough for a power cycle
        self.reset = 0  # +1 whenever this node's report cadence may restart (suspend/resume, Set Freq, ...)
        # R9a: the reset an event started after which the reports come back (a resume, CAN Test off, a Set Freq
        # write), its time and name (None: the first report's delay cannot be judged, e.g. after a power cycle)
        self.event_reset = -1
        self.event_ts: float | None = None
        self.event_what = ""
        self.event_old: list[float | None] | None = None  # a Set Freq write's: the periods before it (R9a)
        # per report: the latest an earlier event's first report may still come, when a new event came before it
        # (a resume right after a Set Freq write: the report due on the old interval may still go first)
        self.pending: list[float | None] = [None] * len(_INTERVAL_FIELDS)
        self.grace_chain = -1  # the stretch after a power cycle the host made (power_switched): R9a-gaps too
        self.periods: list[float | None] = [None] * len(_INTERVAL_FIELDS)  # seconds, as the node last said
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


class _Stream:
    """One (node, message type) of an ESC: transfer ids (F3) and intervals (R9)."""

    __slots__ = ("node", "type_id", "name", "interval", "periodic", "ts", "start", "busy_from", "tid", "data", "can_id",
                 "chain", "reset", "min_gap", "stats", "nth", "grace", "event")

    def __init__(self, node: _Node, type_id: int, name: str, periodic: bool) -> None:
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
        self.min_gap = math.inf
        self.stats = Intervals()
        self.nth = 0  # reports in this stretch (since the chain or the reset changed)
        self.grace = False  # the stretch began at an R9a event: its first two gaps are not judged
        self.event = -1  # the node's R9a event (event_reset) whose first report this stream has had


class _Id:
    """What one CAN id is, worked out once (the hot path looks it up)."""

    __slots__ = ("can_id", "kind", "type_id", "source", "dest", "spec", "side", "node", "label", "count", "priority",
                 "prio_ok", "bad_source", "report", "stream_key", "periodic", "has_tail")

    def __init__(self, can_id: int, node: _Node) -> None:
        kind, type_id, source, dest, spec = classify(can_id)
        self.can_id, self.kind, self.type_id, self.source, self.dest, self.spec = can_id, kind, type_id, source, dest, spec
        self.node = node
        self.count = 0
        self.priority = (can_id >> 24) & 0x1F
        vendor = SERVICE_VENDOR_RANGE if kind is not Kind.MESSAGE else MESSAGE_VENDOR_RANGE
        if spec is None:
            self.side = _UNKNOWN if type_id in vendor else _FOREIGN
            what = "service " + kind.label if kind is not Kind.MESSAGE else "message"
            self.label = f"{'unknown' if self.side == _UNKNOWN else 'foreign'} {what} {type_id}"
        elif kind is Kind.MESSAGE:
            senders = {lay.sender for lay in spec.layouts}
            self.side = _ESC if senders == {"esc"} else _HOST if senders == {"host"} else _EITHER
            self.label = spec.name
        else:
            self.side = _HOST if kind is Kind.REQUEST else _ESC
            self.label = f"{spec.name} {kind.label}"
        expected = spec.priority if spec is not None else None
        self.prio_ok = None if expected is None else self.priority == expected
        self.bad_source = source not in ESC_NODE_IDS  # 0 (the host's / unknown) or reserved (F7)
        self.report = type_id in _REPORTS and kind is Kind.MESSAGE
        self.has_tail = spec is None or spec.has_tail
        # F3 counts per message type; a response carries its request's id (F4), MSG_EXP12 names its record (R15)
        counted = kind is Kind.MESSAGE and spec is not None and spec.has_tail and spec.tail_tag is None
        self.stream_key = (source, type_id) if counted else None
        self.periodic = self.report or type_id == _CAN_TEST.type_id


class BusRules:
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

    def __init__(self, *, tolerance: float = 0.0, bitrate: int = cat.DEFAULT_BITRATE, complete: bool = False,
                 host_nodes=(HOST_NODE_ID,), jitter: float = 0.0, power_known: bool = False) -> None:
        self.tolerance = max(float(tolerance), 1e-9)
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
        self._nodes: dict[int, _Node] = {}
        self._ids: dict[int, _Id] = {}
        self._streams: dict[tuple[int, int], _Stream] = {}
        self._requests: dict[tuple, deque] = {}
        self._tallies: dict[tuple[int | None, str], _Tally] = {}
        self._observed: dict[tuple[int | None, str], _Tally] = {}
        self._by_rule: dict[str, int] = {}
        self._last_throttle: tuple[float, str, int] | None = None
        self._answered: set[int] = set()  # nodes that answered the last Set ID / GET_ESC_ID (a second answer: shared id)
        self._set_id_ts = -math.inf  # the last Set ID: a node id not heard since may have been left by its ESC
        self._bus_end = -math.inf
        self._busy_from = -math.inf
        self.set_bitrate(bitrate)

    # ------------------------------------------------------------------------------------- setup
    def set_bitrate(self, bitrate: int) -> None:
        """The bus's bit rate from now on (the host reopened at another rate after Set Baud)."""
        self.bitrate = int(bitrate)
        self._dur = [frame_bits(n) / self.bitrate for n in range(9)]
        # a real frame is up to ~20 % longer than its unstuffed length: a frame that starts within that of
        # the previous one's end may have waited for it
        self._slack = [0.25 * d + self.tolerance for d in self._dur]
        self._bus_end = self._busy_from = -math.inf

    def _node(self, node_id: int) -> _Node:
        node = self._nodes.get(node_id)
        if node is None:
            node = self._nodes[node_id] = _Node(node_id, node_id in self._host_nodes)
        return node

    def _new_id(self, can_id: int) -> _Id:
        info = _Id(can_id, self._node(can_id & 0x7F))
        if len(self._ids) < _ID_CACHE:
            self._ids[can_id] = info
        return info

    # ------------------------------------------------------------------------------------- findings
    def _violation(self, out: list | None, rules: tuple[str, ...], ts: float, node: int | None, check: str, message: str,
                   frames: tuple[str, ...]) -> list:
        v = Violation(rules, strongest(rules), ts, node, check, message, frames)
        tally = self._tallies.get((node, check))
        if tally is None:
            tally = self._tallies[(node, check)] = _Tally()
        tally.add(v)
        for rid in rules:
            self._by_rule[rid] = self._by_rule.get(rid, 0) + 1
        if out is None:
            out = []
        out.append(v)
        return out

    def _observe(self, rules: tuple[str, ...], ts: float, node: int | None, check: str, message: str,
                 frames: tuple[str, ...] = ()) -> None:
        tally = self._observed.get((node, check))
        if tally is None:
            tally = self._observed[(node, check)] = _Tally()
        tally.add(Violation(rules, "OBSERVE", ts, node, check, message, frames))

    @property
    def violations(self) -> int:
        return sum(t.count for t in self._tallies.values())

    # ------------------------------------------------------------------------------------- the hot path
    def feed(self, can_id: int, data, ts: float, extended: bool = True, remote: bool = False, error: bool = False,
             own: bool = False) -> list[Violation] | tuple:
        """One frame as it was on the bus: its timestamp is when it ended (SocketCAN, the simulated lane).
        ``own``: the host's own frame (its echo). Returns the violations it shows (usually none)."""
        self.frames += 1
        if ts < self.last_ts:
            self._time_jump(ts)
        self.last_ts = ts
        if self.first_ts is None:
            self.first_ts = ts
        n = len(data)
        dur = self._dur[0 if remote else (n if n < 9 else 8)]
        start = ts - dur
        if start > self._bus_end + self._slack[n if n < 9 else 8]:
            self._busy_from = start  # the bus was idle before this frame: it did not wait
        busy_from = self._busy_from
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
        if node.first_ts is None:
            node.first_ts = ts
        if own:
            if not node.host:
                node.host = True
            if side == _HOST or side == _EITHER:
                self._host_frame(info, data, ts)
            return _NONE
        if side == _ESC:
            if not node.esc:
                node.esc = True
            return self._esc_frame(info, node, data, ts, start, busy_from, remote)
        if side == _HOST:
            if node.esc and not node.host:
                return self._host_frame_from_esc(info, data, ts, remote)
            if not node.host:
                node.host = True
            self._host_frame(info, data, ts)
            return _NONE
        if side == _EITHER:
            return self._either_frame(info, node, data, ts, start, busy_from, remote)
        if side == _FOREIGN and node.esc and (info.type_id, 0) not in node.noted:
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
    def _either_frame(self, info: _Id, node: _Node, data, ts: float, start: float, busy_from: float, remote: bool):
        esc_value = _ESC_VALUE.get(info.type_id)
        spec = info.spec
        if esc_value is not None:
            off, size, value = esc_value
            looks_esc = len(data) > off + size and int.from_bytes(data[off:off + size], "little") == value
        else:  # 20013: the query and the reply differ in length
            layout = spec.message_layout(len(data) - 1) if data else None
            looks_esc = layout is not None and layout.sender == "esc"
            if looks_esc and info.source not in self._host_nodes and not node.host:
                node.esc = True
                self._answer(node, ts)
        if node.esc and not node.host:
            return self._esc_frame(info, node, data, ts, start, busy_from, remote)
        if not looks_esc:
            self._host_frame(info, data, ts)  # a host's command (from a foreign node it at most restarts cadence)
        return _NONE

    def _esc_frame(self, info: _Id, node: _Node, data, ts: float, start: float, busy_from: float, remote: bool):
        out = None
        if ts - node.last_ts > RESTART_SILENCE_S + self.tolerance:
            self._silence(node, ts)
        node.last_ts = ts
        if remote:
            return self._violation(out, ("F1",), ts, node.id, "frame-layout",
                                   f"remote frame with {info.label}'s id: all data goes in data frames (4.1.2)",
                                   (quote(info.can_id, data, ts, remote=True),))
        if info.bad_source:
            what = "the host's / unknown node id 0" if info.source == 0 else f"the reserved node id {info.source:#04x}"
            return self._violation(out, ("F7", "4.1.2-N2"), ts, node.id, "reserved-node",
                                   f"{info.label} from {what}: an ESC's node id is 1..0x7D",
                                   (quote(info.can_id, data, ts, note=info.label),))
        if info.report and info.source == DEFAULT_ESC_NODE_ID:
            out = self._violation(out, ("F7",), ts, node.id, "default-node-reports",
                                  f"{info.label} from the factory default node id 0x7D: at 0x7D an ESC reports nothing on its own",
                                  (quote(info.can_id, data, ts, note=info.label),))
        if info.prio_ok is False:
            out = self._violation(out, ("F5",), ts, node.id, "priority",
                                  f"{info.label} at priority {info.priority} ({priority_name(info.priority)}), the table's "
                                  f"is {int(info.spec.priority)} ({priority_name(info.spec.priority)})",
                                  (quote(info.can_id, data, ts, note=info.label),))
        elif info.prio_ok is None and info.spec is not None and (info.type_id, 1) not in node.noted:
            node.noted.add((info.type_id, 1))
            self._observe(("F5-unlisted",), ts, node.id, "priority-unlisted",
                          f"{info.label} at priority {info.priority} ({priority_name(info.priority)}); the table lists none",
                          (quote(info.can_id, data, ts),))
        tid = None
        if info.has_tail:
            if not data:
                return self._violation(out, ("F2",), ts, node.id, "tail-byte", f"{info.label} with no data: no tail byte",
                                       (quote(info.can_id, data, ts),))
            tail = data[-1]
            tid = tail & 0x1F
            if tail & 0xE0 != SINGLE_FRAME:
                out = self._tail(out, info, node, data, ts, tail)
        if info.kind is Kind.RESPONSE:
            return self._response(out, info, node, data, ts, tid)
        if info.type_id == _MSG1.type_id and len(data) > _COMM_BYTE:
            self._comm_flag(node, bool(data[_COMM_BYTE] & _COMM_MASK), ts)
        if info.stream_key is not None and tid is not None:
            st = self._streams.get(info.stream_key)
            if st is None:
                st = self._streams[info.stream_key] = _Stream(node, info.type_id, info.label, info.periodic)
            out = self._stream(out, st, info, node, data, ts, start, busy_from, tid)
        return out or _NONE

    def _tail(self, out, info: _Id, node: _Node, data, ts: float, tail: int):
        t = parse_tail(tail)
        wrong = [f"{name}=0" for name, bit, _ in _TAIL_RULES if not tail & bit] + (["toggle=1"] if t.toggle else [])
        rules = ("F2",) + tuple(rid for _, bit, rid in _TAIL_RULES if not tail & bit) + (("4.1.3-toggle",) if t.toggle else ())
        return self._violation(out, rules, ts, node.id, "tail-byte",
                               f"{info.label}: tail byte 0x{tail:02X} has {', '.join(wrong)}; a single-frame transfer has "
                               "start=1 end=1 toggle=0", (quote(info.can_id, data, ts, note=info.label),))

    def _host_frame_from_esc(self, info: _Id, data, ts: float, remote: bool):
        """A host-side frame from a node known as an ESC: a request means a response sent with the request bit set."""
        if info.kind is not Kind.REQUEST:
            return _NONE
        return self._violation(None, ("F1", "F4"), ts, info.source, "frame-layout",
                               f"{info.label} from node {info.source}, an ESC, to node {info.dest}: an ESC's service frames "
                               "answer requests (request bit 0)", (quote(info.can_id, data, ts, note=info.label),))

    # ------------------------------------------------------------------------------------- F3 and R9
    def _stream(self, out, st: _Stream, info: _Id, node: _Node, data, ts: float, start: float, busy_from: float, tid: int):
        fresh = st.ts is None or st.chain != node.chain or st.reset != node.reset
        if st.ts is not None and st.chain == node.chain and not node.shared and ts > node.unsure_until:
            gap = start - st.start
            advance = (tid - st.tid) % TRANSFER_ID_MODULO
            period = None
            if st.interval is not None:
                period = node.periods[st.interval]
            if period is None and st.periodic and st.min_gap < math.inf:
                period = st.min_gap
            if advance != 1:
                out = self._transfer_ids(out, st, info, node, data, ts, gap, advance, period)
            if st.reset == node.reset:
                st.nth += 1
                st.stats.add(gap)
                if st.nth > 2 or not st.grace:  # R9a-gaps: up to the second report after a restart, not judged
                    if gap < st.min_gap and gap > 0:
                        st.min_gap = gap
                    if st.interval is not None:
                        out = self._cadence(out, st, info, node, data, ts, start, busy_from)
        if fresh:
            st.nth = 1
            first = node.reset == node.event_reset and st.event != node.event_reset  # the first since an R9a event
            st.grace = first or (st.chain != node.chain and node.chain == node.grace_chain)
            if first:
                st.event = node.event_reset
                if st.interval is not None and node.event_ts is not None:
                    out = self._first_report(out, st, info, node, data, ts, start, busy_from)
        st.ts, st.start, st.busy_from, st.tid, st.data, st.can_id = ts, start, busy_from, tid, data, info.can_id
        st.chain, st.reset = node.chain, node.reset
        return out

    def _pair(self, st: _Stream, info: _Id, data, ts: float) -> tuple[str, str]:
        return (quote(st.can_id, st.data, st.ts, note=f"{st.name} tid {st.tid}"),  # type: ignore[arg-type]
                quote(info.can_id, data, ts, note=f"{st.name} tid {data[-1] & 0x1F}"))

    def _transfer_ids(self, out, st: _Stream, info: _Id, node: _Node, data, ts: float, gap: float, advance: int,
                      period: float | None):
        expected = (st.tid + 1) % TRANSFER_ID_MODULO
        if advance and not self.complete:
            if period is None or not st.periodic:
                return out  # a frame of an irregular stream may be missing from the capture: cannot tell
            k = round(gap / period)
            if k >= 2 and abs(gap - k * period) <= 0.25 * period + self.tolerance and advance == k % TRANSFER_ID_MODULO:
                self._observe(("F3",), ts, node.id, "lost-frames",
                              f"{st.name}: transfer id {st.tid} then {st.tid + advance & 0x1F} after {_ms(gap)}: "
                              f"{k - 1} frame(s) missing from the capture", self._pair(st, info, data, ts))
                return out
        return self._violation(out, ("F3", "4.1.3-tid"), ts, node.id, "transfer-id",
                               f"{st.name}: transfer id {data[-1] & 0x1F} after {st.tid} ({_ms(gap)} earlier), expected {expected}",
                               self._pair(st, info, data, ts))

    def _cadence(self, out, st: _Stream, info: _Id, node: _Node, data, ts: float, start: float, busy_from: float):
        """R9 between two reports of one stretch (no restart, no reset between them). Without a period the
        node stated, only a report closer than the shortest legal interval is judged. The DUT's jitter
        allowance widens the interval; the bench's error (``tolerance``) is on top of it."""
        tol = self.tolerance + self.jitter
        # due times lie in [start of the busy stretch, start]: the due-to-due gap lies in [lo, hi]
        lo, hi = busy_from - st.start, start - st.busy_from
        period = node.periods[st.interval]  # type: ignore[index]
        if period is None:
            if not node.floor or hi >= SHORTEST_S - tol:
                return out
            rules: tuple[str, ...] = ("R9",)
            expected = f"never closer than the shortest legal interval, {_ms(SHORTEST_S)}"
        elif hi < period - tol:
            rules = ("R9",) + self._period_rules(node)
            expected = f"expected {_ms(period)} +- {_ms(tol)} ({node.period_note})"
        elif lo > period + tol:
            k_lo, k_hi = math.ceil((lo - tol) / period), math.floor((hi + tol) / period)
            if k_hi >= max(k_lo, 2) and not self.complete:
                self._observe(("R9",), ts, node.id, "lost-frames",
                              f"{st.name} {_ms(start - st.start)} after the previous one: {k_hi - 1} report(s) at "
                              f"{_ms(period)} missing from the capture", self._pair(st, info, data, ts))
                return out
            return self._violation(out, ("R9",) + self._period_rules(node), ts, node.id, "report-interval",
                                   f"{st.name} {_ms(start - st.start)} after the previous one (bus queueing allows no less "
                                   f"than {_ms(lo)}), expected {_ms(period)} +- {_ms(tol)} ({node.period_note})",
                                   self._pair(st, info, data, ts))
        else:
            return out
        return self._violation(out, rules, ts, node.id, "report-interval",
                               f"{st.name} {_ms(start - st.start)} after the previous one (bus queueing allows up to "
                               f"{_ms(hi)}), {expected}", self._pair(st, info, data, ts))

    def _first_report(self, out, st: _Stream, info: _Id, node: _Node, data, ts: float, start: float, busy_from: float):
        """R9a: the first report of a type after a resume / CAN Test off comes within one interval plus a slack of
        max(3 ms, a quarter interval) of it; after a Set Freq write, within the longer of its old and new interval
        plus that slack; and never sooner than an earlier event's first report that had not come yet could. Judged
        on the earliest it can have been due (bus queueing), tolerance and the DUT's report-interval jitter
        allowance on top."""
        period, which = self._restart_period(node, st.interval)  # type: ignore[arg-type]
        if period is None:
            return out
        limit = cat.restart_limit_s(period)
        carried = node.pending[st.interval]  # type: ignore[index]
        if carried is not None and carried - node.event_ts > limit:  # type: ignore[operator]
            limit, which = carried - node.event_ts, "what an earlier restart still allowed"  # type: ignore[operator]
        tol = self.tolerance + self.jitter
        since = busy_from - node.event_ts  # type: ignore[operator]
        if since <= limit + tol:
            return out
        if not self.power_known and since > limit + period + RESTART_SILENCE_S + self.tolerance:
            self._observe(("R9a",), ts, node.id, "first-report-unjudged",
                          f"the first {st.name} {_ms(start - node.event_ts)} after {node.event_what}: not judged, the node "  # type: ignore[operator]
                          "may have been power cycled meanwhile (a capture does not show it)", (quote(info.can_id, data, ts),))
            return out
        return self._violation(out, ("R9a",), ts, node.id, "first-report",
                               f"the first {st.name} {_ms(start - node.event_ts)} after {node.event_what} "  # type: ignore[operator]
                               f"(bus queueing allows no less than {_ms(since)}), expected within {which} plus a slack, "
                               f"{_ms(limit)} +- {_ms(tol)} ({node.period_note})",
                               (quote(info.can_id, data, ts, note=st.name),))

    @staticmethod
    def _restart_period(node: _Node, i: int) -> tuple[float | None, str]:
        """R9a: the interval the first report of report ``i`` after the node's event counts (None: unknown), and
        which: one interval, or after a Set Freq write the longer of its old and new one (the longest legal one
        when the node had stated none)."""
        period = node.periods[i]
        if period is None or node.event_old is None:
            return period, "one interval"
        old = node.event_old[i]
        return max(period, LONGEST_S if old is None else old), "the longer of its old and new interval"

    def _event(self, node: _Node, ts: float, what: str, old: list[float | None] | None = None) -> None:
        """An R9a event for ``node``: its reports (come back and) count from ``ts``; ``old``: a Set Freq write's
        periods before it. A report whose first since the previous event has not come keeps that event's limit."""
        if node.event_ts is None:
            node.pending = [None] * len(_INTERVAL_FIELDS)
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

    def power_switched(self, ts: float) -> None:
        """The host switched the DUT's power (off or on) at ``ts``: a pending R9a event is void (the first
        report after a power-up is the boot's, not the command's); the next stretch has R9a-gaps grace."""
        for node in self._nodes.values():
            node.event_ts = None
            node.grace_chain = node.chain + 1  # the stretch after the silence it makes

    @staticmethod
    def _period_rules(node: _Node) -> tuple[str, ...]:
        """The other clause an interval mismatch may break: the read answer the period came from
        (4.4.22-2), or the persistence of a period stated before the node went silent (R13)."""
        return (("4.4.22-2",) if node.from_read else ()) + (("R13",) if node.before_silence else ())

    # ------------------------------------------------------------------------------------- state the traffic sets
    def _silence(self, node: _Node, ts: float) -> None:
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

    def _reset_all(self) -> None:
        for node in self._nodes.values():
            node.reset += 1

    def _host_frame(self, info: _Id, data, ts: float) -> None:
        type_id = info.type_id
        if info.kind is Kind.MESSAGE:
            if type_id in _THROTTLE:
                self._last_throttle = (ts, info.label, type_id)
                return
            if type_id == _GET_ESC_ID.type_id:
                self._answered.clear()  # a query: every ESC answers once
            switch = _REPORTING_SWITCHES.get(type_id)
            if switch is not None and len(data) > switch[0].offset + switch[0].size and _field(data, switch[0]) in switch[1]:
                value = _field(data, switch[0])
                if _RESTARTS.get(type_id) == value:  # reporting comes back on every ESC (R9a)
                    what = f"{info.label} {value:#x}"
                    for node in self._nodes.values():
                        self._event(node, ts, what)
                else:
                    self._reset_all()  # reporting stops or switches on every ESC: cadence restarts
            return
        if info.kind is not Kind.REQUEST or not data:
            return
        tid = data[-1] & 0x1F
        if type_id in _PSEUDO_BROADCAST:
            key = (info.source, None, type_id)
            self._answered.clear()
            for node in self._nodes.values():  # may re-address any ESC: nobody's intervals are known now
                node.periods = [None] * len(_INTERVAL_FIELDS)
                node.reset += 1
                node.shared = False  # ... nor whether two of them share an id
            self._set_id_shared(data, ts)
        else:
            key = (info.source, info.dest, type_id)
            if type_id == _SET_FREQ.type_id and _field(data, _SET_FREQ_OPTION) == _SET_FREQ_WRITE:
                dest = self._node(info.dest)  # type: ignore[arg-type]
                # the new intervals count from the write (its answer tells them), the old ones as the node last said
                self._event(dest, ts, "a Set Freq write", list(dest.periods))
                dest.periods = [None] * len(_INTERVAL_FIELDS)  # unknown until that answer: it may come after reports
        q = self._requests.get(key)
        if q is None:
            if len(self._requests) > 4096:
                self._requests.clear()
            q = self._requests[key] = deque(maxlen=32)
        q.append((tid, ts))

    def _response(self, out, info: _Id, node: _Node, data, ts: float, tid: int | None):
        service = info.type_id
        requester = info.dest
        key = (requester, None if service in _PSEUDO_BROADCAST else info.source, service)
        asked = [t for t, when in self._requests.get(key, ()) if 0 <= ts - when <= RESPONSE_WINDOW_S]
        if service in _PSEUDO_BROADCAST:
            self._answer(node, ts)
        if tid in asked:
            if service == _SET_FREQ.type_id:
                self._set_freq_answer(node, data, ts)
            return out or _NONE
        frames = (quote(info.can_id, data, ts, note=info.label),)
        if asked:
            return self._violation(out, ("F4",), ts, node.id, "response-match",
                                   f"{info.label} to node {requester} with transfer id {tid}; node {requester}'s requests "
                                   f"to node {info.source} in the last {RESPONSE_WINDOW_S:g} s had transfer ids "
                                   f"{sorted(set(asked))} (a response keeps its request's)", frames)
        others = sorted({k[0] for k, q in self._requests.items() if k[1:] == key[1:] and k[0] != requester
                         and any(0 <= ts - when <= RESPONSE_WINDOW_S for _, when in q)})
        text = (f"{info.label} to node {requester}, but node {requester} sent no {info.spec.title} request to node "  # type: ignore[union-attr]
                f"{info.source} in the last {RESPONSE_WINDOW_S:g} s" + (f" (node(s) {others} did)" if others else ""))
        if self.complete:  # every frame since the bus started was heard: the request was not missed
            return self._violation(out, ("F4",), ts, node.id, "response-match", text + ": a response goes to the requester",
                                   frames)
        self._observe(("F4",), ts, node.id, "response-unmatched", text + " (the capture may have missed it)", frames)
        return out or _NONE

    def _set_id_shared(self, data, ts: float) -> None:
        """Set ID while more than one ESC reports: any of them may take the id (R11: it ignores the destination), and
        their answers from it, alike and in the same slot, may reach the bus as one frame; so the id is taken as
        shared (4.4.18-2): its reports are not compared with one another. An ESC reports if heard lately and since
        the Set ID before (a node id an ESC left then is heard no more)."""
        since = max(self._set_id_ts, ts - LONGEST_S - RESTART_SILENCE_S)
        self._set_id_ts = ts
        escs = sum(1 for n in self._nodes.values() if n.esc and n.last_ts > since)
        if len(data) <= _SET_ID_NODE.offset + _SET_ID_NODE.size:
            return
        if escs == 0:  # none heard: several may take it, and answer up to 64 ms later (their answers tell then)
            self._node(_field(data, _SET_ID_NODE)).unsure_until = ts + 2 * cat.ANSWER_DELAY_MAX_S
        if escs > 1:
            node = self._node(_field(data, _SET_ID_NODE))
            node.shared = True
            self._observe(("4.4.18-2",), ts, node.id, "shared-node-id",
                          f"Set ID {node.id} while {escs} ESCs report: any of them may take it, their reports from it are "
                          "not compared with one another")

    def _answer(self, node: _Node, ts: float) -> None:
        """An answer to a broadcast every ESC answers once (Set ID, GET_ESC_ID): a second one from the same
        node id means two ESCs share it (Set ID sets every ESC on the bus, 4.4.18-2)."""
        if node.id not in self._answered:
            self._answered.add(node.id)
        elif not node.shared:
            node.shared = True
            self._observe(("4.4.18-2",), ts, node.id, "shared-node-id",
                          f"two ESCs answer from node id {node.id}: its reports are not compared with one another")

    def _set_freq_answer(self, node: _Node, data, ts: float) -> None:
        layout = _SET_FREQ.response
        values = [_field(data, layout.field(k)) for k in _INTERVAL_FIELDS]  # type: ignore[union-attr]
        legal = all(layout.field(k).is_legal(v) for k, v in zip(_INTERVAL_FIELDS, values))  # type: ignore[union-attr]
        if not legal:
            # what an answer to an illegal write says is OBSERVE (R10-answer); whether it was applied is R10's test
            node.periods = [None] * len(_INTERVAL_FIELDS)
            node.floor = False
            node.reset += 1
            return
        periods = [round(v * cat.INTERVAL_UNIT_S, 9) for v in values]
        if periods != node.periods and not (node.event_reset == node.reset and node.event_what == "a Set Freq write"):
            node.reset += 1  # (the answer to a write: the write restarted the cadence already, R9a counts from it)
        node.periods = periods
        node.floor = True
        option = "write" if _field(data, _SET_FREQ_OPTION) == _SET_FREQ_WRITE else "read"
        node.from_read, node.before_silence = option == "read", False
        node.period_note = f"its Set/Get Freq {option} answer at {ts:.6f} says {'/'.join(map(str, values))}"

    def _comm_flag(self, node: _Node, on: bool, ts: float) -> None:
        if node.comm_fault is on:
            return
        first = node.comm_fault is None
        node.comm_fault = on
        if first and not on:
            return
        if len(node.comm_events) >= _KEEP * 5:
            node.comm_dropped += 1
            return
        event: dict[str, Any] = {"timestamp": ts, "event": "set" if on else "cleared"}
        if first:
            event["event"] = "set at the first MSG1 heard"
        if self._last_throttle is not None:
            event["since_last_throttle_ms"] = round((ts - self._last_throttle[0]) * 1000, 3)
        node.comm_events.append(event)

    def _error_frame(self, ts: float, can_id: int, data) -> None:
        self.error_frames += 1
        if len(self.error_first) < _KEEP:
            self.error_first.append(ts)
        if self.error_frames == 1:
            self._observe((), ts, None, "error-frames", "error frames on the bus (bus errors: wiring, termination, a node at "
                          "another bit rate)", (quote(can_id, data, ts),))

    # ------------------------------------------------------------------------------------- the summary
    def findings(self, *, observations: bool = False) -> list[Violation]:
        """The first few findings of each kind, in time order."""
        tallies = self._observed if observations else self._tallies
        return sorted((v for t in tallies.values() for v in t.first), key=lambda v: v.timestamp)

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
            "violations": {"count": self.violations, "by_rule": dict(sorted(self._by_rule.items())),
                           "first": [v.to_json() for v in self.findings()]},
            "observations": [v.to_json() for v in self.findings(observations=True)],
            "nodes": nodes,
        }
