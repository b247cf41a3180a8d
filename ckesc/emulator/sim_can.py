"""The simulated bus's CAN nodes (issue #36): each node's controller (:mod:`ckesc.protocol.canbus`), who acknowledges
a frame, and what the world does when nobody does: a node whose tries change nothing any more is *parked* until a
node that can listen appears, a bus-off controller recovers when its time comes, a short ends. Mixed into
:class:`ckesc.emulator.sim_bus.SimWorld`, whose state (``_ctl``, ``_contending``, ``_parked``, ``_alarm``, ...) it
keeps; and another node's traffic on the world's clock (:class:`ShiftedSource`). No IO, no wall clock."""

from __future__ import annotations

import heapq
import math
from typing import Any

from ..protocol.canbus import Attempt, CanController, ErrorState, attempt_bits
from ..protocol.catalogue import DEFAULT_BITRATE
from ..protocol.frame import WireFrame
from ..protocol.traffic import TrafficSource
from .model import EscModel

INF = float("inf")
#: frames an ESC holds to send (its mailboxes and its firmware's queue behind them, sent lowest id first); what does
#: not fit is dropped: the lowest-priority frame queued, where the new one is of a higher priority
ESC_TX_MAILBOXES = 32


def esc_controller(esc: EscModel) -> CanController:
    """An ESC's CAN controller, on either lane (this one and the real-time hub, :mod:`.hub_can`): its mailboxes
    (:data:`ESC_TX_MAILBOXES`, lowest id first) at its own bit rate, recovering from bus-off by itself unless the
    fault ``no_busoff_recovery`` is on."""
    return CanController(esc.state.bitrate, txqueuelen=ESC_TX_MAILBOXES, order="priority",
                         auto_recovery="no_busoff_recovery" not in esc.faults)


def retry_slot(since: float, period: float, t: float) -> float:
    """A node retransmitting every ``period`` since ``since`` (parked: nobody acknowledges it): its first try that
    starts at ``t`` or after."""
    if t == INF:
        return INF
    k = max(0, math.ceil(round((t - since) / period, 9)))
    return round(since + k * period, 12)


