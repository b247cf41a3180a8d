"""The simulated lane: the emulator in simulated time (``ckesc-sim``, :mod:`ckesc.emulator.sim_bus`), exact timing,
clock "simulated"; the lane's base and the real bus's lane are in :mod:`.lanes`."""

from __future__ import annotations

import itertools
import os
from functools import partial
from typing import Any, Iterator

import can

from ..emulator import sim_bus
from ..protocol import canbus
from ..protocol.catalogue import DEFAULT_BITRATE
from ..protocol.frame import WireFrame
from .lanes import BUS_ERRORS, BusFault, Lane, queue_full, room_wait_s
from .power import EmulatorPower

_SIM_CHANNELS = itertools.count()
_BUS_OFF = canbus.ErrorState.BUS_OFF


#: the simulated lane's CAN (ckesc/emulator/sim_bus.py): SocketCAN's defaults, as a real bench has them (a frame needs
#: a second powered node to acknowledge it, the host's transmit queue is FIFO and holds 10 frames, a full queue is
#: ENOBUFS). ``CKESC_SIM_ACK=0`` opens the lane without the CAN model (every frame delivered at once, no queue limit):
#: only to measure the model's cost (benchmarks/README.md)
SIM_CAN: dict[str, Any] = {} if os.environ.get("CKESC_SIM_ACK", "1") != "0" else {"ack": False, "txqueuelen": None}


class SimLane(Lane):
    name = "simulated"
    clock = "simulated"
    timing_error = 0.0

    def __init__(self, *, nodes=(1,), faults=None, flash_path: str | None = None, seed: int = 0,
                 bitrate: int = DEFAULT_BITRATE, esc_config: dict[str, Any] | None = None) -> None:
        self.channel = f"ckesc-suite-{os.getpid()}-{next(_SIM_CHANNELS)}"
        self.bitrate = bitrate
        self.sim = can.Bus(interface="ckesc-sim", channel=self.channel, nodes=list(nodes), faults=faults,
                           flash_path=flash_path, seed=seed, bitrate=bitrate, esc_config=esc_config,
                           receive_own_messages=True, ignore_config=True, **SIM_CAN)
        self.bus = _SimSend(self)
        self.power = EmulatorPower(self)

    @property
    def host_clock(self) -> tuple[str, float]:
        return self.clock, 0.0  # the host acts in simulated time, exactly

    def now(self) -> float:
        return self.sim.world.now

    peek_now = now

    def recv_until(self, deadline: float) -> can.Message | None:
        # Lane.recv_until with the calls between it and the simulated clock taken out (hours of soak read here)
        msg = self.sim.recv_until(deadline)
        if self.sim.world.ack:
            _check_controller(self.sim)
        return self.heard(msg) if msg is not None else None

    def recv(self, timeout: float) -> can.Message | None:
        msg = super().recv(timeout)
        if self.sim.world.ack:
            _check_controller(self.sim)
        return msg

    def frames_until(self, deadline: float) -> Iterator[can.Message]:
        # Lane.frames_until with the calls between it and the simulated bus taken out (hours of soak read here: each
        # data frame as the bus heard it, sim_bus.Heard, with a can.Message's attributes but none made); the
        # listeners are looked for once per call. On a bus with acknowledgement the host's controller is looked at
        # before each frame is handed on and once the world reached the deadline (its bus-off is the bench's failure,
        # not the DUT's)
        sim = self.sim
        frames = sim.frames_until(deadline, partial(_check_controller, sim) if sim.world.ack else None)
        if self.__dict__.get("_listeners"):  # (a listener is handed can.Messages)
            message, heard = self.sim._message, self.heard
            return (heard(message(msg)) for msg in frames)
        return frames

    def frames_into(self, deadline: float, out: list[Any]) -> None:
        """:meth:`frames_until`'s frames onto ``out`` as plain values, four a frame: a data frame's ``arbitration_id``,
        ``data``, ``timestamp`` and ``is_extended_id``; a remote or error frame's first three and, for the fourth, the
        tuple (``is_extended_id``, ``is_remote_frame``, ``is_error_frame``, ``dlc``). What a soak's world hands to its
        reader in another process (:mod:`ckesc.soak.split`): the bus's queue taken whole where the world runs to the
        deadline in one go (no call per frame)."""
        sim = self.sim
        world, rx = sim.world, sim._rx
        now = world.now
        left = deadline - now
        if not rx and 0.0 < left <= now and not sim._is_shutdown and not self.__dict__.get("_listeners"):
            world.advance(deadline, None)  # (frames_until's one run of the world to the deadline)
            if world.ack and (ctl := world._ctl.get(sim)) is not None and ctl.state is _BUS_OFF:  # (no controller
                _check_controller(sim)  # yet: error-active)
            n = len(out)
            try:
                out += itertools.chain.from_iterable(rx)  # (a data frame is the bus's tuple of those four)
                rx.clear()
                return
            except TypeError:  # a can.Message among them (a remote or error frame): one by one
                del out[n:]
        message = can.Message
        for heard in self.frames_until(deadline):
            if heard.__class__ is message:
                out += (heard.arbitration_id, bytes(heard.data), heard.timestamp,
                        (heard.is_extended_id, heard.is_remote_frame, heard.is_error_frame, heard.dlc))
            else:
                out += heard

    def send_wire(self, wire: WireFrame) -> None:
        sim = self.sim  # (no can.Message built: hours of soak send here)
        if sim.world.ack or sim._is_shutdown:
            try:
                if sim._is_shutdown:
                    sim.send_wire(wire)  # (a closed bus refused, as the bus says it)
                else:
                    sim.world.send_wire(sim, wire)  # (the bus's send_wire, one call less)
            except canbus.QueueFull as full:  # (a full queue said as the bus says it)
                placed(sim, sim._enobufs(full), sim.send_wire, wire, boot=self.dut_boot_s)
            except BUS_ERRORS as exc:
                placed(sim, exc, sim.send_wire, wire, boot=self.dut_boot_s)
        else:  # without acknowledgement nothing refuses a frame: the world takes it (the bus's send_wire, one call less)
            sim.world.send_wire(sim, wire)

    def wait_power(self, seconds: float) -> None:
        self.sim.advance(seconds)

    def reopen(self, bitrate: int) -> None:
        old = self.sim
        self.sim = can.Bus(interface="ckesc-sim", channel=self.channel, bitrate=bitrate,
                           receive_own_messages=True, ignore_config=True, **SIM_CAN)
        self.bus = _SimSend(self)
        old.shutdown()
        self.bitrate = bitrate
        self.reopens += 1

    def close(self) -> None:
        self.sim.shutdown()
        sim_bus.discard(self.channel)


