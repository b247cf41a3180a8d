"""Traffic sources (:mod:`ckesc.protocol.traffic`) played on a real bus, in real time.

:class:`TrafficPlayer` sends each source's frames on a python-can bus at their due times, from its own
thread, on the wall clock (its time 0 is :meth:`~TrafficPlayer.start`). It never blocks the caller and
never raises into it: a send that fails is counted (``send_errors``) and the player goes on. What it
reached is measured, not assumed (:class:`PlayerStats`): frames sent, the bus load they made at the
bus's bit rate, and how late the frames went out (this machine wakes up ~0.3 ms late at p99 and stalls
for several ms now and then; a late frame goes out late, it is never dropped or bunched silently).

It sends through the function it is given (``send(msg, timeout)``): on a bench, the lane's
:meth:`~ckesc.bench.lanes.BusLane.play`, the host's one handle on the adapter, so that the frames it plays are
read back like every other frame (their echo, or the lane's copy where the adapter does not echo) and no second
handle is opened on an adapter whose handles do not hear each other, or that allows one.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import can

from ..protocol.frame import frame_bits
from ..protocol.traffic import TrafficSource


@dataclass
class PlayerStats:
    """What a player did (read after :meth:`TrafficPlayer.stop`, or live: a snapshot)."""

    frames: int = 0
    bits: int = 0
    send_errors: int = 0
    elapsed_s: float = 0.0
    late_max_s: float = 0.0
    late_sum_s: float = 0.0
    bitrate: int = 0

    @property
    def load(self) -> float:
        """The share of the bus's capacity the player's frames took (stuff bits not counted)."""
        return 0.0 if not self.elapsed_s else self.bits / self.bitrate / self.elapsed_s

    @property
    def late_mean_s(self) -> float:
        return self.late_sum_s / self.frames if self.frames else 0.0


#: what a failed send raises: python-can's errors, and the OSError of a socket or a device that went away
SEND_ERRORS = (can.CanError, OSError)


class TrafficPlayer:
    """Plays ``sources`` through ``send`` (``send(msg, timeout)``: a lane's ``play``, or a bus's ``send``) at
    ``bitrate`` (for the load figure; sources with their own bit rate are still sent the same way). Use as a
    context manager or :meth:`start` / :meth:`stop`."""

    def __init__(self, send: Callable[[can.Message, float], None], sources: Sequence[TrafficSource], *,
                 bitrate: int) -> None:
        self.send = send
        self.sources = list(sources)
        self.stats = PlayerStats(bitrate=bitrate)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0 = 0.0

    def start(self) -> TrafficPlayer:
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="ckesc-traffic", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> PlayerStats:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.stats.elapsed_s = time.monotonic() - self._t0
        return self.stats

    def __enter__(self) -> TrafficPlayer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        stats = self.stats
        while not self._stop.is_set():
            due = min((s.next_due() for s in self.sources), default=float("inf"))
            if due == float("inf"):
                return
            now = time.monotonic() - self._t0
            if due > now:
                # wait on the event: stop() wakes the thread at once
                if self._stop.wait(due - now):
                    return
                now = time.monotonic() - self._t0
            for source in self.sources:
                for wire in source.take_due(now):
                    msg = can.Message(arbitration_id=wire.arbitration_id, data=wire.data,
                                      is_extended_id=wire.is_extended_id)
                    try:
                        self.send(msg, 0.1)
                    except SEND_ERRORS:
                        stats.send_errors += 1
                        continue
                    late = (time.monotonic() - self._t0) - wire.timestamp
                    stats.frames += 1
                    stats.bits += frame_bits(len(wire.data))
                    stats.late_sum_s += max(late, 0.0)
                    stats.late_max_s = max(stats.late_max_s, late)
            stats.elapsed_s = time.monotonic() - self._t0
