"""Answers to the host's commands, as the sections that send them read them (not a section: no
tests here): the answer slots of R2 (:func:`check_answer_slot`), how long to read for an answer to a
broadcast, an answer a test compares with (:func:`reference`), and what came instead of an answer
that did not decode (:func:`heard_instead`).
"""

from __future__ import annotations

from ckesc.harness.verdict import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify
from ckesc.protocol.ids import Kind

from .reports import frame_start, ms

#: R2: the answer slots, (node_id % SLOTS) x ANSWER_SLOT_S, the last one ending at ANSWER_DELAY_MAX_S
SLOTS = round(cat.ANSWER_DELAY_MAX_S / cat.ANSWER_SLOT_S)
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


def reference(dut, name: str, fields: dict | None = None, *, need: tuple[str, ...] = (), **kw) -> dict:
    """An answer the test compares with (not what it checks): none, one that does not decode, or one
    without the ``need``-ed fields makes the test INCONCLUSIVE rather than failing the frame under test."""
    ex = dut.request(name, fields, **kw)
    if ex.response is None or any(k not in ex.response.fields for k in need):
        raise Inconclusive(f"{name} {fields or ''}: no decodable answer to compare with")
    return ex.response.fields


def check_answer_slot(dut, answer, sent, node: int, what: str, max_requirement: str) -> None:
    """R2: an answer starts no earlier than (node_id % 32) x 2 ms after the request and ends within its
    2 ms slot; ``max_requirement`` (4.4.2-4 / 4.4.3-4): never later than 64 ms. Measured from the
    request's bus time (its echo), or where the bench does not echo from the host clock at send, with
    that clock's larger error (``sent.clock``, ``sent.error``)."""
    slot = (node % SLOTS) * cat.ANSWER_SLOT_S
    err = sent.error * 1000
    start, end = frame_start(dut, answer) - sent.time, answer.timestamp - sent.time
    rec = dut.record
    rec.measure(f"{what} node {node}: answer start after the request", ms(start), limit=ms(slot), op=">=", unit="ms",
                clock=sent.clock, error=err, requirement="R2", strength="READING")
    rec.measure(f"{what} node {node}: answer end after the request", ms(end), limit=ms(slot + cat.ANSWER_SLOT_S),
                unit="ms", clock=sent.clock, error=err, requirement="R2", strength="READING")
    rec.measure(f"{what} node {node}: answer delay", ms(end), limit=ms(cat.ANSWER_DELAY_MAX_S), unit="ms",
                clock=sent.clock, error=err, requirement=max_requirement)


def heard_instead(dut, spec: cat.FrameSpec) -> str:
    """What the DUT sent instead, when its answer did not decode (for the failure message)."""
    bad = [g for g in dut.garbled if (c := classify(g.msg.arbitration_id))[4] is spec and c[0] is Kind.RESPONSE and c[2] == dut.node_id]
    return "".join(f"; heard instead: {len(g.msg.data)} data bytes ({g.error})" for g in bad[:2])
