"""Lane 1: emulated ESCs in simulated time, as a python-can interface (``interface="ckesc-sim"``).

    bus = can.Bus(interface="ckesc-sim", channel="bench", nodes=[1, 2, 3], bitrate=500000,
                  faults=["answer_late"], flash_path="esc-flash.json", seed=0)

Time is a discrete-event clock shared by everything on the channel: ``recv(timeout)`` advances it
to the next frame for this bus or to the timeout, ``send()`` queues a frame at the current time.
Frames take their transmission time at the bus bit rate (an extended data frame of n bytes is
67 + 8n bit times; stuff bits are not modelled, so real frames are up to ~20 % longer) and contend
by arbitration (lowest id first) when the bus frees up. Received frames carry the time their last
bit arrived as ``timestamp``, like SocketCAN. An ESC whose bit rate differs from the host's neither
hears nor is heard. Nothing here reads the wall clock or sleeps, so a run is deterministic for a
given seed and a 120 s window costs milliseconds.

The bus is CAN as hardware makes it (:mod:`ckesc.protocol.canbus`, issue #36): every node (each
``can.Bus`` on the channel, each ESC, each traffic source) has a controller with a transmit queue
and error counters, and only the heads of the queues contend. A frame is sent only when another
node at its bit rate acknowledges it (a powered ESC past its boot time, another bus, a source);
otherwise its sender keeps it at the head and retransmits it (the frames behind it wait): a host
alone on the bus goes error-passive at TEC 128 and its frames meet the ESC at its power-up. A host
bus's queue holds ``txqueuelen`` frames (10, SocketCAN's), in ``tx_order`` "fifo" (SocketCAN's) or
"priority"; a further ``send()`` raises ``can.CanOperationError`` (ENOBUFS, as SocketCAN's).
``bus.state`` is its controller's (ACTIVE, PASSIVE, ERROR for bus-off); ``error_frames=True`` hands
it SocketCAN's error frames (``berr_reporting=True``: each bus error too); :meth:`SimWorld.short`
shorts the bus for a time (every transmitter goes bus-off, and recovers by itself after 128 x 11
bits unless ``auto_recovery=False``: then :meth:`SimEscBus.restart`). An ESC's controller holds
:data:`ESC_TX_MAILBOXES` frames by priority and drops what does not fit.

The flash file (``flash_path``) is written at power-off and when the bus shuts down or the world
is discarded; within the process the ESCs keep their settings across power cycles anyway.

A world lives as long as the process (like a bench that stays plugged in): a second ``can.Bus`` on
the same channel joins it - which is how the harness reopens the host at another bit rate after
Set Baud. :func:`discard` removes it.
"""

from __future__ import annotations

import errno
import heapq
import itertools
import os
from collections import deque
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

import can
from can.broadcastmanager import ModifiableCyclicTaskABC, RestartableCyclicTaskABC

from ..protocol.canbus import DEFAULT_TXQUEUELEN, Attempt, CanController, ErrorFrame, ErrorState, QueueFull
from ..protocol.catalogue import DEFAULT_BITRATE
from ..protocol.frame import WireFrame, frame_bits, new_wire
from ..protocol.traffic import TrafficSource
from .emulated_bench import EmulatedBench
from .model import EscModel
from .sim_can import CanNodes, ShiftedSource
from .sim_frames import FrameOnItsWay, Heard, new_echo, new_heard, new_pending

_WORLDS: dict[str, SimWorld] = {}


class SimClock:
    """The lane's clock: what tests read instead of the wall clock."""

    def __init__(self, world: SimWorld) -> None:
        self._world = world

    def now(self) -> float:
        return self._world.now

    def __call__(self) -> float:
        return self._world.now


INF = float("inf")
_ACKED, _ACTIVE = Attempt.ACKED, ErrorState.ACTIVE  # (module constants: read once per frame)


