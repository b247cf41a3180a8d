"""Spec section 4.1: UAVCAN protocols - the frame format: message and service frames (4.1.1), the
29-bit CAN id and node ids (4.1.2), the tail byte and transfer ids (4.1.3), and commands from a host
other than node 0 (F6).

Framing is judged on every frame the DUT sends, in two scopes (the ``scope`` parameter):

* ``provoked``: the traffic this module provokes itself (:func:`provoke`): every kind of frame a
  DUT sends - MSG1..MSG3, MSG_EXP frames, CAN Test frames, answers to broadcast commands, answers
  to every read-only service request, temperature records - heard for a few seconds in one
  unbroken stretch, so the module means something when run alone. Frames that did not decode are
  judged too, from their raw CAN id and data.
* ``run`` (marked ``last``): the same checks on every frame the DUT sent in the whole run (the
  plugin's ``dut_segments``) plus a fresh provoked capture. The run-wide record holds decoded frames
  only (see :func:`run_heard`).

The wire helpers it shares with section 4.3's module (:class:`HeardFrame`, :func:`provoke`,
:func:`provoked_traffic`, :func:`in_scope`) are in ``conformance/wire.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from ckesc.bench.errors import RestoreFailed
from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import Frame, classify, encode
from ckesc.protocol.ids import DEFAULT_ESC_NODE_ID, ESC_NODE_IDS, Kind
from ckesc.protocol.judgements import Addressed, asked_node, f3_step, f4_mismatches
from ckesc.protocol.transfer import TransferIdCounter, parse_tail

from . import wire
from .answers import BROADCAST_WINDOW_S
from .codes import code
from .telemetry import read_request
from .throttle import command_for
from .wire import QUERIES, SCOPES, HeardFrame, check_each, describe, in_scope, run_heard

SECTION = "4.1"
traffic = wire.traffic  # fixture: the provoked traffic, once per module

INTERVALS = cat.INTERVAL_FIELDS
#: The reports whose interval Set/Get Freq sets (R9): MSG1, MSG2, MSG3
REPORTS = cat.REPORT_FRAMES
SHORTEST_S = cat.REPORT_INTERVAL_RANGE[0] * cat.INTERVAL_UNIT_S
#: ArduPilot's default node id, from which it sends GET_ESC_ID and RawCommand (INTERPRETATIONS, F6)
ARDUPILOT_NODE = 10


# ------------------------------------------------------------------------------------------ the rules, per frame
def id_layout_problems(h: HeardFrame) -> list[str]:
    """F1 (4.1.2): 29-bit extended data frames; a service frame from the ESC answers a request (request
    bit 0); no anonymous message frames (4.1.2: only message and service frames are used)."""
    if not h.extended:
        return ["standard 11-bit id: only 29-bit extended frames are used"]
    if h.remote:
        return ["remote frame: all data is transmitted via data frames"]
    cid = h.cid
    if cid.kind is Kind.REQUEST:
        return ["service frame with the request bit set: the ESC's service frames answer the host's requests"]
    if cid.kind is Kind.MESSAGE and cid.anonymous:
        return ["anonymous message frame (source node 0): only message and service frames are used"]
    return []


def tail_problems(h: HeardFrame) -> list[str]:
    """F2 / 4.1.3: every frame is a single-frame transfer: start=1, end=1, toggle=0."""
    if not h.extended or not h.has_tail:
        return []
    if not h.data:
        return ["no data, so no tail byte (every frame ends with one)"]
    t = parse_tail(h.data[-1])
    out = []
    if not t.start:
        out.append("tail byte start of transfer = 0 (4.1.3-start)")
    if not t.end:
        out.append("tail byte end of transfer = 0 (4.1.3-end)")
    if t.toggle:
        out.append("tail byte toggle = 1 (4.1.3-toggle)")
    return out


def source_problems(h: HeardFrame) -> list[str]:
    """4.1.2-N2 / F7: an ESC's node id is 1..0x7D; 0 is 'unknown', 0x7E and 0x7F are reserved."""
    if not h.extended:
        return []
    src = h.cid.source
    if src not in ESC_NODE_IDS:
        return [f"source node id {src:#04x} is not an ESC node id ({ESC_NODE_IDS.start:#04x}..{ESC_NODE_IDS.stop - 1:#04x})"]
    return []


