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

Also home of the wire helpers that section 4.3's module shares: :class:`Heard`, :func:`provoke`,
:func:`provoked_traffic`, :func:`in_scope`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import pytest

from ckesc.harness.dut import Dut, DutError
from ckesc.harness.plugin import state
from ckesc.harness.verdict import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import FALLBACK_PRIORITY, Frame, WireFrame, classify, encode
from ckesc.protocol.ids import DEFAULT_ESC_NODE_ID, ESC_NODE_IDS, Kind, parse_can_id, service_id
from ckesc.protocol.transfer import TRANSFER_ID_MODULO, TransferIdCounter, parse_tail, tail_byte

from .throttle import command_for

SECTION = "4.1"

INTERVALS = tuple(cat.DEFAULT_REPORT_INTERVALS)  # msg1_interval, msg2_interval, msg3_interval
#: The reports whose interval Set/Get Freq sets (R9): MSG1, MSG2, MSG3
REPORTS = tuple(k.removesuffix("_interval") for k in INTERVALS)
#: The longest report interval the document allows (250 x 2 ms): any report comes within it
LONGEST_S = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
SHORTEST_S = cat.REPORT_INTERVAL_RANGE[0] * cat.INTERVAL_UNIT_S
#: Every ESC answers a broadcast within 64 ms (R2); the harness's discovery reads twice that
BROADCAST_WINDOW_S = 2 * cat.ANSWER_DELAY_MAX_S
#: ArduPilot's default node id, from which it sends GET_ESC_ID and RawCommand (INTERPRETATIONS, F6)
ARDUPILOT_NODE = 10
#: DroneCAN's uavcan.protocol.GetNodeInfo: what a DroneCAN flight controller asks the nodes it sees.
#: Not a CKESC id - the probe that shows whether the DUT answers outside its vendor range (4.3.1).
DRONECAN_GET_NODE_INFO = 1


def code(frame: str, field_name: str, label: str, *, layout: str = "request") -> int:
    """The catalogue's code for ``label`` of one field (e.g. Set Rotation's "query")."""
    spec = cat.spec(frame)
    lay = spec.request if layout == "request" else next(x for x in spec.all_layouts if x.name == layout)
    assert lay is not None
    codes = lay.field(field_name).codes or {}
    return next(k for k, v in codes.items() if v == label)


def read_request(frame: str) -> dict[str, int]:
    """Set/Get Freq's read (option "read"): the intervals sent are ignored (4.4.22-2)."""
    return {"option": code(frame, "option", "read"), **dict.fromkeys(INTERVALS, 0)}


#: Every request that only reads: (label, frame, fields). They change nothing on the DUT.
QUERIES: tuple[tuple[str, str, dict[str, int]], ...] = (
    ("self_test", "self_test", {}),
    ("set_rotation-query", "set_rotation", {"rotation": code("set_rotation", "rotation", "query")}),
    ("set_freq-read", "set_freq", read_request("set_freq")),
    ("esc_information", "esc_information", {"option": code("esc_information", "option", "query")}),
    *((f"maintenance_information-{o}", "maintenance_information", {"option": o})
      for o in cat.spec("maintenance_information").request.field("option").codes or {}),  # type: ignore[union-attr]
    ("get_major_configuration", "get_major_configuration", {"option": code("get_major_configuration", "option", "query")}),
)


