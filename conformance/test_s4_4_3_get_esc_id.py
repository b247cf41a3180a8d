"""Spec section 4.4.3: FRAME_MSG_GET_ESC_ID (20013) - every ESC replies [node_id, throttle_channel] in its slot."""

from __future__ import annotations

import pytest

from . import multi_esc
from .answers import answer_window_s, check_answer_slot, host_replies, query_esc_id, settle, slot_node
from .multi_esc import several_escs
from .telemetry import describe_garbled, garbled, ms

SECTION = "4.4.3"
escs = multi_esc.escs  # fixture: several ESCs on one bus, with the run's emulator faults
#: between queries: not a multiple of any report interval, so each query meets the reports at another phase
PHASE_STEP_S = 0.007


def _query(dut):
    """Broadcast the query and read every answer the 64 ms window (and as long again) brings."""
    settle(dut)
    return query_esc_id(dut, answer_window_s(dut))  # a late reply is seen, and measured


def _replies(dut, sent, node: int) -> list:
    return host_replies(dut, sent, source=node)


def _check_reply(dut, sent, node: int) -> object:
    """R1: exactly one reply from ``node``, 2 payload bytes [node_id, throttle_channel], node_id = source,
    the channel the node's own configuration (242) names."""
    bad = garbled(dut, "get_esc_id", source=node, since=sent.time)
    assert not bad, (f"[R1 READING] node {node}: GET_ESC_ID reply is not [node_id, throttle_channel] + tail: "
                     f"{describe_garbled(bad)}")
    replies = _replies(dut, sent, node)
    assert replies, f"node {node}: no GET_ESC_ID reply within {ms(answer_window_s(dut))} ms of the broadcast query"
    assert len(replies) == 1, f"node {node}: {len(replies)} replies to one query"
    r = replies[0]
    assert r.fields["node_id"] == r.source == node, (
        f"[R1 READING] reply names node {r.fields['node_id']} but comes from node {r.source} (expected {node})")
    channel = dut.ask("get_major_configuration", {"option": 0}, destination=node)["throttle_channel"]
    assert r.fields["throttle_channel"] == channel, (
        f"node {node}: reply names throttle channel {r.fields['throttle_channel']}, its configuration (242) {channel}")
    return r


@pytest.mark.requirement("4.4.3-1", "4.4.3-3", "R1")
def test_reply_is_node_id_and_throttle_channel(dut):
    """The broadcast query is answered with exactly [node_id, throttle_channel]: no option byte
    (4.4.3-3 read as R1), node_id equal to the frame's source."""
    sent = _query(dut)
    r = _check_reply(dut, sent, dut.node_id)
    dut.record.observe("reply", r.fields)


@pytest.mark.requirement("4.4.3-4", "R2")
@pytest.mark.may_power_cycle  # slot_node: Set ID in a fresh window on a coarse bench
def test_reply_comes_in_the_node_slot(dut):
    """The reply starts (node_id % 32) x 2 ms after the query, within that 2 ms slot, never later than
    64 ms. Three queries, each meeting the periodic reports at another phase. On a bench whose error is not
    smaller than node 1's slot, at a node id whose slot it can tell (slot_node: Set ID there and back)."""
    with slot_node(dut) as node:
        for n in range(3):
            dut.wait(n * PHASE_STEP_S)
            sent = _query(dut)
            # a malformed reply (R1, its own test) still has a time
            replies = _replies(dut, sent, node) or [g.msg for g in garbled(dut, "get_esc_id", source=node, since=sent.time)]
            assert replies, f"query {n + 1}: no GET_ESC_ID reply from node {node} within {ms(answer_window_s(dut))} ms"
            check_answer_slot(dut, replies[0], sent, node, f"GET_ESC_ID query {n + 1}", "4.4.3-4")


@pytest.mark.requirement("4.4.3-2", "4.4.3-4", "R1", "R2")
def test_every_esc_replies_in_its_slot(escs):
    """All ESCs on the bus reply, each once, with its own id and channel, each in its own slot
    (node ids sharing node_id % 32 share a slot and go out by arbitration)."""
    nodes = several_escs(escs, "all ESCs")
    sent = _query(escs)
    heard = sorted({f.source for f in escs.frames("get_esc_id", since=sent.time) if f.source != escs.host_node})
    escs.record.observe("nodes", {"discovered": nodes, "replied": heard})
    for node in sorted(set(nodes) | set(heard)):  # each node discovery found, and any it missed
        r = _check_reply(escs, sent, node)
        check_answer_slot(escs, r, sent, node, "GET_ESC_ID", "4.4.3-4")
