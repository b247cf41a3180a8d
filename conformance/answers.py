"""Answers to the host's commands, as the sections that send them read them (not a section: no
tests here): the answer slots of R2 (:func:`check_answer_slot`, and :func:`slot_node`, which moves the
DUT to a node id whose slot a coarse bench can tell), how long to read for an answer to a broadcast, an
answer a test compares with (:func:`reference`), what came instead of an answer that did not decode
(:func:`heard_instead`), which query a GET_ESC_ID reply answers (:func:`esc_id_pairings`, the decision of
:class:`~ckesc.evidence.pairing.QueryPairing` that the bus rules and the soak take too), and who answers
GET_ESC_ID (:func:`esc_ids`, :func:`put_back`, used by Set ID's tests too).
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Iterable
from weakref import WeakKeyDictionary

import pytest

from ckesc.bench.dut import restoring
from ckesc.bench.errors import RestoreFailed
from ckesc.bench.outcomes import Inconclusive
from ckesc.evidence.pairing import QueryPairing, ReplyPairing
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import Frame, classify
from ckesc.protocol.ids import DEFAULT_ESC_NODE_ID, Kind
from ckesc.protocol.judgements import answer_bound, r2_slot_end, r2_slot_start
from ckesc.protocol.requirements import Verdict

from .telemetry import frame_end, frame_start, ms, on_bus_s

#: Every ESC answers a broadcast within 64 ms (R2); the harness's discovery reads twice that
BROADCAST_WINDOW_S = 2 * cat.ANSWER_DELAY_MAX_S


def answer_window_s(dut) -> float:
    """How long a test reads for the answer to a broadcast command: twice the 64 ms limit, plus the
    lane's stated timing error, so that an answer late by up to that error is seen and measured
    (INCONCLUSIVE there), not taken for no answer."""
    return 2 * cat.ANSWER_DELAY_MAX_S + dut.lane.timing_error


def settle(dut) -> None:
    """Let any answer to an earlier broadcast (the fixture's own MSG Control, a late one) arrive first."""
    dut.wait(2 * cat.ANSWER_DELAY_MAX_S)


#: How often a GET_ESC_ID query is sent again when another node's query made its replies ambiguous
QUERY_TRIES = 3


def esc_id_pairings(frames: Iterable[Frame], *, host: int, error: float) -> list[tuple[Frame, ReplyPairing]]:
    """Each GET_ESC_ID reply among ``frames`` (any node's, in time order) with what it answers: the host's query,
    another node's (a flight controller's, F6), either, or none (:class:`~ckesc.evidence.pairing.QueryPairing`, the
    decision the bus rules and the soak take too), every query among ``frames`` fed to it."""
    pairing = QueryPairing(error=error, host=host)
    out = []
    for f in sorted((f for f in frames if f.name == "get_esc_id" and f.layout is not None), key=lambda f: f.timestamp or 0.0):
        if f.layout.name == "query":  # type: ignore[union-attr]
            pairing.query(f.timestamp or 0.0, f.source)
        else:
            out.append((f, pairing.reply(f.timestamp or 0.0, f.source)))
    return out


#: per DUT: (its trace's length and last frame, the pairing of its GET_ESC_ID replies then), made again when it changed
_PAIRED: WeakKeyDictionary = WeakKeyDictionary()


def _pairings(dut) -> dict[int, ReplyPairing]:
    """:func:`esc_id_pairings` over the DUT's trace, by the reply frame's ``id``."""
    mark = (len(dut.trace), id(dut.trace[-1]) if dut.trace else None)
    kept = _PAIRED.get(dut)
    if kept is None or kept[0] != mark:
        paired = esc_id_pairings(dut.frames("get_esc_id"), host=dut.host_node, error=delay_error(dut))
        kept = _PAIRED[dut] = (mark, {id(f): p for f, p in paired}, paired)  # (the frames kept: their ids stay theirs)
    return kept[1]


def query_esc_id(dut, read_s: float):
    """Broadcast the GET_ESC_ID query and read ``read_s``: the host's ``Sent``; its replies are :func:`host_replies`.
    A reply is a broadcast that names no query, so where a reply since then may answer the host's query or another
    node's (a flight controller's, once a second, asked within 64 ms before it: :func:`esc_id_pairings`), which
    cannot be told: the host asks again, at most :data:`QUERY_TRIES` times, and is INCONCLUSIVE if it never could
    tell. A reply that answers the other node's query only is that node's, and no reason to ask again. On a quiet
    bus: one query. (A reply that answers no query is the DUT's, judged by the caller.)"""
    for _ in range(QUERY_TRIES):
        sent = dut.broadcast("get_esc_id", {"option": 0}, layout="query")
        dut.wait(read_s)
        paired = _pairings(dut)
        if not any(p.ambiguous(dut.host_node) for f in dut.frames("get_esc_id", since=sent.time)
                   if (p := paired.get(id(f))) is not None):
            return sent
    raise Inconclusive(f"another node's GET_ESC_ID queries came within {ms(cat.ANSWER_DELAY_MAX_S)} ms of the replies "
                       f"to each of {QUERY_TRIES} queries: which query a reply answers cannot be told")


def host_replies(dut, sent, *, source: int | None = None) -> list[Frame]:
    """The GET_ESC_ID replies since the host's query ``sent`` (:func:`query_esc_id`; ``source``: one node's) that
    are the host's to judge: every one but those that answer another node's query only (a flight controller's, F6)."""
    paired = _pairings(dut)
    return [f for f in dut.frames("get_esc_id", since=sent.time, source=source)
            if f.layout is not None and f.layout.name == "reply"
            and not ((p := paired.get(id(f))) is not None and p.may_answer_another(dut.host_node)
                     and not p.ambiguous(dut.host_node))]


def answers_another_node(dut, f) -> bool:
    """``f`` is a GET_ESC_ID reply that may answer another node's query (a flight controller's, F6), not one to
    anything the host sent (:func:`esc_id_pairings`; a second reply to a query it answered already is not)."""
    if f.name != "get_esc_id" or f.layout is None or f.layout.name != "reply":
        return False
    p = _pairings(dut).get(id(f))
    return p is not None and p.may_answer_another(dut.host_node)


def reference(dut, name: str, fields: dict | None = None, *, need: tuple[str, ...] = (), **kw) -> dict:
    """An answer the test compares with (not what it checks): none, one that does not decode, or one
    without the ``need``-ed fields makes the test INCONCLUSIVE rather than failing the frame under test."""
    ex = dut.request(name, fields, **kw)
    if ex.response is None or any(k not in ex.response.fields for k in need):
        raise Inconclusive(f"{name} {fields or ''}: no decodable answer to compare with")
    return ex.response.fields


def delay_error(dut, sent=None) -> float:
    """The error (s) of an answer's delay from the request: the bench's stated error, or the larger error of
    the request's own time where it is the host clock at send (an adapter without echo; ``sent.error``)."""
    return max(dut.lane.timing_error, dut.lane.own_error if sent is None else sent.error)


def tells(node: int, error: float) -> bool:
    """Whether, on a bench with ``error``, node ``node``'s slot tells an answer that waits for it from one sent at
    once (inside the first 2 ms slot after the request, whatever the node id): the slot's start less the error
    is not before the first slot's end plus the error."""
    return cat.answer_slot_s(node) - 2 * error >= cat.ANSWER_SLOT_S - 1e-12


def wide_node(error: float) -> int | None:
    """The node id the answer-slot tests move the DUT to on a bench with ``error`` where its own slot does not
    tell (:func:`tells`): the latest slot whose end stays decisively within 64 ms (its end plus twice the error),
    so that an ESC that ignores the stagger and answers at any fixed delay up to that slot's start less twice the
    error (at once, after 10 ms, ...) answers decisively before it. None: no node id below 32 does both."""
    n = math.floor(round((cat.ANSWER_DELAY_MAX_S - cat.ANSWER_SLOT_S - 2 * error) / cat.ANSWER_SLOT_S, 9))
    n = min(n, cat.ANSWER_SLOTS - 1)
    return n if n >= 2 and tells(n, error) and n != DEFAULT_ESC_NODE_ID else None


def request_end(dut, sent) -> float:
    """When the DUT had the whole request (its last bit), from which its answer slot counts: the request's echo's
    stamp where it marks the frame's end, that stamp and its time on the bus where the lane's stamps mark a frame's
    start (a host clock time at send, without an echo, is taken as it is: its stated error covers the frame)."""
    if sent.bus_time is not None and dut.lane.stamp == "start":
        return sent.time + on_bus_s(dut, sent.wire)
    return sent.time


def check_answer_slot(dut, answer, sent, node: int, what: str, max_requirement: str) -> None:
    """R2: node n's slot is [n x 2 ms, n x 2 ms + 2 ms] after the request (n = node_id % 32; the 32 slots tile the
    64 ms): the answer starts no earlier than its slot and ends inside it; ``max_requirement`` (4.4.2-4 /
    4.4.3-4): never later than 64 ms. Measured from the request's bus time (its echo), or where the bench does
    not echo from the host clock at send, with that clock's larger error (``sent.clock``, ``sent.error``).

    Each slot edge is judged with the bench's error given to the DUT: the answer fails only where it is
    certainly outside its slot (its start more than the error before the slot's start, its end more than the
    error after the slot's end), so that a correct ESC - one answering at its slot's start included - passes
    on any bench. Where the slot does not tell an answer sent at once from one in the slot at that error
    (:func:`tells`; :func:`slot_node` moves the DUT to one that does), a start that passes is INCONCLUSIVE,
    saying so. The 64 ms bound (a SHALL) is measured with the error as usual.

    A request sent while the host was alone on the bus (the ESC off or booting) and without an echo is not timed: a
    real adapter held it until the ESC's controller came up, and when it went out is not known (R20: INCONCLUSIVE,
    saying so, never a FAIL); with an echo it is timed from the echo, as every request is."""
    if (held := sent.held) is not None:
        dut.record.inconclusive.append(f"{what} node {node}: the answer's delay is not judged: the request was {held} "
                                       "(R20)")
        return
    slot = cat.answer_slot_s(node)
    error = delay_error(dut, sent)
    err = error * 1000
    heard = request_end(dut, sent)
    start, end = frame_start(dut, answer) - heard, frame_end(dut, answer) - heard
    rec = dut.record
    first, last = r2_slot_start(start, node, error=error), r2_slot_end(end, node, error=error)
    lo, hi = first.limit - first.error, last.limit + last.error  # (the DUT is given the error: judged on these)
    if error:
        rec.observe(f"{what} node {node}: slot judged", f"{ms(lo):g}..{ms(hi):g} ms: the 2 ms slot {ms(slot):g}.."
                    f"{ms(slot + cat.ANSWER_SLOT_S):g} ms widened by the bench's stated error +-{err:g} ms on each side "
                    "(an answer fails only where it is certainly outside its slot)")
    low = rec.measure(f"{what} node {node}: answer start after the request (slot start - bench error)", ms(start),
                      limit=ms(lo), op=">=", unit="ms", clock=sent.clock, requirement="R2", strength="READING")
    rec.measure(f"{what} node {node}: answer end after the request (slot end + bench error)", ms(end), limit=ms(hi),
                unit="ms", clock=sent.clock, requirement="R2", strength="READING")
    if low.verdict != Verdict.FAIL and not tells(node, error):
        rec.inconclusive.append(f"the bench's stated error +-{err:g} ms: at node {node} (slot {ms(slot):g} ms) it cannot "
                                "tell an answer in its slot from one sent at once, whatever the node id (the DUT's own "
                                "slot tests move it to a slot that tells)")
    bound = answer_bound(end, error=error, rule=max_requirement)
    rec.measure(f"{what} node {node}: answer delay", ms(bound.measured), limit=ms(bound.limit), unit="ms",
                clock=sent.clock, error=err, requirement=bound.rule)


def esc_id_replies(dut) -> list[tuple[int, int]]:
    """(node id, throttle channel) of each GET_ESC_ID reply (R1) to one broadcast query, by the reply's source."""
    sent = query_esc_id(dut, BROADCAST_WINDOW_S)  # every ESC answers within 64 ms (R2)
    return [(f.source, f.fields["throttle_channel"]) for f in host_replies(dut, sent)]


def esc_ids(dut) -> list[tuple[int, int]]:
    """The distinct (node id, throttle channel) pairs that answer GET_ESC_ID."""
    return sorted(set(esc_id_replies(dut)))


#: lane seconds of the current window that must be left to restore the node id in it without a power cycle
RESTORE_IN_WINDOW_S = 10.0


def _set_id_at(dut, ids: list[int], node: int, channel: int) -> None:
    for dest in dict.fromkeys([*ids, node]):  # to each id it may listen at (R11 says any)
        dut.request("set_id", {"node_id": node, "throttle_channel": channel}, destination=dest)


def put_back(dut, node: int, channel: int) -> None:
    """Put the DUT back at ``node`` on ``channel`` and verify: RestoreFailed (the harness's, never the DUT's verdict)
    when it is not. Set ID (a pseudo-broadcast, R11) goes inside the window of the DUT's current power-up while
    :data:`RESTORE_IN_WINDOW_S` of it is left (no power cycle), else, or when that did not take, inside a fresh window
    after a power cycle."""
    with restoring(f"the DUT at node id {node}, channel {channel}"):
        found = esc_ids(dut)
        if found and found != [(node, channel)] and dut.window_left() >= RESTORE_IN_WINDOW_S:
            _set_id_at(dut, [n for n, _ in found], node, channel)
            found = esc_ids(dut)
        if found != [(node, channel)]:
            dut.switch_power()  # a fresh 120 s window (R11)
            found = esc_ids(dut)
            _set_id_at(dut, [n for n, _ in found], node, channel)
            found = esc_ids(dut)
    dut.node_id = node
    if found != [(node, channel)]:
        raise RestoreFailed(f"could not put the DUT back at node id {node}, channel {channel}: GET_ESC_ID answers {found}")


@pytest.fixture
def original(dut):
    """(node id, channel) before the test; put back afterwards, whatever happened (Set ID's section and the
    robustness section's malformed Set ID). INCONCLUSIVE when another ESC answers GET_ESC_ID too."""
    found = esc_ids(dut)
    if found != [(dut.node_id, dut.settings()["throttle_channel"])]:
        raise Inconclusive(f"GET_ESC_ID answers {found}, not just the DUT (node {dut.node_id}): Set ID needs one ESC "
                           "on the bus, and its effects are read with GET_ESC_ID (see 4.4.3)")
    node, channel = found[0]
    try:
        yield node, channel
    finally:
        put_back(dut, node, channel)


@contextmanager
def slot_node(dut):
    """The node id at which the answer slots (R2) are checked, for the ``with`` block: the DUT's own, unless at the
    bench's error (:func:`delay_error`) its slot cannot tell an answer in it from one sent at once (:func:`tells`).
    Then the DUT is moved to :func:`wide_node` with Set ID inside the 120 s window of a
    proven power cycle (R11), proven there by GET_ESC_ID, and moved back and proven afterwards on every way
    out (RestoreFailed when it cannot be). Where no node id tells, there is no power control to open the window, or
    other ESCs share the bus (Set ID moves every one), the DUT's own node id, saying why: there the answer's start
    is INCONCLUSIVE (:func:`check_answer_slot`) and the slot's end and the 64 ms bound (a SHALL) are still judged.
    INCONCLUSIVE, saying why, when Set ID does not move it (4.4.18's verdict)."""
    error = delay_error(dut)
    if tells(dut.node_id, error):
        yield dut.node_id
        return
    target = wide_node(error)
    why = (f"at the bench's stated error +-{ms(error):g} ms node {dut.node_id}'s answer slot ({ms(cat.answer_slot_s(dut.node_id)):g} ms "
           "after the request) cannot tell an answer in it from one sent at once: whether its answers wait for their "
           f"slot (R2) shows only at a node id whose slot starts at least {ms(2 * error + cat.ANSWER_SLOT_S):g} ms after "
           "it; the latest slot that keeps 64 ms decisively tells the most")
    found = esc_ids(dut) if target is not None and dut.lane.power.available else []
    stay = ""
    if target is None:
        stay = f"{why}, and none below 32 does"
    elif not dut.lane.power.available:
        stay = (f"{why} (node {target}), and moving it there needs Set ID's window after a power-up (R11): no power "
                "control (--power)")
    elif [n for n, _ in found] != [dut.node_id]:
        stay = f"{why} (node {target}); GET_ESC_ID answers {found}: Set ID would move every ESC on the bus"
    if stay:  # the slot's start stays INCONCLUSIVE (check_answer_slot), its end and the 64 ms bound are judged here
        dut.record.observe("answer slots checked at", f"node {dut.node_id} (its own): {stay}")
        dut.record.inconclusive.append(stay)  # (a broken limit still FAILs the test)
        yield dut.node_id
        return
    node, channel = found[0]
    dut.open_window()  # a Set ID window (R11) with nothing sent in it yet
    try:
        dut.request("set_id", {"node_id": target, "throttle_channel": channel})
        dut.node_id = target
        moved = esc_ids(dut)
        if moved != [(target, channel)]:
            raise Inconclusive(f"{why}; Set ID did not move the DUT to node {target} (GET_ESC_ID answers {moved}, "
                               "see 4.4.18)")
        dut.record.observe("answer slots checked at", f"node {target} (moved from {node} with Set ID and back): {why}")
        yield target
    finally:
        put_back(dut, node, channel)


def heard_instead(dut, spec: cat.FrameSpec) -> str:
    """What the DUT sent instead, when its answer did not decode (for the failure message)."""
    bad = [g for g in dut.garbled if (c := classify(g.msg.arbitration_id))[4] is spec and c[0] is Kind.RESPONSE and c[2] == dut.node_id]
    return "".join(f"; heard instead: {len(g.msg.data)} data bytes ({g.error})" for g in bad[:2])
