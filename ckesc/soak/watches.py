"""The soak's watches, sans-IO: every frame of the run in (with its lane timestamp), findings out.

One owner per watched property (R19), each calling the rule's judgement in :mod:`ckesc.protocol.judgements`:

* :class:`ResetWatch` - no reset: 241's power-up count does not grow, its run time neither goes back nor jumps, no
  report gap with a transfer id restart (:func:`~ckesc.protocol.judgements.r19_power_ups`, ``r19_run_time``,
  ``r19_report_restart``);
* :class:`IntervalWatch` - R9 over every minute, per report (MSG1..3): the mean of that minute's gaps
  (:func:`~ckesc.protocol.judgements.r9_mean`); the trend is one mean per minute and report;
* :class:`CommFlagWatch` - the comm flag (MSG1's status, R8) set only when the stream stops
  (:func:`~ckesc.protocol.judgements.r8_flag_due`);
* :class:`AnswerWatch` - GET_ESC_ID's answers in the node's slot (R2) and within 64 ms (4.4.3-4), their delays as
  a fixed-bin histogram (another node's query, a flight controller's on the bus, is answered too: its answer is
  neither the host's nor one to no query);
* :class:`SettingsWatch` - 242's answers unchanged (:func:`~ckesc.protocol.judgements.r13_read_back`);
* :class:`UnexpectedWatch` - frames the ESC should not send: one that does not decode, or a frame type normal
  reporting never sends and the player never asked for.

Memory does not grow with the run's length: counters, fixed-bin histograms, the last value of each counter, a ring
of recent frames (:data:`RING_FRAMES`), at most :data:`MAX_FINDINGS` findings kept whole (the rest counted), and
the R9 trend, one value per minute and report (1440 a day: the one thing that grows, as the trend plot needs it).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

from ..evidence.resets import POWER_UPS, RUN_TIME, ResetSigns
from ..protocol import catalogue as cat
from ..protocol import judgements as jd
from ..protocol.errors import DecodeError
from ..protocol.frame import Decoder, Frame, classify, frame_bits
from ..protocol.ids import Kind

#: frames kept before a finding (the ring) and read after it
RING_FRAMES = 40
AFTER_FRAMES = 10
#: findings kept whole; past these only counted (a DUT that breaks a rule all the time must not fill the memory)
MAX_FINDINGS = 100
#: ... and at most this many of one watch (a watch finding all the time must not hide the others' findings)
MAX_FINDINGS_PER_WATCH = 20
#: CAN ids whose classification is kept, and messages kept decoded (a DUT sending ever new ones must not grow the memory)
MAX_IDS = 4096
#: the R9 minute
MINUTE_S = 60.0
#: GET_ESC_ID delay histogram: bins of a quarter slot over twice the 64 ms bound, then one overflow bin
DELAY_BIN_S = cat.ANSWER_SLOT_S / 4
DELAY_BINS = 2 * round(cat.ANSWER_DELAY_MAX_S / DELAY_BIN_S)
#: other nodes' GET_ESC_ID queries kept open (a flight controller asks once a second), and how long one stays open:
#: the histogram's span, twice the 64 ms bound (an ESC need not answer other hosts, F6)
FOREIGN_QUERIES = 8
FOREIGN_ANSWER_S = DELAY_BINS * DELAY_BIN_S
#: the host's send times kept per frame (id and bytes) until its echo comes back (the stream's repeat every 32 transfers)
SENT_KEPT = 8
#: how late the bench stamped the host's own frames (their echo's time minus the host's send): bins of a tenth of a
#: millisecond up to 50 ms, then one overflow bin
LAG_BIN_S = 0.0001
LAG_BINS = 500
#: the report frames R9 and the reset watch follow
REPORTS = cat.REPORT_FRAMES
#: what normal reporting sends besides the reports, and the answers to what the player asks
ANSWERS = ("get_esc_id", "maintenance_information", "get_major_configuration")
#: MSG1's comm-loss flag (R8) as a plain int
_COMM_FAULT = int(cat.Status.COMM_FAULT)
#: a frame that does not decode: the requirement its reason breaks
DECODE_RULES = {"not-extended-data-frame": "F1", "not-single-frame": "F2", "reserved-node-id": "F7",
                "unknown-type-id": "4.3.1-1"}


@dataclass
class Finding:
    """One thing a watch found: when (s into the run), which watch, the requirements, what, and the frames around it
    (candump lines with times into the run)."""

    t: float
    watch: str
    rules: tuple[str, ...]
    message: str
    before: list[str] = field(default_factory=list)
    after: list[str] = field(default_factory=list)
    file: str | None = None  # the file of the run's trace holding these frames (--trace-budget), once written

    def to_json(self) -> dict[str, Any]:
        return {"t_s": round(self.t, 6), "watch": self.watch, "rules": list(self.rules), "message": self.message,
                "frames_before": self.before, "frames_after": self.after, "frames_file": self.file}

    def line(self) -> str:
        return f"{clock(self.t)} [{' '.join(self.rules)}] {self.watch}: {self.message}"


def clock(seconds: float) -> str:
    """``3725.5`` -> ``1:02:05.500`` (a time into the run)."""
    whole = int(seconds)
    h, rest = divmod(whole, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}.{int(round((seconds - whole) * 1000)) % 1000:03d}"


class Histogram:
    """A streaming distribution of values in seconds: count, min, max, mean and fixed bins (percentiles from them)."""

    def __init__(self, width: float, bins: int) -> None:
        self.width, self.counts = width, [0] * (bins + 1)  # the last bin: everything beyond
        self.n, self.total, self.lo, self.hi = 0, 0.0, math.inf, -math.inf

    def add(self, value: float) -> None:
        self.n += 1
        self.total += value
        if value < self.lo:
            self.lo = value
        if value > self.hi:
            self.hi = value
        i = int(value / self.width)
        self.counts[i if 0 <= i < len(self.counts) else (0 if i < 0 else -1)] += 1

    def percentile(self, p: float) -> float | None:
        """The upper edge of the bin holding the ``p``-th percentile (None: empty; the max for the overflow bin)."""
        if not self.n:
            return None
        need, seen = p / 100 * self.n, 0
        for i, c in enumerate(self.counts):
            seen += c
            if seen >= need and c:
                return self.hi if i == len(self.counts) - 1 else min((i + 1) * self.width, self.hi)
        return self.hi

    def to_json(self) -> dict[str, Any]:
        def ms(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else round(v * 1000, 3)

        return {"count": self.n, "min_ms": ms(self.lo), "max_ms": ms(self.hi),
                "mean_ms": ms(self.total / self.n) if self.n else None,
                **{f"p{p}_ms": ms(self.percentile(p)) for p in (50, 90, 99)},
                "bin_ms": self.width * 1000, "bins": self.counts}


@dataclass(frozen=True)
class WatchConfig:
    """What the watches need to know of the bench and the DUT: node ids, the report intervals (s) the DUT was set to
    at the start, the bench's timing error (s; its own frames' error ``own_error``), the DUT's declared jitter, the
    bit rate (frame durations)."""

    node_id: int
    host_node: int
    intervals: Mapping[str, float]
    error: float = 0.0
    own_error: float = 0.0
    jitter: float = 0.0
    bitrate: int = cat.DEFAULT_BITRATE
    nibble_order: str = "lsb"
    #: the host's stream frames one tick sends: each, at the highest priority, may be queued ahead of an answer
    stream_frames: int = 1


class Watch:
    """A watched property: its name, the requirement(s) it judges, how many times it was judged (``trials``) and how
    many events broke it (``events``). ``statement_unit``: ``hour`` (events per hour of run) or what a trial is."""

    name = ""
    rules: tuple[str, ...] = ()
    statement_unit = "hour"
    what = ""  # the events, for the statement: "resets"
    one = ""  # one event: "reset"

    def __init__(self, monitor: Monitor) -> None:
        self.monitor = monitor
        self.cfg = monitor.cfg
        self.trials = 0
        self.events = 0

    def find(self, t: float, message: str, rules: Iterable[str] | None = None) -> None:
        self.events += 1
        self.monitor.found(self, t, message, tuple(rules) if rules is not None else self.rules)

    def statistics(self) -> dict[str, Any]:
        return {}

    def close(self, now: float) -> None:
        """The run ended at ``now``: judge what is still open."""


# ------------------------------------------------------------------------------------------------ resets
class ResetWatch(Watch):
    name = "resets"
    rules = ("R19", "R17")
    what = "resets"
    one = "reset"

    def __init__(self, monitor: Monitor) -> None:
        super().__init__(monitor)
        #: the reset bookkeeping the bus rules keep too: the last report of each type, the last 241 readings
        self.signs = ResetSigns(error=self.cfg.error, jitter=self.cfg.jitter)
        self.reads = {POWER_UPS: 0, RUN_TIME: 0}

    def report(self, name: str, t: float, tid: int | None) -> bool:
        """A report of the ESC: whether its counter started again (the first report after a restart, R9a)."""
        signs = self.signs
        sign = signs.report(name, t, tid, self.cfg.intervals.get(name))
        if sign is not None:
            self.find(t, sign.text, (sign.rule, "R17"))
        return signs.restarted

    def maintenance(self, frame: Frame, t: float) -> None:
        f = frame.fields
        for counter in (POWER_UPS, RUN_TIME):
            if counter in f:
                self.reads[counter] += 1
                self.trials += 1
                if (sign := self.signs.counter(counter, f[counter], t)) is not None:
                    self.find(t, sign.text, (sign.rule, "R17"))
                return

    def statistics(self) -> dict[str, Any]:
        ups, run_time = self.signs.last(POWER_UPS), self.signs.last(RUN_TIME)
        return {"reads_241": self.reads, "power_ups": ups.value if ups else None,
                "run_time_s": run_time.value if run_time else None}


# ------------------------------------------------------------------------------------------------ R9
class _Span:
    """One report's gaps in the minute being read, without keeping them: the stretch open now (its first and last
    report, how many) and the stretches a restart closed in this minute (their spans summed, their gaps, how many).
    A restart (a report whose counter started again) closes the open stretch, and the reports whose gaps R9a leaves
    unjudged open none (:func:`~ckesc.protocol.judgements.r9_judged`: the gaps up to and including the second report
    after the restart), so the minute's mean is that of the gaps R9 judges."""

    __slots__ = ("first", "last", "n", "spanned", "gaps", "stretches", "skip", "heard", "seen")

    def __init__(self) -> None:
        self.first = self.last = self.spanned = 0.0
        self.n = self.gaps = self.stretches = self.skip = self.heard = 0
        self.seen = False  # a report heard in an earlier minute

    def add(self, t: float, restarted: bool) -> None:
        self.heard += 1
        if restarted:
            self._close()
            self.skip = jd.R9A_UNJUDGED - 1  # the report after which R9 judges the gaps again opens the next stretch
        if self.skip:
            self.skip -= 1
        elif self.n:
            self.last = t
            self.n += 1
        else:
            self.first = self.last = t
            self.n = 1

    def _close(self) -> None:
        if self.n >= 2:
            self.spanned += self.last - self.first
            self.gaps += self.n - 1
            self.stretches += 1
        self.n = 0

    def minute(self) -> tuple[_Joined, int]:
        """The minute's judged stretches joined end to end, and how many they are; the open stretch then goes on from
        its last report (the gap across the minute's end is the next minute's)."""
        going_on = self.n > 0
        self._close()
        joined, stretches = _Joined(self.spanned, self.gaps), self.stretches
        self.seen = self.seen or self.heard > 0
        self.spanned, self.gaps, self.stretches, self.heard = 0.0, 0, 0, 0
        if going_on:
            self.first, self.n = self.last, 1
        return joined, stretches