def counter_streams(frames: list[HeardFrame]) -> dict[tuple[int, int], list[HeardFrame]]:
    """The frames that carry a transfer-id counter, by (source node, message type), in order. Service
    responses carry the request's transfer id (F4) and MSG_EXP12 names its record with it (R15): not
    counters; RawCommand_10b (the host's) has no tail byte."""
    streams: dict[tuple[int, int], list[HeardFrame]] = {}
    for h in frames:
        if not h.extended or h.remote or h.transfer_id is None:
            continue
        cid, spec = h.cid, h.spec
        if cid.kind is Kind.MESSAGE and (spec is None or spec.tail_tag is None):
            streams.setdefault((cid.source, cid.type_id), []).append(h)
    return streams


def counting_problems(stream: list[HeardFrame], adjacent: Callable[[HeardFrame, HeardFrame], bool] | None = None
                      ) -> tuple[list[tuple[HeardFrame, str]], int, int]:
    """F3 / 4.1.3-tid: +1 per transfer, modulo 32, between consecutive frames of one stream;
    ``adjacent`` says which pairs provably had no frame of the stream between them (None: all of
    them, one unbroken capture). Returns (problems, pairs checked, wrap-arounds seen)."""
    problems: list[tuple[HeardFrame, str]] = []
    pairs = wraps = 0
    for prev, h in zip(stream, stream[1:]):
        if adjacent is not None and not adjacent(prev, h):
            continue
        pairs += 1
        step = f3_step(prev.transfer_id, h.transfer_id)  # type: ignore[arg-type]
        wraps += step.wrapped
        if not step.ok:
            problems.append((h, str(step)))
    return problems, pairs, wraps


def run_counting_problems(frames: list[HeardFrame], error_s: float) -> list[tuple[HeardFrame, str]]:
    """F3 on the run-wide record, where frames are missing between tests (see :func:`run_heard`). Only
    MSG1/MSG2/MSG3 pairs from one test's capture are judged (frames heard between tests are in no
    record), and only pairs less than 1.5 shortest legal report intervals apart: a report comes at
    least that interval after the last of its type (R9), so nothing of the stream (nor a power cycle)
    can lie between them. The record is cut between tests and where time runs backwards
    (``multi_dut``'s bench has its own clock), and a stream with two frames closer than that interval
    is skipped: two ESCs sharing a node id (what Set ID does to a bench, 4.4.18-2), or a DUT whose
    intervals break R9 (section 4.4.22's verdict), where no pair is provably adjacent."""
    shortest = SHORTEST_S - error_s
    segments: list[list[HeardFrame]] = [[]]
    for h in frames:
        if segments[-1] and (h.timestamp < segments[-1][-1].timestamp or h.segment != segments[-1][-1].segment):
            segments.append([])
        segments[-1].append(h)
    problems: list[tuple[HeardFrame, str]] = []
    for segment in segments:
        for stream in counter_streams(segment).values():
            spec = stream[0].spec
            if spec is None or spec.name not in REPORTS:
                continue
            gaps = [b.timestamp - a.timestamp for a, b in zip(stream, stream[1:])]
            if any(g < shortest for g in gaps):
                continue
            problems += counting_problems(stream, lambda a, b: b.timestamp - a.timestamp < 1.5 * SHORTEST_S)[0]
    return problems


# ------------------------------------------------------------------------------------------ tests: every frame
@pytest.mark.requirement("F1")
@pytest.mark.parametrize("scope", SCOPES)
def test_frames_are_29_bit_message_or_service_frames(traffic, ckesc_run, scope):
    """Every frame the DUT sends is a 29-bit extended data frame with the F1 layout: a message frame
    (not an anonymous one), or a service frame answering a request (request bit 0)."""
    frames = in_scope(scope, traffic, ckesc_run)
    problems = check_each(frames, id_layout_problems)
    assert not problems, f"[F1] {describe(problems)}"


