"""The soak's monitor, sans-IO: every frame of the run in (with its lane timestamp), read once by the bus reader (one
:class:`~ckesc.evidence.rules.BusRules`, as the suite's live rules and check-log read the bus: the host's own frames,
the played foreign traffic, the DUT's), whose events the watches take (:class:`Sinks`); findings out.

The reader keeps the state of the stateful rules (which query a reply answers, a reset's signs, each report's
restarts, the last throttle command) and tells it as events (:class:`~ckesc.evidence.events.ReaderEvents`); each watch
owns one property (R19) and keeps only what the soak alone needs of them, judging with the reader's word or its rule's
judgement in :mod:`ckesc.protocol.judgements`:

* :class:`~.reset_watch.ResetWatch` - no reset: the reader's reset signs (241's power-up count and run time, a
  report gap with a transfer id restart; :class:`~ckesc.evidence.resets.ResetSigns`), one finding per reset;
* :class:`~.interval_watch.IntervalWatch` - R9 over every minute, per report (MSG1..3): the mean of that minute's
  gaps, less those R9a leaves unjudged after a restart the reader told (:func:`~ckesc.protocol.judgements.r9_mean`);
  the trend is one mean per minute and report;
* :class:`~.comm_watch.CommFlagWatch` - the comm flag (MSG1's status, R8) set only when the stream stops
  (:func:`~ckesc.protocol.judgements.r8_flag_due`, from the last command the reader heard carry the ESC's channel);
* :class:`~.watches.AnswerWatch` - GET_ESC_ID's answers in the node's slot (R2) and within 64 ms (4.4.3-4), their
  delays as a fixed-bin histogram; which query a reply answers is the reader's (another node's query, a flight
  controller's on the bus, is answered too: its answer is neither the host's nor one to no query);
* :class:`~.frame_watches.SettingsWatch` - 242's answers unchanged (:func:`~ckesc.protocol.judgements.r13_read_back`);
* :class:`~.frame_watches.UnexpectedWatch` - frames the ESC should not send: one that does not decode, or a frame
  type normal reporting never sends and the player never asked for.

Memory does not grow with the run's length: the reader's is bounded (counters, fixed-bin histograms, bounded caches),
and so are the watches' (counters, fixed-bin histograms, the last value of each counter), a ring of recent frames
(:data:`~.watch.RING_FRAMES`), at most :data:`~.watch.MAX_FINDINGS` findings kept whole (the rest counted), and the
R9 trend, one value per minute and report (1440 a day: the one thing that grows, as the trend plot needs it).
"""

from __future__ import annotations

from collections import deque
from typing import Any

from ..evidence.events import ReaderEvents
from ..evidence.rules import BusRules
from ..protocol.errors import DecodeError
from ..protocol.frame import Decoder, Frame, classify
from ..protocol.histogram import Histogram
from ..protocol.ids import HOST_NODE_ID, Kind
from .comm_watch import CommFlagWatch
from .frame_watches import SettingsWatch, UnexpectedWatch
from .interval_watch import IntervalWatch
from .reset_watch import ResetWatch
from .watch import (
    AFTER_FRAMES,
    MAX_FINDINGS,
    MAX_FINDINGS_PER_WATCH,
    MAX_IDS,
    REPORTS,
    RING_FRAMES,
    SoakFinding,
    Watch,
    WatchConfig,
)
from .watches import AnswerWatch

#: the host's send times kept per frame (id and bytes) until its echo comes back (the stream's repeat every 32 transfers)
SENT_KEPT = 8
#: how late the bench stamped the host's own frames (their echo's time minus the host's send): bins of a tenth of a
#: millisecond up to 50 ms, then one overflow bin
LAG_BIN_S = 0.0001
LAG_BINS = 500