# ------------------------------------------------------------------------------------------ frames as heard
@dataclass(frozen=True)
class Heard:
    """One frame as it came off the wire, decoded or not: framing is judged on the raw id and data."""

    can_id: int
    data: bytes
    timestamp: float
    extended: bool = True
    remote: bool = False
    rx: bool = True  # False: the host's own frame, echoed back (when the adapter says)
    frame: Frame | None = None  # None: it did not decode
    error: str | None = None  # why it did not decode
    segment: int = 0  # run-wide record: which test's capture it is from (frames between tests are in none)

    @classmethod
    def of_frame(cls, f: Frame) -> Heard:
        return cls(f.can_id, bytes(f.data), f.timestamp or 0.0, frame=f)

    @classmethod
    def of_garbled(cls, g: Any) -> Heard:
        m = g.msg
        return cls(m.arbitration_id, bytes(m.data), m.timestamp or 0.0, bool(getattr(m, "is_extended_id", True)),
                   bool(getattr(m, "is_remote_frame", False)), bool(getattr(m, "is_rx", True)), error=str(g.error))

    @property
    def cid(self):  # CanId: kind, priority, type_id, source, destination, anonymous
        return parse_can_id(self.can_id)

    @property
    def spec(self) -> cat.FrameSpec | None:
        return classify(self.can_id)[4]

    @property
    def has_tail(self) -> bool:
        spec = self.spec
        return spec is None or spec.has_tail

    @property
    def transfer_id(self) -> int | None:
        return parse_tail(self.data[-1]).transfer_id if self.data and self.has_tail else None

    def __str__(self) -> str:
        cid = self.cid
        spec = self.spec
        what = f"{spec.title if spec else '?'} {cid.kind.label} {cid.type_id} from {cid.source}"
        if cid.destination is not None:
            what += f" to {cid.destination}"
        raw = f"{self.can_id:08X}#{self.data.hex().upper()}" if self.extended else f"{self.can_id:03X}#{self.data.hex().upper()}"
        return f"{what} [{raw}]" + (f" ({self.error})" if self.error else "")


def describe(problems: list[tuple[Heard, str]], limit: int = 5) -> str:
    """The first few problems, one per frame type, and how many in all."""
    seen: dict[tuple[str, int], tuple[Heard, str]] = {}
    for h, why in problems:
        seen.setdefault((why, h.cid.type_id), (h, why))
    lines = [f"{why}: {h}" for h, why in list(seen.values())[:limit]]
    return f"{len(problems)} frame(s): " + "; ".join(lines)


