"""Which GET_ESC_ID query a reply answers, sans-IO: the one owner of that decision. The suite's helpers
(``conformance/answers.py``) and the bus reader (:mod:`.tracker`: the bus rules, check-log, and the soak, whose
``AnswerWatch`` takes the reader's word with each reply) feed it every query and every reply, with their times, and
take its word.

A reply is a broadcast that names no query (R1). Every ESC answers each query once, in its slot after it, within
64 ms (R2); another host on the bus (a flight controller at node 10, F6) queries too, and the ESC may answer it as
well. What the owner reads of that, and nothing more:

* **the 64 ms bound** (:func:`~ckesc.protocol.judgements.r2_may_answer`): a reply may answer a query asked up to
  64 ms (and the bench's error) before it; where none was, a late answer to one asked up to twice that before
  (so that a late answer is judged late, not taken for no answer);
* **once per query, in order**: each ESC (a node id) answers each query once, and its answers keep the queries'
  order (each comes its slot after its query, the same slot for every query). So a node's reply may answer only
  queries later than the one its previous reply answers in the earliest reading (each reply taking the earliest
  query it may answer, first in, first out), which is the reading under which the most replies find a query;
* **not the slot**: the slot is judged on an answer once paired (R2), never used to pair it, so an answer out of
  its slot is judged out of its slot, not given to another query.

It says, for each reply (:class:`ReplyPairing`): the queries it may answer (``could``); ``none``: it answers no
query (a reply nobody asked for, or a second reply from one node id to one query: two ESCs share it); which query it
answers when only one may be; and ``ambiguous`` for a host: it may answer that host's query or another node's, so
it is neither judged as the host's answer nor found to answer none (the ESC is given every reading under which it
conforms). A skipped query (a flight controller's, which the ESC need not answer) never makes a later reply another's.

Memory is bounded: the queries of the last twice 64 ms, at most :data:`QUERIES_KEPT`; per replying node id the
query its last reply took; the first :data:`KEPT` decisions (for reports and tests) and a tally of all.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass

from ..protocol import catalogue as cat
from ..protocol.judgements import R2_LATE_BOUNDS, r2_may_answer

#: queries kept open at most (a bus flooded with queries must not grow the memory: the oldest go first)
QUERIES_KEPT = 64
#: replying node ids remembered at most
NODES_KEPT = 256
#: decisions kept whole (the rest are counted in :attr:`QueryPairing.tally`)
KEPT = 100

HOST, OTHER, AMBIGUOUS, NONE = "host", "another node", "ambiguous", "none"


@dataclass(frozen=True, slots=True)
class Query:
    """A GET_ESC_ID query heard: when, from which node, and its place in the order heard."""

    t: float
    source: int
    seq: int


@dataclass(frozen=True, slots=True)
class ReplyPairing:
    """What one GET_ESC_ID reply (from ``node`` at ``t``) answers: the queries it ``could`` answer, earliest
    first (empty: none), ``late`` when only as a late answer (no query within 64 ms before it)."""

    t: float
    node: int
    could: tuple[Query, ...]
    late: bool = False

    @property
    def none(self) -> bool:
        """It answers no query."""
        return not self.could

    @property
    def query(self) -> Query | None:
        """The one query it answers, when only one may be."""
        return self.could[0] if len(self.could) == 1 else None

    def answers(self, host: int) -> bool:
        """It answers ``host``'s query, and no other node's could be."""
        return bool(self.could) and all(q.source == host for q in self.could)

    def may_answer_another(self, host: int) -> bool:
        """Another node's query than ``host``'s may be the one it answers (a flight controller's, F6)."""
        return any(q.source != host for q in self.could)

    def ambiguous(self, host: int) -> bool:
        """It may answer ``host``'s query or another node's: which cannot be told."""
        return self.may_answer_another(host) and any(q.source == host for q in self.could)

    def outcome(self, host: int) -> str:
        """One word for it, seen from ``host``: :data:`HOST`, :data:`OTHER`, :data:`AMBIGUOUS` or :data:`NONE`."""
        if self.none:
            return NONE
        if self.answers(host):
            return HOST
        return AMBIGUOUS if self.ambiguous(host) else OTHER

    def delay(self) -> float | None:
        """From the one query it answers to the reply (None: not one)."""
        q = self.query
        return None if q is None else self.t - q.t


class QueryPairing:
    """The owner: :meth:`query` for every GET_ESC_ID query heard, :meth:`reply` for every reply, in time order (see
    the module docstring). ``error``: the bench's timing error (seconds) on the times fed; ``host``: the node whose
    view :attr:`tally` counts (the host's queries, another node's, ambiguous, none)."""

    def __init__(self, *, error: float = 0.0, host: int = 0) -> None:
        self.error = max(float(error), 0.0)
        self.host = host
        self.reach = R2_LATE_BOUNDS * cat.ANSWER_DELAY_MAX_S + self.error
        self._queries: deque[Query] = deque(maxlen=QUERIES_KEPT)
        self._seq = 0
        #: per replying node id: the place of the query its last reply took (the earliest reading)
        self._taken: dict[int, int] = {}
        self._last_t = float("-inf")
        self.queries = 0
        self.tally: Counter[str] = Counter()
        self.kept: list[ReplyPairing] = []

    def _time(self, t: float) -> None:
        if t < self._last_t:  # time went back (a capture's jump): nothing before is paired with what follows
            self._queries.clear()
            self._taken.clear()
        self._last_t = t
        while self._queries and t - self._queries[0].t > self.reach:
            self._queries.popleft()

    def query(self, t: float, source: int) -> Query:
        """A GET_ESC_ID query from node ``source`` at ``t``."""
        self._time(t)
        q = Query(t, source, self._seq)
        self._seq += 1
        self.queries += 1
        self._queries.append(q)
        return q

    def open(self, t: float) -> list[Query]:
        """The queries a reply at ``t`` may still answer as far as time goes (asked within the reach before it)."""
        return [q for q in self._queries if 0 <= t - q.t <= self.reach]

    def reply(self, t: float, node: int) -> ReplyPairing:
        """A GET_ESC_ID reply from node ``node`` at ``t``: what it answers."""
        self._time(t)
        after = self._taken.get(node, -1)
        in_time, late = [], []
        for q in self._queries:
            if q.seq <= after:
                continue
            may = r2_may_answer(t - q.t, error=self.error)
            if may:
                in_time.append(q)
            elif may is None:
                late.append(q)
        could = tuple(in_time or late)
        if could:
            if node not in self._taken and len(self._taken) >= NODES_KEPT:
                self._taken.clear()
            self._taken[node] = could[0].seq
        p = ReplyPairing(t, node, could, late=bool(could) and not in_time)
        self.tally[p.outcome(self.host)] += 1
        if len(self.kept) < KEPT:
            self.kept.append(p)
        return p

    def statistics(self) -> dict[str, int]:
        """JSON-able: the queries heard and the replies by what they answer (seen from :attr:`host`)."""
        return {"queries": self.queries, **{k: self.tally.get(k, 0) for k in (HOST, OTHER, AMBIGUOUS, NONE)}}
