"""The host alone on the bus (``ckesc emulate --host-alone``), sans-IO: what becomes of the host's frames while no
ESC's controller is up to acknowledge them (R20, issue #36).

On real CAN a frame is sent only when another node acknowledges it. While the ESC is unpowered (or still booting:
its controller not yet started) the host is the only node: its controller retransmits the first frame without end
and the frames behind it wait in the transmit queue (SocketCAN's ``txqueuelen``, 10 by default), after which
``send()`` fails (ENOBUFS) and the frame is lost. When the ESC's controller comes up it acknowledges the frame on
the bus at once and the queued ones follow back to back: the ESC meets them all then, and their echoes (SocketCAN's
loopback comes when a frame has been sent) are stamped then.

``deliver`` (the default) is what every lane did before: a frame reaches the bus whether or not anyone takes it.
``hold``: the first frame and up to :data:`TX_QUEUE_LEN` more are held and released, in order, when an ESC's
controller comes up; the rest are lost (counted: ``host_held``, ``host_lost``). A hub without an ESC of its own (a
bare hub between clients, ``--nodes none``) leaves acknowledging to the other clients: it holds nothing.
"""

from __future__ import annotations

from collections import deque
from typing import Any

HOST_ALONE = ("deliver", "hold")
#: SocketCAN's default transmit queue length (``ip link ... txqueuelen``): the frames behind the one retransmitted
TX_QUEUE_LEN = 10


class HostAlone:
    """The host's frames while it is alone on the bus: :meth:`take` each one as it comes, :meth:`release` the held
    ones when an ESC's controller is up. ``counters``: ``host_held`` and ``host_lost``, frames held and lost so far."""

    def __init__(self, mode: str = "deliver", queue_len: int = TX_QUEUE_LEN) -> None:
        if mode not in HOST_ALONE:
            raise ValueError(f"host_alone must be one of {', '.join(HOST_ALONE)}, not {mode!r}")
        self.mode = mode
        self.queue_len = queue_len
        self.held: deque[Any] = deque()
        self.counters = {"host_held": 0, "host_lost": 0}

    def take(self, item: Any, acknowledged: bool, hold: bool = False) -> list[Any]:
        """A host frame (``item``) as it comes, ``acknowledged``: whether some node's controller is up to acknowledge
        it. Returns what goes on the bus now, in order: the frames held before it (a queue keeps its order) and it;
        nothing when it is held or lost. ``hold``: as ``hold`` mode whatever the mode (a bus fault on)."""
        if self.mode == "deliver" and not hold:
            return [item]
        if acknowledged:
            out = [*self.held, item]
            self.held.clear()
            return out
        if len(self.held) <= self.queue_len:  # the one retransmitted, and the queue behind it
            self.held.append(item)
            self.counters["host_held"] += 1
        else:
            self.counters["host_lost"] += 1  # send() failed: ENOBUFS
        return []

    def release(self, acknowledged: bool) -> list[Any]:
        """The held frames, in order, once a controller is up to acknowledge them (else none)."""
        if not acknowledged or not self.held:
            return []
        out = list(self.held)
        self.held.clear()
        return out