# ------------------------------------------------------------------------------------------ provoking traffic
class Recorder(Dut):
    """A Dut that remembers every frame it puts on the bus, to tell its own echoes from the DUT's frames."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.sent_wires: set[tuple[int, bytes]] = set()
        super().__init__(*args, **kwargs)

    def send_wire(self, wire: WireFrame):
        self.sent_wires.add((wire.arbitration_id, bytes(wire.data)))
        return super().send_wire(wire)

    def heard(self) -> list[Heard]:
        """Everything heard that the host side did not send (the DUT's frames), decoded or not, in order.
        Error frames are the adapter's news of bus errors, nobody's frame: left out."""
        raw = [Heard.of_garbled(g) for g in self.garbled if not getattr(g.msg, "is_error_frame", False)]
        # one frame on the wire is one (id, end of frame time): a frame the harness also decoded after
        # repairing it (a wrong tail byte) is judged as it came, once
        seen = {(h.can_id, h.timestamp) for h in raw}
        out = [h for h in map(Heard.of_frame, self.trace) if (h.can_id, h.timestamp) not in seen] + raw
        others = set(self.nodes) - {self.node_id}  # other ESCs found by discovery (a real bus)
        out = [h for h in out if not self.ours(h) and not (h.frame and h.cid.source in others)]
        return sorted(out, key=lambda h: h.timestamp)

    def ours(self, h: Heard) -> bool:
        """The host side's frame: one this host sent, or the echo of another host object's on the same
        bus (a request, or a host's message from the host's node id), never an ESC's."""
        if (h.can_id, h.data) in self.sent_wires:
            return True
        if not h.extended or h.cid.source != self.host_node:
            return False
        if h.frame is None:
            return not h.rx
        layout = h.frame.layout
        return h.frame.kind is Kind.REQUEST or (layout is not None and layout.sender != "esc")


@dataclass
class Asked:
    """One request of the provoked traffic and the DUT's service frames with its service id."""

    label: str
    name: str
    transfer_id: int
    sent_at: float
    until: float
    answers: list[Heard] = field(default_factory=list)


@dataclass
class Traffic:
    node: int
    host: int
    heard: list[Heard]  # the DUT's frames in the order they came, one unbroken stretch
    asked: dict[str, Asked]  # the read-only requests, by label
    broadcasts: dict[str, list[Heard]]  # the DUT's messages after each broadcast command, by label


def find_node(d: Recorder) -> int:
    """The DUT's node id when GET_ESC_ID discovery failed (its answers did not decode): the source
    of the frames heard that this host did not send."""
    d.broadcast("get_esc_id", {"option": 0}, layout="query")
    d.wait(LONGEST_S + BROADCAST_WINDOW_S)
    sources = [h.cid.source for h in d.heard() if h.extended]
    if not sources:
        raise DutError("no frame at all from any ESC: is it powered, at the bus's bit rate, and not at node id 0x7D?")
    return max(set(sources), key=sources.count)


def bare_dut(config: pytest.Config, lane) -> Recorder:
    """A host on the lane that needs no decodable answer to start. The plugin's ``dut`` fixture reads
    the settings through decoded answers: with a DUT whose framing is broken it cannot even start,
    yet that is exactly the DUT this module must fail, not error on."""
    st = state(config)
    node = config.getoption("node_id") or st.node_id
    if node:
        return Recorder(lane, st.profile, node_id=node)
    try:
        d = Recorder(lane, st.profile)  # GET_ESC_ID discovery (R1)
    except DutError:
        d = Recorder(lane, st.profile, node_id=0)  # a placeholder until the raw search below
        d.node_id = find_node(d)
        d.nodes = [d.node_id]
    st.node_id = st.node_id or d.node_id
    return d


def _window(d: Recorder, seconds: float) -> tuple[float, float]:
    start = d.now()
    d.wait(seconds)
    return start, d.now()


def provoke(d: Recorder) -> Traffic:
    """Make the DUT send every kind of frame it has, and keep all it sent meanwhile."""
    asked: dict[str, Asked] = {}
    for label, name, fields in QUERIES:
        ex = d.request(name, fields)
        asked[label] = Asked(label, name, ex.pending.transfer_id, ex.sent.time, d.now())
    windows: dict[str, tuple[float, float]] = {}
    answer_window = BROADCAST_WINDOW_S + d.lane.timing_error  # an answer late by the lane's error is still one
    d.broadcast("get_esc_id", {"option": 0}, layout="query")
    windows["get_esc_id"] = _window(d, answer_window)
    d.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
    windows["msg_control"] = _window(d, answer_window)
    try:  # MSG_EXP mode: the MSG_EXP frames (which ones come is OBSERVE, R9-exp)
        d.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME_EXP})
        d.wait(LONGEST_S + BROADCAST_WINDOW_S)
    finally:
        d.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
        d.wait(BROADCAST_WINDOW_S)
    try:  # CAN Test mode: the CAN Test frames (R16)
        d.broadcast("can_test", {"option": cat.CAN_TEST_ON, "count": 0})
        d.wait(BROADCAST_WINDOW_S)
    finally:
        d.broadcast("can_test", {"option": cat.CAN_TEST_OFF, "count": 0})
        d.wait(BROADCAST_WINDOW_S)
    d.request("get_rec", {"payload": []})  # the temperature records, MSG_EXP12 (R15)
    d.wait(BROADCAST_WINDOW_S)
    probe_id = service_id(FALLBACK_PRIORITY, DRONECAN_GET_NODE_INFO, True, d.node_id, d.host_node)
    d.send_wire(WireFrame(probe_id, bytes((tail_byte(0),))))  # GetNodeInfo has no payload: the tail byte only
    d.wait(BROADCAST_WINDOW_S + 2 * LONGEST_S)  # then normal reporting: every report at least once, MSG1 over 32 times
    heard = d.heard()
    for a in asked.values():
        sid = cat.spec(a.name).type_id
        a.answers = [h for h in heard if h.cid.kind is not Kind.MESSAGE and h.cid.type_id == sid and a.sent_at <= h.timestamp <= a.until]

    def during(label: str) -> list[Heard]:
        start, end = windows[label]
        return [h for h in heard if start <= h.timestamp <= end]

    broadcasts = {name: [h for h in during(name) if h.cid.kind is Kind.MESSAGE and h.spec is not None and h.spec.name == name]
                  for name in ("get_esc_id", "msg_control")}
    return Traffic(d.node_id, d.host_node, heard, asked, broadcasts)


def provoked_traffic(request: pytest.FixtureRequest, lane) -> Iterator[Traffic]:
    """Body of the module-scoped ``traffic`` fixtures: provoke, yield, and put the DUT's decoded frames
    into the run-wide record as the plugin does for every test."""
    d = bare_dut(request.config, lane)
    try:
        yield provoke(d)
    finally:
        d.zero_throttle()
        d.wait(cat.ANSWER_DELAY_MAX_S)  # read the echoes: the next test's host must not hear them as new
        state(request.config).dut_segments.append([f for f in d.trace if f.source == d.node_id])


