"""A flight controller's and its neighbours' traffic, encoded by the ``dronecan`` package: the foreign frames
a CKESC hears on a real bus (R17, issue #30), as a :class:`~ckesc.protocol.traffic.TrafficSource`.

Every frame here is made by ``dronecan`` (pydronecan 1.0.27): its DSDL serialises the payload, its transport
(``Transfer.to_frames``) builds the CAN id, the tail bytes and, for a multi-frame transfer, the transfer CRC
seeded with the type's signature. Nothing is encoded with ckesc's own codec, so the traffic is what a DroneCAN
stack would send, not what this project thinks one sends.

What the ``ardupilot`` traffic is (:func:`ardupilot`), from ArduPilot's ``libraries/AP_DroneCAN/AP_DroneCAN.cpp``
(priorities are libcanard's: LOWEST 31, LOW 24, MEDIUM 16, HIGH 8):

==========================================  =======  ========  ===========================================
frame                                       node     rate      from ArduPilot
==========================================  =======  ========  ===========================================
``ardupilot.indication.SafetyState`` (20000)  10     2 Hz      ``safety_state_send``: every 500 ms, LOW;
                                                               status 0 (safety on): a 2-byte frame
``uavcan.protocol.NodeStatus`` (341)          10     1 Hz      ``send_node_status``: every 1000 ms, LOWEST
``com.hobbywing.esc.GetEscID`` ``[0]`` (20013) 10    1 Hz      ``hobbywing_ESC_update``: every 1000 ms while
                                                               disarmed, MEDIUM (the publisher's default)
``uavcan.equipment.esc.RawCommand`` (1030)    10     400 Hz    ``SRV_push_servos``: every output cycle
                                                               (Copter's main loop, 400 Hz), priority
                                                               HIGH - 1; four channels, ZERO only
``ardupilot.equipment.power.BatteryCells``    40     1 Hz      a smart battery (AP_Periph); its DSDL says
(20010, a multi-frame transfer)                                the rate is the battery's parameter: 1 Hz
``uavcan.protocol.NodeStatus`` (341)          40     1 Hz      every DroneCAN node
==========================================  =======  ========  ===========================================

What the ESC makes of each (R17, INTERPRETATIONS.md): SafetyState is a foreign message on CAN Test's id, a frame
shorter than CAN Test's table: ignored. BatteryCells is a whole multi-frame transfer on MSG Control's id, its
first frame a start without an end: ignored. NodeStatus and the standard RawCommand (1030) are not this
document's type ids: ignored. GET_ESC_ID ``[0]`` from node 10 is a legitimate query, the same frame the host
sends (only its source differs, F6): an ESC that answers other hosts answers it with its ``[node_id,
throttle_channel]`` broadcast, which the host hears too (its answer matching pairs a reply with its own query
only where no other node's query could have asked for it: :mod:`ckesc.bench.link`).

The throttle is ZERO, always: the flight controller's command here is the standard DroneCAN ESC command (1030)
on ArduPilot's 0..8191 scale with every channel 0, what it sends to DroneCAN ESCs sharing the bus. Hobbywing's
RawCommand (20100) from node 10 is not played: it is one of this ESC's own frames, which an ESC that accepts
other hosts (F6) takes, so it would command the DUT behind the suite's back rather than be foreign traffic.

BatteryCells on 20010 is ArduPilot's layout as the DroneCAN DSDL defined it on that id (``uint8 index``,
``float16[<=24] voltages``, ``float16[<=24] resistances``: up to 97 bytes); the ``dronecan`` package ships a later
layout on 20012 and BatteryContinuous on 20010, so this module parses the definition (``dsdl/``, beside it)
with ``dronecan``'s own DSDL parser, without adding it to the package's type table.

``import dronecan`` takes about a second and imports python-can: this module is imported only when foreign
traffic is asked for (``--foreign-traffic``).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any, Callable

import dronecan
from dronecan import dsdl, transport

from ..protocol.frame import WireFrame
from ..protocol.transfer import TRANSFER_ID_MODULO

#: the traffic profiles ``--foreign-traffic`` takes (none: a quiet bus, the default)
PROFILES = ("ardupilot",)
#: ArduPilot's DroneCAN node id by default (``CAN_D1_UC_NODE``, AP_DroneCAN.cpp), its flight controller's
FLIGHT_CONTROLLER_NODE = 10
#: the smart battery's node id: any id no ESC of the suite's benches takes (the DUT at 1, the multi-ESC bench's 1, 2
#: and 33, the ids Set ID moves the DUT to: 2, 63..124, the answer-slot tests' slots below 32 but 20..31)
BATTERY_NODE = 40
#: libcanard's priorities (canard.h)
LOWEST, LOW, MEDIUM, HIGH = 31, 24, 16, 8
#: ArduPilot Copter's main loop rate (SCHED_LOOP_RATE's default): the ESC command goes out once per output cycle
COPTER_LOOP_HZ = 400

_DSDL = Path(__file__).with_name("dsdl")


def _us(microseconds: int) -> float:
    """A stream's phase (when its first frame is due), in microseconds: not a timing fact, just where it starts."""
    return microseconds / 1_000_000


