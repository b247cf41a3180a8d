"""A loaded bus (R18), sans-IO: foreign frames at a set share of the bus's capacity at its bit rate.

:class:`LoadSource` is a :class:`~.traffic.TrafficSource` (played by ``SimWorld.add_source`` in the simulated lane, by
:class:`ckesc.bench.traffic_player.TrafficPlayer` in real time). Its frames are single-frame DroneCAN messages
(a tail byte with start=1, end=1, each node's transfer id counting) of 1 to 8 data bytes and random payloads, from a
handful of foreign nodes, each sending one foreign message type:

* **never a frame the ESC takes.** Messages only (no request to anyone), of type ids outside the catalogue
  (:data:`~.catalogue.MESSAGES`) and outside the vendor range the catalogue's ids sit in (no DroneCAN standard type
  the emulator knows either: NodeStatus, 341, is left out), from node ids not on the bench (``exclude_nodes``:
  the ESCs' and the host's, 0 always) nor reserved for ESCs (F7);
* **priority.** ``"high"``: ids that win arbitration against every report of the ESC (LOWEST, F5) and lose it to
  its answers (MEDIUM): priorities strictly between the two (:data:`HIGH_PRIORITIES`). ``"low"``: ids that lose
  to every frame the ESC sends: LOWEST priority and a type id above the catalogue's highest service id shifted
  into the type field, so that even a LOWEST service frame of the ESC wins (:data:`LOW_TYPE_IDS`). ``"mixed"``:
  each burst either, at random;
* **share and spacing.** Bursts of 1 to ``R18_BURST_FRAMES // 2`` frames (all due at once: they queue back to
  back), the n-th due at its nominal time (the bits before it at ``share x bitrate``) plus a random delay of up to
  one longest burst's nominal time, never before the burst before it. Over any window of length t the load then
  takes at most ``share x t`` plus ``R18_BURST_FRAMES`` longest frames of bus time, the burst
  :func:`~.judgements.r18_queueing_s` assumes, and over a long run exactly ``share`` (stuff bits not counted, as
  :func:`~.traffic.bus_load` does not);
* **deterministic** for a ``seed``.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Iterable

from . import catalogue as cat
from .frame import WireFrame, classify, frame_bits
from .ids import MESSAGE_VENDOR_RANGE, RESERVED_NODE_IDS, Kind, Priority, message_id
from .judgements import R18_BURST_FRAMES
from .transfer import next_transfer_id, tail_byte

INF = math.inf
PRIORITIES = ("high", "low", "mixed")
#: "high" load: beats the ESC's reports (LOWEST), loses to its answers (MEDIUM, R2's slot is not widened: R18)
HIGH_PRIORITIES = range(Priority.MEDIUM + 1, Priority.LOWEST)
#: "low" load: LOWEST priority, type ids whose message ids lie above every id the ESC sends (its LOWEST services
#: included: a service id s sits at s << 16 of the id, a message type id t at t << 8)
LOW_TYPE_IDS = range((max(cat.SERVICES) + 1) << 8, 0xFFFF + 1)
#: DroneCAN standard types a stack (or an emulator fault, dronecan_node_info) reacts to: never sent
_KNOWN_DRONECAN = frozenset({341})
#: the foreign nodes of one load: how many, each with its own message type
NODES = 6
MAX_DATA = 8


def _high_type_ids() -> list[int]:
    """Foreign message type ids for the "high" load: below the vendor range, never one the catalogue or DroneCAN's
    well-known types hold."""
    taken = set(cat.MESSAGES) | _KNOWN_DRONECAN
    return [t for t in range(1000, MESSAGE_VENDOR_RANGE.start) if t not in taken]


@dataclass(frozen=True)
class ForeignNode:
    """One foreign node of a load: its node id, message type and priority."""

    node: int
    type_id: int
    priority: int

    @property
    def high(self) -> bool:
        return self.priority < Priority.LOWEST


@dataclass
class LoadSource:
    """Foreign frames at ``share`` of a bus at ``bitrate`` (see the module docstring), from 0 until ``until``."""

    share: float
    bitrate: int
    priority: str = "mixed"
    seed: int = 0
    exclude_nodes: Iterable[int] = ()
    until: float = INF
    name: str = "load"
    nodes: list[ForeignNode] = field(init=False)
    _rng: random.Random = field(init=False, repr=False)
    _tids: dict[int, int] = field(init=False, repr=False)
    _bits: int = field(default=0, init=False, repr=False)
    _due: float = field(default=0.0, init=False, repr=False)
    _burst: list[WireFrame] = field(default_factory=list, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.priority not in PRIORITIES:
            raise ValueError(f"{self.name}: priority must be one of {', '.join(PRIORITIES)}, not {self.priority!r}")
        if not 0 < self.share < 1:
            raise ValueError(f"{self.name}: share must be in (0, 1), not {self.share!r}")
        self._rng = random.Random(f"ckesc-load-{self.seed}-{self.priority}")
        excluded = {0, *RESERVED_NODE_IDS, *self.exclude_nodes}
        free = [n for n in range(1, 0x80) if n not in excluded]
        ids = self._rng.sample(free, NODES)
        highs = self._rng.sample(_high_type_ids(), NODES)
        lows = self._rng.sample(LOW_TYPE_IDS, NODES)
        kinds = {"high": [True] * NODES, "low": [False] * NODES, "mixed": [i % 2 == 0 for i in range(NODES)]}[self.priority]
        self.nodes = [ForeignNode(n, h if up else lo, self._rng.choice(HIGH_PRIORITIES) if up else Priority.LOWEST)
                      for n, h, lo, up in zip(ids, highs, lows, kinds)]
        self._tids = {fn.node: 0 for fn in self.nodes}
        self.bitrate = int(self.bitrate)
        self._next_burst(0.0)

    # ------------------------------------------------------------------ TrafficSource
    def next_due(self) -> float:
        return self._due if self._due < self.until else INF

    def take_due(self, now: float) -> list[WireFrame]:
        out: list[WireFrame] = []
        while self.next_due() <= now:
            out.extend(self._burst)
            self._next_burst(self._due)
        return out

    # ------------------------------------------------------------------ the bursts
    @property
    def longest_burst_bits(self) -> int:
        return R18_BURST_FRAMES // 2 * frame_bits(MAX_DATA)

    def _next_burst(self, previous: float) -> None:
        rng = self._rng
        nominal = self._bits / (self.share * self.bitrate)
        late = rng.random() * self.longest_burst_bits / (self.share * self.bitrate)
        self._due = max(previous, nominal + late)
        high = None if self.priority != "mixed" else rng.random() < 0.5
        pool = [fn for fn in self.nodes if high is None or fn.high is high]
        burst = []
        for _ in range(rng.randint(1, R18_BURST_FRAMES // 2)):
            fn = rng.choice(pool)
            size = rng.randint(1, MAX_DATA)
            tid = self._tids[fn.node]
            self._tids[fn.node] = next_transfer_id(tid)
            data = rng.randbytes(size - 1) + bytes((tail_byte(tid),))
            burst.append(WireFrame(message_id(fn.priority, fn.type_id, fn.node), data, timestamp=self._due))
            self._bits += frame_bits(size)
        self._burst = burst

    # ------------------------------------------------------------------ what it is
    def describe(self) -> str:
        """For a report: the share, bit rate, priority and the foreign nodes."""
        who = ", ".join(f"node {fn.node} type {fn.type_id} prio {fn.priority}" for fn in self.nodes)
        return (f"{self.share:.0%} of {self.bitrate} bit/s, {self.priority} priority, bursts of up to "
                f"{R18_BURST_FRAMES // 2} frames (seed {self.seed}): {who}")


def takes(frame: WireFrame) -> bool:
    """Whether the ESC could take ``frame`` by its id (a message of a catalogue type, a request of a catalogue
    service): a load frame never is one."""
    kind, _, _, _, spec = classify(frame.arbitration_id)
    return spec is not None and kind is not Kind.RESPONSE