class _Joined:
    """A minute's judged stretches joined end to end, as :func:`~ckesc.protocol.judgements.r9_mean` reads a sequence
    of report starts (the first, the last, how many): from 0 to the sum of their spans, over the sum of their gaps."""

    __slots__ = ("span", "gaps")

    def __init__(self, span: float, gaps: int) -> None:
        self.span, self.gaps = span, gaps

    def __len__(self) -> int:
        return self.gaps + 1

    def __getitem__(self, i: int) -> float:
        if i in (0, -self.gaps - 1):
            return 0.0
        if i in (-1, self.gaps):
            return self.span
        raise IndexError("joined stretches keep their ends only")


class IntervalWatch(Watch):
    name = "report intervals"
    rules = ("R9", "R19")
    statement_unit = "report-minute"
    what = "report-minutes out of R9"
    one = "report-minute out of R9"

    def __init__(self, monitor: Monitor) -> None:
        super().__init__(monitor)
        self.t0 = monitor.t0
        self.minute = 0
        self.spans = {r: _Span() for r in REPORTS}
        #: the trend: per report, the mean interval (ms) of each minute (None: not judged)
        self.series: dict[str, list[float | None]] = {r: [] for r in REPORTS}
        self.worst: dict[str, float] = {}

    def report(self, name: str, t: float, restarted: bool = False) -> None:
        """A report of the ESC at ``t``; ``restarted``: its counter started again (the first after a restart, R9a)."""
        minute = int((t - self.t0) // MINUTE_S)
        while minute > self.minute:
            self._close_minute(self.t0 + (self.minute + 1) * MINUTE_S)
        self.spans[name].add(t, restarted)

    def _close_minute(self, end: float, *, partial: bool = False) -> None:
        for name in REPORTS:
            interval = self.cfg.intervals.get(name)
            span = self.spans[name]
            silent = not span.heard and span.seen
            joined, stretches = span.minute()
            if interval is None:
                self.series[name].append(None)
                continue
            if joined.gaps < 1:
                self.series[name].append(None)
                if silent and not partial:
                    self.trials += 1
                    self.find(end, f"no {name} in minute {self.minute + 1} (interval {interval * 1000:g} ms)")
                continue
            if partial and joined.gaps < jd.R9_GAPS:
                self.series[name].append(None)
                continue
            # each stretch's two ends carry the bench's error, as one span's do
            judged = jd.r9_mean(joined, interval, error=stretches * self.cfg.error, what=name)
            assert judged is not None
            self.series[name].append(round(joined.span / joined.gaps * 1000, 4))
            self.worst[name] = max(self.worst.get(name, 0.0), judged.measured)
            self.trials += 1
            if not judged.ok:
                self.find(end, f"minute {self.minute + 1}: {judged}")
        self.minute += 1

    def close(self, now: float) -> None:
        minute = int((now - self.t0) // MINUTE_S)
        while minute > self.minute:
            self._close_minute(self.t0 + (self.minute + 1) * MINUTE_S)
        if now - self.t0 > self.minute * MINUTE_S:  # a part of a minute left
            self._close_minute(now, partial=True)

    def statistics(self) -> dict[str, Any]:
        return {"minutes_judged": self.trials, "worst_mean_error_ms": {k: round(v * 1000, 4) for k, v in self.worst.items()},
                "intervals_ms": {k: v * 1000 for k, v in self.cfg.intervals.items()}}


# ------------------------------------------------------------------------------------------------ comm flag
class CommFlagWatch(Watch):
    name = "comm flag"
    rules = ("R8", "R19")
    what = "comm flag glitches"
    one = "comm flag glitch"

    def __init__(self, monitor: Monitor) -> None:
        super().__init__(monitor)
        self.last_command: float | None = None
        self.msg1_since_stream = 0
        self.flagged = False  # inside an episode already found
        self.stream_gaps = 0  # the host's stream stopped for longer than the comm-loss time
        self.longest_command_gap = 0.0
        self.flag_set = 0
        interval = self.cfg.intervals.get("msg1")
        #: R8's window opens here after the last command (its judgement's: r8_window_s)
        self._early = jd.r8_window_s(interval, jitter=self.cfg.jitter)[0] if interval else 0.0
        self._interval = interval
        self._error = self.cfg.error + self.cfg.own_error

    def command(self, t: float) -> None:
        if self.last_command is not None:
            gap = t - self.last_command
            if gap > self.longest_command_gap:
                self.longest_command_gap = gap
            if gap > cat.COMM_LOSS_TIMEOUT_S:
                self.stream_gaps += 1
        else:
            self.msg1_since_stream = 0
        self.last_command = t

    def msg1(self, frame: Frame, t: float) -> None:
        if self.last_command is None:
            return
        self.msg1_since_stream += 1
        if self.msg1_since_stream < 2:  # the MSG1 due as the stream began may still show the flag of before it
            return
        interval = self._interval
        if interval is None:
            return
        flag = bool(frame.fields.get("status", 0) & _COMM_FAULT)  # (a plain int: IntFlag's & is slow, once per MSG1)
        self.flag_set += flag
        since = t - self.last_command
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
            since = (t - self.last_command) * 1000
            self.find(t, f"MSG1 {'shows' if flag else 'lacks'} the comm-loss flag {since:.1f} ms after the last command "
                      f"({'the stream runs' if not due else 'the stream stopped'})")

    def statistics(self) -> dict[str, Any]:
        return {"msg1_judged": self.trials, "msg1_with_flag": self.flag_set,
                "host_stream_gaps_over_200ms": self.stream_gaps,
                "longest_command_gap_ms": round(self.longest_command_gap * 1000, 3)}


# ------------------------------------------------------------------------------------------------ GET_ESC_ID
class AnswerWatch(Watch):
    name = "GET_ESC_ID answers"
    rules = ("R2", "4.4.3-4")
    statement_unit = "answer"
    what = "answers late, early or missing"
    one = "answer late, early or missing"

    def __init__(self, monitor: Monitor) -> None:
        super().__init__(monitor)
        self.delays = Histogram(DELAY_BIN_S, DELAY_BINS)
        self.query: float | None = None
        self.answered = True
        self.missing = 0
        self.error = max(self.cfg.error, self.cfg.own_error)
        #: the host's own stream may delay an answer (never blame the DUT for the bench's traffic): one tick's stream
        #: frames ahead of it on the bus widen the late side of R2's slot and of the 64 ms bound
        self.queueing = self.cfg.stream_frames * frame_bits(8) / self.cfg.bitrate
        #: other nodes' GET_ESC_ID queries not answered yet (a flight controller's on the bus, R17): the ESC answers
        #: them with the same broadcast reply, which must not be taken for the host's answer nor for one to no query
        self.foreign: deque[float] = deque(maxlen=FOREIGN_QUERIES)
        self.foreign_queries = 0
        self.foreign_answers = 0
        #: the bus time (s) other frames took since the host's query: the answer may wait for each of them
        self.busy = 0.0
        #: the worst lag of the bench's stamps on the host's own frames since the query (:meth:`lagged`)
        self.lag = 0.0
        self.pending: tuple[Frame, float, float] | None = None  # an answer not judged yet: (frame, time, delay)
        self.bench_late = 0  # answers late only by the bench's own lag: not judged (not a trial)
        self.worst_lag = 0.0

    def foreign_asked(self, t: float) -> None:
        """Another node's GET_ESC_ID query, heard at ``t``."""
        self.foreign_queries += 1
        self.foreign.append(t)

    def bus_taken(self, data_bytes: int) -> None:
        """A frame of another node (or the ESC's answer to another node) on the bus while the host's query waits."""
        if self.query is not None and not self.answered:
            self.busy += frame_bits(data_bytes) / self.cfg.bitrate

    def lagged(self, t: float, lag: float) -> None:
        """One of the host's own frames, stamped at ``t``, ``lag`` after the host sent it: the bench (its bus, a
        socketcand hub, the adapter) stamped it that late. While the host's query waits, and until the frames
        stamped with its answer are read, the worst such lag widens the answer's late side: a bench that stamps
        late stamps the answer late as well, which is the bench's, not the DUT's."""
        if self.query is not None and t >= self.query and (not self.answered or self.pending is not None):
            self.lag = max(self.lag, lag)

    def tick(self, t: float) -> None:
        """A frame stamped at ``t``: the answer waiting for the frames stamped with it is judged once one is later."""
        if self.pending is not None and t > self.pending[1]:
            self._judge()

    def asked(self, t: float) -> None:
        self._judge()
        if self.query is not None and not self.answered:
            self.trials += 1
            self.missing += 1
            bound = jd.answer_bound(t - self.query, error=self.error, rule="4.4.3-4")
            self.find(t, f"no answer to GET_ESC_ID within {(t - self.query) * 1000:.0f} ms: {bound}", ("4.4.3-4", "R19"))
        self.query, self.answered, self.busy, self.lag = t, False, 0.0, 0.0

    def reply(self, frame: Frame, t: float) -> None:
        foreign = self.foreign
        while foreign and t - foreign[0] > FOREIGN_ANSWER_S:  # a query the ESC did not answer (F6 leaves it free)
            foreign.popleft()
        if foreign and (self.query is None or self.answered or foreign[0] < self.query):
            foreign.popleft()  # the answer to the earliest query still open, another node's: not the host's to judge
            self.foreign_answers += 1
            self.bus_taken(len(frame.data))
            return
        if self.query is None or self.answered:
            self.monitor.unexpected.find(t, f"a GET_ESC_ID reply that answers no query ({frame.fields})", ("R1",))
            return
        self.answered = True
        end = t - self.query
        self.delays.add(end)
        self.pending = (frame, t, end)  # judged once the frames stamped with it are read (tick): their lag counts

    def _judge(self) -> None:
        if self.pending is None:
            return
        frame, t, end = self.pending
        self.pending = None
        start = end - frame_bits(len(frame.data)) / self.cfg.bitrate
        late = self.error + self.queueing + self.busy
        broken = self._broken(start, end, late)
        if broken and self.lag and not self._broken(start, end, late + self.lag):
            self.bench_late += 1  # late only by as much as the bench stamped the host's own frames late: not judged
            self.worst_lag = max(self.worst_lag, self.lag)
            return
        self.trials += 1
        if broken:
            self.find(t, "; ".join(str(j) for j in broken), tuple(dict.fromkeys(j.rule for j in broken)))

    def _broken(self, start: float, end: float, late: float) -> list:
        node = self.cfg.node_id
        return [j for j in (jd.r2_slot_start(start, node, error=self.error), jd.r2_slot_end(end, node, error=late),
                            jd.answer_bound(end, error=late, rule="4.4.3-4")) if not j.ok]

    def close(self, now: float) -> None:
        self._judge()

    def statistics(self) -> dict[str, Any]:
        return {"answers": self.delays.n, "missing": self.missing, "delay": self.delays.to_json(),
                "not_judged_late_by_the_bench": self.bench_late, "worst_bench_lag_excused_ms": round(self.worst_lag * 1000, 3),
                "other_nodes_queries": self.foreign_queries, "answers_to_other_nodes": self.foreign_answers}


# ------------------------------------------------------------------------------------------------ settings
class SettingsWatch(Watch):
    name = "settings"
    rules = ("R19", "R13")
    what = "settings changes"
    one = "settings change"

    def __init__(self, monitor: Monitor) -> None:
        super().__init__(monitor)
        self.first: dict[str, Any] | None = None
        self.now: dict[str, Any] | None = None

    def read(self, frame: Frame, t: float) -> None:
        self.trials += 1
        fields = dict(frame.fields)
        if self.first is None:
            self.first = self.now = fields
            return
        changed = jd.r13_read_back(self.now or {}, fields)
        if changed:
            self.find(t, "Get Major Configuration (242) changed: " + ", ".join(str(d) for d in changed))
        self.now = fields

    def statistics(self) -> dict[str, Any]:
        return {"reads_242": self.trials, "first": self.first, "last": self.now}


# ------------------------------------------------------------------------------------------------ unexpected
class UnexpectedWatch(Watch):
    name = "unexpected frames"
    rules = ("R19",)
    what = "unexpected frames"
    one = "unexpected frame"

    def __init__(self, monitor: Monitor) -> None:
        super().__init__(monitor)
        self.kinds: dict[str, int] = {}

    def garbled(self, error: DecodeError, t: float) -> None:
        self._note(f"undecodable ({error.reason})", t, f"a frame that does not decode: {error}",
                   (DECODE_RULES.get(error.reason, "R19"),))

    def frame(self, frame: Frame, t: float) -> None:
        self._note(frame.name, t, f"{frame.name} ({frame.kind.label}) {frame.fields}: normal reporting never sends it and "
                   "the flight controller asked for nothing it answers", self.rules)

    def _note(self, kind: str, t: float, message: str, rules: tuple[str, ...]) -> None:
        self.kinds[kind] = self.kinds.get(kind, 0) + 1
        self.find(t, message, rules)

    def statistics(self) -> dict[str, Any]:
        return {"by_kind": self.kinds}


# ------------------------------------------------------------------------------------------------ the monitor
class Monitor:
    """Every frame of the run in (:meth:`feed`), in order, the DUT's and the host's own (their echo), with lane
    timestamps; the watches fed; findings kept (:attr:`findings`, the first :data:`MAX_FINDINGS`) and counted."""

    def __init__(self, cfg: WatchConfig, t0: float) -> None:
        self.cfg = cfg
        self.t0 = t0
        self.decoder = Decoder(nibble_order=cfg.nibble_order)
        self.ring: deque[tuple[float, int, bytes]] = deque(maxlen=RING_FRAMES)
        self.findings: list[Finding] = []
        self.dropped = 0  # findings counted but not kept
        self._kept: dict[str, int] = {}  # findings kept per watch
        self._open: list[tuple[Finding, int]] = []  # findings still collecting frames after them
        self.frames = 0
        self.dut_frames = 0
        self.own_frames = 0
        self.other_frames = 0
        self.last_t = t0
        self._ids: dict[int, tuple[Any, ...]] = {}
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

    # ------------------------------------------------------------------ findings
    def found(self, watch: Watch, t: float, message: str, rules: tuple[str, ...]) -> None:
        kept = self._kept.get(watch.name, 0)
        if len(self.findings) >= MAX_FINDINGS or kept >= MAX_FINDINGS_PER_WATCH:
            self.dropped += 1
            return
        self._kept[watch.name] = kept + 1
        f = Finding(t - self.t0, watch.name, rules, message, [self._line(*r) for r in self.ring])
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
        ``data``, ``is_extended_id`` (and the error / remote flags)."""
        t = msg.timestamp
        can_id = msg.arbitration_id
        data = bytes(msg.data)
        self.frames += 1
        self.last_t = t
        if self.answers.pending is not None:
            self.answers.tick(t)
        if self._open:
            line = self._line(t, can_id, data)
            still = []
            for f, left in self._open:
                f.after.append(line)
                if left > 1:
                    still.append((f, left - 1))
            self._open = still
        self.ring.append((t, can_id, data))
        info = self._ids.get(can_id)
        if info is None:
            if len(self._ids) > MAX_IDS:  # a DUT sending ever new ids must not grow the memory
                self._ids.clear()
            info = self._ids[can_id] = classify(can_id) if getattr(msg, "is_extended_id", True) else (None,) * 5
        kind, type_id, source, _, spec = info
        cfg = self.cfg
        if source == cfg.host_node and spec is not None:
            self.own_frames += 1
            if self._sent and (q := self._sent.get((can_id, data))):
                lag = max(t - q.popleft(), 0.0)
                self.bench_lag.add(lag)
                self.answers.lagged(t, lag)
            name = spec.name
            if name in cat.THROTTLE_FRAMES:
                self.comm.command(t)
            elif name == "get_esc_id":
                self.answers.asked(t)
            elif kind is Kind.REQUEST:
                self._decode(msg, data)  # the decoder remembers a 241 request: its answer's layout depends on it
            return
        if source != cfg.node_id:
            self.other_frames += 1
            self.answers.bus_taken(len(data))
            if spec is not None and spec.name == "get_esc_id" and kind is Kind.MESSAGE:
                frame = self._decode(msg, data, judge=False)
                if frame is not None and frame.layout is not None and frame.layout.name == "query":
                    self.answers.foreign_asked(t)
            return
        self.dut_frames += 1
        self.unexpected.trials += 1  # every frame of the DUT is judged by it
        frame = self._decode(msg, data)
        if frame is None:
            return
        name = frame.name
        if kind is Kind.MESSAGE:
            if name in REPORTS:
                self.intervals.report(name, t, self.resets.report(name, t, frame.transfer_id))
                if name == "msg1":
                    self.comm.msg1(frame, t)
                return
            if name == "get_esc_id" and frame.layout is not None and frame.layout.name == "reply":
                self.answers.reply(frame, t)
                return
        elif kind is Kind.RESPONSE and frame.destination == cfg.host_node:
            if name == "maintenance_information":
                self.resets.maintenance(frame, t)
                return
            if name == "get_major_configuration":
                self.settings.read(frame, t)
                return
        self.unexpected.frame(frame, t)

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
