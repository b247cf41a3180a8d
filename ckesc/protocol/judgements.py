"""One judgement per timed or matched rule, sans-IO: the conformance tests, the live bus rules, ``ckesc explore``'s
judge and ``ckesc check-log`` all call these, so that one change of reading changes every verdict alike.

Each function takes what was measured (times in seconds, frames) and the limits the bench and the DUT state (the
bench's timing error, the DUT's declared jitter, the bus's bit rate as frame durations) and returns a
:class:`Judgement`: the rule, the measured value, the limit, the allowance given for the measurement's error, and
whether it holds. A consumer words its own message and keeps its own record (a test's measurement, a bus rule's
violation, an explorer finding) from it; it never writes a tolerance of its own.

* R2 (:func:`r2_slot_start`, :func:`r2_slot_end`): an answer to MSG Control or GET_ESC_ID starts no earlier than
  its node's slot, (node_id % 32) x 2 ms after the request, and ends inside it;
* the 64 ms bound (:func:`answer_bound`, 4.4.2-4, 4.4.3-4);
* R8 (:func:`r8_onset`, :func:`r8_flag_due`): the comm-loss flag comes up no earlier than 200 ms after the last
  command and no later than 200 ms + one MSG1 interval;
* R9 (:func:`r9_mean`, :func:`r9_gap`, :func:`r9_gaps_needed`): a report's interval is the mean of its gaps, held to
  the scheduling tolerance (1 ms) plus twice the bench's error and the DUT's declared jitter over the number of gaps
  (the mean of n gaps is the span from its first report to its last over n: only the two ends' error and jitter
  remain); a mean whose bound exceeds a quarter of the interval is not judged (OBSERVE); the jitter widens a single
  gap in full;
* R9a (:func:`r9a_limit_s`, :func:`r9a_first`, :func:`r9_judged`): the first report after a restart within the
  catalogue's restart limit; the gaps up to and including the second report after it are not judged;
* F3 (:func:`f3_step`, :func:`f3_holds`): consecutive frames of one counter (a sender's message type) carry transfer ids +1 modulo 32;
* R13 read-back (:func:`r13_read_back`): the persisted settings (the catalogue's ``PERSISTED_SETTINGS``) read back,
  at once and after a power cycle, are what was written and saved;
* F4 (:func:`f4_mismatches`, :func:`f4_pairs`, :func:`f4_answers`): a response keeps its request's service id and
  transfer id, has request=0, goes to the requester, comes from the node asked; it answers the request it carries;
* R18 (:func:`r18_queueing_s`, :func:`r18_mean`, :func:`r18_gap`, :func:`r18_judged`): under foreign load of up to
  half the bus, R9 with each gap widened by the queueing the load can put ahead of a lowest-priority frame; above
  half load, OBSERVE.
* R20 (:func:`r20_back`, :func:`r20_bound_s`, :data:`R20_UNJUDGED`): after a bus fault ends the ESC's reports go on
  within its controller's bus-off recovery (128 x 11 recessive bits) plus two MSG1 intervals plus the bench's error;
  its reports' timing and transfer-id sequence from the fault until each is back on its grid are OBSERVE.
* R19 (R17: never reset) resets (:func:`r19_power_ups`, :func:`r19_run_time`, :func:`r19_report_restart`,
  :func:`r19_counter_restarted`): the
  power-up count of 241 does not grow, its run time does not go back or jump, no report gap with a transfer id
  restart.

The readings are ``spec/INTERPRETATIONS.md``'s; the protocol facts (200 ms, the slots, the restart slack) are the
catalogue's (:mod:`.catalogue`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

from . import catalogue as cat
from .canbus import recovery_seconds
from .frame import Frame, frame_bits
from .ids import Kind
from .transfer import TRANSFER_ID_MODULO, next_transfer_id

#: R9: how far a report interval's mean may stray from its target besides the bench's error (the ESC's
#: report scheduling); also the tick a real-time bench's single report may stray by on top of its stated error
SCHEDULING_TOLERANCE_S = 0.001
#: A test allowance, not a protocol fact: a frame that starts within this time of a command may have been queued
#: before the DUT could act on the command, and is not held against it (the suite's, ``conformance.telemetry``; the
#: explorer's R8 near a command). On a lane with a stated timing error a frame may also leave that much late.
REACT_S = 0.005
#: R9a: the gaps up to and including this report after a restart are OBSERVE; from the next one on, R9
R9A_UNJUDGED = 2
#: R9: a test whose purpose is a report's interval judges the mean of at least this many gaps
R9_GAPS = 10
#: float noise, never a tolerance: a value computed from stamps that equals its limit on paper holds
_NOISE_S = 1e-9

_OPS = {"<=": lambda v, lim: v <= lim, ">=": lambda v, lim: v >= lim}


@dataclass(frozen=True)
class Judgement:
    """One rule judged on one measurement (seconds). ``ok``: the measurement holds the limit, with ``error`` (the
    part of the measurement that is the bench's, not the DUT's) given to the DUT: it fails only where it is
    certainly outside. ``op``: how ``measured`` compares with ``limit`` (``<=`` a bound from above)."""

    rule: str
    measured: float
    limit: float
    op: str = "<="
    error: float = 0.0
    text: str = ""
    #: False: the measurement is too coarse for the rule to be judged (R9's mean over too few gaps): OBSERVE, ``ok``
    judged: bool = True

    @property
    def ok(self) -> bool:
        if not self.judged:
            return True
        edge = self.limit + self.error + _NOISE_S if self.op == "<=" else self.limit - self.error - _NOISE_S
        return _OPS[self.op](self.measured, edge)

    @property
    def margin(self) -> float:
        """How far inside its limit the measurement is (negative: outside), before the error."""
        return self.limit - self.measured if self.op == "<=" else self.measured - self.limit

    def __str__(self) -> str:
        return (f"[{self.rule}] {self.text}: {self.measured * 1000:.3f} ms, limit {self.op} {self.limit * 1000:g} ms"
                + (f" +- {self.error * 1000:g} ms" if self.error else "") + ("" if self.ok else " (broken)"))


# ------------------------------------------------------------------------------------------ tolerances
def timing_tolerance(clock: str, timing_error: float) -> float:
    """The timing tolerance of a lane: exact (0) in simulated time; elsewhere the lane's stated error plus one
    report-scheduling tick. The bus rules judge single gaps with it, and ``Dut.interval_tolerance_ms`` allows it a
    report interval."""
    return 0.0 if clock == "simulated" else timing_error + SCHEDULING_TOLERANCE_S


def r9_mean_tolerance_s(gaps: int, error: float, jitter: float = 0.0) -> float:
    """R9: how far the mean of ``gaps`` gaps may stray from the interval: the scheduling tolerance plus twice the
    bench's error and the DUT's declared jitter over the number of gaps (the stamps' errors and the reports' jitter
    cancel but at the two ends; INTERPRETATIONS R9, amended 2026-12-02)."""
    return SCHEDULING_TOLERANCE_S + 2 * (error + jitter) / gaps


def r9_mean_tells(gaps: int, interval: float, *, error: float = 0.0, jitter: float = 0.0) -> bool:
    """R9: whether a mean of ``gaps`` gaps is judged at all: its bound (:func:`r9_mean_tolerance_s`) is no more than a
    quarter of the interval. Over fewer gaps it is OBSERVE."""
    return r9_mean_tolerance_s(gaps, error, jitter) <= interval / 4 + _NOISE_S


def r9_gaps_needed(interval: float, *, error: float = 0.0, jitter: float = 0.0, purpose: bool = True) -> int:
    """How many gaps a test reads to judge a report's mean interval. Where R9 is its ``purpose``: :data:`R9_GAPS`, or
    more where the DUT's declared ``jitter`` needs them to keep its part of the mean's bound (twice it over the gaps)
    within the scheduling tolerance, so that an ESC reporting every 25 ms instead of 20 FAILs whatever jitter its
    vendor declares. Otherwise the fewest (two at least, :data:`R9_GAPS` at most) over which the mean is judged at
    all (:func:`r9_mean_tells`) with the bench's ``error`` too. The bench's error never lengthens a test: it stays the
    INCONCLUSIVE band it is, and on a bench too coarse for the interval the mean is not judged (OBSERVE)."""
    if purpose:
        return max(R9_GAPS, math.ceil(2 * jitter / SCHEDULING_TOLERANCE_S - _NOISE_S))
    spare = interval / 4 - SCHEDULING_TOLERANCE_S
    if spare <= 0:
        return R9_GAPS
    return min(R9_GAPS, max(2, math.ceil(2 * (error + jitter) / spare - _NOISE_S)))


# ------------------------------------------------------------------------------------------ R9, R9a
def r9_judged(starts: Sequence[float], after_restart: bool = True) -> list[float]:
    """The reports whose gaps R9 judges: after a restart (R9a-gaps) from the second report on, so that the first
    gap judged is the second to the third report; otherwise all."""
    return list(starts[R9A_UNJUDGED - 1:] if after_restart else starts)


def r9_mean(starts: Sequence[float], interval: float, *, error: float = 0.0, jitter: float = 0.0,
            what: str = "report") -> Judgement | None:
    """R9 on the mean of the gaps between ``starts`` (the reports judged, :func:`r9_judged`): ``measured`` is how far
    the mean strays from ``interval``, ``limit`` the scheduling tolerance and twice the DUT's declared ``jitter`` over
    the gaps (the DUT's allowance), ``error`` twice the bench's error over the gaps (the measurement's): both count
    at the two ends only. Over so few gaps that this bound
    exceeds a quarter of the interval the judgement is not made (:func:`r9_mean_tells`): ``judged`` False, ``ok``
    True, a consumer records it as OBSERVE. None: fewer than two reports."""
    gaps = len(starts) - 1
    if gaps < 1:
        return None
    mean = (starts[-1] - starts[0]) / gaps
    return Judgement("R9", abs(mean - interval), SCHEDULING_TOLERANCE_S + 2 * jitter / gaps, "<=", 2 * error / gaps,
                     f"{what} every {mean * 1000:.3f} ms (mean of {gaps} gaps), not {interval * 1000:g} ms",
                     judged=r9_mean_tells(gaps, interval, error=error, jitter=jitter))


def r9_gap(lo: float, hi: float, interval: float, *, tolerance: float, jitter: float = 0.0) -> Judgement:
    """R9 on one gap (the live rule) known to lie in ``[lo, hi]`` (bus queueing): held to ``interval`` within the
    lane's ``tolerance`` (:func:`timing_tolerance`) and the DUT's declared ``jitter``. The judgement is the side that
    breaks: ``hi`` below the interval (too soon, ``op`` ``>=``) or ``lo`` above it (too late)."""
    allowance = tolerance + jitter  # (the bus rules' hot path: no text formatted here)
    if hi < interval:
        return Judgement("R9", hi, interval, ">=", allowance, "a gap, at its longest")
    return Judgement("R9", lo, interval, "<=", allowance, "a gap, at its shortest")


def r9a_limit_s(interval: float, old: float | None = None, *, jitter: float = 0.0) -> float:
    """R9a: how long after a restart the first report may come: the catalogue's restart limit of its interval (after
    a Set Freq write, of the longer of its ``old`` and new interval), with the DUT's declared jitter on top."""
    return cat.restart_limit_s(interval if old is None else max(interval, old)) + jitter


def r9_stopped(silence: float, interval: float, *, error: float = 0.0, jitter: float = 0.0,
               what: str = "report") -> Judgement:
    """R9, R19: a report silent at the end of what was heard of a run: ``silence`` from its last report to the last
    frame heard, at ``interval``. Its next gap is at least that long, and a report may be absent no longer than
    a restart may take (:func:`r9a_limit_s`, with the DUT's declared ``jitter``), as a reset's gap is read
    (:func:`r19_report_restart`); longer, it stopped. ``error``: the two ends' stamps' (the bench's)."""
    return Judgement("R9", silence, r9a_limit_s(interval, jitter=jitter), "<=", error,
                     f"no {what} since its last one, at the end of what was heard (interval {interval * 1000:g} ms)")


def r9a_first(delay: float, limit: float, *, error: float = 0.0, what: str = "the first report") -> Judgement:
    """R9a: the first report ``delay`` after a restart is within ``limit`` (:func:`r9a_limit_s`)."""
    return Judgement("R9a", delay, limit, "<=", error, f"{what} {delay * 1000:.3f} ms after the restart")


def report_stamp_error_s(*, error: float, bitrate: int, queueing: float = 0.0) -> float:
    """How far a report's bus stamp may stray from when the ESC's schedule put it, besides its declared jitter: the
    scheduling tolerance, twice the bench's ``error``, one longest frame's bus access at ``bitrate`` (a stamp is the
    frame's end) and the ``queueing`` a foreign load can put ahead of it (R18, :func:`r18_queueing_s`)."""
    return SCHEDULING_TOLERANCE_S + 2 * error + frame_bits(8) / bitrate + queueing


# ------------------------------------------------------------------------------------------ R8
def r8_window_s(msg1_interval: float, *, jitter: float = 0.0) -> tuple[float, float]:
    """R8: the earliest and latest the comm-loss flag may show after the last command: 200 ms, and 200 ms plus one
    MSG1 interval (the MSG1 that carries it may stray by the DUT's declared jitter)."""
    return cat.COMM_LOSS_TIMEOUT_S, cat.COMM_LOSS_TIMEOUT_S + msg1_interval + jitter


def r8_onset(onset: float, msg1_interval: float, *, jitter: float = 0.0, error: float = 0.0) -> tuple[Judgement, Judgement]:
    """R8 on the first MSG1 with the comm-loss flag ``onset`` after the last command: (not before 200 ms, not after
    200 ms + one MSG1 interval)."""
    early, late = r8_window_s(msg1_interval, jitter=jitter)
    text = f"the comm-loss flag {onset * 1000:.3f} ms after the last command"
    return (Judgement("R8", onset, early, ">=", error, text), Judgement("R8", onset, late, "<=", error, text))


def r8_flag_due(since: float, msg1_interval: float, *, jitter: float = 0.0, error: float = 0.0) -> bool | None:
    """R8: what an MSG1 ``since`` after the last command must show: False (clear) before 200 ms, True (set) after
    200 ms + one MSG1 interval, None (free) in between or within ``error`` of either edge."""
    early, late = r8_onset(since, msg1_interval, jitter=jitter, error=error)
    if not early.ok:
        return False
    if not late.ok:
        return True
    return None


# ------------------------------------------------------------------------------------------ R2 and the 64 ms bound
def r2_slot_start(start: float, node_id: int, *, error: float = 0.0) -> Judgement:
    """R2: an answer ``start`` after its request (MSG Control, GET_ESC_ID) starts no earlier than node ``node_id``'s
    slot (the node id it has now)."""
    return Judgement("R2", start, cat.answer_slot_s(node_id), ">=", error,
                     f"node {node_id}'s answer starts {start * 1000:.3f} ms after the request")


def r2_slot_end(end: float, node_id: int, *, error: float = 0.0) -> Judgement:
    """R2: ... and ends inside its slot, ``end`` after the request."""
    return Judgement("R2", end, cat.answer_slot_s(node_id) + cat.ANSWER_SLOT_S, "<=", error,
                     f"node {node_id}'s answer ends {end * 1000:.3f} ms after the request")


def answer_bound(end: float, *, error: float = 0.0, rule: str = "4.4.2-4") -> Judgement:
    """4.4.2-4 / 4.4.3-4: an answer to a broadcast ends no later than 64 ms after the request."""
    return Judgement(rule, end, cat.ANSWER_DELAY_MAX_S, "<=", error, f"answer {end * 1000:.3f} ms after the request")


#: R2 pairing: a GET_ESC_ID reply that no query asked for within the 64 ms bound may still be a late answer to one
#: asked up to this many bounds before it (and judged late, 4.4.3-4), never to an older one
R2_LATE_BOUNDS = 2


def r2_may_answer(delay: float, *, error: float = 0.0) -> bool | None:
    """R2 read for pairing: whether a GET_ESC_ID reply may answer a query asked ``delay`` before it (a broadcast reply
    names no query: every ESC answers each query once, within 64 ms). True: within the 64 ms bound with the bench's
    ``error``, an answer under which the ESC conforms; None: only as a late answer (within :data:`R2_LATE_BOUNDS`
    bounds); False: not at all (asked after it, or longer before). The slot (:func:`r2_slot_start`) is judged on
    the answer once paired, never used to pair it."""
    if delay < 0:
        return False
    if delay <= cat.ANSWER_DELAY_MAX_S + error + _NOISE_S:
        return True
    return None if delay <= R2_LATE_BOUNDS * cat.ANSWER_DELAY_MAX_S + error + _NOISE_S else False


# ------------------------------------------------------------------------------------------ F3
@dataclass(frozen=True, slots=True)
class F3Step:
    """F3 between two consecutive frames of one counter (one sender's frame type, to one destination): the transfer
    id ``current`` after ``previous``. Which pairs are consecutive (no frame of the counter between them, no power
    cycle) is the consumer's to know; what they must carry is this."""

    previous: int
    current: int
    rule = "F3"

    @property
    def expected(self) -> int:
        """The transfer id F3 wants after ``previous``: +1, modulo 32."""
        return next_transfer_id(self.previous)

    @property
    def advance(self) -> int:
        """How far the counter moved, modulo 32 (1: as F3 wants; 0: stuck)."""
        return (self.current - self.previous) % TRANSFER_ID_MODULO

    @property
    def ok(self) -> bool:
        return f3_holds(self.previous, self.current)

    @property
    def wrapped(self) -> bool:
        """The counter went from 31 to 0, as F3 wants."""
        return self.ok and self.current == 0

    def explained_by(self, missing: int) -> bool:
        """Whether ``missing`` frames of the counter lost between the two (a capture's gap) explain the step: it
        moved by one per frame sent, modulo 32, and moved at all."""
        return self.advance != 0 and self.advance == next_transfer_id(missing)

    def __str__(self) -> str:
        return f"transfer id {self.current} after {self.previous}, expected {self.expected}"


def f3_holds(previous: int, current: int) -> bool:
    """F3: whether ``current`` follows ``previous`` on one counter (+1 modulo 32). The bus rules' hot path asks this
    of every frame and builds the :class:`F3Step` only for one that breaks it."""
    return current == next_transfer_id(previous)


def f3_step(previous: int, current: int) -> F3Step:
    """F3: the transfer id ``current`` after ``previous`` on one counter (:class:`F3Step`; ``ok``: +1 modulo 32)."""
    return F3Step(previous, current)


# ------------------------------------------------------------------------------------------ R13 read-back
@dataclass(frozen=True)
class Differs:
    """One setting read back other than expected: its name as read back (a ``PERSISTED_SETTINGS`` key, ``rotation``),
    the value expected (written, saved, or the model's) and the value read. ``str``: ``rotation 0 -> 1``."""

    key: str
    expected: Any
    read: Any

    def __str__(self) -> str:
        return f"{self.key} {self.expected} -> {self.read}"


def r13_read_back(expected: Mapping[str, Any], read: Mapping[str, Any], keys: Iterable[str] | None = None, *,
                  missing: Any = None) -> list[Differs]:
    """R13 on a read-back (after a power cycle: the persisted settings kept; at once: the write taken): every setting
    among ``keys`` (default: ``expected``'s then ``read``'s, in order, each once) whose value read differs from the one
    expected, in that order; a setting one side lacks is ``missing`` there. Empty: the read-back is what was
    expected. Which settings persist, and which request reads each back, is the catalogue's
    (``PERSISTED_SETTINGS``); which were expected is the consumer's (what it wrote, what its model holds)."""
    names = dict.fromkeys(keys if keys is not None else [*expected, *read])
    return [Differs(k, expected.get(k, missing), read.get(k, missing)) for k in names
            if expected.get(k, missing) != read.get(k, missing)]


# ------------------------------------------------------------------------------------------ F4
@dataclass(frozen=True)
class Addressed:
    """What F4 reads of a frame (a :class:`~.frame.Frame` has all of it): for a frame known only by its raw id."""

    kind: Kind
    type_id: int
    transfer_id: int | None
    destination: int | None
    source: int


def f4_mismatches(frame: Frame | Addressed, *, service: int, transfer_id: int | None, requester: int, asked: int | None) -> list[str]:
    """F4: what of ``frame`` differs from an answer to a request (``service``, ``transfer_id``) that ``requester`` sent
    to node ``asked`` (None: any node may answer, Set ID being a pseudo-broadcast, R11). Empty: it is that answer."""
    out = []
    if frame.type_id != service:
        out.append(f"service {frame.type_id} != the request's {service} (F4)")
    if frame.kind is not Kind.RESPONSE:
        out.append("request bit set in a response (F1/F4)")
    if frame.transfer_id != transfer_id:
        out.append(f"transfer id {frame.transfer_id} != request's {transfer_id} (F4)")
    if frame.destination != requester:
        out.append(f"destination {frame.destination} != requester {requester} (F4)")
    if asked is not None and frame.source != asked:
        out.append(f"source {frame.source} != the node asked, {asked} (F4)")
    return out


#: F4: a frame of the request's service that differs from its answer in at most this many other fields is still
#: taken as the answer (and failed with the field named), never as no answer
F4_PAIRING_SLACK = 1


def f4_pairs(mismatches: Sequence[str]) -> bool:
    """Whether a frame with ``mismatches`` (:func:`f4_mismatches`, same service) is taken as the request's answer."""
    return len(mismatches) <= F4_PAIRING_SLACK


def asked_node(name: str, destination: int) -> int | None:
    """The node an answer to request ``name`` sent to ``destination`` must come from (None: any, Set ID answers from
    its new id, R11)."""
    return None if name in cat.PSEUDO_BROADCAST else destination


def f4_answers(frame: Frame | Addressed, requests: Sequence[tuple[int, int | None, int, int | None]]) -> int | None:
    """F4: which of ``requests`` (each ``(service, transfer id, requester, node asked)``: the requests still open when
    the response ``frame`` came, in the order sent) it answers: the one whose service id, transfer id and requester
    it carries, from the node asked; else the first it is off from in at most :data:`F4_PAIRING_SLACK` fields (its
    answer, failed with the field named). None: it answers none of them. Never by order alone: an answer another
    request carries is not the open request's before it."""
    best: tuple[int, int] | None = None
    for i, (service, transfer_id, requester, asked) in enumerate(requests):
        if service != frame.type_id:
            continue
        off = len(f4_mismatches(frame, service=service, transfer_id=transfer_id, requester=requester, asked=asked))
        if best is None or off < best[0]:
            best = (off, i)
    return best[1] if best is not None and best[0] <= F4_PAIRING_SLACK else None


# ------------------------------------------------------------------------------------------ R18 a loaded bus
# (issue #30: the load generator is ckesc.protocol.load; the conformance module conformance/test_robustness_r18_load.py)

#: R18: foreign traffic up to this share of the bus's capacity at its bit rate is judged; above it, OBSERVE
R18_MAX_SHARE = 0.5
#: R18's load, as the suite plays it: over any window of length t its frames take at most ``share x t`` of bus time
#: plus this many longest frames (its bursts); :class:`ckesc.protocol.load.LoadSource` keeps to it by construction
R18_BURST_FRAMES = 4
#: R18 in real time: the load reached may fall this far short of the share asked (a player's share is measured
#: over a short run, its first and last bursts at the edges) before the bench is said not to have reached it
R18_SHARE_SHORTFALL = 0.1


def r18_judged(share: float) -> bool:
    """R18: whether a DUT is held to R9, R2 and the 64 ms bound under foreign traffic of ``share`` of the bus's
    capacity (up to half of it); above, what it does is recorded only (OBSERVE)."""
    return share <= R18_MAX_SHARE + _NOISE_S


def r18_reached(asked: float, reached: float) -> bool:
    """R18 in real time: whether a player that was asked for ``asked`` of the bus and measured ``reached`` made the
    load a test judges with (else the bench's limit: the test cannot judge the DUT at the share it names)."""
    return reached >= asked * (1 - R18_SHARE_SHORTFALL)


def r18_queueing_s(share: float, bitrate: int, *, late: float = 0.0) -> float:
    """R18: the longest queueing a load of ``share`` of the bus at ``bitrate`` can put ahead of a lowest-priority
    frame (which loses arbitration to every load frame), in seconds.

    Let ``C`` be the longest classic frame's time on the bus (8 data bytes, :func:`~.frame.frame_bits`, stuff bits
    not counted, as the share is not), ``u`` the share, and ``s = R18_BURST_FRAMES x C + u x late`` the load's burst:
    over any window of length ``t`` the load takes at most ``u t + s`` of bus time (a real-time player late by
    ``late`` sends the frames due meanwhile back to back: ``u x late`` more). A frame that becomes ready at ``t0``
    waits for the frame already on the bus (CAN does not preempt: at most ``C``), then for every load frame that
    arrives before the bus is free for it; the wait ``w`` therefore satisfies ``w = C + s + u w``, so

        w = (C + s) / (1 - u)        (for u <= 1/2: at most 2 (C + s); 500 kbit/s, u = 1/2: 2.6 ms)

    R18 widens R9 by it: a report due at ``d`` starts in ``[d, d + w]``, so each gap lies within ``w`` of its
    interval and the mean of ``n`` gaps within ``w / n`` (the delays cancel but at the two ends). R18 does not widen
    R2's slot or the 64 ms bound: it names the widening for R9 only ("keeps R9 (each gap widened by the queueing
    ...), R2 and the 64 ms bound"); an answer is MEDIUM and the suite's "high" load ranks between the answers and
    the reports (:mod:`ckesc.protocol.load`), so the only load queued ahead of an answer is the frame in flight,
    which R2 allows on any bus."""
    longest = frame_bits(8) / bitrate
    burst = R18_BURST_FRAMES * longest + share * max(late, 0.0)
    return (longest + burst) / (1.0 - share) if share < 1 else float("inf")


def r18_tells(interval: float, share: float, bitrate: int, *, late: float = 0.0) -> bool:
    """R18: whether a gap judged with the load's queueing (:func:`r18_queueing_s`, a late player's included) still
    tells a report one interval late, or a report missing, from one the load delayed: the widening is shorter than
    the interval. Where it is not, the bench's player was too late for R9 to be judged under its load."""
    return r18_queueing_s(share, bitrate, late=late) < interval


def r18_mean(starts: Sequence[float], interval: float, *, share: float, bitrate: int, error: float = 0.0,
             jitter: float = 0.0, late: float = 0.0, what: str = "report") -> Judgement | None:
    """R18 (R9 under load) on the mean of the gaps between ``starts``: held to R9's scheduling tolerance plus the
    load's queueing (:func:`r18_queueing_s`) and twice the DUT's declared ``jitter`` over the number of gaps
    (``limit``: R9's two ends), twice the bench's ``error`` over the number of gaps given to the DUT (``error``). Not judged
    (``judged`` False) where R9's own bound exceeds a quarter of the interval (:func:`r9_mean_tells`). None: fewer
    than two reports."""
    gaps = len(starts) - 1
    if gaps < 1:
        return None
    mean = (starts[-1] - starts[0]) / gaps
    w = r18_queueing_s(share, bitrate, late=late)
    return Judgement("R18", abs(mean - interval), SCHEDULING_TOLERANCE_S + (w + 2 * jitter) / gaps, "<=", 2 * error / gaps,
                     f"{what} every {mean * 1000:.3f} ms (mean of {gaps} gaps) under {share:.0%} load, not "
                     f"{interval * 1000:g} ms (R9, each gap widened by up to {w * 1000:.3f} ms of queueing)",
                     judged=r9_mean_tells(gaps, interval, error=error, jitter=jitter))


def r18_gap(gap: float, interval: float, *, share: float, bitrate: int, error: float = 0.0, jitter: float = 0.0,
            late: float = 0.0, what: str = "report") -> Judgement:
    """R18 (R9 under load) on one gap: within the scheduling tolerance, the load's queueing
    (:func:`r18_queueing_s`) and the DUT's declared ``jitter`` of ``interval`` (``limit``), twice the bench's
    ``error`` given to the DUT (``error``)."""
    w = r18_queueing_s(share, bitrate, late=late)
    return Judgement("R18", abs(gap - interval), SCHEDULING_TOLERANCE_S + w + jitter, "<=", 2 * error,
                     f"a {what} gap of {gap * 1000:.3f} ms under {share:.0%} load, not {interval * 1000:g} ms")
# ------------------------------------------------------------------------------------------ R19 (R17) resets
@dataclass(frozen=True)
class Reset:
    """R19 (and R17's "never resets"): one sign that the ESC restarted between two observations of it, the rule's id,
    what restarted (``power_ups``, ``run_time``, or the report's name) and the sign in words."""

    what: str
    text: str
    rule: str = "R19"

    def __str__(self) -> str:
        return f"[{self.rule}] {self.text}"


#: 241 option 2's power-up count is a u16: it wraps (the count after 65535 is 0, not a reset)
POWER_UPS_MODULO = 1 << 16


def r19_power_ups(previous: int, current: int) -> Reset | None:
    """R19: 241 option 2's power-up count, read ``previous`` and later ``current`` with the power left on, has not grown
    (modulo its u16 width). None: no reset shown; else the :class:`Reset`."""
    grown = (current - previous) % POWER_UPS_MODULO
    if not grown:
        return None
    return Reset("power_ups", f"the power-up count (241 option 2) went from {previous} to {current} with the power on")


def r19_run_time(previous: int, current: int, elapsed: float, *, error: float = 0.0) -> Reset | None:
    """R19: 241 option 1's run time (whole seconds), read ``previous`` and ``elapsed`` seconds later ``current``, went
    neither back nor forward by more than the time that passed: at most ``elapsed`` plus one count (two whole-second
    reads of a running count differ by up to one more than the seconds between them) plus the bench's ``error``. It
    may stand still (it counts the motor's running time): only a step back or a jump is a reset."""
    if current < previous:
        return Reset("run_time", f"the run time (241 option 1) went back from {previous} s to {current} s")
    if current - previous > elapsed + 1 + error + _NOISE_S:
        return Reset("run_time", f"the run time (241 option 1) jumped from {previous} s to {current} s in "
                     f"{elapsed:.3f} s")
    return None


def r19_counter_restarted(gap: float, interval: float | None, step: F3Step) -> bool:
    """R19, R9a: whether a report's counter started again across a ``gap`` between two consecutive reports of one
    frame type: the transfer id ``step`` (:func:`f3_step`) neither counted on by one nor by the reports the gap's
    length at ``interval`` says are missing (lost on the bus, F3; ``interval`` None: by one only). Such a report is
    the first after a restart of the ESC's reporting (R9a: its gap and the next are not judged); with a gap longer
    than a restart may take, a reset (:func:`r19_report_restart`)."""
    if step.ok:
        return False
    return interval is None or not step.explained_by(max(round(gap / interval) - 1, 0))


def r19_report_restart(gap: float, interval: float, step: F3Step, *, error: float = 0.0, jitter: float = 0.0,
                       what: str = "report") -> Reset | None:
    """R19: a report gap with a transfer id restart. ``gap``: the time between two consecutive reports of one frame
    type from the ESC, ``interval`` the report's interval, ``step`` the transfer ids across the gap (:func:`f3_step`).
    A reset shows as a gap longer than a restart may take (R9a's restart limit, :func:`r9a_limit_s`, and the bench's
    ``error``) across which the transfer id neither counted on by one (a late report: R9's, not a reset) nor by the
    reports the gap's length says are missing (lost on the bus, F3): a counter that starts again."""
    if gap <= r9a_limit_s(interval, jitter=jitter) + error + _NOISE_S or not r19_counter_restarted(gap, interval, step):
        return None
    return Reset(what, f"{what} stopped for {gap * 1000:.1f} ms (interval {interval * 1000:g} ms) and came back with "
                 f"{step}: its counter started again")


# ------------------------------------------------------------------------------------------ R20: a bus fault freed
#: R20: the bus rules left unjudged from a bus fault until each report type is back on its grid: the reports' timing
#: (held through bus-off and sent back to back at recovery) and their transfer-id sequence (whether a recovered ESC's
#: first reports keep it is OBSERVE: one whose mailboxes were full dropped some)
R20_UNJUDGED = frozenset({"R9", "R9a", "F3"})


def r20_bound_s(msg1_interval: float, *, bitrate: int) -> float:
    """R20: how long after a bus fault ends the ESC's reports may take to go on, before the bench's error: its
    controller's bus-off recovery at ``bitrate`` and two MSG1 intervals."""
    return recovery_seconds(bitrate) + 2 * msg1_interval


def r20_back(delay: float, msg1_interval: float, *, bitrate: int, error: float = 0.0) -> Judgement:
    """R20: the first MSG1 ``delay`` after the bus was freed (``math.inf``: none came) within :func:`r20_bound_s`
    and the bench's ``error``."""
    return Judgement("R20-recovery", delay, r20_bound_s(msg1_interval, bitrate=bitrate), "<=", error,
                     "the first MSG1 after the bus was freed")
