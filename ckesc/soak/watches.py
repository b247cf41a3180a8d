"""The soak's GET_ESC_ID answer watch, sans-IO (the other watches: :mod:`.reset_watch`, :mod:`.interval_watch`,
:mod:`.comm_watch`, :mod:`.frame_watches`; their base :mod:`.watch`; the monitor that feeds them all :mod:`.monitor`).

:class:`AnswerWatch` - GET_ESC_ID's answers in the node's slot (R2) and within 64 ms (4.4.3-4), their delays as a
fixed-bin histogram; which query a reply answers is the bus reader's (its :class:`~ckesc.evidence.pairing.QueryPairing`,
told with each reply: :meth:`~ckesc.evidence.events.ReaderEvents.reply`; another node's query, a flight controller's on
the bus, may be answered too: its answer is neither the host's nor one to no query, and one that may be either is not
judged).
"""

from __future__ import annotations

from typing import Any

from ..evidence.pairing import ReplyPairing
from ..protocol import catalogue as cat
from ..protocol import judgements as jd
from ..protocol.errors import DecodeError
from ..protocol.frame import WireFrame, frame_bits
from ..protocol.histogram import Histogram
from .watch import Monitoring, Watch

#: GET_ESC_ID delay histogram: bins of a quarter slot over twice the 64 ms bound, then one overflow bin
DELAY_BIN_S = cat.ANSWER_SLOT_S / 4
DELAY_BINS = 2 * round(cat.ANSWER_DELAY_MAX_S / DELAY_BIN_S)


# ------------------------------------------------------------------------------------------------ GET_ESC_ID
class AnswerWatch(Watch):
    name = "GET_ESC_ID answers"
    rules = ("R2", "4.4.3-4")
    statement_unit = "answer"
    what = "answers late, early or missing"
    one = "answer late, early or missing"

    def __init__(self, monitor: Monitoring) -> None:
        super().__init__(monitor)
        self.delays = Histogram(DELAY_BIN_S, DELAY_BINS)
        self.query: float | None = None
        self.answered = True
        self.maybe = False  # a reply that may answer the host's query or another node's came: it is not missing
        self.missing = 0
        self.error = max(self.cfg.error, self.cfg.own_error)
        #: the host's own stream may delay an answer (never blame the DUT for the bench's traffic): one tick's stream
        #: frames ahead of it on the bus widen the late side of R2's slot and of the 64 ms bound
        self.queueing = self.cfg.stream_frames * frame_bits(8) / self.cfg.bitrate
        self.foreign_queries = 0
        self.foreign_answers = 0
        self.ambiguous = 0
        #: the bus time (s) other frames took since the host's query: the answer may wait for each of them
        self.busy = 0.0
        #: the worst lag of the bench's stamps on the host's own frames since the query (:meth:`lagged`)
        self.lag = 0.0
        self.pending: tuple[int, float, float] | None = None  # an answer not judged yet: (its bytes, time, delay)
        self.bench_late = 0  # answers late only by the bench's own lag: not judged (not a trial)
        self.worst_lag = 0.0

    def foreign_asked(self, t: float) -> None:
        """Another node's GET_ESC_ID query, heard at ``t`` (the reader pairs it)."""
        self.foreign_queries += 1

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
        if self.query is not None and not self.answered and not self.maybe:
            self.trials += 1
            self.missing += 1
            bound = jd.answer_bound(t - self.query, error=self.error, rule="4.4.3-4")
            self.find(t, f"no answer to GET_ESC_ID within {(t - self.query) * 1000:.0f} ms: {bound}", ("4.4.3-4", "R19"))
        self.query, self.answered, self.maybe, self.busy, self.lag = t, False, False, 0.0, 0.0

    def reply(self, t: float, p: ReplyPairing, can_id: int, data: bytes) -> None:
        """The ESC's reply at ``t``, and what it answers (the reader's word)."""
        host = self.cfg.host_node
        if p.none:
            try:
                fields = self.monitor.decoder.decode(WireFrame(can_id, data, t)).fields
            except DecodeError as exc:
                fields = str(exc)
            self.monitor.unexpected.find(t, f"a GET_ESC_ID reply that answers no query ({fields})", ("R1",))
            return
        current = any(q.source == host and q.t == self.query for q in p.could)
        if p.answers(host):
            if current and not self.answered:
                self.answered = True
                end = t - self.query  # type: ignore[operator]
                self.delays.add(end)
                self.pending = (len(data), t, end)  # judged once the frames stamped with it are read (tick): their lag counts
            return  # (an answer to an earlier query of the host's, already found missing: nothing more)
        if p.ambiguous(host):  # the host's answer or another node's: neither judged nor missing
            self.ambiguous += 1
            self.maybe = self.maybe or current
        else:  # another node's answer: not the host's to judge
            self.foreign_answers += 1
        self.bus_taken(len(data))

    def _judge(self) -> None:
        if self.pending is None:
            return
        size, t, end = self.pending
        self.pending = None
        start = end - frame_bits(size) / self.cfg.bitrate
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
                "other_nodes_queries": self.foreign_queries, "answers_to_other_nodes": self.foreign_answers,
                "answers_to_the_host_or_another_node": self.ambiguous}
