"""The DUT's frames as they came off the wire, decoded or not, for the sections that judge every
frame it sends (4.1 framing, 4.3 the frame table); not a section: no tests here.

- :class:`HeardFrame`: one frame as heard; :func:`describe` a list of problems with them;
- :func:`provoke` / :func:`provoked_traffic`: make the DUT send every kind of frame it has, and keep
  all it sent meanwhile (:class:`Traffic`), with a host that needs no decodable answer to start
  (:func:`bare_dut`);
- :data:`SCOPES` / :func:`in_scope`: the provoked capture, or the whole run's frames as well
  (:func:`run_heard`); :func:`check_each` applies a per-frame rule.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import pytest

from ckesc.bench.dut import Dut, DutError
from ckesc.bench.link import Sent
from ckesc.evidence.live import LaneRules
from ckesc.evidence.pairing import RequestPairing
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import FALLBACK_PRIORITY, Frame, WireFrame, classify
from ckesc.protocol.ids import ESC_NODE_IDS, Kind, parse_can_id, service_id
from ckesc.protocol.judgements import asked_node
from ckesc.protocol.transfer import parse_tail, tail_byte

from .answers import BROADCAST_WINDOW_S
from .codes import code
from .telemetry import read_request

#: The longest report interval the document allows (250 x 2 ms): any report comes within it
LONGEST_S = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S
#: DroneCAN's uavcan.protocol.GetNodeInfo: what a DroneCAN flight controller asks the nodes it sees.
#: Not a CKESC id - the probe that shows whether the DUT answers outside its vendor range (4.3.1).
DRONECAN_GET_NODE_INFO = 1

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
class HeardFrame:
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
    def of_frame(cls, f: Frame) -> HeardFrame:
        return cls(f.can_id, bytes(f.data), f.timestamp or 0.0, frame=f)

    @classmethod
    def of_garbled(cls, g: Any) -> HeardFrame:
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


def describe(problems: list[tuple[HeardFrame, str]], limit: int = 5) -> str:
    """The first few problems, one per frame type, and how many in all."""
    seen: dict[tuple[str, int], tuple[HeardFrame, str]] = {}
    for h, why in problems:
        seen.setdefault((why, h.cid.type_id), (h, why))
    lines = [f"{why}: {h}" for h, why in list(seen.values())[:limit]]
    return f"{len(problems)} frame(s): " + "; ".join(lines)


# ------------------------------------------------------------------------------------------ provoking traffic
class RecordingDut(Dut):
    """A Dut that remembers every frame it puts on the bus, to tell its own echoes from the DUT's frames."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.sent_wires: set[tuple[int, bytes]] = set()
        super().__init__(*args, **kwargs)

    def send_wire(self, wire: WireFrame):
        self.sent_wires.add((wire.arbitration_id, bytes(wire.data)))
        return super().send_wire(wire)

    def heard(self, *, every_node: bool = False) -> list[HeardFrame]:
        """Everything heard that the host side did not send (the DUT's frames), decoded or not, in order.
        Error frames are the adapter's news of bus errors, nobody's frame: left out. ``every_node``: other nodes'
        frames too (:meth:`another_nodes`)."""
        raw = [HeardFrame.of_garbled(g) for g in self.garbled if not getattr(g.msg, "is_error_frame", False)]
        # one frame on the wire is one (id, end of frame time): a frame the harness also decoded after
        # repairing it (a wrong tail byte) is judged as it came, once
        seen = {(h.can_id, h.timestamp) for h in raw}
        out = [h for h in map(HeardFrame.of_frame, self.trace) if (h.can_id, h.timestamp) not in seen] + raw
        return sorted((h for h in out if not self.ours(h) and (every_node or not self.another_nodes(h))),
                      key=lambda h: h.timestamp)

    def another_nodes(self, h: HeardFrame) -> bool:
        """A frame whose source field (F1) names another node an ESC may be: another ESC of the bench, a flight
        controller or a battery sharing the bus (``--foreign-traffic``), never the DUT's to be judged. A frame
        from node 0 or a reserved id (0x7E, 0x7F) that the host did not send is still the DUT's (F7)."""
        return h.extended and h.cid.source in ESC_NODE_IDS and h.cid.source != self.node_id

    def ours(self, h: HeardFrame) -> bool:
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
    """One request of the provoked traffic and its answers, in the bus's clock: ``sent_at`` when it was on the bus
    (:attr:`~ckesc.bench.link.Sent.time`, stated to ``error``), ``until`` when the host stopped waiting for its answer
    (:attr:`~ckesc.bench.link.Exchange.until`)."""

    label: str
    name: str
    transfer_id: int
    sent_at: float
    until: float
    answers: list[HeardFrame] = field(default_factory=list)
    error: float = 0.0


