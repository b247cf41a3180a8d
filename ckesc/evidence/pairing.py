"""Which request or query an ESC's answer answers, sans-IO: the one owner of that decision.

:class:`RequestPairing` pairs a service response with the request it answers (F4, by
:func:`~ckesc.protocol.judgements.f4_answers`: per requester, node asked and service, by transfer id, never by order
alone) and a broadcast command's answer (MSG Control's, a message naming no request) with the command; the bus reader
(:mod:`.tracker`, :mod:`.rules`) feeds it every request and every answer and tells its consumers the pairing
(:meth:`~.events.ReaderEvents.response`: the explorer's judge takes it instead of pairing again). An answer addressed
to a node that asked nothing it answers pairs with no request, and says which other node's request it answers but for
its destination (:class:`Misaddressed`): the framing section (``conformance/wire.answers_of``) fails it under F4 as
that request's answer.

:class:`QueryPairing` decides which GET_ESC_ID query a reply answers. The suite's helpers
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
from ..protocol.ids import Kind
from ..protocol.judgements import R2_LATE_BOUNDS, Addressed, f4_answers, f4_mismatches, r2_may_answer

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
        # (a time earlier than the latest is no jump here: the host's own frames, timed by their send without echo,
        # run ahead of the bus's frames not read yet; whether the clock jumped is the reader's to say, :meth:`forget`)
        if t > self._last_t:
            self._last_t = t
            while self._queries and t - self._queries[0].t > self.reach:
                self._queries.popleft()

    def forget(self) -> None:
        """The clock went back (a capture's jump, as the reader tells): nothing before is paired with what follows."""
        self._queries.clear()
        self._taken.clear()
        self._last_t = float("-inf")

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


# ------------------------------------------------------------------------------------------ requests (F4)
#: How long after a request its response may still come (the document sets no bound for services; 64 ms for
#: broadcasts): generous, so that a slow answer is never taken for an unasked one.
RESPONSE_WINDOW_S = 5.0
#: requests kept per (requester, node asked, service), and such keys at most
REQUESTS_KEPT = 32
KEYS_KEPT = 4096


@dataclass(frozen=True, slots=True)
class Request:
    """A host's frame an ESC answers, as the reader heard it: a service request, or a broadcast command whose answer
    is a message (MSG Control). ``asked``: the node whose answer it wants (None: any, Set ID being a
    pseudo-broadcast, R11, and a broadcast); ``taken``: False where R17 says an ESC ignores it (a malformed frame,
    :mod:`.taken`), so that an answer to it is one too many."""

    t: float
    kind: Kind
    service: int
    transfer_id: int | None
    requester: int
    asked: int | None
    taken: bool = True


@dataclass(frozen=True, slots=True)
class Misaddressed:
    """An answer addressed to node ``to``, which sent no request it answers, that answers ``request`` (another node's)
    in every other field: F4's answer to ``request``, failed for its destination."""

    request: Request
    to: int

    def __str__(self) -> str:
        r = self.request
        return (f"answers node {r.requester}'s request (service {r.service}, transfer id {r.transfer_id}) but is "
                f"addressed to node {self.to}")


@dataclass(frozen=True, slots=True)
class ResponsePairing:
    """What one answer (from ``node`` at ``t``) answers: ``request`` (None: none), the fields F4 finds off from it
    (``mismatches``: a response paired as its request's answer and failed with the field named,
    :data:`~ckesc.protocol.judgements.F4_PAIRING_SLACK`), ``again``: the request had this node's answer already (a
    repeat, judged no further); ``asked``: the transfer ids of the requests of its key in the window (what F4 says
    it should have carried); ``misaddressed`` (``request`` None): the request of another node it answers but for
    its destination (:class:`Misaddressed`)."""

    t: float
    node: int
    request: Request | None
    mismatches: tuple[str, ...] = ()
    again: bool = False
    asked: tuple[int | None, ...] = ()
    misaddressed: Misaddressed | None = None

    @property
    def holds(self) -> bool:
        """F4 holds: it answers a request the ESC acts on, with that request's transfer id."""
        return self.request is not None and self.request.taken and not self.mismatches


class RequestPairing:
    """The owner of F4's pairing on one bus: :meth:`request` for every host frame an ESC answers (in time order, as
    heard), :meth:`response` for every ESC's response, :meth:`command_answer` for every broadcast command's answer.
    ``error``: the bench's stated timing error of the stamps (an answer stamped up to it before its request, two
    stamps in the other order, still answers it). Memory: :data:`REQUESTS_KEPT` per key, :data:`KEYS_KEPT` keys."""

    def __init__(self, *, error: float = 0.0) -> None:
        self.error = max(float(error), 0.0)
        #: per (requester, service): the requests, each with the nodes that answered it
        self._requests: dict[tuple, deque[tuple[Request, set[int]]]] = {}

    def request(self, t: float, kind: Kind, service: int, transfer_id: int | None, requester: int, asked: int | None,
                *, taken: bool = True) -> Request:
        r = Request(t, kind, service, transfer_id, requester, asked, taken)
        key = (requester, service)
        q = self._requests.get(key)
        if q is None:
            if len(self._requests) >= KEYS_KEPT:
                self._requests.clear()
            q = self._requests[key] = deque(maxlen=REQUESTS_KEPT)
        q.append((r, set()))
        return r

    def response(self, t: float, node: int, service: int, transfer_id: int | None, requester: int) -> ResponsePairing:
        """A response of ``service`` from ESC ``node`` to ``requester`` with ``transfer_id``: the request it answers
        among ``requester``'s of that service within :data:`RESPONSE_WINDOW_S` (F4's
        :func:`~ckesc.protocol.judgements.f4_answers`: the one it carries the transfer id of, from the node asked, Set ID
        from any; else the one it is off from in a field, e.g. an answer from a node id that was not asked; each
        request answered once by each node, a repeat of an answer already given being ``again``)."""
        window = [e for e in self._requests.get((requester, service), ()) if -self.error <= t - e[0].t <= RESPONSE_WINDOW_S
                  and e[0].kind is Kind.REQUEST]
        asked = tuple(dict.fromkeys(r.transfer_id for r, _ in window if r.asked in (node, None)))
        this = Addressed(Kind.RESPONSE, service, transfer_id, requester, node)
        open_ = [e for e in window if node not in e[1]]
        # the latest request it answers exactly (two alike are 32 transfer ids apart, or Set IDs to two node ids the
        # ESC moved between), else the earliest it is F4's answer to, off in a field (f4_answers)
        k = None
        for order in (open_[::-1], open_):
            k = f4_answers(this, [(r.service, r.transfer_id, r.requester, r.asked) for r, _ in order])
            off: tuple[str, ...] = ()
            if k is not None:
                r, by = order[k]
                off = tuple(f4_mismatches(this, service=r.service, transfer_id=r.transfer_id, requester=r.requester, asked=r.asked))
                if not off:
                    break
        if k is None or off:  # not the answer to an open request as F4 says: a repeat of one given?
            again = next((r for r, by in window if node in by and r.transfer_id == transfer_id and r.asked in (node, None)), None)
            if again is not None:
                return ResponsePairing(t, node, again, again=True, asked=asked)
        if k is None:
            return ResponsePairing(t, node, None, asked=asked, misaddressed=self._misaddressed(t, node, service, transfer_id,
                                                                                                requester))
        by.add(node)
        return ResponsePairing(t, node, r, off, asked=asked)

    def _misaddressed(self, t: float, node: int, service: int, transfer_id: int | None, to: int) -> Misaddressed | None:
        """The latest open request of another requester than ``to`` that this answer carries exactly but for its
        destination (F4: one field off, the one it is failed with), None: none. Nothing is marked answered: the reading
        is told, not taken."""
        fits = [r for (requester, sid), q in self._requests.items() if sid == service and requester != to for r, by in q
                if r.kind is Kind.REQUEST and node not in by and -self.error <= t - r.t <= RESPONSE_WINDOW_S
                and not f4_mismatches(Addressed(Kind.RESPONSE, service, transfer_id, requester, node), service=r.service,
                                      transfer_id=r.transfer_id, requester=r.requester, asked=r.asked)]
        return Misaddressed(max(fits, key=lambda r: r.t), to) if fits else None

    def others(self, node: int, service: int, requester: int, t: float) -> list[int]:
        """The requesters other than ``requester`` that asked ``node`` (or any node, Set ID) for ``service`` within
        :data:`RESPONSE_WINDOW_S` before ``t`` (for a message: whose request it may have been)."""
        return sorted({k[0] for k, q in self._requests.items() if k[1] == service and k[0] != requester
                       and any(0 <= t - r.t <= RESPONSE_WINDOW_S and r.asked in (node, None) for r, _ in q)})

    def command_answer(self, t: float, node: int, service: int) -> ResponsePairing:
        """A broadcast command's answer (a message, which names no command) from ``node``: the earliest command of
        ``service`` (from any host) it has not answered yet whose answer may be this one as R2 reads it
        (:func:`~ckesc.protocol.judgements.r2_may_answer`: within 64 ms, else as a late answer), each ESC answering
        each command once and in order."""
        reach = R2_LATE_BOUNDS * cat.ANSWER_DELAY_MAX_S + self.error
        window = [e for k, q in self._requests.items() if k[1] == service for e in q
                  if e[0].kind is Kind.MESSAGE and -self.error <= t - e[0].t <= reach]
        window.sort(key=lambda e: e[0].t)
        answered = max((i for i, (_, by) in enumerate(window) if node in by), default=-1)
        rest = window[answered + 1:]
        in_time = [e for e in rest if r2_may_answer(max(t - e[0].t, 0.0), error=self.error)]
        pick = (in_time or rest)[:1]
        if not pick:
            return ResponsePairing(t, node, None)
        r, by = pick[0]
        by.add(node)
        return ResponsePairing(t, node, r)
