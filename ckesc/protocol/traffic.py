"""Other nodes on the bus, sans-IO: the seam through which foreign traffic and load reach a bus.

A flight puts more on an ESC's bus than one polite host: a flight controller's SafetyState and
NodeStatus, a smart battery's BatteryCells, other nodes' load (R17, R18). A :class:`TrafficSource`
is such a node as a plain object: it says when its next frame is due (:meth:`~TrafficSource.next_due`)
and hands over the frames due by a time (:meth:`~TrafficSource.take_due`), each stamped with the time
it was due. Nothing here reads a clock or sends anything; the lanes play a source:

- the simulated lane: ``SimWorld.add_source(source)`` (:mod:`ckesc.emulator.sim_bus`) queues each frame
  at its due time, where it contends by arbitration and takes its frame time like any other, so the
  queueing a load causes is real there;
- real time: :class:`ckesc.bench.traffic_player.TrafficPlayer` sends them on the host's own handle of the
  adapter (the lane's ``play``, read back like every frame) at their due times (on the wall clock, from its own
  thread) and reports how late it was and the load it reached.

A source's times are on its player's clock, which starts at 0 when the source is added or the player
starts. ``bitrate``: the bit rate the source's node talks at; None follows the bus (the simulated lane:
the bit rate of the host bus opened last).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, Sequence, runtime_checkable

from .frame import WireFrame, frame_bits

INF = math.inf


@runtime_checkable
class TrafficSource(Protocol):
    """A node on the bus that is not the host and not the DUT (see the module docstring)."""

    name: str
    bitrate: int | None

    def next_due(self) -> float:
        """When the next frame is due (``math.inf``: nothing more)."""
        ...

    def take_due(self, now: float) -> list[WireFrame]:
        """The frames due at or before ``now``, oldest first, each stamped with its due time."""
        ...


@dataclass
class PeriodicFrames:
    """The simplest source: ``frames`` sent one after another, one every ``period`` seconds, from
    ``start`` until ``until`` (exclusive). A list of several frames cycles (a multi-frame transfer
    is its frames in order)."""

    name: str
    frames: Sequence[WireFrame]
    period: float
    start: float = 0.0
    until: float = INF
    bitrate: int | None = None
    _n: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.frames:
            raise ValueError(f"{self.name}: a periodic source needs at least one frame")
        if not self.period > 0:
            raise ValueError(f"{self.name}: period must be > 0, not {self.period!r}")

    def next_due(self) -> float:
        t = self.start + self._n * self.period
        return t if t < self.until else INF

    def take_due(self, now: float) -> list[WireFrame]:
        out = []
        while (t := self.next_due()) <= now:
            frame = self.frames[self._n % len(self.frames)]
            out.append(frame._replace(timestamp=t))
            self._n += 1
        return out


def bus_load(frames: int | Sequence[WireFrame], seconds: float, bitrate: int, dlc: int | None = None) -> float:
    """The share of a bus's capacity ``frames`` took over ``seconds`` at ``bitrate`` (0.5: half).
    ``frames``: the frames themselves, or a count of frames of ``dlc`` data bytes. Stuff bits are
    not counted (:func:`~ckesc.protocol.frame.frame_bits`), so a real bus is up to ~20 % busier."""
    if seconds <= 0:
        return 0.0
    if isinstance(frames, int):
        if dlc is None:
            raise ValueError("bus_load: a count of frames needs their dlc")
        bits = frames * frame_bits(dlc)
    else:
        bits = sum(frame_bits(len(f.data)) for f in frames)
    return bits / bitrate / seconds
