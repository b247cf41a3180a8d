"""The real-time hub's CAN controllers (issue #36): acknowledgement and the bus faults (``ckesc control bus``, R20),
sans-IO: no clock, no socket.

The real-time hub delivers every frame at once and models no arbitration, as long as CAN would: someone acknowledges
the frame and the bus is free. Where that does not hold, each ESC's frames go through a controller of its own
(:func:`~.sim_can.esc_controller`, the simulated lane's: its mailboxes, lowest id first, what does not fit dropped),
each try timed in bit times at the ESC's bit rate, by ISO 11898-1's rules
(:class:`~ckesc.protocol.canbus.CanController`):

* **Nobody listens.** A frame is acknowledged only by another powered node at its bit rate: a host handle open at
  the hub's rate (:meth:`HubCan.host_listens`: a socketcand client from when it can take frames; the emulator's
  python-can bus), or another booted ESC that takes frames at that rate. The node at another bit rate of an
  ``other_bitrate`` fault never does. Unacknowledged, the controller retransmits its head frame, goes
  error-passive after 16 tries (the ACK exception keeps it there) and is *parked* with its queue, as the simulated
  lane parks it, until a listener comes (the host reopens its bus, moves to the ESC's rate after Set Baud, an ESC
  boots): then the queue goes back to back from its next retransmission, each frame stamped at its try.
* **A bus fault.** While the bus is shorted (CANH to CANL, every bit dominant) or a node at another bit rate
  garbles it, a try that starts while the bus is held dominant is a bit error: the ESC goes bus-off as its
  controller does. A bus-off controller recovers by itself after 128 x 11 recessive bits, counted once the bus is
  free (fault ``no_busoff_recovery``: never, until a power cycle; ``busoff_recovery_resets``: by rebooting its
  ESC), then sends what it held back to back.

Once every controller is error-active again with both counters at 0 and nothing queued, and no fault is on, the hub
goes back to delivering at once.

The host's frames meet a fault as its adapter would (SocketCAN's, with ``restart-ms``): held, the first and its
transmit queue behind it, until an ESC listens again (the fault over, its controller not bus-off), the rest lost;
the emulator keeps them in its :class:`~.host_alone.HostAlone` queue, whatever ``--host-alone`` says.

Kinds (:data:`KINDS`): ``short`` holds the bus dominant from its start to its end; ``other_bitrate`` is a node at
another bit rate sending at about 1 kHz, played as what the others meet: the bus held for :data:`FOREIGN_FRAME_S` (a frame
at 250 kbit/s) every :data:`FOREIGN_PERIOD_S`, as the simulated lane plays it (:mod:`ckesc.bench.bus_fault`). A
fault lasts a given time, or (a relay: ``on`` / ``off``) until it is ended.
"""

from __future__ import annotations

import math
from typing import Any, Iterable, NamedTuple

from ..protocol.canbus import Attempt, CanController, ErrorFrame, ErrorState, attempt_bits, recovery_seconds
from ..protocol.frame import WireFrame, frame_bits
from .model import EscModel
from .sim_can import esc_controller, retry_slot

INF = math.inf
#: the kinds of fault
KINDS = ("short", "other_bitrate")
#: how long after a bus-off the host's adapter is restarted (SocketCAN's ``restart-ms``, as docs/bench/bus-fault.md
#: asks a bench to set it)
HOST_RESTART_S = 0.1
#: ``other_bitrate``: how long each frame of the node at another bit rate holds the bus (an 8-byte extended frame at
#: 250 kbit/s) and how often it sends one (about 1 kHz: a babbling node). On its own clock: a period that divides no
#: whole-millisecond grid, so that an ESC's reports meet its frames at every phase as an unsynchronised node's do (at
#: exactly 1 ms an ESC whose report grid fell in the gaps never went bus-off, so the fault missed a controller
#: without recovery at 7 of 20 starting phases)
FOREIGN_FRAME_S = 0.0005
FOREIGN_PERIOD_S = 0.00103


