"""Lanes: where the DUT lives and which clock the suite measures with.

* :class:`~.sim_lane.SimLane` (:mod:`.sim_lane`) - the emulator in simulated time (``ckesc-sim``): exact timing,
  clock "simulated".
* :class:`BusLane` - a real python-can bus (a real ESC on SocketCAN, or ``ckesc emulate`` behind
  socketcand): the clock is the bus timestamps, with the DUT profile's stated measurement error. The
  lane finds out at the start (:meth:`BusLane.find_echo`) whether the host's own frames come back
  (``receive_own_messages``, the socketcand echo). Where they do not (many USB adapters: python-can's
  slcan, gs_usb, canalystii), it hands out a copy of each frame it sent (:class:`OwnFrame`, throttle
  streams included) stamped by the host clock at send, so that everything reading the lane (the
  tests, the live rules, the traces) still sees both directions; measurements that use such a time
  say "host clock" and carry the larger error: the bench's plus :attr:`Lane.host_send_error`.

Tests never read the wall clock or sleep: they ask the lane (through the ``dut`` fixture).
"""

from __future__ import annotations

import errno
import math
import shlex
import socket
import subprocess
import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from typing import Any, Iterator

import can

from ..protocol.canbus import DEFAULT_TXQUEUELEN
from ..protocol.catalogue import DEFAULT_BITRATE
from ..protocol.frame import WireFrame, frame_bits
from ..protocol.judgements import R18_MAX_SHARE, r18_queueing_s
from .adapter import AdapterWatch
from .epochs import PowerEpoch
from .power import PowerControl
from .profile import DEFAULT_BUS_ERROR_S

#: How long the lane waits for the echo of its probe frame, and how often it tries while the bus is silent
ECHO_PROBE_S = 0.25
ECHO_PROBE_TRIES = 3


class OwnFrame(can.Message):
    """A frame the host sent, handed out by a lane whose adapter does not echo (``is_rx`` False, like an
    echo), stamped by the host clock when it was sent."""

    __slots__ = ()