@dataclass
class Traffic:
    node: int
    host: int
    heard: list[HeardFrame]  # the DUT's frames in the order they came, one unbroken stretch
    asked: dict[str, Asked]  # the read-only requests, by label
    broadcasts: dict[str, list[HeardFrame]]  # the DUT's messages after each broadcast command, by label
    #: the stretches (first, last stamp) of frames the nodes held while the host was away, as the bus reader tells
    #: (:meth:`~ckesc.evidence.rejoin.Rejoin.held_stretches`, R20: their transfer ids and gaps OBSERVE)
    held: tuple[tuple[float, float], ...] = ()

    def adjacent(self, a: HeardFrame, b: HeardFrame) -> bool:
        """No held stretch lies between frames ``a`` and ``b`` nor holds either: F3 may pair them."""
        return not any(a.timestamp <= last and b.timestamp >= first for first, last in self.held)


def find_node(d: RecordingDut) -> int:
    """The DUT's node id when GET_ESC_ID discovery failed (its answers did not decode): the source
    of the reports (MSG1..MSG3, decoded or not) heard, which only an ESC sends (a flight controller or a battery
    on the bus sends none)."""
    d.broadcast("get_esc_id", {"option": 0}, layout="query")
    d.wait(LONGEST_S + BROADCAST_WINDOW_S)
    sources = [h.cid.source for h in d.heard(every_node=True)
               if h.extended and h.spec is not None and h.spec.name in cat.REPORT_FRAMES]
    sources = sources or [h.cid.source for h in d.heard(every_node=True) if h.extended]
    if not sources:
        raise DutError("no frame at all from any ESC: is it powered, at the bus's bit rate, and not at node id 0x7D?")
    return max(set(sources), key=sources.count)


def bare_dut(run, lane) -> RecordingDut:
    """A host on the lane that needs no decodable answer to start. The plugin's ``dut`` fixture reads
    the settings through decoded answers: with a DUT whose framing is broken it cannot even start,
    yet that is exactly the DUT this module must fail, not error on."""
    node = run.node_id
    if node:
        return RecordingDut(lane, run.profile, node_id=node)
    try:
        d = RecordingDut(lane, run.profile)  # GET_ESC_ID discovery (R1)
    except DutError:
        d = RecordingDut(lane, run.profile, node_id=0)  # a placeholder until the raw search below
        d.node_id = find_node(d)
        d.nodes = [d.node_id]
    run.node_id = run.node_id or d.node_id
    return d


def _window(d: RecordingDut, sent: Sent, seconds: float) -> tuple[float, float]:
    """Wait ``seconds`` after the broadcast ``sent``: the window from it to the wait's end, in the bus's clock."""
    d.wait(seconds)
    return sent.time, d.bus_now()


def held_stretches(lane) -> tuple[tuple[float, float], ...]:
    """What the bus reader on ``lane`` (the plugin's live rules) says the nodes held while the host was away (none
    where no reader watches the lane: then nothing is excused)."""
    return tuple(s for w in lane.listeners if isinstance(w, LaneRules) for s in w.rules.held_stretches())


def provoke(d: RecordingDut) -> Traffic:
    """Make the DUT send every kind of frame it has, and keep all it sent meanwhile. The frames of a
    function the profile declares absent (MSG_EXP mode, CAN Test, Get Rec) are not provoked: the
    framing and frame-table checks judge the rest (R9b), never skipped whole."""
    claims = d.profile.claims
    asked: dict[str, Asked] = {}
    for label, name, fields in QUERIES:
        ex = d.request(name, fields)
        asked[label] = Asked(label, name, ex.pending.transfer_id, ex.sent.time, ex.until, error=ex.sent.error)  # type: ignore[arg-type]
    windows: dict[str, tuple[float, float]] = {}
    answer_window = BROADCAST_WINDOW_S + d.lane.timing_error  # an answer late by the lane's error is still one
    windows["get_esc_id"] = _window(d, d.broadcast("get_esc_id", {"option": 0}, layout="query"), answer_window)
    windows["msg_control"] = _window(d, d.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME}),
                                     answer_window)
    if claims("msg_exp_mode"):
        try:  # MSG_EXP mode: the MSG_EXP frames (which ones come is OBSERVE, R9-exp)
            d.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME_EXP})
            d.wait(LONGEST_S + BROADCAST_WINDOW_S)
        finally:
            d.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
            d.wait(BROADCAST_WINDOW_S)
    if claims("can_test"):
        try:  # CAN Test mode: the CAN Test frames (R16)
            d.broadcast("can_test", {"option": cat.CAN_TEST_ON, "count": 0})
            d.wait(BROADCAST_WINDOW_S)
        finally:
            d.broadcast("can_test", {"option": cat.CAN_TEST_OFF, "count": 0})
            d.wait(BROADCAST_WINDOW_S)
    if claims("get_rec"):
        d.request("get_rec", {"payload": []})  # the temperature records, MSG_EXP12 (R15)
        d.wait(BROADCAST_WINDOW_S)
    probe_id = service_id(FALLBACK_PRIORITY, DRONECAN_GET_NODE_INFO, True, d.node_id, d.host_node)
    d.send_wire(WireFrame(probe_id, bytes((tail_byte(0),))))  # GetNodeInfo has no payload: the tail byte only
    d.wait(BROADCAST_WINDOW_S + 2 * LONGEST_S)  # then normal reporting: every report at least once, MSG1 over 32 times
    heard = d.heard()
    answers_of(asked, heard, d.host_node, d.node_id)

    def during(label: str) -> list[HeardFrame]:
        start, end = windows[label]
        return [h for h in heard if start <= h.timestamp <= end]

    broadcasts = {name: [h for h in during(name) if h.cid.kind is Kind.MESSAGE and h.spec is not None and h.spec.name == name]
                  for name in ("get_esc_id", "msg_control")}
    return Traffic(d.node_id, d.host_node, heard, asked, broadcasts, held_stretches(d.lane))