class _SimSend:
    """The simulated bus as the suite sends on it, as a careful host sends on SocketCAN: a send that finds the transmit
    queue full (ENOBUFS) waits for room while the bus carries the frames ahead of it (a burst of more than the queue,
    up to :func:`~.lanes.room_wait_s`) and is then placed; a queue that nobody empties (no acknowledgement: the DUT
    off or silent; the host's controller bus-off), and any other failed send, is the bench's failure under the test
    (:class:`BusFault`: an ERROR, its one line naming the queue and the controller's state), as on a real bus;
    everything else is the bus's own."""

    def __init__(self, lane: SimLane) -> None:
        self._lane = lane

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        bus = self._lane.sim
        try:
            bus.send(msg, timeout)
        except BUS_ERRORS as exc:
            placed(bus, exc, bus.send, msg, timeout, boot=self._lane.dut_boot_s)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._lane.sim, name)


def placed(bus: Any, exc: BaseException, send: Any, *args: Any, boot: float = 0.0) -> None:
    """After ``send(*args)`` on the simulated ``bus`` raised ``exc``: wait for room in its transmit queue and send again
    (:class:`_SimSend`), or raise :class:`BusFault` naming the queue, the controller and the wait. The wait is
    :func:`~.lanes.room_wait_s`, and ``boot`` more (the DUT's declared boot time, :attr:`~.lanes.Lane.dut_boot_s`):
    while nobody acknowledges, the DUT may be rebooting, and takes the frames once it is back."""
    ctl = bus.controller
    waited = 0.0
    if queue_full(exc) and not ctl.bus_off:
        world, n = bus.world, ctl.txqueuelen
        t0 = world.now
        world.run_until(t0 + room_wait_s(bus.bitrate, n) + boot, stop=lambda: ctl.size < n or ctl.bus_off)
        waited = world.now - t0
        if ctl.size < n:
            try:
                send(*args)
                return
            except BUS_ERRORS as again:
                exc = again
    why = "nobody acknowledged them" if ctl.tec else "sent faster than the bus carries them"
    raise BusFault(f"the host's CAN send failed ({type(exc).__name__}: {exc}; its controller {ctl.state.value}, "
                   f"TEC {ctl.tec}, {len(ctl)} frame(s) waiting after {waited * 1000:.3f} ms: {why})") from exc


def _check_controller(bus: Any) -> None:
    """The host's own controller bus-off: the bench failed under the test (:class:`BusFault`), not the DUT."""
    ctl = bus.controller
    if ctl.bus_off:
        raise BusFault(f"the host's CAN controller is bus-off (TEC {ctl.tec}, {ctl.counts['bus_off']} time(s) this run; "
                       f"{'it recovers by itself' if ctl.auto_recovery else 'no automatic recovery: restart it'})")