@cache
def battery_cells_type() -> Any:
    """ArduPilot's BatteryCells on 20010 (see the module docstring), parsed by ``dronecan``'s DSDL parser from
    ``dsdl/ardupilot/equipment/power/20010.BatteryCells.uavcan``; its transfer CRC seed made as
    ``dronecan.load_dsdl`` makes every type's."""
    (t,) = dsdl.parse_namespaces([str(_DSDL / "ardupilot")])
    t.base_crc = dsdl.crc16_from_bytes(struct.pack("<Q", t.get_data_type_signature()))
    return t


def encode(payload: Any, *, source: int, priority: int, transfer_id: int) -> list[WireFrame]:
    """One DroneCAN message transfer, framed by ``dronecan``'s transport: its frames in order."""
    tr = transport.Transfer(payload=payload, source_node_id=source, transfer_id=transfer_id, transfer_priority=priority)
    return [WireFrame(f.message_id, bytes(f.bytes)) for f in tr.to_frames()]


@dataclass
class ForeignStream:
    """One message a node broadcasts every ``period`` seconds from ``start``: ``make(n)`` is the n-th transfer's
    payload (a ``dronecan`` value); ``fixed``: the payload never changes, so its frames are made once per transfer
    id. Its transfer id counts +1 modulo 32 per transfer, as every DroneCAN publisher's does."""

    name: str
    node: int
    priority: int
    period: float
    make: Callable[[int], Any]
    start: float = 0.0
    fixed: bool = True
    n: int = 0
    _frames: dict[int, list[WireFrame]] = field(default_factory=dict, repr=False)

    @property
    def due(self) -> float:
        return self.start + self.n * self.period

    def frames(self) -> list[WireFrame]:
        """The next transfer's frames, stamped with its due time (a multi-frame transfer's frames back to back)."""
        tid = self.n % TRANSFER_ID_MODULO
        frames = self._frames.get(tid) if self.fixed else None
        if frames is None:
            frames = encode(self.make(self.n), source=self.node, priority=self.priority, transfer_id=tid)
            if self.fixed:
                self._frames[tid] = frames
        due = self.due
        self.n += 1
        return [f._replace(timestamp=due) for f in frames]


@dataclass
class ForeignTraffic:
    """Several nodes' streams as one :class:`~ckesc.protocol.traffic.TrafficSource`; ``sent``: transfers taken
    per stream name."""

    name: str
    streams: list[ForeignStream]
    bitrate: int | None = None

    def next_due(self) -> float:
        return min((s.due for s in self.streams), default=math.inf)

    def take_due(self, now: float) -> list[WireFrame]:
        out: list[WireFrame] = []
        while True:
            s = min(self.streams, key=lambda s: s.due, default=None)
            if s is None or s.due > now:
                return out
            out.extend(s.frames())

    @property
    def nodes(self) -> frozenset[int]:
        return frozenset(s.node for s in self.streams)

    def describe(self) -> list[dict[str, Any]]:
        """What is played: one row per stream (its name, node, rate, priority, frames per transfer)."""
        return [{"frame": s.name, "node": s.node, "rate_hz": round(1 / s.period, 3), "priority": s.priority,
                 "frames_per_transfer": len(encode(s.make(0), source=s.node, priority=s.priority, transfer_id=0))}
                for s in self.streams]