@pytest.fixture(scope="module")
def traffic(request: pytest.FixtureRequest, ckesc_lane) -> Iterator[Traffic]:
    yield from provoked_traffic(request, ckesc_lane)


def run_heard(config: pytest.Config) -> list[Heard]:
    """Every frame the DUT sent in the run so far, as the plugin collected them.

    Harness gap: ``dut_segments`` keeps decoded frames only (a frame that did not decode - the very
    frames framing faults produce - is in no record after its test), it keeps no frame heard while
    a test's settings are restored, and the frames of ``multi_dut``'s private bench come with that
    bench's own clock. The run-wide checks therefore add a fresh provoked capture, and the transfer
    id check looks only at pairs of frames that provably had nothing between them."""
    return [replace(Heard.of_frame(f), segment=i) for i, seg in enumerate(state(config).dut_segments) for f in seg]


SCOPES = (pytest.param("provoked", id="provoked"), pytest.param("run", id="run", marks=pytest.mark.last))


def in_scope(scope: str, traffic: Traffic, config: pytest.Config) -> list[Heard]:
    return traffic.heard if scope == "provoked" else run_heard(config) + traffic.heard


def check_each(frames: list[Heard], rule: Callable[[Heard], list[str]]) -> list[tuple[Heard, str]]:
    return [(h, why) for h in frames for why in rule(h)]


# ------------------------------------------------------------------------------------------ the rules, per frame
def id_layout_problems(h: Heard) -> list[str]:
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


def tail_problems(h: Heard) -> list[str]:
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


def source_problems(h: Heard) -> list[str]:
    """4.1.2-N2 / F7: an ESC's node id is 1..0x7D; 0 is 'unknown', 0x7E and 0x7F are reserved."""
    if not h.extended:
        return []
    src = h.cid.source
    if src not in ESC_NODE_IDS:
        return [f"source node id {src:#04x} is not an ESC node id ({ESC_NODE_IDS.start:#04x}..{ESC_NODE_IDS.stop - 1:#04x})"]
    return []


def counter_streams(frames: list[Heard]) -> dict[tuple[int, int], list[Heard]]:
    """The frames that carry a transfer-id counter, by (source node, message type), in order. Service
    responses carry the request's transfer id (F4) and MSG_EXP12 names its record with it (R15): not
    counters; RawCommand_10b (the host's) has no tail byte."""
    streams: dict[tuple[int, int], list[Heard]] = {}
    for h in frames:
        if not h.extended or h.remote or h.transfer_id is None:
            continue
        cid, spec = h.cid, h.spec
        if cid.kind is Kind.MESSAGE and (spec is None or spec.tail_tag is None):
            streams.setdefault((cid.source, cid.type_id), []).append(h)
    return streams


def counting_problems(stream: list[Heard], adjacent: Callable[[Heard, Heard], bool] | None = None
                      ) -> tuple[list[tuple[Heard, str]], int, int]:
    """F3 / 4.1.3-tid: +1 per transfer, modulo 32, between consecutive frames of one stream;
    ``adjacent`` says which pairs provably had no frame of the stream between them (None: all of
    them, one unbroken capture). Returns (problems, pairs checked, wrap-arounds seen)."""
    problems: list[tuple[Heard, str]] = []
    pairs = wraps = 0
    for prev, h in zip(stream, stream[1:]):
        if adjacent is not None and not adjacent(prev, h):
            continue
        pairs += 1
        want = (prev.transfer_id + 1) % TRANSFER_ID_MODULO  # type: ignore[operator]
        wraps += want == 0 and h.transfer_id == 0
        if h.transfer_id != want:
            problems.append((h, f"transfer id {h.transfer_id} after {prev.transfer_id}, expected {want}"))
    return problems, pairs, wraps