class Monitor:
    """Every frame of the run in (:meth:`feed`), in order, the DUT's and the host's own (their echo), with lane
    timestamps; the watches fed; findings kept (:attr:`findings`, the first :data:`MAX_FINDINGS`) and counted."""

    def __init__(self, cfg: WatchConfig, t0: float) -> None:
        self.cfg = cfg
        self.t0 = t0
        self.decoder = Decoder(nibble_order=cfg.nibble_order)
        self.ring: deque[tuple[float, int, bytes]] = deque(maxlen=RING_FRAMES)
        self._ring_append = self.ring.append  # (looked up once: every frame goes to the ring)
        self.findings: list[SoakFinding] = []
        self.dropped = 0  # findings counted but not kept
        self._kept: dict[str, int] = {}  # findings kept per watch
        self._open: list[tuple[SoakFinding, int]] = []  # findings still collecting frames after them
        self.frames = 0
        self.dut_frames = 0
        self.own_frames = 0
        self.other_frames = 0
        self.last_t = t0
        self._node, self._host = cfg.node_id, cfg.host_node
        self._frames: dict[tuple[int, bytes], Frame] = {}
        self._sent: dict[tuple[int, bytes], deque[float]] = {}  # the host's send times of frames not echoed yet
        #: how late the bench stamped the host's own frames after the host sent them (:meth:`sent`)
        self.bench_lag = Histogram(LAG_BIN_S, LAG_BINS)
        self.resets = ResetWatch(self)
        self.intervals = IntervalWatch(self)
        self.comm = CommFlagWatch(self)
        self.answers = AnswerWatch(self)
        self.settings = SettingsWatch(self)
        self.unexpected = UnexpectedWatch(self)
        self.watches: tuple[Watch, ...] = (self.resets, self.intervals, self.comm, self.answers, self.settings,
                                           self.unexpected)
        #: the bus reader, fed every frame: the bench's stated error (its own frames' too), the DUT's declared jitter,
        #: power switched by nobody during the run (a reset is one), the intervals the DUT stated at the start
        self.rules = BusRules(tolerance=cfg.error, own_error=cfg.own_error, bitrate=cfg.bitrate, jitter=cfg.jitter,
                              host_nodes=(HOST_NODE_ID, cfg.host_node), power_known=True)
        self.rules.stated(cfg.node_id, dict(cfg.intervals), "its Set/Get Freq settings read at the soak's start")
        self.rules.events = Sinks(self)

    # ------------------------------------------------------------------ findings
    def found(self, watch: Watch, t: float, message: str, rules: tuple[str, ...]) -> None:
        kept = self._kept.get(watch.name, 0)
        if len(self.findings) >= MAX_FINDINGS or kept >= MAX_FINDINGS_PER_WATCH:
            self.dropped += 1
            return
        self._kept[watch.name] = kept + 1
        f = SoakFinding(t - self.t0, watch.name, rules, message, [self._line(*r) for r in self.ring])
        self.findings.append(f)
        self._open.append((f, AFTER_FRAMES))

    def _line(self, t: float, can_id: int, data: bytes) -> str:
        return f"{t - self.t0:12.6f}  {can_id:08X}#{data.hex().upper()}"

    @property
    def count(self) -> int:
        return len(self.findings) + self.dropped

    @property
    def open_findings(self) -> int:
        """How many findings (the last kept ones) are still collecting the frames after them."""
        return len(self._open)

    @property
    def settled(self) -> bool:
        """No finding is still collecting the frames after it."""
        return not self._open

    # ------------------------------------------------------------------ frames
    def sent(self, can_id: int, data: bytes, t: float) -> None:
        """The host sent this frame at ``t`` (lane time, the host's clock): its echo's stamp says how late the bench
        stamped it (a lane without echo hands the frame out stamped at the send: no lag)."""
        key = (can_id, bytes(data))
        q = self._sent.get(key)
        if q is None:
            if len(self._sent) > MAX_IDS:
                self._sent.clear()
            q = self._sent[key] = deque(maxlen=SENT_KEPT)
        q.append(t)

    def feed(self, msg: Any) -> None:
        """One frame heard (a ``can.Message`` or anything with its attributes): ``timestamp``, ``arbitration_id``,
        ``data``, ``is_extended_id`` (and the error / remote flags). The reader reads it (its events go to the
        watches); the monitor keeps the frames around findings, the bench's stamp lag and what the reader does not
        judge (a frame that does not decode, 242's settings, frames normal reporting never sends). What the CAN id is
        (whose, which kind) is the reader's (:meth:`~ckesc.evidence.tracker.Tracker.frame_id`): classified once."""
        t = msg.timestamp
        can_id = msg.arbitration_id
        data = msg.data
        if data.__class__ is not bytes:  # (a Heard's data is bytes already: no copy per frame)
            data = bytes(data)
        self.frames += 1
        self.last_t = t
        answers = self.answers
        if answers.pending is not None:
            answers.tick(t)
        if self._open:
            self._after(t, can_id, data)
        self._ring_append((t, can_id, data))
        extended = getattr(msg, "is_extended_id", True)
        error = getattr(msg, "is_error_frame", False)
        rules = self.rules
        if extended and not error:
            info = rules.frame_id(can_id)
            kind, source = info.kind, info.source
            own = source == self._host and info.spec is not None
        elif extended:  # an error frame (the reader takes none of its id)
            kind, _, source, _, spec = classify(can_id)
            own = source == self._host and spec is not None
        else:
            kind = source = None
            own = False
        if own:
            self.own_frames += 1
            if self._sent and (q := self._sent.get((can_id, data))):
                lag = max(t - q.popleft(), 0.0)
                self.bench_lag.add(lag)
                if answers.query is not None:
                    answers.lagged(t, lag)
            if kind is Kind.REQUEST:
                self._decode(msg, data)  # the decoder remembers a 241 request: its answer's layout depends on it
            rules.feed(can_id, data, t, extended, getattr(msg, "is_remote_frame", False), error, True)
            return
        if source != self._node:
            self.other_frames += 1
            answers.bus_taken(len(data))
            rules.feed(can_id, data, t, extended, getattr(msg, "is_remote_frame", False), error, False)
            return
        self.dut_frames += 1
        self.unexpected.trials += 1  # every frame of the DUT is judged by it
        rules.feed(can_id, data, t, extended, getattr(msg, "is_remote_frame", False), error, False)
        frame = self._decode(msg, data)
        if frame is None:
            return
        name = frame.name
        if kind is Kind.MESSAGE:
            if name in REPORTS or (name == "get_esc_id" and frame.layout is not None and frame.layout.name == "reply"):
                return  # the reader's (its events)
        elif kind is Kind.RESPONSE and frame.destination == self._host:
            if name == "maintenance_information":
                return  # the reader's (its counters' events)
            if name == "get_major_configuration":
                self.settings.read(frame, t)
                return
        self.unexpected.frame(frame, t)

    def _after(self, t: float, can_id: int, data: bytes) -> None:
        """A frame read after the findings still open: each keeps it, the first :data:`AFTER_FRAMES` of them."""
        line = self._line(t, can_id, data)
        still = []
        for f, left in self._open:
            f.after.append(line)
            if left > 1:
                still.append((f, left - 1))
        self._open = still

    def _decode(self, msg: Any, data: bytes, *, judge: bool = True) -> Frame | None:
        """The frame decoded; a message (its layout the frame's own) decoded once per distinct id and bytes: a report
        of the same values differs only in its transfer id, hours long (the cached frame's ``timestamp`` is its
        first's: the watches take the time from the feed)."""
        key = (msg.arbitration_id, data)
        frame = self._frames.get(key)
        if frame is not None:
            return frame
        try:
            frame = self.decoder.decode(msg)
        except DecodeError as exc:
            if judge and (msg.arbitration_id & 0x7F) == self.cfg.node_id:
                self.unexpected.garbled(exc, msg.timestamp)
            return None
        if frame.kind is Kind.MESSAGE and getattr(msg, "is_extended_id", True) and not getattr(msg, "is_error_frame", False) \
                and not getattr(msg, "is_remote_frame", False):
            if len(self._frames) > MAX_IDS:
                self._frames.clear()
            self._frames[key] = frame
        return frame

    def close(self, now: float) -> None:
        """The run ended at lane time ``now``: the watches judge what is still open."""
        for w in self.watches:
            w.close(now)