class Disturbance(NamedTuple):
    """A fault on the bus from ``start`` to ``end`` (INF: until ended): the bus held dominant for ``on_s`` of every
    ``period_s`` (a short: all of it)."""

    kind: str
    start: float
    end: float
    on_s: float
    period_s: float

    @classmethod
    def of(cls, kind: str, start: float, seconds: float | None) -> Disturbance:
        if kind not in KINDS:
            raise ValueError(f"bus fault {kind!r}: one of {', '.join(KINDS)}")
        end = INF if seconds is None else start + seconds
        if kind == "short":
            return cls(kind, start, end, INF, INF)
        return cls(kind, start, end, FOREIGN_FRAME_S, FOREIGN_PERIOD_S)

    def dominant_until(self, t: float) -> float | None:
        """Until when the bus is held dominant at ``t`` (None: it is free at ``t``)."""
        if not self.start <= t < self.end:
            return None
        phase = (t - self.start) % self.period_s
        if phase >= self.on_s:
            return None
        return min(t - phase + self.on_s, self.end)

    def next_dominant(self, t: float) -> float:
        """The first instant at or after ``t`` at which the bus is held dominant (INF: none)."""
        if t >= self.end:
            return INF
        if t < self.start:
            return self.start
        phase = (t - self.start) % self.period_s
        if phase < self.on_s:
            return t
        later = t - phase + self.period_s
        return later if later < self.end else INF

    def quiet_from(self, t: float, need: float) -> float:
        """The first instant at or after ``t`` from which the bus stays free for ``need`` (INF: not before an end
        that is not set yet)."""
        until = self.dominant_until(t)
        if until is not None:
            t = until
        if t >= self.end:
            return t
        if self.period_s - self.on_s < need:  # the gaps between the foreign frames are too short: the fault's end
            return self.end
        nxt = self.next_dominant(t)
        return t if nxt - t >= need else self.dominant_until(nxt) or nxt