def run_counting_problems(frames: list[Heard], error_s: float) -> list[tuple[Heard, str]]:
    """F3 on the run-wide record, where frames are missing between tests (see :func:`run_heard`). Only
    MSG1/MSG2/MSG3 pairs from one test's capture are judged (frames heard between tests are in no
    record), and only pairs less than 1.5 shortest legal report intervals apart: a report comes at
    least that interval after the last of its type (R9), so nothing of the stream (nor a power cycle)
    can lie between them. The record is cut between tests and where time runs backwards
    (``multi_dut``'s bench has its own clock), and a stream with two frames closer than that interval
    is skipped: two ESCs sharing a node id (what Set ID does to a bench, 4.4.18-2), or a DUT whose
    intervals break R9 (section 4.4.22's verdict), where no pair is provably adjacent."""
    shortest = SHORTEST_S - error_s
    segments: list[list[Heard]] = [[]]
    for h in frames:
        if segments[-1] and (h.timestamp < segments[-1][-1].timestamp or h.segment != segments[-1][-1].segment):
            segments.append([])
        segments[-1].append(h)
    problems: list[tuple[Heard, str]] = []
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
def test_frames_are_29_bit_message_or_service_frames(traffic, request, scope):
    """Every frame the DUT sends is a 29-bit extended data frame with the F1 layout: a message frame
    (not an anonymous one), or a service frame answering a request (request bit 0)."""
    frames = in_scope(scope, traffic, request.config)
    problems = check_each(frames, id_layout_problems)
    assert not problems, f"[F1] {describe(problems)}"


@pytest.mark.requirement("F2", "4.1.3-start", "4.1.3-end", "4.1.3-toggle")
@pytest.mark.parametrize("scope", SCOPES)
def test_tail_byte_marks_a_single_frame_transfer(traffic, request, scope):
    """Every frame the DUT sends ends with a tail byte start=1, end=1, toggle=0 (RawCommand_10b, the
    one frame without a tail byte, is the host's)."""
    frames = in_scope(scope, traffic, request.config)
    problems = check_each(frames, tail_problems)
    assert not problems, describe(problems)


@pytest.mark.requirement("F3", "4.1.3-tid")
@pytest.mark.parametrize("scope", SCOPES)
def test_transfer_ids_count_per_frame_type(traffic, request, scope):
    """Consecutive frames of one message type carry transfer ids +1 modulo 32 (the provoked capture
    has more than 32 MSG1 frames: the wrap from 31 to 0 is seen)."""
    problems, pairs = [], 0
    for stream in counter_streams(traffic.heard).values():
        more, n, _ = counting_problems(stream)
        problems, pairs = problems + more, pairs + n
    assert pairs, "no two frames of one message type in the capture: nothing to check"
    if scope == "run":
        lane = state(request.config).lane
        problems += run_counting_problems(run_heard(request.config), lane.timing_error if lane else 0.0)
    assert not problems, describe(problems)


@pytest.mark.requirement("4.1.2-N2", "F7")
@pytest.mark.parametrize("scope", SCOPES)
def test_source_is_an_esc_node_id(traffic, request, scope):
    """Every frame the DUT sends comes from a node id in 1..0x7D."""
    frames = in_scope(scope, traffic, request.config)
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
    problems = []
    if cid.kind is not Kind.RESPONSE:
        problems.append("request bit set")
    if h.transfer_id != a.transfer_id:
        problems.append(f"transfer id {h.transfer_id}, the request's is {a.transfer_id}")
    if cid.destination != traffic.host:
        problems.append(f"destination {cid.destination}, the requester is node {traffic.host}")
    if cid.source != traffic.node:
        problems.append(f"source {cid.source}, the ESC is node {traffic.node}")
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
                on_its_own[(g.msg.arbitration_id, g.msg.timestamp)] = spec.name if spec else str(Heard.of_garbled(g))
        dut.record.observe(f"message frames from node 0x7D in {window:.3f} s", len(on_its_own))
        assert not on_its_own, (f"at node id 0x7D the ESC sent {len(on_its_own)} frames on its own: "
                                f"{sorted(set(on_its_own.values()))}")
    finally:
        dut.request("set_id", {"node_id": node, "throttle_channel": channel}, destination=DEFAULT_ESC_NODE_ID)
        restored = dut.request("set_freq", read_request("set_freq")).response is not None
    if not restored:  # (a verdict above is not hidden by this)
        raise DutError(f"could not set the node id back to {node} (Set ID from 0x7D)")


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