class SimWorld(CanNodes):
    """One simulated CAN bus with its bench of ESCs and the host buses attached to it.

    Frames wait in ``_waiting`` (a heap by ready time) until the clock reaches their ready time, then join their
    sender's transmit queue (its :class:`~ckesc.protocol.canbus.CanController`); the heads of the queues contend
    for the bus (arbitration: the lowest id wins). A node whose head nobody can acknowledge and whose tries change
    nothing any more (error-passive: the ACK exception) is *parked*: its tries are not played one by one until a
    node that can listen appears (an ESC's boot ends, a bus opens, a source joins), when it resumes at its next
    retransmission slot. ``_alarm`` is the earliest of the resumptions, the bus-off recoveries and a short's end."""

    def __init__(self, channel: str, bench: EmulatedBench, *, power_on: bool = True, ack: bool = True) -> None:
        self.channel = channel
        #: whether a frame needs another node's acknowledgement (False: every try is sent, as a bus that no
        #: one needs to hear: the lanes before issue #36)
        self.ack = ack
        self.bench = bench
        self.now = 0.0
        self.clock = SimClock(self)
        self.buses: list[SimEscBus] = []
        self._waiting: list[tuple[float, int, FrameOnItsWay]] = []
        self._in_flight: tuple[float, FrameOnItsWay] | None = None
        self._ready: list[tuple[int, int, FrameOnItsWay]] = []  # without acknowledgement: every node's frames, by id
        self._outcome = Attempt.ACKED  # what the frame in flight meets
        self._seq = itertools.count()
        self._tasks: list[SimCyclicTask] = []
        self._sources: list[TrafficSource] = []
        self._ctl: dict[Any, CanController] = {}  # each node's controller (a bus, an ESC, a source)
        self._contending: list[Any] = []  # the nodes with a head frame to try now
        self._parked: dict[Any, tuple[float, float, float]] = {}  # node -> (since, retry period, resume at)
        self._short_until = -INF
        self._alarm = INF
        self._frames, self._busy_s, self._counts = 0, 0.0, {"retries": 0, "dropped": 0}  # (:attr:`stats`, kept apart)
        #: per traffic source (by name): frames it put on the bus and the bus time they took
        self.source_stats: dict[str, dict[str, float]] = {}
        if power_on:
            self.power_on()

    @property
    def stats(self) -> dict[str, float]:  # frames carried, bus time of the tries (s), tries not acknowledged, dropped
        return {"frames": self._frames, "busy_s": self._busy_s, **self._counts}

    # ------------------------------------------------------------------ event loop
    def advance(self, deadline: float, rx: deque | None = None, stop: Callable[[], bool] | None = None) -> bool | None:
        """Process the events due by ``deadline``, the earliest first, until ``rx`` (a host bus's queue) holds a frame
        or ``stop()`` says so: True then, the clock at the event that did it. False once the next event is after
        ``deadline``, None when nothing is scheduled at all: the clock then at ``deadline`` (where it was, if that is
        later; as it was, for an infinite ``deadline``).

        The event loop of every simulated run (hours of soak: each frame two events or three): finding the next event
        and processing it in one loop, plain comparisons, no min() of pairs, no call but the events' own work."""
        deadlines = self.bench._deadlines  # (one per ESC, refreshed in place)
        one = len(deadlines) == 1
        while True:
            if rx or (stop is not None and stop()):
                return True
            # the next event: the ESCs' earliest deadline, the frame on the bus ending (else one ready to contend
            # now, else the first waiting one), a controller's alarm (a recovery, a retry), a periodic task, another
            # node's frame
            now = self.now
            t = deadlines[0] if one else min(deadlines) if deadlines else INF
            in_flight = self._in_flight
            if in_flight is not None:
                if in_flight[0] < t:
                    t = in_flight[0]
            elif self._contending or self._ready:
                t = now
            elif self._waiting:
                if self._waiting[0][0] < t:
                    t = self._waiting[0][0]
            if self._alarm < t:
                t = self._alarm
            tasks, sources = self._tasks, self._sources
            if tasks:
                for task in tasks:
                    if task.next_time < t:
                        t = task.next_time
            if sources:
                for source in sources:
                    due = source.next_due()
                    if due < t:
                        t = due
            if t == INF:
                if deadline != INF and deadline > now:
                    self.now = deadline
                return None
            if t < now:
                t = now
            if t > deadline:
                if deadline > now:
                    self.now = deadline
                return False
            # ... and what happens at it
            self.now = t
            if in_flight is not None and in_flight[0] <= t:
                self._finish_transmission()
            if self._alarm <= t:
                self._on_alarm(t)
            if tasks:
                for task in self._tasks:
                    if task.next_time <= t:
                        task.fire(t)
            if sources:
                for source in self._sources:
                    if source.next_due() <= t:
                        bitrate = source.bitrate or self._host_bitrate()
                        for wire in source.take_due(t):
                            self._queue(wire, source, bitrate, ready=wire.timestamp)
            if (deadlines[0] if one else min(deadlines) if deadlines else INF) <= t:
                for esc, wire in self.bench.poll(t):
                    self._queue(wire, esc, esc.state.bitrate, ready=wire.timestamp)
            if self._in_flight is None and (self._ready or self._waiting or self._contending):
                self._start_transmission()

    def run_until(self, t_end: float, stop: Callable[[], bool] | None = None) -> None:
        self.advance(t_end, None, stop)

    def _queue(self, wire: WireFrame, origin: Any, bitrate: int, ready: float, flags: dict[str, bool] | None = None) -> None:
        now = self.now
        seq = next(self._seq)
        if ready <= now:
            self._submit(new_pending((now, seq, wire, origin, bitrate, flags)))
        else:
            heapq.heappush(self._waiting, (ready, seq, new_pending((ready, seq, wire, origin, bitrate, flags))))

    # ------------------------------------------------------------------ the nodes' controllers (sim_can.CanNodes: a
    # frame joining its node's queue, arbitration and the frame's try)
    def _finish_transmission(self) -> None:
        end, p = self._in_flight  # type: ignore[misc]
        self._in_flight = None
        _, _, old, origin, bitrate, flags = p
        if self.ack:
            ctl = self._ctl.get(origin)
            if ctl is None or ctl.sending is not p:  # its queue went away meanwhile (a power-off, a bus shut down)
                return
            if self._outcome is not _ACKED:
                self._failed(origin, ctl, end)
                return
            was = ctl.state
            ctl.attempt(_ACKED, end)
            if not ctl.size:
                self._contending.remove(origin)
            if was is not _ACTIVE:  # (only a controller past 95 can change its state by a success)
                self._report(origin, ctl)
        self._frames += 1
        own = isinstance(origin, SimEscBus)  # (a host's frame: most of a soak's; asked first)
        if not own and isinstance(origin, ShiftedSource):
            st = self.source_stats[origin.name]
            st["frames"] += 1
            st["busy_s"] += frame_bits(len(old.data)) / bitrate
        if not flags:
            # one frame for everyone (not _replace: once per frame): the ESCs' wire, and what a host's bus queues
            # as it is (no can.Message until one is read with recv): a host bus's own frame is its Echo
            wire = (new_echo if own else new_heard)((old.arbitration_id, old.data, end, old.is_extended_id))
            self.bench.deliver(wire, end, bitrate, None if own or not isinstance(origin, EscModel) else origin)
            for bus in self.buses:
                if bus.bitrate == bitrate:
                    if bus is origin:
                        if not bus.receive_own_messages:
                            continue
                        heard = wire
                    else:
                        heard = new_heard(wire) if own else wire
                    if bus._filters is None or bus._matches_filters(heard):
                        bus._rx.append(heard)
            return
        wire = new_wire((old.arbitration_id, old.data, end, old.is_extended_id))
        sender = origin if isinstance(origin, EscModel) else None
        heard = can.Message(timestamp=end, arbitration_id=wire.arbitration_id, data=wire.data,
                            is_extended_id=wire.is_extended_id, **flags)
        self.bench.deliver(heard, end, bitrate, sender=sender)  # the ESCs' decoder rejects remote/error frames
        for bus in self.buses:
            if bus.bitrate != bitrate:
                continue
            if bus is origin and not bus.receive_own_messages:
                continue
            bus._deliver(wire, is_rx=bus is not origin, **flags)

    # ------------------------------------------------------------------ other nodes
    def add_source(self, source: TrafficSource) -> None:
        """Put another node on this bus (:mod:`ckesc.protocol.traffic`): its frames are queued at their due
        times, its clock starting now, and contend by arbitration with everyone else's."""
        if not isinstance(source, TrafficSource):
            raise TypeError(f"not a traffic source: {source!r}")
        if any(s.name == source.name for s in self._sources):
            raise ValueError(f"a traffic source named {source.name!r} is already on {self.channel}")
        self._sources.append(ShiftedSource(source, self.now))
        self.source_stats.setdefault(source.name, {"frames": 0, "busy_s": 0.0})
        self._wake()

    def remove_source(self, source: TrafficSource | str) -> None:
        """Take a source off the bus (its frames already queued still go out)."""
        name = source if isinstance(source, str) else source.name
        self._sources = [s for s in self._sources if s.name != name]

    # ------------------------------------------------------------------ host side
    def send_wire(self, bus: SimEscBus, wire: WireFrame) -> None:
        """A host's data frame as it goes on the wire (``send`` without the ``can.Message``: a soak's stream):
        :meth:`_queue`'s, ready now."""
        self._submit(new_pending((self.now, next(self._seq), wire, bus, bus.bitrate, None)))

    def send(self, bus: SimEscBus, msg: can.Message) -> None:
        """Queue ``msg`` on ``bus``'s controller; raises :class:`~ckesc.protocol.canbus.QueueFull`."""
        flags = None
        if msg.is_remote_frame or msg.is_error_frame:
            flags = {"is_remote_frame": msg.is_remote_frame, "is_error_frame": msg.is_error_frame}
        # the ESCs ignore standard-id, remote and error frames; they still occupy the bus
        wire = new_wire((msg.arbitration_id, bytes(msg.data), 0.0, msg.is_extended_id))
        self._queue(wire, bus, bus.bitrate, ready=self.now, flags=flags)

    def attach(self, bus: SimEscBus) -> None:
        self.buses.append(bus)
        self._wake()

    def detach(self, bus: SimEscBus) -> None:
        if bus in self.buses:
            self.buses.remove(bus)
        self._forget(bus)

    # ------------------------------------------------------------------ power
    def power_off(self) -> None:
        self.bench.power_off(self.now)
        if self.ack:  # (without acknowledgement, the lanes' bus before issue #36: what an ESC queued still goes out)
            for esc in self.bench.escs:
                self._forget(esc)

    def power_on(self) -> None:
        self.bench.power_on(self.now)
        self._wake()

    def power_cycle(self, off_time: float = 1.0) -> None:
        self.power_off()
        self.run_until(self.now + off_time)
        self.power_on()