def answers_of(asked: dict[str, Asked], heard: list[HeardFrame], host: int, node: int) -> None:
    """Each request's answers (``Asked.answers``): the service frames F4's one pairing
    (:class:`~ckesc.evidence.pairing.RequestPairing`, the bus reader's: by transfer id, never by order alone) gives
    it, heard before the host stopped waiting for it. A late answer to an earlier request, heard while the host waited
    for a later one, is the earlier's (late: after its wait, so no answer of either), not the later's answer with a
    wrong transfer id; an answer addressed to another node than the requester is the answer of the request it answers
    in every other field (:class:`~ckesc.evidence.pairing.Misaddressed`), failed by F4's test; one the pairing gives
    no request answers none. Every time is the bus's: the requests' (:attr:`Asked.sent_at`, stated to
    :attr:`Asked.error`, the pairing's error) and the waits' ends are the stamps' clock."""
    pairing, owner = RequestPairing(error=max((a.error for a in asked.values()), default=0.0)), {}
    sids = {cat.spec(a.name).type_id for a in asked.values()}
    events = [(a.sent_at, 0, a) for a in asked.values()]
    events += [(h.timestamp, 1, h) for h in heard if h.cid.kind is not Kind.MESSAGE and h.cid.type_id in sids]
    for a in asked.values():
        a.answers = []
    for _, is_answer, x in sorted(events, key=lambda e: (e[0], e[1])):
        if not is_answer:
            r = pairing.request(x.sent_at, Kind.REQUEST, cat.spec(x.name).type_id, x.transfer_id, host,
                                asked_node(x.name, node))
            owner[id(r)] = x
            continue
        cid = x.cid
        p = pairing.response(x.timestamp, cid.source, cid.type_id, x.transfer_id, cid.destination)
        r = p.request if p.misaddressed is None else p.misaddressed.request
        a = owner.get(id(r)) if r is not None else None
        if a is not None and x.timestamp <= a.until:
            a.answers.append(x)


def provoked_traffic(run, lane) -> Iterator[Traffic]:
    """Body of the module-scoped ``traffic`` fixtures: provoke, yield, and put the DUT's decoded frames
    into the run-wide record as the plugin does for every test."""
    d = bare_dut(run, lane)
    try:
        yield provoke(d)
    finally:
        d.zero_throttle()
        d.wait(cat.ANSWER_DELAY_MAX_S)  # read the echoes: the next test's host must not hear them as new
        run.keep([f for f in d.trace if f.source == d.node_id])


@pytest.fixture(scope="module")
def traffic(ckesc_run, ckesc_lane) -> Iterator[Traffic]:
    """The provoked traffic, once per module that uses it (``traffic = wire.traffic``)."""
    yield from provoked_traffic(ckesc_run, ckesc_lane)


# ------------------------------------------------------------------------------------------ scopes
def run_heard(run) -> list[HeardFrame]:
    """Every frame the DUT sent in the run so far, as the plugin collected them.

    Harness gap: ``dut_segments`` keeps decoded frames only (a frame that did not decode - the very
    frames framing faults produce - is in no record after its test), it keeps no frame heard while
    a test's settings are restored, and the frames of ``multi_dut``'s private bench come with that
    bench's own clock. The run-wide checks therefore add a fresh provoked capture, and the transfer
    id check looks only at pairs of frames that provably had nothing between them."""
    return [replace(HeardFrame.of_frame(f), segment=i) for i, seg in enumerate(run.segments) for f in seg]


SCOPES = (pytest.param("provoked", id="provoked"), pytest.param("run", id="run", marks=pytest.mark.last))


def in_scope(scope: str, traffic: Traffic, run) -> list[HeardFrame]:
    return traffic.heard if scope == "provoked" else run_heard(run) + traffic.heard


def check_each(frames: list[HeardFrame], rule: Callable[[HeardFrame], list[str]]) -> list[tuple[HeardFrame, str]]:
    return [(h, why) for h in frames for why in rule(h)]