class Lane(ABC):
    name: str
    clock: str  # the verdict clock label: "simulated" or "bus timestamp"
    timing_error: float = 0.0  # seconds: margins smaller than this are INCONCLUSIVE
    #: which end of a frame the lane's timestamps mark: "end" (SocketCAN, socketcand, both emulators) or "start"
    #: (an adapter stamping the start of frame; the DUT profile's [timing] stamp)
    stamp: str = "end"
    #: whether the host's own frames come back from the bus (their echo gives their bus time); False: the
    #: lane hands out :class:`OwnFrame` copies stamped by the host clock at send
    echo: bool = True
    #: how the lane found out about the echo (for the reports)
    echo_note: str = "the lane's own bus echoes every frame"
    #: how much later than the host clock read at ``send()`` a frame may be on the bus (s; driver and USB latency, a TX
    #: queue, lost arbitration): the error of the time a lane without echo gives the host's own frames, on top of the
    #: bench's stated one; by default a real bench's (:data:`ckesc.bench.profile.DEFAULT_BUS_ERROR_S`)
    host_send_error: float = DEFAULT_BUS_ERROR_S
    can_change_bitrate: bool = True  # reopen() really moves the host to another bit rate (Set Baud's tests)
    #: the DUT's current power-up as the harness made it (None: unknown, or off); see epochs.py
    epoch: PowerEpoch | None = None
    #: why the host may be alone on this bus now (None: another node has been heard since the ESC's power was last
    #: switched): nobody may acknowledge the host's frames, and a real adapter holds them (R20); set by the supply
    #: (:mod:`.supply`: :data:`SWITCHED_OFF`, :data:`BOOTING`, :data:`UNHEARD`), cleared by the first frame of another
    #: node the link reads (:mod:`.link`), kept with each send
    alone: str | None = "no other node was heard yet"
    #: the other nodes' traffic playing on this lane (``--foreign-traffic``: a station.ForeignPlay), None: a quiet bus
    foreign_traffic: Any = None
    bus: can.BusABC
    power: PowerControl
    bitrate: int
    #: how long a send that finds the host's transmit queue full waits for room beyond :func:`room_wait_s` (s): the DUT's
    #: declared boot time (the profile's ``boot_s``, set by :meth:`.station.Station.open_lane`): while nobody acknowledges the host's frames
    #: the DUT may be rebooting (a reset is the test's verdict to give, not a bench ERROR), and takes them once back
    dut_boot_s: float = 0.0
    #: how many times the host's bus was reopened (:meth:`reopen`): the bus rules start again at each (a node's frames
    #: held meanwhile come at once, as it is acknowledged again)
    reopens: int = 0

    @abstractmethod
    def now(self) -> float:
        """Lane time in the bus's time base (what frame timestamps are compared with)."""

    @abstractmethod
    def wait_power(self, seconds: float) -> None:
        """Let ``seconds`` pass while the DUT is unpowered (no frames to read)."""

    def peek_now(self) -> float:
        """Lane time for an onlooker (the run's progress): :meth:`now` without its effects on what a test reads
        (a real-time lane's :meth:`now` may read the bus to hold its clock at a frame not read yet)."""
        return self.now()

    @property
    def host_clock(self) -> tuple[str, float]:
        """The clock that times what the host does when no echo says when it reached the bus (a send),
        and that time's error (s): the bench's stated error plus :attr:`host_send_error`."""
        return "host clock", self.timing_error + self.host_send_error

    @property
    def own_clock(self) -> str:
        """The clock that times the host's own frames as the lane hands them out: the lane's (their
        echo), or the host clock without an echo."""
        return self.clock if self.echo else self.host_clock[0]

    @property
    def own_error(self) -> float:
        """The error (s) of a time the lane gives one of the host's own frames (:attr:`own_clock`)."""
        return self.timing_error if self.echo else self.host_clock[1]

    @property
    def listeners(self) -> list[can.Listener]:
        """python-can listeners (``can.BLFWriter``, ``can.ASCWriter``, a live rule checker) handed every
        frame the lane reads off the bus, in order, as python-can gave it (lane timestamps, frames that
        do not decode, error and remote frames): the DUT's frames and the host's own, which come back
        as their ``receive_own_messages`` echo (``is_rx`` False) stamped when they left. A frame the
        host sent that never reached the bus is, rightly, not seen."""
        try:
            return self.__dict__["_listeners"]
        except KeyError:
            return self.__dict__.setdefault("_listeners", [])

    def heard(self, msg: can.Message | None) -> can.Message | None:
        """Hand ``msg`` (if any) to the listeners; every lane calls it on each frame it reads."""
        if msg is not None:
            listeners = self.__dict__.get("_listeners")  # (none, mostly: every frame read passes here)
            if listeners:
                for listener in listeners:
                    listener.on_message_received(msg)
        return msg

    def recv(self, timeout: float) -> can.Message | None:
        return self.heard(self.bus.recv(timeout=max(timeout, 0.0)))

    def send_wire(self, wire: WireFrame) -> None:
        """Send one data frame as it goes on the wire, on the host's handle (``bus.send``): a long run's stream
        (``ckesc soak``), every frame of it."""
        self.bus.send(can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=wire.is_extended_id))

    def recv_until(self, deadline: float) -> can.Message | None:
        """The next frame read before lane time ``deadline`` (``recv(deadline - now())``), else None: a long run's
        read loop (``ckesc soak``), every frame of it."""
        return self.recv(deadline - self.now())

    def frames_until(self, deadline: float) -> Iterator[can.Message]:
        """Every frame read before lane time ``deadline``, one :meth:`recv_until` after another (the clock at
        ``deadline`` once it ends): a long run's read loop, every frame of it."""
        while (msg := self.recv_until(deadline)) is not None:
            yield msg

    @abstractmethod
    def reopen(self, bitrate: int) -> None:
        """Reopen the host's bus at another bit rate (after Set Baud); counted in :attr:`reopens`."""

    def stop_streams(self) -> None:
        """Stop every throttle stream on this lane, whichever host (a test's :class:`.link.Link`, a helper's)
        started it: python-can keeps a bus's periodic tasks (``stop_all_periodic_tasks``). The exit paths'
        zero throttle calls it, so that no stream outlives a Ctrl-C that cut its owner's teardown short."""
        self.bus.stop_all_periodic_tasks()

    def close(self) -> None:
        self.bus.shutdown()