class SimCyclicTask(ModifiableCyclicTaskABC, RestartableCyclicTaskABC):
    """``bus.send_periodic`` in simulated time: exact periods on the lane's clock."""

    def __init__(self, bus: SimEscBus, messages, period: float, duration: float | None,
                 modifier_callback: Callable[[can.Message], None] | None) -> None:
        super().__init__(messages, period)
        self.bus = bus
        self.duration = duration
        self.modifier_callback = modifier_callback
        self.active = False
        self.index = 0
        self.start()

    def start(self) -> None:
        world = self.bus.world
        self.active = True
        self.next_time = world.now
        self.end_time = None if self.duration is None else world.now + self.duration
        if self not in world._tasks:
            world._tasks.append(self)

    def stop(self) -> None:
        self.active = False
        if self in self.bus.world._tasks:
            self.bus.world._tasks.remove(self)

    def fire(self, t: float) -> None:
        if self.end_time is not None and t > self.end_time:
            self.stop()
            return
        msg = self.messages[self.index]
        self.index = (self.index + 1) % len(self.messages)
        if self.modifier_callback is not None:
            self.modifier_callback(msg)
        try:
            self.bus.world.send(self.bus, msg)
        except QueueFull:  # SocketCAN's BCM: the frame is lost, the task goes on
            self.bus.world._counts["dropped"] += 1
        self.next_time = round(self.next_time + self.period, 9)


