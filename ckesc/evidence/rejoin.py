"""The host back on the bus (issue #36, R20): what the bus rules make of the frames the nodes held while the host was
away, a mixin of :class:`~.tracker.Tracker` (its ``_held``, ``_nodes``, ``power_switches``, ``set_bitrate``).

On CAN a frame is sent only when another node acknowledges it. While the host's bus is closed or at another bit rate
(Set Baud's tests reopen it at each rate), an ESC alone at its rate gets no acknowledgement: its controller retransmits
its head frame and queues the rest, and when the host comes back they go at once, back to back, each as late as it
waited. Their gaps and transfer ids tell what the ESC did while error-passive, which R20 leaves OBSERVE; R9 resumes
after them with R9a-gaps grace.
"""

from __future__ import annotations

from collections import deque
from typing import Any

#: held stretches remembered (the latest), for :meth:`Rejoin.held_stretches`
STRETCHES_KEPT = 16


class Rejoin:
    """See the module docstring."""

    _held: bool | float | None
    _nodes: dict[int, Any]
    power_switches: int
    set_bitrate: Any  # (Tracker's)
    _stretches: deque[list[float]]  # made at the first stretch: (its first frame's start, its last frame's stamp)

    def rejoined(self, bitrate: int) -> None:
        """The host reopened its bus (at ``bitrate``, another or the same: Set Baud's tests): while it listened
        elsewhere it saw nothing of the DUT (a power cycle meanwhile, its rate search), so a restart across it is not
        judged a reset (R19), as across a power switch; and the first busy stretch from here is :meth:`held`."""
        self.power_switches += 1
        self._held = True
        self.set_bitrate(bitrate)

    def held(self, node: Any, ts: float, busy_from: float, own: bool) -> None:
        """A frame after the host came back to the bus: the busy stretch of the first frame of another node is what the
        nodes queued while nobody at this rate acknowledged them (R20), sent back to back as the host acknowledges
        again. Each is taken alone (its gap and its transfer id: OBSERVE); after the stretch every node starts again
        with R9a-gaps grace."""
        if self._held is True:
            if own:
                return
            self._held = busy_from
            self.__dict__.setdefault("_stretches", deque(maxlen=STRETCHES_KEPT)).append([busy_from, ts])
        if busy_from == self._held:
            node.unsure_until = max(node.unsure_until, ts)
            self._stretches[-1][1] = ts
            return
        self._held = None
        for other in self._nodes.values():
            other.chain += 1
            other.grace_chain = other.chain
            other.paused = False

    def held_stretches(self) -> list[tuple[float, float]]:
        """The held stretches (:meth:`held`) read so far, the latest :data:`STRETCHES_KEPT`: each (the start of its
        first frame on the bus, the stamp of its last), in the stamps' clock. A consumer that judges those frames
        itself (the framing section's F3) asks here which were held, as the reader took them."""
        return [(a, b) for a, b in self.__dict__.get("_stretches", ())]