class Sinks(ReaderEvents):
    """The reader's events about the DUT, each handed to the watch that owns its property."""

    def __init__(self, monitor: Monitor) -> None:
        self.node, self.host = monitor.cfg.node_id, monitor.cfg.host_node
        self.resets, self.intervals, self.comm, self.answers = monitor.resets, monitor.intervals, monitor.comm, monitor.answers

    def query(self, ts: float, source: int) -> None:
        if source == self.host:
            self.answers.asked(ts)
        else:
            self.answers.foreign_asked(ts)

    def reply(self, ts, node, pairing, can_id, data) -> None:
        if node == self.node:
            self.answers.reply(ts, pairing, can_id, data)

    def report(self, ts: float, node: int, name: str, restarted: bool) -> None:
        if node == self.node and name in REPORTS:
            self.intervals.report(name, ts, restarted)
            if restarted:
                self.comm.restarted(ts)

    def reset(self, ts, node, sign, signs) -> None:
        if node == self.node:
            self.resets.sign(ts, sign, signs)

    def counter(self, ts: float, node: int, name: str, value: int) -> None:
        if node == self.node:
            self.resets.read(name)

    def msg1(self, ts: float, node: int, flag: bool, last_command: float | None) -> None:
        if node == self.node:
            self.comm.msg1(ts, flag, last_command)