class SimEscBus(can.BusABC):
    """A host's view of a simulated bench. See the module docstring."""

    def __init__(
        self,
        channel: Any = "ckesc-sim",
        can_filters=None,
        *,
        nodes: Iterable[int] | str = (1,),
        bitrate: int = DEFAULT_BITRATE,
        faults: Iterable[str] | Mapping[int, Iterable[str]] | str | None = None,
        flash_path: str | None = None,
        seed: int = 0,
        esc_config: Mapping[str, Any] | None = None,
        receive_own_messages: bool = False,
        txqueuelen: int | None = DEFAULT_TXQUEUELEN,
        ack: bool = True,
        tx_order: str = "fifo",
        auto_recovery: bool = True,
        error_frames: bool = False,
        berr_reporting: bool = False,
        **kwargs: Any,
    ) -> None:
        channel = str(channel)
        if isinstance(nodes, str):  # from can.conf / CAN_CONFIG strings: "1,2,3"
            nodes = [int(n, 0) for n in nodes.split(",") if n.strip()]
        if isinstance(faults, str):
            faults = [f for f in faults.split(",") if f.strip()]
        world = _WORLDS.get(channel)
        if world is None:
            bench = EmulatedBench(nodes, faults=faults, flash=flash_path, seed=seed, config=esc_config)
            world = _WORLDS[channel] = SimWorld(channel, bench, ack=_flag(ack))
        self.world = world
        self.bitrate = int(bitrate)
        self.receive_own_messages = receive_own_messages
        #: this bus's controller (:mod:`ckesc.protocol.canbus`): its transmit queue, and its recovery from bus-off
        self.controller_options = {"txqueuelen": None if txqueuelen in (None, "", "none") else int(txqueuelen),
                                   "order": tx_order,
                                   "auto_recovery": _flag(auto_recovery), "berr_reporting": _flag(berr_reporting)}
        CanController(self.bitrate, **self.controller_options)  # (checks them before the bus joins the world)
        self.error_frames = _flag(error_frames)  # SocketCAN's CAN_RAW_ERR_FILTER: hand this bus its error frames
        self._rx: deque[Heard | can.Message] = deque()  # (a data frame as heard: recv makes its Message)
        self.channel_info = f"ckesc-sim {channel} @ {self.bitrate} bit/s ({len(world.bench.escs)} ESCs)"
        super().__init__(channel, can_filters=can_filters, **kwargs)
        self.channel = channel
        world.attach(self)

    # ---------------------------------------------------------------- the lane's extras
    @property
    def clock(self) -> SimClock:
        return self.world.clock

    @property
    def bench(self) -> EmulatedBench:
        return self.world.bench

    def now(self) -> float:
        return self.world.now

    def advance(self, seconds: float) -> None:
        """Let simulated time pass (frames that arrive meanwhile wait in this bus's queue)."""
        self.world.run_until(self.world.now + seconds)

    def power_off(self) -> None:
        self.world.power_off()

    def power_on(self) -> None:
        self.world.power_on()

    def power_cycle(self, off_time: float = 1.0) -> None:
        self.world.power_cycle(off_time)

    def set_fault(self, name: str, on: bool = True, node: int | None = None) -> None:
        self.world.bench.set_fault(name, on, node)

    @property
    def controller(self) -> CanController:
        """This bus's CAN controller: its error counters (``tec``, ``rec``), state and transmit queue."""
        return self.world.controller(self)

    @property
    def state(self) -> can.BusState:
        """python-can's view of the controller: ACTIVE (error-active or -warning), PASSIVE, ERROR (bus-off)."""
        return _BUS_STATE[self.world.controller(self).state]

    def restart(self) -> None:
        """Restart the controller (SocketCAN's ``ip link set canX type can restart``): error-active again,
        its queue kept."""
        ctl = self.world.controller(self)
        was_off = ctl.bus_off
        ctl.restart(self.world.now)
        self.world._report(self, ctl)
        if was_off and ctl and self not in self.world._contending:
            self.world._contending.append(self)
        self.world._wake()

    # ---------------------------------------------------------------- BusABC
    def _deliver(self, wire: WireFrame, is_rx: bool, **flags: bool) -> None:
        msg = can.Message(timestamp=wire.timestamp, arbitration_id=wire.arbitration_id, is_extended_id=wire.is_extended_id,
                          data=wire.data, is_rx=is_rx, channel=self.channel, **flags)
        if self._filters is None or self._matches_filters(msg):
            self._rx.append(msg)

    def _deliver_error(self, frame: ErrorFrame) -> None:
        self._rx.append(can.Message(timestamp=frame.timestamp, arbitration_id=frame.can_id, is_extended_id=False,
                                    is_error_frame=True, dlc=len(frame.data), data=frame.data, channel=self.channel))

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Queue ``msg`` on this bus's controller; a full queue raises ``can.CanOperationError`` at once, as
        SocketCAN's ENOBUFS does (its ``timeout`` waits for the socket, which a full queue leaves writable)."""
        self._check_open()
        try:
            self.world.send(self, msg)
        except QueueFull as exc:
            raise self._enobufs(exc) from exc

    def send_wire(self, wire: WireFrame) -> None:
        """:meth:`send` of a data frame given as it goes on the wire (its ``timestamp`` unused): no ``can.Message``
        built for it, as a soak's stream sends hours of them."""
        if self._is_shutdown:
            self._check_open()
        try:
            self.world.send_wire(self, wire)
        except QueueFull as exc:
            raise self._enobufs(exc) from exc

    def _enobufs(self, exc: QueueFull) -> can.CanOperationError:
        return can.CanOperationError(f"Failed to transmit: {os.strerror(errno.ENOBUFS)} ({exc}; controller "
                                     f"{self.world.controller(self).state.value})", errno.ENOBUFS)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The next frame, advancing simulated time up to ``timeout`` seconds to wait for it."""
        self._check_open()
        if self._rx:
            return self._message(self._rx.popleft())
        world = self.world
        return self._until(float("inf") if timeout is None else world.now + max(timeout, 0.0), timeout is None)

    def recv_until(self, deadline: float) -> can.Message | None:
        """:meth:`recv` with ``timeout`` ``deadline - now`` (a lane's read loop: every frame of a soak)."""
        if self._is_shutdown:
            self._check_open()
        if self._rx:
            return self._message(self._rx.popleft())
        now = self.world.now
        return self._until(now + max(deadline - now, 0.0), False)  # (recv's arithmetic: the same instant)

    def frames_until(self, deadline: float, bus_off: Callable[[], None] | None = None) -> Iterator[Heard | can.Message]:
        """Every frame until ``deadline``: :meth:`recv_until` again and again until it gives none (the clock then at
        ``deadline``), without a call per frame between the reader and the simulated clock, and each data frame as
        the bus heard it (a :class:`Heard`: ``timestamp``, ``arbitration_id``, ``data``, ``is_extended_id``,
        ``is_rx`` and the flags, as a ``can.Message`` has them; no ``can.Message`` made: a soak reads hours of them).
        The world runs up to ``deadline`` in one go and the frames it heard meanwhile are yielded after it: the frames
        a :meth:`recv_until` loop reads, with the same stamps, but the clock, read between two of them, is at the
        deadline already; a reader that sends between the frames it reads reads with :meth:`recv_until` (a soak
        sends between its reads, not during them). ``bus_off``: called where this bus's controller is bus-off, looked at
        after each run of the world (nothing else moves it between two frames handed on) and before the first frame."""
        rx, world, off, ctl = self._rx, self.world, ErrorState.BUS_OFF, self.controller if bus_off is not None else None
        advance = world.advance
        if ctl is not None and ctl.state is off and rx:
            bus_off()
        while True:
            if self._is_shutdown:
                self._check_open()
            if rx:
                yield rx.popleft()
                continue
            now = world.now
            left = deadline - now  # (recv_until's arithmetic, max(left, 0.0) as :meth:`_until` reads, without the call)
            # where 0 < left <= now, now + left is the deadline exactly, and stays so for every later now (Sterbenz:
            # deadline - now is exact while now >= deadline / 2): recv_until's calls would each run the world to the
            # deadline, one call does it once
            whole = 0.0 < left <= now
            more = advance(deadline, None) if whole else advance(now + left if left > 0.0 else now, rx)
            if ctl is not None and ctl.state is off:
                bus_off()
            if whole:
                while rx:
                    yield rx.popleft()
                return
            if not more:
                return

    def _until(self, deadline: float, forever: bool) -> can.Message | None:
        rx = self._rx
        came = self.world.advance(deadline, rx)
        if came:
            return self._message(rx.popleft())
        if came is None and forever:
            raise can.CanOperationError("ckesc-sim: recv() without timeout on a bus where nothing will ever happen")
        return None

    def _recv_internal(self, timeout: float | None):
        return (self._message(self._rx.popleft()) if self._rx else None), True

    def _message(self, heard: Heard | can.Message) -> can.Message:
        """The ``can.Message`` of a frame this bus heard (a data frame is queued as the bus heard it, a remote or
        error frame as its ``can.Message``)."""
        if type(heard) is can.Message:
            return heard
        return can.Message(timestamp=heard.timestamp, arbitration_id=heard.arbitration_id,
                           is_extended_id=heard.is_extended_id, data=heard.data, is_rx=heard.is_rx, channel=self.channel)

    def _send_periodic_internal(self, msgs: can.Message | Sequence[can.Message], period: float,
                                duration: float | None = None, autostart: bool = True,
                                modifier_callback: Callable[[can.Message], None] | None = None) -> SimCyclicTask:
        task = SimCyclicTask(self, msgs, period, duration, modifier_callback)
        if not autostart:
            task.stop()
        return task

    def _check_open(self) -> None:
        if self._is_shutdown:
            raise can.CanOperationError("ckesc-sim: the bus was shut down")

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        self.world.detach(self)
        self.world.bench.persist()
        super().shutdown()

    @staticmethod
    def _detect_available_configs():
        return [{"interface": "ckesc-sim", "channel": "ckesc-sim"}]


_BUS_STATE = {ErrorState.ACTIVE: can.BusState.ACTIVE, ErrorState.WARNING: can.BusState.ACTIVE,
              ErrorState.PASSIVE: can.BusState.PASSIVE, ErrorState.BUS_OFF: can.BusState.ERROR}


def _flag(value: Any) -> bool:
    """A yes/no option, also as can.conf / CAN_CONFIG give it (a string)."""
    if isinstance(value, str):
        return value.strip().lower() not in ("", "0", "false", "no", "off")
    return bool(value)


def discard(channel: str) -> None:
    """Forget the world on ``channel`` (its flash file, if any, is written first)."""
    world = _WORLDS.pop(str(channel), None)
    if world is not None:
        world.bench.persist()


def world(channel: str) -> SimWorld:
    return _WORLDS[str(channel)]