# ------------------------------------------------------------------------------------------ real bus


#: The receive buffer a SocketCAN socket asks for. A host that is not scheduled for a while (a loaded
#: machine, a VM) must not lose what arrives meanwhile: the kernel drops frames silently once a socket's
#: buffer is full, and the default (~200 KB) holds about 200 frames, 50 ms of a busy 1 Mbit/s bus, or
#: one burst of a late emulator; a lost frame reads as a transfer-id gap (F3) or a missing report.
SOCKETCAN_RCVBUF = 8 << 20
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # Linux: past net.core.rmem_max, with CAP_NET_ADMIN


def enlarge_receive_buffer(sock: socket.socket, size: int = SOCKETCAN_RCVBUF) -> int:
    """Ask for ``size`` bytes of receive buffer (forced where permitted, else up to rmem_max); returns
    what the kernel granted."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, _SO_RCVBUFFORCE, size)
    except OSError:  # no CAP_NET_ADMIN: as much as net.core.rmem_max allows
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
    return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)


class BenchGone(RuntimeError):
    """The bench itself went away mid-run (the emulator's process exited, the adapter vanished): no
    further test can reach the DUT, so the plugin aborts the run with this message."""


class BusFault(RuntimeError):
    """The host's bus failed under a test (a send or a read raised: bus-off, a full TX queue, an adapter
    unplugged) and the lane reopened it: that test ERRORs with this message, the run goes on."""


#: :attr:`Lane.alone` while the ESC's power is switched off, and from power-on until it reports (its controller may come
#: up at any moment: what the host sent meanwhile goes out then)
SWITCHED_OFF = "the ESC was switched off"
BOOTING = "the ESC was booting"
#: ... and once its boot time has passed without a report from it (nothing will take the host's frames soon)
UNHEARD = "no report from the ESC since its power-on"

#: How often, and how far apart, the lane tries to reopen a bus that failed before it gives up (BenchGone)
REOPEN_TRIES = 3
REOPEN_PAUSE_S = 0.5
#: python-can exceptions (and the OSError of a vanished device) that mean the bus failed
BUS_ERRORS = (OSError, can.CanError)


def queue_full(exc: BaseException) -> bool:
    """Whether a send failed because the host's transmit queue is full (SocketCAN's ENOBUFS: python-can's
    ``CanOperationError`` with that error code, or the ``OSError`` itself): the frames ahead of it have not gone yet."""
    return getattr(exc, "error_code", None) == errno.ENOBUFS or getattr(exc, "errno", None) == errno.ENOBUFS


def room_wait_s(bitrate: int, txqueuelen: int | None = DEFAULT_TXQUEUELEN) -> float:
    """How long a careful host waits for room in its full transmit queue before it calls the bus failed: each frame
    of the queue waiting as long as R18's heaviest judged load can hold a lowest-priority frame back
    (:func:`~ckesc.protocol.judgements.r18_queueing_s`; 26 ms for SocketCAN's 10 frames at 500 kbit/s). A queue that
    stays full longer is not the host's burst: nobody acknowledges its frames (the DUT off or silent), or the bus
    carries less than a conforming one must."""
    return (txqueuelen or DEFAULT_TXQUEUELEN) * r18_queueing_s(R18_MAX_SHARE, bitrate)


class _SendTap:
    """A python-can bus whose send() tells the lane when the host sent a frame, or that the send failed
    (everything else is the bus's own). Throttle streams (send_periodic) are python-can's thread-based
    tasks sending through the tap (unless the interface has its own and echoes), so that a failed send
    reaches the lane and, without an echo, the lane sees every frame a stream sent."""

    def __init__(self, bus: can.BusABC, lane: BusLane, *, stream: bool = False) -> None:
        self._bus = bus
        self._lane = lane
        self._stream = stream  # a periodic task's sends: noted, but they hold no reading of the lane clock

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._send(msg, timeout, self._stream)

    def send_played(self, msg: can.Message, timeout: float | None = None) -> None:
        """A frame the bench plays from a thread of its own (another node's traffic, a load): sent as a stream's
        are (a failure raised to the player, which counts it; no hold on the lane clock), and seen by the lane."""
        self._send(msg, timeout, True)

    def _send(self, msg: can.Message, timeout: float | None, stream: bool) -> None:
        with self._lane._send_lock:  # one frame at a time on the one handle, whichever thread sends it
            try:
                t = self._place(msg, timeout, stream)
            except BUS_ERRORS as exc:
                failed = exc
            else:
                self._lane._sent(t, msg, stream=stream)
                return
        # (the lock let go first: reopening the bus stops the streams, whose threads may wait for it)
        if not stream:  # a stream's task hands it to the lane itself (on_error); a player counts it
            self._lane._io_failed(failed)
        raise failed

    def _place(self, msg: can.Message, timeout: float | None, stream: bool) -> float:
        """``send()``; a test's frame that finds the transmit queue full (ENOBUFS) waits for room, polling one longest
        frame's bus time apart, up to :func:`room_wait_s` and the DUT's boot time (:attr:`Lane.dut_boot_s`), as the
        simulated lane's :func:`~.sim_lane.placed` does; a stream's or a player's frame is lost at once, as SocketCAN's
        BCM loses it. Returns the host clock read just before the send that went."""
        lane = self._lane
        deadline = None
        while True:
            t = time.time()  # the kernel stamps the frame (and its echo) after this
            try:
                self._bus.send(msg, timeout)
                return t
            except BUS_ERRORS as exc:
                if stream or not queue_full(exc):
                    raise
                now = time.monotonic()
                if deadline is None:
                    deadline = now + room_wait_s(lane.bitrate) + lane.dut_boot_s
                elif now >= deadline:
                    raise
            time.sleep(frame_bits(8) / lane.bitrate)  # the harness waits for the bus, not a test for the DUT

    def send_periodic(self, msgs, period: float, duration: float | None = None, store_task: bool = True,
                      autostart: bool = True, modifier_callback=None):
        native = type(self._bus)._send_periodic_internal is not can.BusABC._send_periodic_internal
        if self._lane.echo and native:  # the interface's own (e.g. SocketCAN's kernel BCM): its frames come back
            return _stopped_means_stopped(self._bus.send_periodic(msgs, period, duration, store_task, autostart,
                                                                  modifier_callback))
        # python-can's thread-based task, as the bus itself would run it, but sending through the tap: a
        # failed send reaches the lane, and without an echo the lane sees every frame the stream sent
        task = can.broadcastmanager.ThreadBasedCyclicSendTask(
            _SendTap(self._bus, self._lane, stream=True), self._lane._stream_lock, msgs, period, duration,
            on_error=self._lane._stream_failed, autostart=autostart, modifier_callback=modifier_callback)
        self._lane._tasks.append(task)
        return _stopped_means_stopped(task)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._bus, name)


class BusLane(Lane):
    name = "bus"
    clock = "bus timestamp"

    def __init__(self, bus_kwargs: dict[str, Any], power: PowerControl, *, timing_error: float,
                 bitrate_cmd: str | None = None, host_send_error: float = DEFAULT_BUS_ERROR_S, stamp: str = "end") -> None:
        self.bus_kwargs = dict(bus_kwargs)
        self.stamp = stamp
        self.host_send_error = host_send_error
        self.bus_kwargs.setdefault("receive_own_messages", True)
        self._pending: deque[can.Message] = deque()  # arrived, seen by now(), not yet handed out by recv()
        self._own: deque[OwnFrame] = deque()  # without an echo: the host's frames, not yet handed out
        self._last_ts = -math.inf  # the latest timestamp handed out (an OwnFrame is never stamped before it)
        self._tasks: list[Any] = []  # the throttle streams' thread-based tasks (stopped on close)
        self._stream_lock = threading.Lock()  # one send at a time from the streams' threads
        self._send_lock = threading.Lock()  # one send at a time on the handle: the test's, a stream's, a player's
        self._fault: BaseException | None = None  # a throttle stream's send failed (in its thread)
        self._hold: float | None = None  # see now(): after a read -inf, after a send its time, else None
        self.rcvbuf: int | None = None  # a SocketCAN socket's receive buffer, as the kernel granted it
        self.echo = True  # until find_echo() says otherwise: what python-can was asked for
        self.echo_note = "not probed"
        self.recoveries: list[str] = []  # each bus failure the lane recovered from (reopened)
        self.adapter = AdapterWatch(self)  # the host's own adapter's state (bus-off, error-passive): adapter.py
        self.bus = self._open(self.bus_kwargs)
        self.bitrate = int(self.bus_kwargs.get("bitrate") or DEFAULT_BITRATE)
        self.power = power
        self.timing_error = timing_error
        # run by reopen() to move the bus itself to another bit rate ("{bitrate}" is replaced): python-can's
        # socketcan interface cannot (`ip link set can0 type can bitrate N` does), and vcan has none (the
        # emulator's `ckesc control bitrate N` decides who hears whom)
        self.bitrate_cmd = bitrate_cmd

    def _open(self, kwargs: dict[str, Any]) -> Any:
        self._pending.clear()  # the old bus's backlog (the host's own frames not yet handed out are kept)
        self._hold = None
        bus = can.Bus(**kwargs)
        sock = getattr(bus, "socket", None)  # python-can's SocketcanBus
        if isinstance(sock, socket.socket) and sock.family == getattr(socket, "AF_CAN", None):
            self.rcvbuf = enlarge_receive_buffer(sock)
        return _SendTap(bus, self)

    # ------------------------------------------------------------------ the echo
    def find_echo(self, probe: can.Message) -> bool:
        """Find out whether the host's own frames come back: send ``probe`` (a harmless frame, e.g. the
        GET_ESC_ID query the suite sends anyway) and read for :data:`ECHO_PROBE_S`. Its echo: the lane
        times the host's frames by it. Other frames but no echo (something on the bus took the frame):
        no echo, the lane hands out :class:`OwnFrame` copies from now on. A silent bus is asked again,
        and taken as having no echo if it stays silent (should an echo turn up later, the lane
        switches back). Every frame read meanwhile goes to the listeners."""
        heard = 0
        for _ in range(ECHO_PROBE_TRIES):
            self.echo = True  # the probe itself is not handed out as an OwnFrame
            self.bus.send(probe)
            end = time.monotonic() + ECHO_PROBE_S
            while (left := end - time.monotonic()) > 0:
                msg = self.recv(left)
                if msg is None:
                    continue
                if _same_frame(msg, probe):
                    self.echo, self.echo_note = True, "the probe frame came back from the bus"
                    return True
                heard += 1
            if heard:
                break
        self.echo = False
        self.echo_note = (f"the probe frame did not come back within {ECHO_PROBE_S * 1000:g} ms ({heard} other frame(s) heard)"
                          if heard else f"the bus stayed silent through {ECHO_PROBE_TRIES} probes: taken as no echo")
        return False

    def play(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` from another thread of the bench (:class:`.traffic_player.TrafficPlayer`: other nodes'
        traffic, a load) on the host's own handle, so that the lane reads it as every reader of the bus must: by its
        echo, or without one as an :class:`OwnFrame` stamped at the send. An adapter whose handles do not hear each
        other (most USB adapters), or that allows one handle, is never opened twice. A failed send raises to the
        caller (python-can's ``CanError`` or ``OSError``) and is not a fault of the lane."""
        self.bus.send_played(msg, timeout)

    def _sent(self, t: float, msg: can.Message, *, stream: bool = False) -> None:
        if not stream:
            self._hold = t
        if not self.echo:
            self._own.append(OwnFrame(timestamp=t, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                                      is_remote_frame=msg.is_remote_frame, data=bytes(msg.data), is_rx=False,
                                      channel=msg.channel))

    def _next(self, timeout: float) -> can.Message | None:
        """The next frame in time order: the bus's (peeked by now() or read) and, without an echo, the
        host's own (:class:`OwnFrame`, never stamped before a frame already handed out)."""
        if self._own:
            if not self._pending and (msg := self.bus.recv(timeout=0)) is not None:
                self._pending.append(msg)
        elif self._pending:
            return self._pending.popleft()
        else:
            msg = self.bus.recv(timeout=max(timeout, 0.0))
            if msg is None or not self._own:
                return self._echo_seen(msg)
            self._pending.append(msg)
        if self._pending and (self._pending[0].timestamp or 0.0) < self._own[0].timestamp:
            return self._echo_seen(self._pending.popleft())
        own = self._own.popleft()
        own.timestamp = max(own.timestamp, self._last_ts)
        return own

    def _echo_seen(self, msg: can.Message | None) -> can.Message | None:
        """Without an echo (a silent probe): a frame equal to one the host just sent is its echo after all."""
        if msg is not None and not self.echo and self.echo_note.startswith("the bus stayed silent"):
            if any(_same_frame(msg, own) for own in self._own) or (msg.is_rx is False and msg.is_extended_id):
                self.echo, self.echo_note = True, "the bus was silent at the probe; a later frame came back"
                self._own.clear()
        return msg

    # ------------------------------------------------------------------ bus faults
    def _stream_failed(self, exc: BaseException) -> bool:
        """A throttle stream's send raised (in its thread): the stream stops; the next read reports it."""
        self._fault = self._fault or exc
        return False

    def _io_failed(self, exc: BaseException) -> None:
        """A send or a read raised: reopen the bus and raise :class:`BusFault` naming what happened, or
        :class:`BenchGone` when the bus cannot be reopened."""
        self._fault = None
        what = f"{type(exc).__name__}: {exc}"
        state = self._bus_state()
        for task in self._tasks:
            stop_task(task)
        self._tasks.clear()
        errors = []
        for attempt in range(REOPEN_TRIES):
            if attempt:
                time.sleep(REOPEN_PAUSE_S)  # the harness waits for an adapter, not a test for the DUT
            try:
                self.bus.shutdown()
            except Exception:  # noqa: BLE001 - a failed bus may fail to close too; it is replaced
                pass
            try:
                self.bus = self._open(self.bus_kwargs)
                break
            except Exception as again:  # noqa: BLE001 - whatever python-can raises, the bus is gone
                errors.append(f"{type(again).__name__}: {again}")
        else:
            raise BenchGone(f"the CAN bus failed ({what}; bus state {state}) and could not be reopened "
                            f"({REOPEN_TRIES} tries: {errors[-1]})") from exc
        self.recoveries.append(f"{what} (bus state {state})")
        raise BusFault(f"the CAN bus failed under this test ({what}; bus state {state}); the lane reopened it "
                       "and the run goes on") from exc

    def _bus_state(self) -> str:
        try:
            return self.bus.state.name
        except Exception:  # noqa: BLE001 - not every interface can tell
            return "unknown"

    def _check_fault(self) -> None:
        if self._fault is not None:
            self._io_failed(self._fault)

    @property
    def can_change_bitrate(self) -> bool:
        """Whether reopen() really moves the host to another bit rate (Set Baud's tests need it)."""
        # python-can sets no bit rate on SocketCAN (ip link does) nor through socketcand (its daemon's interface does)
        return bool(self.bitrate_cmd) or self.bus_kwargs.get("interface") not in ("socketcan", "socketcand")

    def now(self) -> float:
        """Lane time: the epoch clock that SocketCAN (kernel receive stamps, and the host's own frames by
        their receive_own_messages echo) and socketcand stamp frames with, except where the host is
        behind the bus. A host that is slow or was descheduled (a loaded machine, a VM) may read the
        clock after frames have arrived that it has not read yet:

        * right after recv() handed out a frame (the host is reading), lane time does not run past a
          frame that has already arrived: a frame stamped before a deadline is read before the deadline
          is judged passed, however late the host gets to it;
        * right after the host sent a frame, lane time does not run past a frame that arrived after
          that send: a window started "now" after a command includes the answers to it.

        Anywhere else (a test's start time, a request's send time) it is the wall clock, so that
        windows are anchored at the real time, not at a backlog not yet read. Each hold is for one
        reading of the clock."""
        wall = time.time()
        hold, self._hold = self._hold, None
        if hold is None:
            return wall
        if not self._pending:
            try:
                msg = self.bus.recv(timeout=0)
            except BUS_ERRORS as exc:
                self._io_failed(exc)
            if msg is None:
                return wall
            self._pending.append(msg)
        stamp = self._pending[0].timestamp
        return min(wall, max(hold, stamp)) if stamp else wall

    def peek_now(self) -> float:
        return time.time()

    def recv(self, timeout: float) -> can.Message | None:
        self._check_fault()
        try:
            msg = self._next(timeout)
        except BUS_ERRORS as exc:
            self._io_failed(exc)
        if msg is not None and msg.is_error_frame:
            self.adapter.heard(msg)
        if (said := self.adapter.check()) is not None:  # the host's own adapter bus-off or error-passive
            gone, line = said
            if gone:
                raise BenchGone(line)
            self.recoveries.append(line)
            raise BusFault(line)
        self._hold = -math.inf if msg is not None else None
        if msg is not None and msg.timestamp:
            self._last_ts = max(self._last_ts, msg.timestamp)
        return self.heard(msg)

    def wait_power(self, seconds: float) -> None:
        while self._pending or self._own:
            self.heard(self._next(0))
        self._hold = None
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.heard(self.bus.recv(timeout=left))  # drain whatever a powered-off bus still shows

    def stop_streams(self) -> None:
        for task in list(self._tasks):  # the tap's thread-based tasks (a native task is the bus's own)
            stop_task(task)
        self._tasks.clear()
        super().stop_streams()

    def close(self) -> None:
        self.stop_streams()
        super().close()

    def reopen(self, bitrate: int) -> None:
        if not self.can_change_bitrate and bitrate != self.bitrate:
            raise RuntimeError(f"the host cannot move {self.bus_kwargs.get('channel') or 'its interface'} to "
                               f"{bitrate} bit/s: python-can does not set a SocketCAN or socketcand bit rate (and vcan has "
                               "none). Give "
                               "--can-bitrate-cmd (see --help), or deselect the tests that change it (-k 'not set_baud')")
        self.bus.shutdown()
        if self.bitrate_cmd:
            cmd = self.bitrate_cmd.replace("{bitrate}", str(bitrate))
            done = subprocess.run(shlex.split(cmd), capture_output=True, text=True, timeout=60)
            if done.returncode != 0:
                self.bus = self._open(self.bus_kwargs)  # still usable at the old rate
                raise RuntimeError(f"bit rate command {cmd!r} failed ({done.returncode}): {done.stderr.strip()}")
        kwargs = dict(self.bus_kwargs, bitrate=bitrate)
        self.bus = self._open(kwargs)
        self.bus_kwargs = kwargs
        self.bitrate = bitrate
        self.reopens += 1


def _same_frame(msg: can.Message, other: can.Message) -> bool:
    return (msg.arbitration_id == other.arbitration_id and msg.is_extended_id == other.is_extended_id
            and bytes(msg.data) == bytes(other.data))


def _stopped_means_stopped(task: Any) -> Any:
    """A python-can thread-based periodic task whose stop() returns once its thread has ended: without
    it a thread held up (a loaded host) sends one more frame after stop(), unseen by a test that took
    the stream's last frame, and the DUT's comm-loss timer runs from that one (R8)."""
    thread = getattr(task, "thread", None)
    if not isinstance(thread, threading.Thread):
        return task
    stop = task.stop

    def stop_and_join(*args: Any, **kwargs: Any) -> None:
        stop(*args, **kwargs)
        if thread is not threading.current_thread():
            thread.join(timeout=1.0)

    task.stop = stop_and_join
    return task


def stop_task(task: Any) -> None:
    """Stop a periodic task, whatever its stop() raises (on an exit path every stop is attempted)."""
    try:
        task.stop()
    except Exception:  # noqa: BLE001 - on an exit path every stop is attempted
        pass