@pytest.mark.requirement("F2", "4.1.3-start", "4.1.3-end", "4.1.3-toggle")
@pytest.mark.parametrize("scope", SCOPES)
def test_tail_byte_marks_a_single_frame_transfer(traffic, ckesc_run, scope):
    """Every frame the DUT sends ends with a tail byte start=1, end=1, toggle=0 (RawCommand_10b, the
    one frame without a tail byte, is the host's)."""
    frames = in_scope(scope, traffic, ckesc_run)
    problems = check_each(frames, tail_problems)
    assert not problems, describe(problems)


@pytest.mark.requirement("F3", "4.1.3-tid")
@pytest.mark.parametrize("scope", SCOPES)
def test_transfer_ids_count_per_frame_type(traffic, ckesc_run, scope):
    """Consecutive frames of one message type carry transfer ids +1 modulo 32 (the provoked capture
    has more than 32 MSG1 frames: the wrap from 31 to 0 is seen). Frames the DUT held while the host was away (a
    reopen at another bit rate before: the bus reader's held stretch) are taken alone: R20 leaves their transfer ids
    OBSERVE."""
    problems, pairs = [], 0
    for stream in counter_streams(traffic.heard).values():
        more, n, _ = counting_problems(stream, traffic.adjacent)  # not across what the DUT held (R20, the reader)
        problems, pairs = problems + more, pairs + n
    assert pairs, "no two frames of one message type in the capture: nothing to check"
    if scope == "run":
        lane = ckesc_run.lane
        problems += run_counting_problems(run_heard(ckesc_run), lane.timing_error if lane else 0.0)
    assert not problems, describe(problems)


@pytest.mark.requirement("4.1.2-N2", "F7")
@pytest.mark.parametrize("scope", SCOPES)
def test_source_is_an_esc_node_id(traffic, ckesc_run, scope):
    """Every frame the DUT sends comes from a node id in 1..0x7D."""
    frames = in_scope(scope, traffic, ckesc_run)
    problems = check_each(frames, source_problems)
    assert not problems, describe(problems)


# ------------------------------------------------------------------------------------------ tests: messages, services
@pytest.mark.requirement("4.1.1-1", "4.4.2-2", "4.4.2-4", "4.4.3-2", "4.4.3-4")
def test_broadcast_commands_reach_the_esc(traffic):
    """A message frame is a broadcast that every node receives: the DUT answers the broadcast
    commands GET_ESC_ID and MSG Control (addressed to no node) with message frames."""
    missing = [cat.spec(name).title for name, answers in traffic.broadcasts.items() if not answers]
    assert not missing, (f"no answer to the broadcast {', '.join(missing)} within {BROADCAST_WINDOW_S * 1000:.0f} ms "
                         "(plus the lane's timing error)")


@pytest.mark.requirement("4.1.1-2")
def test_every_request_is_answered(traffic):
    """A service frame 'requires a service answer': every read-only request of the catalogue that has
    a response is answered by a service frame with its service id."""
    missing = [a.label for a in traffic.asked.values() if not a.answers]
    assert not missing, f"no service frame answered {', '.join(missing)} (node {traffic.node})"


@pytest.mark.requirement("F4")
@pytest.mark.parametrize("label", [q[0] for q in QUERIES])
def test_answer_matches_its_request(traffic, label):
    """The answer keeps the request's service id and transfer id, has request=0, goes to the requester
    and comes from the ESC's node id."""
    a = traffic.asked[label]
    if not a.answers:
        raise Inconclusive(f"{label}: no answer to check (4.1.1-2 fails that)")
    h = a.answers[0]
    cid = h.cid
    problems = f4_mismatches(Addressed(cid.kind, cid.type_id, h.transfer_id, cid.destination, cid.source),
                             service=cat.spec(a.name).type_id, transfer_id=a.transfer_id, requester=traffic.host,
                             asked=asked_node(a.name, traffic.node))
    assert not problems, f"answer to {label}: {'; '.join(problems)}: {h}"
    assert len(a.answers) == 1, f"{len(a.answers)} answers to one {label} request: {'; '.join(map(str, a.answers))}"