class HubCan:
    """The hub's CAN controllers (see the module docstring). The emulator calls :meth:`send` with each ESC's frames as
    they fall due, :meth:`poll` at :meth:`next_deadline`, :meth:`forget` at a power-off, and tells it who listens:
    :meth:`host_listens` and :meth:`host_gone` as the host's handles come and go, :meth:`set_bitrate` when the host
    moves; ``escs``: the ESCs on the bus (each acknowledges the others' frames at its rate once booted)."""

    def __init__(self, bitrate: int, escs: Iterable[EscModel] = (), host_restart_s: float | None = HOST_RESTART_S) -> None:
        self.bitrate = bitrate
        self.escs = list(escs)
        self.host_restart_s = host_restart_s
        self.fault: Disturbance | None = None
        self.counters = {"bus_faults": 0, "esc_bus_off": 0, "esc_recovered": 0, "esc_dropped": 0, "esc_no_ack": 0}
        self.hosts: dict[Any, float] = {}  # each host handle open: from when it listens at the hub's rate
        self._ctl: dict[EscModel, CanController] = {}
        self._free: dict[EscModel, float] = {}  # when each controller may start its next try
        self._parked: dict[EscModel, tuple[float, float]] = {}  # nobody acknowledges: (last try's end, retry period)
        self._host_ctl: dict[Any, CanController] = {}  # the host's adapters that met a fault, by handle
        self._host_free: dict[Any, float] = {}

    # ------------------------------------------------------------------ who listens
    def host_listens(self, handle: Any, since: float | None) -> None:
        """The host's ``handle`` (a connection, a bus) listens at the hub's rate from ``since`` (kept if earlier);
        None: it closed (:meth:`host_gone`)."""
        if since is None:
            self.host_gone(handle)
        else:
            self.hosts[handle] = min(self.hosts.get(handle, INF), since)

    def host_gone(self, handle: Any) -> None:
        """The host's ``handle`` closed: it acknowledges nothing any more (and its adapter's state goes)."""
        self.hosts.pop(handle, None)
        self._forget_host(handle)

    def set_bitrate(self, bitrate: int, now: float) -> None:
        """The host moved to ``bitrate`` at ``now`` (its adapter reopened there): its handles listen at it from now."""
        if bitrate != self.bitrate:
            self.bitrate = bitrate
            self.hosts = {h: max(since, now) for h, since in self.hosts.items()}

    def listener_from(self, esc: EscModel) -> float | None:
        """From when some other node acknowledges ``esc``'s frames (None: nobody does): a host handle open at its bit
        rate, another ESC powered, booted, not bus-off and taking frames at that rate (``listens_at``). A node at
        another bit rate (``other_bitrate``) never does."""
        rate = esc.state.bitrate
        first = min(self.hosts.values(), default=INF) if rate == self.bitrate else INF
        for other in self.escs:
            if other is not esc and other.powered and other.state.ready_at < first and other.listens_at(rate):
                ctl = self._ctl.get(other)
                if ctl is None or not ctl.bus_off:
                    first = other.state.ready_at
        return None if first == INF else first

    # ------------------------------------------------------------------ the fault
    @property
    def quiet(self) -> bool:
        """No fault and no controller kept: every ESC frame is acknowledged at once (the emulator's fast path)."""
        return self.fault is None and not self._ctl and not self._host_ctl

    @property
    def disturbing(self) -> bool:
        """A fault on, a controller still bus-off from one, or a host adapter that met one: the host's frames meet it
        (held while no ESC can acknowledge them), whatever ``--host-alone`` says. An ESC that merely waited for a
        listener changes nothing of the host's frames."""
        return self.fault is not None or bool(self._host_ctl) or any(ctl.bus_off for ctl in self._ctl.values())

    def start(self, kind: str, now: float, seconds: float | None = None) -> Disturbance:
        """A fault from ``now`` for ``seconds`` (None: until :meth:`stop`). One at a time."""
        if self.fault is not None and self.fault.end > now:
            end = "until ended" if self.fault.end == INF else f"for {self.fault.end - now:.3f} s more"
            raise ValueError(f"a bus fault ({self.fault.kind}) is on {end}")
        if seconds is not None and not 0 < seconds <= 3600:
            raise ValueError(f"seconds must be a number of seconds above 0 up to 3600, not {seconds!r}")
        self.fault = Disturbance.of(kind, now, seconds)
        self.counters["bus_faults"] += 1
        return self.fault

    def stop(self, now: float) -> Disturbance | None:
        """End the fault now (a relay opened); the fault that was on, or None."""
        fault = self.fault
        if fault is None or fault.end <= now:
            return None
        self.fault = fault._replace(end=now)
        return self.fault

    def disturbed(self, t: float) -> bool:
        """Whether a fault is on at ``t``."""
        f = self.fault
        return f is not None and f.start <= t < f.end

    # ------------------------------------------------------------------ the ESCs' frames
    def send(self, esc: EscModel, frames: list[WireFrame], now: float) -> list[WireFrame]:
        """``esc``'s frames as they fell due by ``now``: those that went on the bus, each stamped with the start of
        the try that carried it; the others wait in its controller (:meth:`poll` sends them) or were dropped."""
        ctl = self._ctl.get(esc)
        if ctl is None:
            if self.fault is None and (heard := self.listener_from(esc)) is not None and heard <= now:
                return frames
            ctl = self._ctl[esc] = esc_controller(esc)
        for w in frames:
            if ctl.full:
                self.counters["esc_dropped"] += 1
                if ctl.evict_for(w.arbitration_id) is None:  # its lowest-priority frame goes, else this one
                    continue
            ctl.submit(w, w.arbitration_id)
        return self._run(esc, ctl, now)

    def place_host(self, t: float, dlc: int) -> float:
        """A host frame of ``dlc`` bytes heard (its end) at ``t`` while controllers are kept: where it goes on the one
        wire. An ESC frame on the bus then (a held queue going back to back) is not overlapped: the host's frame goes
        at the next frame boundary and the ESCs' next tries wait for its end, which is returned."""
        dur = frame_bits(dlc) / self.bitrate
        sending = [esc for esc, ctl in self._ctl.items()
                   if esc.state.bitrate == self.bitrate and not ctl.bus_off and esc not in self._parked]
        end = max([t] + [self._free.get(esc, -INF) + dur for esc in sending])
        for esc in sending:
            self._free[esc] = max(self._free.get(esc, -INF), end)
        return end

    def _resume(self, esc: EscModel) -> float:
        """A parked controller's first retransmission that someone acknowledges (INF: nobody listens)."""
        since, period = self._parked[esc]
        heard = self.listener_from(esc)
        return INF if heard is None else retry_slot(since, period, max(heard, since))

    def _run(self, esc: EscModel, ctl: CanController, now: float) -> list[WireFrame]:
        """The tries of ``esc``'s queued frames that start by ``now``."""
        out: list[WireFrame] = []
        t = self._free.get(esc, -INF)
        if esc in self._parked:
            if (resume := self._resume(esc)) > now:
                return out
            del self._parked[esc]
            t = resume
        bit_s = 1.0 / ctl.bitrate
        fault = self.fault
        while ctl.size and not ctl.bus_off:
            head = ctl.head()
            t = max(t, head.timestamp)  # (a frame is not tried before it is due)
            if t > now:
                break
            passive = ctl.passive
            ctl.begin()
            if fault is not None and fault.dominant_until(t) is not None:
                t += attempt_bits(len(head.data), Attempt.SHORT, passive) * bit_s
                ctl.attempt(Attempt.SHORT, t)
                if ctl.bus_off:
                    self.counters["esc_bus_off"] += 1
            elif (heard := self.listener_from(esc)) is not None and t >= heard:
                ctl.attempt(Attempt.ACKED, t + frame_bits(len(head.data)) * bit_s)
                out.append(head._replace(timestamp=t))
                t += frame_bits(len(head.data)) * bit_s
            else:  # nobody at its rate listens: retransmitted, error-passive, then parked until someone does
                t += attempt_bits(len(head.data), Attempt.NO_ACK, passive) * bit_s
                ctl.attempt(Attempt.NO_ACK, t)
                self.counters["esc_no_ack"] += 1
                if ctl.steady_without_ack():
                    self._parked[esc] = (t, attempt_bits(len(head.data), Attempt.NO_ACK, True) * bit_s)
                    break
        self._free[esc] = t
        return out

    def _quiet_start(self, ctl: CanController) -> float:
        """From when a bus-off controller counts its recessive bits: when it went bus-off, or once the bus is free."""
        assert ctl.bus_off_at is not None
        if self.fault is None:
            return ctl.bus_off_at
        return self.fault.quiet_from(ctl.bus_off_at, recovery_seconds(ctl.bitrate))

    def recovery_due(self, esc: EscModel) -> float | None:
        """When ``esc``'s bus-off controller recovers by itself: 128 x 11 bits from when it went bus-off, counted once
        the bus is free (None: it is not bus-off, or does not recover by itself)."""
        ctl = self._ctl.get(esc)
        if ctl is None or ctl.bus_off_at is None:
            return None
        return ctl.recovery_due(self._quiet_start(ctl))

    def listens_from(self, esc: EscModel) -> float | None:
        """From when ``esc``'s controller may acknowledge a frame as far as the fault goes: its end, and its own
        recovery where it is bus-off (None: never by itself); -INF where nothing stands in the way."""
        t = -INF if self.fault is None else self.fault.end
        ctl = self._ctl.get(esc)
        if ctl is not None and ctl.bus_off:
            due = self.recovery_due(esc)
            t = INF if due is None else max(t, due)
        return None if t == INF else t

    def next_deadline(self) -> float | None:
        """The next instant :meth:`poll` has work: a try to start, a recovery, the fault's end."""
        times = [] if self.fault is None or self.fault.end == INF else [self.fault.end]
        if (restart := self.host_restart_due()) is not None:
            times.append(restart)
        for handle, ctl in self._host_ctl.items():
            if ctl.size and not ctl.bus_off and self.fault is not None:
                if (t := self.fault.next_dominant(self._host_free[handle])) < INF:
                    times.append(t)
        for esc, ctl in self._ctl.items():
            if ctl.bus_off:
                due = self.recovery_due(esc)
                if due is not None and due < INF:
                    times.append(due)
            elif esc in self._parked:
                if (resume := self._resume(esc)) < INF:
                    times.append(resume)
            elif ctl.size:
                times.append(max(self._free.get(esc, -INF), ctl.head().timestamp))
        return min(times) if times else None

    def poll(self, now: float) -> tuple[list[tuple[EscModel, WireFrame]], list[tuple[EscModel, float]]]:
        """Recoveries and tries due by ``now``: the frames that went on the bus (in time order) and the ESCs that
        rebooted at their recovery (fault ``busoff_recovery_resets``: the caller powers each off and on at that
        time; its controller is gone)."""
        sent: list[tuple[EscModel, WireFrame]] = []
        rebooted: list[tuple[EscModel, float]] = []
        for esc, ctl in list(self._ctl.items()):
            if ctl.bus_off:
                due = self.recovery_due(esc)
                if due is None or due > now:
                    continue
                if "busoff_recovery_resets" in esc.faults:
                    self.forget(esc)
                    rebooted.append((esc, due))
                    continue
                ctl.poll(now, self._quiet_start(ctl))  # (the same instant: recovery_due's own sum)
                self.counters["esc_recovered"] += 1
                self._free[esc] = due
            sent += [(esc, w) for w in self._run(esc, ctl, now)]
        if self.fault is not None and self.fault.end <= now and not any(c.bus_off for c in self._ctl.values()):
            self.fault = None  # (kept while a controller is bus-off: its recovery counts from the fault's end)
        if self.fault is None:  # settled controllers: the hub delivers at once again
            for esc, ctl in list(self._ctl.items()):
                if not ctl.size and ctl.state is ErrorState.ACTIVE and not ctl.tec and not ctl.rec:
                    self.forget(esc)
        sent.sort(key=lambda pair: pair[1].timestamp)
        return sent, rebooted

    # ------------------------------------------------------------------ the host's adapters
    def host_waiting(self, handle: Any, since: float, dlc: int) -> None:
        """The host's ``handle`` has a frame of ``dlc`` bytes held from ``since`` while a fault is on: its adapter's
        controller tries it (:meth:`host_poll`) and meets the fault as an ESC's does."""
        ctl = self._host_ctl.get(handle)
        if ctl is None:  # SocketCAN's: no recovery of its own, the driver restarts it after restart-ms
            ctl = self._host_ctl[handle] = CanController(self.bitrate, txqueuelen=None, auto_recovery=False)
        if not ctl.size:
            ctl.submit(dlc, 0)
            self._host_free[handle] = max(self._host_free.get(handle, -INF), since)

    def host_poll(self, now: float) -> list[tuple[Any, ErrorFrame]]:
        """The host adapters' tries by ``now`` while the bus is held dominant (a bit error each: error-passive after
        16, bus-off after 32) and their restarts ``host_restart_s`` after a bus-off (SocketCAN's ``restart-ms``;
        None: never); the error frames each reports (SocketCAN's, state changes only), with its handle."""
        out: list[tuple[Any, ErrorFrame]] = []
        fault, bit_s = self.fault, 1.0 / self.bitrate
        for handle, ctl in self._host_ctl.items():
            t = self._host_free.get(handle, -INF)
            if ctl.bus_off_at is not None and self.host_restart_s is not None and now >= ctl.bus_off_at + self.host_restart_s:
                t = ctl.bus_off_at + self.host_restart_s
                ctl.restart(t)
            while ctl.size and not ctl.bus_off and fault is not None and t < fault.end:
                t = max(t, fault.next_dominant(t))
                if t > now:
                    break
                ctl.begin()
                t += attempt_bits(ctl.head(), Attempt.SHORT, ctl.passive) * bit_s
                ctl.attempt(Attempt.SHORT, t)
            self._host_free[handle] = t
            out += [(handle, f) for f in ctl.take_error_frames()]
        return out

    def host_sent(self, handle: Any, t: float) -> None:
        """A frame of the host's ``handle`` went on the bus at ``t`` (acknowledged): its adapter's TEC takes 1 off;
        an adapter back to error-active, counters at 0, is forgotten."""
        ctl = self._host_ctl.get(handle)
        if ctl is None or ctl.bus_off:
            return
        if not ctl.size:
            ctl.submit(0, 0)
        ctl.begin()
        ctl.attempt(Attempt.ACKED, t)
        ctl.take_error_frames()  # (its way back to error-active: python-can's socketcand client cannot carry it)
        if ctl.state is ErrorState.ACTIVE and not ctl.tec and not ctl.rec:
            self._forget_host(handle)

    def host_restart_due(self) -> float | None:
        """The next restart of a bus-off host adapter (None: none due)."""
        return min((ctl.bus_off_at + self.host_restart_s for ctl in self._host_ctl.values()
                    if ctl.bus_off_at is not None and self.host_restart_s is not None), default=None)

    def host_bus_off(self) -> bool:
        """Whether a host adapter is bus-off (it sends nothing until its restart)."""
        return any(ctl.bus_off for ctl in self._host_ctl.values())

    def _forget_host(self, handle: Any) -> None:
        """The host adapter of ``handle`` left (its handle closed) or is back to nothing to tell."""
        self._host_ctl.pop(handle, None)
        self._host_free.pop(handle, None)

    def forget(self, esc: EscModel) -> None:
        """``esc`` left the bus (powered off, rebooted): its controller and what it held go."""
        self._ctl.pop(esc, None)
        self._free.pop(esc, None)
        self._parked.pop(esc, None)

    # ------------------------------------------------------------------ what the status says
    def settled(self) -> bool:
        """No fault, and every controller back (not bus-off, nothing left to send but what waits for a listener):
        what a test waits for."""
        return self.fault is None and all(not ctl.bus_off and (not ctl.size or esc in self._parked)
                                          for esc, ctl in self._ctl.items())

    def state(self, esc: EscModel) -> dict[str, Any]:
        """``esc``'s controller as ``ip -details link show`` would say it (error-active, counters 0 where the hub
        keeps none)."""
        ctl = self._ctl.get(esc)
        if ctl is None:
            return {"state": ErrorState.ACTIVE.value, "tec": 0, "rec": 0, "queued": 0, "bus_off": 0, "no_ack": False}
        return {"state": ctl.state.value, "tec": ctl.tec, "rec": ctl.rec, "queued": ctl.size,
                "bus_off": ctl.counts["bus_off"], "no_ack": esc in self._parked}

    def describe(self, now: float) -> dict[str, Any] | None:
        """The fault on now (its kind, since when and for how long more, in seconds; None: none)."""
        f = self.fault
        if f is None or f.end <= now:
            return None
        return {"kind": f.kind, "since_s": round(now - f.start, 6), "left_s": None if f.end == INF else round(f.end - now, 6)}