class AtBitrate:
    """``source``'s nodes as configured for one bit rate: while the bus is at another (``bus_bitrate()``, e.g. a
    Set Baud test moved the ESC and the host), they are not heard, and their frames due meanwhile are dropped
    (``dropped``), as on a real bus a node at the wrong rate gets none of its frames through."""

    def __init__(self, source: ForeignTraffic, bitrate: int, bus_bitrate: Callable[[], int]) -> None:
        self.source, self.bitrate, self.bus_bitrate = source, bitrate, bus_bitrate
        self.name = source.name
        self.dropped = 0

    def next_due(self) -> float:
        return self.source.next_due()

    def take_due(self, now: float) -> list[WireFrame]:
        frames = self.source.take_due(now)
        if frames and self.bus_bitrate() != self.bitrate:
            self.dropped += len(frames)
            return []
        return frames


def ardupilot(*, esc_rate_hz: float = COPTER_LOOP_HZ, cells: int = 12) -> ForeignTraffic:
    """ArduPilot's flight controller (node 10) and a smart battery (node 40), as the module docstring lists them.
    ``esc_rate_hz``: the flight controller's output rate (its ZERO RawCommand); ``cells``: the battery's cells."""
    fc, batt = FLIGHT_CONTROLLER_NODE, BATTERY_NODE
    ap, uavcan = dronecan.ardupilot, dronecan.uavcan
    safety_on = 0  # STATUS_SAFETY_ON: a bench's flight controller, disarmed
    cells_t = battery_cells_type()

    def node_status(n: int, period: float) -> Any:
        return uavcan.protocol.NodeStatus(uptime_sec=int(n * period), health=0, mode=0, sub_mode=0,
                                          vendor_specific_status_code=0)

    def battery_cells(_n: int) -> Any:
        value = transport.CompoundValue(cells_t)
        value.index = 0
        value.voltages = [3900.0] * cells  # mV: a charged LiPo
        value.resistances = [math.nan]  # "field not provided"
        return value

    # phases: the streams do not all start at one instant (different nodes, different loops)
    streams = [
        ForeignStream("ardupilot.indication.SafetyState", fc, LOW, 0.5, lambda n: ap.indication.SafetyState(status=safety_on),
               start=_us(3000)),
        ForeignStream("uavcan.protocol.NodeStatus", fc, LOWEST, 1.0, lambda n: node_status(n, 1.0), start=_us(11000), fixed=False),
        ForeignStream("com.hobbywing.esc.GetEscID", fc, MEDIUM, 1.0, lambda n: dronecan.com.hobbywing.esc.GetEscID(payload=[0]),
               start=_us(17000)),
        ForeignStream("uavcan.equipment.esc.RawCommand", fc, HIGH - 1, 1.0 / esc_rate_hz,
               lambda n: uavcan.equipment.esc.RawCommand(cmd=[0, 0, 0, 0]), start=_us(500)),
        ForeignStream("ardupilot.equipment.power.BatteryCells", batt, LOW, 1.0, battery_cells, start=_us(29000)),
        ForeignStream("uavcan.protocol.NodeStatus", batt, LOWEST, 1.0, lambda n: node_status(n, 1.0), start=_us(37000), fixed=False),
    ]
    return ForeignTraffic("ardupilot", streams)


def profile(name: str) -> ForeignTraffic:
    """The traffic ``--foreign-traffic NAME`` plays."""
    if name == "ardupilot":
        return ardupilot()
    raise ValueError(f"unknown foreign traffic {name!r} (one of: {', '.join(PROFILES)})")