# ------------------------------------------------------------------------------------------ tests: node ids
def alone_on_bus(dut) -> None:
    """Set ID re-addresses every ESC on the bus (4.4.18-2): a test that uses it needs the DUT alone."""
    sent = dut.broadcast("get_esc_id", {"option": 0}, layout="query")
    dut.wait(BROADCAST_WINDOW_S)
    nodes = {f.source for f in dut.frames("get_esc_id", since=sent.time) if f.layout is not None and f.layout.name == "reply"}
    if len(nodes) > 1:
        pytest.skip(f"several ESCs answer GET_ESC_ID ({sorted(nodes)}): Set ID would re-address all of them")


@pytest.mark.requirement("F7")
@pytest.mark.power_cycle
def test_silent_at_the_default_node_id(dut):
    """At the factory default node id 0x7D the ESC reports nothing on its own (4.4.18 note 4). Set ID
    counts only within 120 s of power-up (R11): the test cycles power, sets 0x7D, listens for twice
    the longest report interval, and puts the node id back."""
    alone_on_bus(dut)
    s = dut.settings()
    node, channel = dut.node_id, s["throttle_channel"]
    window = 2 * max(s[k] for k in INTERVALS) * cat.INTERVAL_UNIT_S
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    restored = False
    try:
        dut.request("set_id", {"node_id": DEFAULT_ESC_NODE_ID, "throttle_channel": channel})
        if dut.request("set_freq", read_request("set_freq"), destination=DEFAULT_ESC_NODE_ID).response is None:
            raise Inconclusive("after Set ID 0x7D nothing answers at node id 0x7D: the id did not change")
        start = dut.now()
        dut.wait(window)
        # message frames from 0x7D, decoded or not (each frame once: the harness may also keep a repaired copy)
        on_its_own = {(f.can_id, f.timestamp): f.name for f in dut.frames(since=start, source=DEFAULT_ESC_NODE_ID, kind=Kind.MESSAGE)}
        for g in dut.garbled:
            kind, _, source, _, spec = classify(g.msg.arbitration_id)
            if (g.msg.timestamp or 0.0) >= start and kind is Kind.MESSAGE and source == DEFAULT_ESC_NODE_ID:
                on_its_own[(g.msg.arbitration_id, g.msg.timestamp)] = spec.name if spec else str(HeardFrame.of_garbled(g))
        # a GET_ESC_ID reply that answers a query another node sent meanwhile (a flight controller's, F6) is not
        # sent on its own: it answers, as at any node id (R1, R2: within 64 ms of the query)
        queries = [f.timestamp or 0.0 for f in dut.frames("get_esc_id", since=start - cat.ANSWER_DELAY_MAX_S)
                   if f.layout is not None and f.layout.name == "query"]
        on_its_own = {k: name for k, name in on_its_own.items()
                      if name != "get_esc_id" or not any(0 < k[1] - q <= cat.ANSWER_DELAY_MAX_S for q in queries)}
        dut.record.observe(f"message frames from node 0x7D in {window:.3f} s", len(on_its_own))
        assert not on_its_own, (f"at node id 0x7D the ESC sent {len(on_its_own)} frames on its own: "
                                f"{sorted(set(on_its_own.values()))}")
    finally:
        dut.request("set_id", {"node_id": node, "throttle_channel": channel}, destination=DEFAULT_ESC_NODE_ID)
        restored = dut.request("set_freq", read_request("set_freq")).response is not None
    if not restored:  # (a verdict above is not hidden by this)
        raise RestoreFailed(f"could not set the node id back to {node} (Set ID from 0x7D)")