class CanNodes:
    """The CAN side of :class:`~ckesc.emulator.sim_bus.SimWorld` (see this module's docstring)."""

    now: float
    ack: bool
    buses: list[Any]
    bench: Any
    _busy_s: float
    _counts: dict[str, int]
    _ctl: dict[Any, CanController]
    _contending: list[Any]
    _parked: dict[Any, tuple[float, float, float]]
    _sources: list[Any]
    _short_until: float
    _alarm: float
    _outcome: Attempt
    _ready: list[tuple[int, int, Any]]
    _waiting: list[tuple[float, int, Any]]
    _in_flight: tuple[float, Any] | None

    # ------------------------------------------------------------------ a frame's way onto the bus
    def _submit(self, p: Any) -> None:
        """A frame joins its sender's queue (an ESC's that does not fit is dropped; a bus's raises QueueFull)."""
        if not self.ack:  # the bus before issue #36: no queue of its own for a node, every frame contends at once
            heapq.heappush(self._ready, (p.wire.arbitration_id, p.seq, p))
            return
        node = p.origin
        ctl = self._ctl.get(node)
        if ctl is None:  # (not ``or``: an empty controller is falsy, and would be looked up twice)
            ctl = self.controller(node)
        n = ctl.txqueuelen
        if n is not None and ctl.size >= n and node not in self.buses:  # (a host's bus raises QueueFull instead)
            self._counts["dropped"] += 1
            if ctl.evict_for(p.wire.arbitration_id) is None:  # an ESC's: its lowest-priority frame goes, else this one
                return
        ctl.submit(p, p.wire.arbitration_id)
        # a queue that was empty: its node starts to contend (a node with frames contends, is parked or is bus-off)
        if ctl.size == 1 and ctl.state is not ErrorState.BUS_OFF and node not in self._parked:
            self._contending.append(node)

    def _start_transmission(self) -> None:
        waiting = self._waiting
        while waiting and waiting[0][0] <= self.now:
            self._submit(heapq.heappop(waiting)[2])
        if self._ready:
            winner = heapq.heappop(self._ready)[2]
            duration = (67 + 8 * len(winner.wire.data)) / winner.bitrate  # frame_bits, inline: once per frame
            self._in_flight = (round(self.now + duration, 12), winner)
            self._busy_s += duration
            return
        contending = self._contending
        if not contending:
            return
        ctls = self._ctl
        # arbitration: the lowest head id wins (a frame at another bit rate than its listeners' is garbage to
        # them; a mixed-rate bus is broken anyway, so rates do not interact here)
        if len(contending) == 1:  # (one node with frames: a soak's host most of the time)
            ctl = ctls[contending[0]]
            winner = ctl.begin()  # on the bus: a frame its node queues meanwhile waits, whatever its priority
        else:
            winner = ctls[contending[0]].head()
            best = winner.wire.arbitration_id
            for node in contending:
                p = ctls[node].head()
                can_id = p.wire.arbitration_id
                if can_id < best or (can_id == best and p.seq < winner.seq):
                    winner, best = p, can_id
            ctl = ctls[winner.origin]
            ctl.begin()
        bitrate, n = winner.bitrate, len(winner.wire.data)
        now = self.now
        if now < self._short_until:
            self._outcome = Attempt.SHORT
        elif self._acknowledged(winner.origin, bitrate):
            self._outcome = Attempt.ACKED
            duration = (67 + 8 * n) / bitrate  # frame_bits, inline: once per frame
            self._in_flight = (round(now + duration, 12), winner)
            self._busy_s += duration
            return
        else:
            self._outcome = Attempt.NO_ACK
        duration = attempt_bits(n, self._outcome, ctl.passive) / bitrate
        self._in_flight = (round(now + duration, 12), winner)
        self._busy_s += duration

    def _host_bitrate(self) -> int:
        return self.buses[-1].bitrate if self.buses else DEFAULT_BITRATE

    def controller(self, node: Any) -> CanController:
        """``node``'s CAN controller (a host's bus, an :class:`EscModel`, a traffic source)."""
        ctl = self._ctl.get(node)
        if ctl is None:
            options = getattr(node, "controller_options", None)  # a host's bus (sim_bus.SimEscBus)
            if options is not None:
                ctl = CanController(node.bitrate, **options)
            elif isinstance(node, EscModel):
                ctl = esc_controller(node)
            else:
                ctl = CanController(node.bitrate or self._host_bitrate(), txqueuelen=None, order="priority")
            self._ctl[node] = ctl
        return ctl

    def _acknowledged(self, sender: Any, bitrate: int) -> bool:
        """Whether another node at ``bitrate`` listens now (and so acknowledges what ``sender`` sends)."""
        ctls = self._ctl
        for bus in self.buses:
            if bus is not sender and bus.bitrate == bitrate:
                ctl = ctls.get(bus)
                if ctl is None or ctl.state is not ErrorState.BUS_OFF:
                    return True
        now = self.now
        for esc in self.bench.escs:
            if esc is not sender and esc.powered and esc.listens_at(bitrate) and now >= esc.state.ready_at:
                ctl = ctls.get(esc)
                if ctl is None or ctl.state is not ErrorState.BUS_OFF:
                    return True
        for source in self._sources:
            if source is not sender and (source.bitrate or self._host_bitrate()) == bitrate:
                return True
        return False

    def _failed(self, node: Any, ctl: CanController, end: float) -> None:
        """A try that was not acknowledged (or met a short): the frame stays at the head; the node goes on trying,
        is parked (the ACK exception: nothing changes until someone listens) or is bus-off."""
        self._counts["retries"] += 1
        ctl.attempt(self._outcome, end)
        self._report(node, ctl)
        if ctl.bus_off:
            self._contending.remove(node)
            self._set_alarm()
        elif self._outcome is Attempt.NO_ACK and ctl.steady_without_ack():
            self._contending.remove(node)
            p = ctl.head()
            period = attempt_bits(len(p.wire.data), Attempt.NO_ACK, True) / p.bitrate
            self._parked[node] = (end, period, retry_slot(end, period, self._next_listener(p.bitrate)))
            self._set_alarm()

    def _report(self, node: Any, ctl: CanController) -> None:
        frames = ctl.take_error_frames()
        if frames and getattr(node, "error_frames", False):  # a host's bus that asked for them
            for f in frames:
                node._deliver_error(f)

    def _next_listener(self, bitrate: int) -> float:
        """When the next ESC at ``bitrate`` that is booting now starts to listen (INF: none is)."""
        now = self.now
        t = INF
        for esc in self.bench.escs:
            if esc.powered and esc.listens_at(bitrate) and now < esc.state.ready_at < t:
                t = esc.state.ready_at
        return t

    def _wake(self) -> None:
        """Someone may listen now (a power-up, a bus opened, a source joined, a recovery): parked nodes try again
        at their next retransmission slot."""
        now = self.now
        for node, (since, period, resume) in self._parked.items():
            self._parked[node] = (since, period, min(resume, retry_slot(since, period, now)))
        self._set_alarm()

    def _set_alarm(self) -> None:
        t = self._short_until if self._short_until > self.now else INF
        for _, _, resume in self._parked.values():
            t = min(t, resume)
        for ctl in self._ctl.values():
            if ctl.bus_off_at is not None:
                due = ctl.recovery_due(self._short_until)  # (a short holds the bus dominant: no bit counts)
                if due is not None:
                    t = min(t, due)
        self._alarm = t

    def _on_alarm(self, t: float) -> None:
        woke = False
        for node, ctl in list(self._ctl.items()):
            if ctl.bus_off_at is not None and ctl.poll(t, self._short_until):
                if isinstance(node, EscModel) and "busoff_recovery_resets" in node.faults:
                    self._reboot(node, t)
                    woke = True
                    continue
                self._report(node, ctl)
                if ctl and node not in self._contending:
                    self._contending.append(node)
                woke = True
        for node, (_, _, resume) in list(self._parked.items()):
            if resume <= t:
                del self._parked[node]
                if self._ctl[node]:
                    self._contending.append(node)
        if woke:
            self._wake()
        self._set_alarm()

    def _reboot(self, esc: EscModel, t: float) -> None:
        """Fault ``busoff_recovery_resets``: the ESC's firmware resets at bus-off's end (its queue goes with it)."""
        self._forget(esc)
        esc.power_off(t)
        esc.power_on(t)
        self.bench.touch(esc)

    def short(self, seconds: float) -> None:
        """Short the bus (CANH to CANL) for ``seconds`` from now: every try meets a bit error, nothing is
        delivered; the nodes that try to send go bus-off and recover as their controllers do."""
        self._short_until = max(self._short_until, self.now + seconds)
        self._wake()

    def _forget(self, node: Any) -> None:
        """``node`` left the bus (an ESC powered off, a bus shut down): its queue and its state go."""
        ctl = self._ctl.pop(node, None)
        if ctl is not None:
            ctl.clear()
        if node in self._contending:
            self._contending.remove(node)
        self._parked.pop(node, None)
        self._set_alarm()


class ShiftedSource:
    """A source on the world's clock: its own clock starts at ``t0``."""

    def __init__(self, source: TrafficSource, t0: float) -> None:
        self.source, self.t0 = source, t0
        self.name, self.bitrate = source.name, source.bitrate

    def next_due(self) -> float:
        return self.source.next_due() + self.t0

    def take_due(self, now: float) -> list[WireFrame]:
        # compared on the world's clock (``now - t0`` could round below a due time and stall the world)
        out: list[WireFrame] = []
        while (due := self.source.next_due()) + self.t0 <= now:
            out.extend(w._replace(timestamp=w.timestamp + self.t0) for w in self.source.take_due(due))
        return out