# ------------------------------------------------------------------------------------------ tests: a non-zero host
@pytest.mark.requirement("F6")
def test_observe_commands_from_a_non_zero_host(dut):
    """ArduPilot talks to these ESCs from node 10, not 0: whether the DUT answers a broadcast, a
    request and a setting from node 10, and counts its zero throttle as a command, is recorded."""
    host = ARDUPILOT_NODE
    tids = TransferIdCounter()
    node = dut.node_id
    seen: dict[str, str] = {}

    def send(name: str, fields: dict, **kw: Any):
        tid = tids.next((name, kw.get("destination")))
        return dut.send_wire(encode(name, fields, source=host, transfer_id=tid, **kw)), tid

    def answer(name: str, sent) -> Frame | None:
        sid = cat.spec(name).type_id
        return dut.read_until(sent.time + BROADCAST_WINDOW_S, stop=lambda f: f.kind is Kind.RESPONSE
                              and f.type_id == sid and f.source == node)

    sent, _ = send("get_esc_id", {"option": 0}, layout="query")
    dut.wait(BROADCAST_WINDOW_S)
    replies = [f for f in dut.frames("get_esc_id", since=sent.time, source=node) if f.layout and f.layout.name == "reply"]
    seen["GET_ESC_ID broadcast from node 10"] = "answered" if replies else "not answered"

    for name, fields in (("get_major_configuration", {"option": 0}), ("self_test", {})):
        sent, tid = send(name, fields, destination=node)
        got = answer(name, sent)
        seen[f"{cat.spec(name).title} request from node 10"] = (
            "not answered" if got is None else f"answered to node {got.destination}, transfer id {got.transfer_id} (request's {tid})")

    before = dut.settings()
    lo, hi = cat.REPORT_INTERVAL_RANGE
    new = {k: before[k] + 1 if before[k] < hi else before[k] - 1 for k in INTERVALS}
    sent, _ = send("set_freq", {"option": code("set_freq", "option", "write"), **new}, destination=node)
    answer("set_freq", sent)
    after = dut.settings()
    seen["Set Freq write from node 10"] = "applied" if all(after[k] == new[k] for k in INTERVALS) else "not applied"

    if before["throttle_source"] == code("throttle_select", "source", "CAN"):
        seen["zero RawCommand_12b from node 10"] = _throttle_from(dut, host, before, tids)
    for what, value in seen.items():
        dut.record.observe(what, value)
    accepted = sum(v.startswith(("answered", "applied", "counts")) for v in seen.values())
    dut.record.observe("F6: commands from node 10 accepted", f"{accepted} of {len(seen)}")


def _throttle_from(dut, host: int, settings: dict, tids: TransferIdCounter) -> str:
    """Whether zero throttle from ``host`` clears the comm-loss flag (MSG1 bit 13) that 200 ms without
    a command set (4.4.4-3)."""
    msg1_s = settings["msg1_interval"] * cat.INTERVAL_UNIT_S
    dut.wait(cat.COMM_LOSS_TIMEOUT_S + 2 * msg1_s)
    flag = int(cat.Status.COMM_FAULT)
    last = dut.frames("msg1", source=dut.node_id)
    if not last or not last[-1].fields["status"] & flag:
        return "not judged: the comm-loss flag did not come up without commands"
    fields = command_for("raw_command_12b", settings["throttle_channel"], 0)
    if fields is None:
        return "not judged: no 12-bit group for the DUT's throttle channel"
    for _ in range(3):
        dut.send_wire(encode("raw_command_12b", fields, source=host, transfer_id=tids.next(("raw_command_12b", None))))
        dut.wait(msg1_s)
    start = dut.now()
    dut.wait(2 * msg1_s)
    after = dut.frames("msg1", since=start, source=dut.node_id)
    if after and not any(f.fields["status"] & flag for f in after):
        return "counts as a command (the comm-loss flag cleared)"
    return "ignored (the comm-loss flag stayed set)"
