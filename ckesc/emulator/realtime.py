"""Lane 2: a bench of emulated ESCs in real time, meant to run in its own process (``ckesc emulate``).

One thread drives everything: it waits in ``select()`` on all its inputs (the bus, the socketcand
clients, the control connections, a wake-up pipe) with a timeout that ends at the earliest absolute
deadline of the ESCs and of its own timers, and then does the work that is due. The :class:`EmulatedBench`
and its models are touched from that thread only; other threads (a bus reader for buses without a
file descriptor, callers of :meth:`RealtimeEmulator.request`) hand work over through a queue and the
wake-up pipe. On Linux the thread's timer slack is set to 1 ns (``prctl(PR_SET_TIMERSLACK)``) and
the interpreter's switch interval to 0.5 ms while it runs (see the transport timing notes).

Time bases
    The models run on ``time.monotonic()`` seconds (CLOCK_MONOTONIC, shared by every process on
    the machine). Frames on the bus carry wall-clock stamps (``time.time()`` base, as SocketCAN,
    socketcand and python-can's virtual bus use): ``bus = monotonic + offset``, with ``offset``
    read again every ``OFFSET_REFRESH_S`` so that stamps follow a wall clock NTP slews, as the host's
    do (intervals between stamps are exact but for the slew). An ESC frame is stamped
    at its end, as SocketCAN stamps a frame it received: its start plus its duration at the bus's
    bit rate (``frame_bits``). With ``stamp="due"`` (the default) it starts when it was due, so
    report intervals and answer delays seen in bus timestamps are the model's, not this machine's
    scheduling noise; ``stamp="send"`` starts it when it was actually handed to the bus. Either way the lateness
    of every frame (send time - due time) is counted (:meth:`RealtimeEmulator.stats`).
    A frame from the host is given to the ESCs at the time it arrived: the socketcand read time,
    or the bus's own receive stamp where it is plausible (SocketCAN's kernel stamp).

Buses
    ``bus``: any python-can bus. Frames the ESCs send go out with ``bus.send``; frames read from it
    go to the ESCs. A bus with ``fileno()`` (socketcan) is waited on directly; any other (virtual,
    a socketcand client, ...) is read by one helper thread that only queues frames.
    ``socketcand_port``: serve the socketcand ASCII protocol on 127.0.0.1, as a hub that python-can's
    stock socketcand client connects to (:mod:`.socketcand`, which describes the protocol as served).
    Both may be given: the emulator then also bridges the two.
    The emulated bus has one bit rate (``bitrate``, the host's): an ESC at another bit rate (after Set
    Baud and a power cycle) neither hears nor is heard by the host. An ESC frame is sent only when
    another node acknowledges it (:mod:`.hub_can`): a socketcand client in raw mode (from when it can
    take frames), the python-can bus (its other nodes), or another booted ESC at its rate; until one
    does, the ESC's controller holds its queue and sends it back to back when one comes (the host's
    handle reopened, the host moved to its rate). While someone listens, frames leave in due order as
    soon as they are due: arbitration is not modelled.

Control channel (``control_port``), for harness power switching and fault injection
    Line-based JSON on 127.0.0.1, served by :mod:`.control`, which lists the requests; their
    handlers are this emulator's ``_cmd_*`` methods. :func:`.control.control_request` is the
    client; ``ckesc control`` wraps it.
"""

from __future__ import annotations

import math
import os
import select
import sys
import threading
import time
from collections import deque
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any, Callable

import can

from ..protocol.catalogue import DEFAULT_BITRATE
from ..protocol.frame import WireFrame, frame_bits
from .control import ControlServer, Handler, Reply, dispatch
from .emulated_bench import EmulatedBench
from .host_alone import HostAlone
from .hub_can import HubCan
from .model import EscModel
from .realtime_control import ControlCommands
from .realtime_timing import OFFSET_REFRESH_S, clock_offset, durations, set_rt_priority, set_timer_slack
from .socketcand import SocketcandServer, fmt_frame
from .tcp import Conn

TIMER_SLACK_NS = 1
SWITCH_INTERVAL_S = 5e-4
READER_POLL_S = 0.1  # how often the bus reader thread looks at the stop flag
PLAUSIBLE_RX_STAMP_S = 1.0  # a bus receive stamp further back than this is not trusted
MAX_POLL_ROUNDS = 100  # polls of the due ESCs at one instant (frames they hear from one another can make more due)

class _Input:
    __slots__ = ("t", "msg", "wire", "origin")

    def __init__(self, t: float, msg: Any, wire: WireFrame, origin: Any) -> None:
        self.t, self.msg, self.wire, self.origin = t, msg, wire, origin


# ---------------------------------------------------------------------------------------------------
# the emulator


class RealtimeEmulator(ControlCommands):
    """An :class:`EmulatedBench` driven in real time on a python-can bus and/or as a socketcand hub.

    ``run()`` drives it in the calling thread until :meth:`stop` (the CLI: main thread, signals call
    ``stop``); ``start()`` runs it in a background thread (tests). Listening sockets are opened by
    the constructor, so the ports are known (and a port in use raises ``OSError``) before it runs.
    """

    def __init__(
        self,
        bench: EmulatedBench,
        *,
        bus: can.BusABC | None = None,
        own_bus: bool = False,
        socketcand_port: int | None = None,
        control_port: int | None = None,
        bitrate: int = DEFAULT_BITRATE,
        stamp: str = "due",
        frame_stamp: str = "end",
        echo_own: bool = True,
        handles: str = "shared",
        rt_priority: int | None = None,
        host_alone: str = "deliver",
        log: Callable[[str], None] | None = None,
    ) -> None:
        if stamp not in ("due", "send"):
            raise ValueError(f"stamp must be 'due' or 'send', not {stamp!r}")
        if frame_stamp not in ("end", "start"):
            raise ValueError(f"frame_stamp must be 'end' or 'start', not {frame_stamp!r}")
        if bus is None and socketcand_port is None:
            raise ValueError("nothing to talk to: give a python-can bus or a socketcand port")
        self.bench = bench
        self.bus = bus
        self._own_bus = own_bus
        self.bitrate = int(bitrate)
        self.stamp = stamp
        self.frame_stamp = frame_stamp
        self.echo_own = echo_own
        self.rt_priority = rt_priority
        self.scheduling = "normal"
        self._log = log or (lambda text: print(f"ckesc emulate: {text}", file=sys.stderr, flush=True))
        self.offset, self._offset_due = clock_offset(), time.monotonic() + OFFSET_REFRESH_S
        self.lateness = durations()  # per frame: handed to the bus - due
        self.wakeup = durations()  # per timed wake: select() returned - the deadline it waited for
        self.counters = {"tx": 0, "rx": 0, "tx_other_bitrate": 0, "tx_errors": 0, "rx_malformed": 0, "clients": 0}
        self.host_alone = HostAlone(host_alone)  # the host's frames while no ESC acknowledges them (--host-alone)
        self.counters.update(self.host_alone.counters)
        #: the ESCs' controllers while nobody acknowledges them or a bus fault lasts (ckesc control bus)
        self.can = HubCan(self.bitrate, bench.escs)
        #: bus faults and settles answered later: (by when, whether a settled bus answers it sooner, the answer)
        self._bus_waiters: list[tuple[float, bool, Callable[[], None]]] = []
        self._escs: list[EscModel] = list(bench.escs)
        self._deadlines: list[float | None] = [None] * len(self._escs)
        self._deadlines_stale = True
        self._model_time = 0.0
        self._stuck_logged = False
        self._inputs: list[_Input] = []
        self._posted: deque[tuple[Callable[..., Any], tuple]] = deque()
        self._rx_queue: deque[tuple[Any, float]] = deque()
        self._stopping = False
        self._started = threading.Event()
        self._finished = threading.Event()
        self._thread: threading.Thread | None = None
        self._loop_ident: int | None = None
        self._power_on_at: float | None = None
        self._power_waiters: list[Reply] = []
        self._stop_at: float | None = None
        self._t_start = time.monotonic()
        self._reader: threading.Thread | None = None
        self._bus_fd: int | None = None
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._commands: dict[str, Handler] = {
            "status": self._cmd_status,
            "power": self._cmd_power,
            "fault": self._cmd_fault,
            "faults": self._cmd_faults,
            "bitrate": self._cmd_bitrate,
            "bus_fault": self._cmd_bus_fault,
            "bus_settle": self._cmd_bus_settle,
            "stats": self._cmd_stats,
            "save": self._cmd_save,
            "stop": self._cmd_stop,
        }
        self._socketcand: SocketcandServer | None = None
        self._control: ControlServer | None = None
        try:
            if socketcand_port is not None:
                self._socketcand = SocketcandServer(socketcand_port, on_frame=self._host_input, counters=self.counters,
                                                    log=self._log, handles=handles, echo_own=echo_own,
                                                    on_listen=self.can.host_listens)
            if control_port is not None:
                self._control = ControlServer(control_port, submit=self._submit, log=self._log)
        except OSError:
            self._close_sockets()
            raise
        if bus is not None:
            self.can.host_listens(bus, -math.inf)  # a python-can bus: its other nodes are taken to acknowledge
            try:
                fd = bus.fileno()
                self._bus_fd = fd if isinstance(fd, int) and fd >= 0 else None
            except (NotImplementedError, AttributeError, OSError):
                self._bus_fd = None

    # ------------------------------------------------------------------ addresses

    @property
    def socketcand_address(self) -> tuple[str, int] | None:
        return None if self._socketcand is None else self._socketcand.address

    @property
    def control_address(self) -> tuple[str, int] | None:
        return None if self._control is None else self._control.address

    # ------------------------------------------------------------------ lifecycle

    def run(self, *, duration: float | None = None, power_on: bool = True) -> None:
        """Drive the bench in the calling thread until :meth:`stop` (or ``duration`` seconds).
        On the way out the bench is powered off (the flash file written) and every socket closed."""
        old_slack = set_timer_slack(TIMER_SLACK_NS)
        old_switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        old_policy, self.scheduling = set_rt_priority(self.rt_priority, self._log)
        self._loop_ident = threading.get_ident()
        try:
            now = time.monotonic()
            self._t_start = now
            self._model_time = now
            if duration is not None:
                self._stop_at = now + duration
            if power_on:
                self.bench.power_on(now)
                self._deadlines_stale = True
            if self.bus is not None and self._bus_fd is None:
                self._reader = threading.Thread(target=self._read_bus, name="ckesc-bus-reader", daemon=True)
                self._reader.start()
            self._started.set()
            self._loop()
        finally:
            try:
                self._shutdown()
            finally:
                sys.setswitchinterval(old_switch)
                if old_slack is not None:
                    set_timer_slack(old_slack)
                if old_policy is not None:
                    os.sched_setscheduler(0, *old_policy)
                self._finished.set()

    def start(self, **kwargs: Any) -> RealtimeEmulator:
        """Run in a background thread; returns once the loop has started."""
        self._thread = threading.Thread(target=self.run, kwargs=kwargs, name="ckesc-realtime", daemon=True)
        self._thread.start()
        while not self._started.wait(0.05):
            if not self._thread.is_alive():
                raise RuntimeError("the real-time emulator thread died while starting")
        return self

    def stop(self) -> None:
        """Ask the loop to stop (any thread, or a signal handler)."""
        self._stopping = True
        self._wake()

    def join(self, timeout: float | None = None) -> bool:
        if self._thread is not None:
            self._thread.join(timeout)
        return self._finished.is_set()

    def close(self, timeout: float = 10.0) -> None:
        self.stop()
        if self._thread is not None:
            self._thread.join(timeout)
        elif not self._started.is_set():  # never run: nothing else will close the sockets
            self._close_sockets()

    def __enter__(self) -> RealtimeEmulator:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------------ cross-thread requests

    def request(self, req: dict, timeout: float | None = None) -> dict:
        """One control request (see the module docstring), from any thread; the answer dict."""
        if threading.get_ident() == self._loop_ident:
            raise RuntimeError("request() from the loop thread would wait on itself")
        if self._finished.is_set() or not self._started.is_set():
            raise RuntimeError("the real-time emulator is not running")
        fut: Future = Future()

        def reply(answer: dict) -> None:
            if not fut.done():
                fut.set_result(answer)

        self._submit(req, reply)
        self._wake()
        if timeout is None:
            timeout = 10.0 + float(req.get("off_time") or 0.0)
        end = time.monotonic() + timeout
        while True:
            try:
                return fut.result(min(0.2, max(0.0, end - time.monotonic())))
            except FutureTimeout:
                if self._finished.is_set():
                    raise RuntimeError(f"the real-time emulator stopped before answering {req}") from None
                if time.monotonic() >= end:
                    raise TimeoutError(f"no answer from the emulator loop to {req} within {timeout} s") from None

    def status(self) -> dict:
        return self.request({"cmd": "status"})

    def power_off(self) -> dict:
        return self.request({"cmd": "power", "action": "off"})

    def power_on(self) -> dict:
        return self.request({"cmd": "power", "action": "on"})

    def power_cycle(self, off_time: float = 1.0) -> dict:
        return self.request({"cmd": "power", "action": "cycle", "off_time": off_time})

    def set_fault(self, name: str, on: bool = True, node: int | None = None) -> dict:
        return self.request({"cmd": "fault", "name": name, "on": on, "node": node})

    def stats(self, reset: bool = False) -> dict:
        return self.request({"cmd": "stats", "reset": reset})

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"\0")
        except (BlockingIOError, OSError):  # pipe full: a wake-up is pending anyway; closed: stopping
            pass

    # ------------------------------------------------------------------ the loop

    def _refresh_deadlines(self) -> None:
        if self._deadlines_stale:
            self._deadlines = [esc.next_deadline() for esc in self._escs]
            self._deadlines_stale = False

    def _next_wake(self) -> float | None:
        self._refresh_deadlines()
        times = [t for t in self._deadlines if t is not None]
        for t in (self._power_on_at, self._stop_at, self._controller_up(), None if self.can.quiet else
                  self.can.next_deadline(), min((w[0] for w in self._bus_waiters), default=None)):
            if t is not None:
                times.append(t)
        return min(times) if times else None

    def _loop(self) -> None:
        mono = time.monotonic
        servers = [s for s in (self._socketcand, self._control) if s is not None]
        while not self._stopping:
            deadline = self._next_wake()
            rlist: list[Any] = [self._wake_r, *(c for s in servers for c in s.conns), *servers]
            if self._bus_fd is not None:
                rlist.append(self._bus_fd)
            wlist = [c for s in servers for c in s.conns if c.out]
            timeout = None if deadline is None else max(0.0, deadline - mono())
            readable, writable, _ = select.select(rlist, wlist, [], timeout)
            now = mono()
            if now >= self._offset_due:  # the wall clock as it is now: NTP may slew it (stamps follow it, as SocketCAN's)
                self.offset, self._offset_due = clock_offset(), now + OFFSET_REFRESH_S
            if not readable and not writable and deadline is not None:
                self.wakeup.add(max(now - deadline, 0.0))
            for c in writable:
                c.server.flush(c)
            for r in readable:
                self._on_readable(r, now)
            self._process()

    def _on_readable(self, r: Any, now: float) -> None:
        if r == self._wake_r:
            try:
                while os.read(self._wake_r, 4096):
                    pass
            except BlockingIOError:
                pass
            while self._rx_queue:
                msg, t = self._rx_queue.popleft()
                self._bus_input(msg, t)
        elif r is self._socketcand or r is self._control:
            r.accept()
        elif r == self._bus_fd:
            while True:
                msg = self.bus.recv(0)  # type: ignore[union-attr]
                if msg is None:
                    break
                self._bus_input(msg, now)
        elif isinstance(r, Conn):
            r.server.read(r, now)

    def _process(self) -> None:
        """Feed the frames heard in arrival order (emitting what fell due before each), then the
        requests (control), then the timers, then send everything due now."""
        if self._inputs:
            inputs, self._inputs = self._inputs, []
            inputs.sort(key=lambda item: item.t)  # bus reader and socketcand clients interleave
            for item in inputs:
                t = min(max(item.t, self._model_time), time.monotonic())
                self._emit_due(t)
                self._model_time = t
                self._host_frame(item, t)
        while self._posted:
            fn, args = self._posted.popleft()
            fn(*args)
        now = time.monotonic()
        if self._power_on_at is not None and now >= self._power_on_at:
            self._do_power_on(self._power_on_at)
        if self._stop_at is not None and now >= self._stop_at:
            self._stopping = True
        if not self.can.quiet or self._bus_waiters:
            self._can_poll(now)
        if self.host_alone.held and (up := self._controller_up()) is not None and now >= up:
            self._emit_due(up)
            for item in self.host_alone.release(True):  # acknowledged at last, back to back: stamped then
                self._host_delivered(item, max(up, self._model_time))
        self._emit_due(time.monotonic())

    def _controller_up(self) -> float | None:
        """While the host's frames are held: when the first powered ESC's controller is up (it hears from its
        ``ready_at``, and from a bus fault's end and its own bus-off recovery), None when none is or nothing is held."""
        if not self.host_alone.held:
            return None
        up = min((max(esc.state.ready_at, up) for esc in self._escs
                  if esc.powered and (up := self.can.listens_from(esc)) is not None), default=None)
        return up if up is None or not self.can.host_bus_off() else max(up, self.can.host_restart_due() or up)

    def _acknowledged(self, t: float) -> bool:
        """Whether some node acknowledges a host frame at ``t``: an ESC powered with its controller up (no bus fault
        on, not bus-off), or (a bare hub, no ESC of its own) the other clients."""
        if self.can.quiet:
            return not self._escs or any(esc.powered and t >= esc.state.ready_at for esc in self._escs)
        return not self.can.disturbed(t) and (not self._escs or any(
            esc.powered and t >= esc.state.ready_at and (up := self.can.listens_from(esc)) is not None and t >= up
            for esc in self._escs))

    # ------------------------------------------------------------------ ESC output

    def _emit_due(self, t: float) -> None:
        """Poll the ESCs whose deadline has come by ``t``, earliest first, and put what each sends on
        the bus at once; then let the other ESCs hear those frames (which may make more due: again)."""
        for _ in range(MAX_POLL_ROUNDS):
            self._refresh_deadlines()
            due = sorted((d, i) for i, d in enumerate(self._deadlines) if d is not None and d <= t)
            if not due:
                return
            sent: list[tuple[EscModel, WireFrame]] = []
            for _, i in due:
                esc = self._escs[i]
                frames = esc.poll(t)
                self._deadlines[i] = esc.next_deadline()
                if frames:  # acknowledged at once, else through its controller (nobody listens, a bus fault)
                    frames = self.can.send(esc, frames, t)
                if frames:
                    self._transmit(esc, frames)
                    sent.extend((esc, w) for w in frames)
            if t > self._model_time:
                self._model_time = t
            for esc, w in sent:  # the other ESCs on the bus hear them too (after the sends: off the hot path)
                self.bench.deliver(w, w.timestamp, esc.state.bitrate, sender=esc)
            self._deadlines_stale = True
        if not self._stuck_logged:  # a model whose deadline does not move past a poll: say so once
            self._stuck_logged = True
            self._log(f"an ESC model stays due after {MAX_POLL_ROUNDS} polls at t={t:.6f}; its next_deadline() does not advance")

    def _transmit(self, esc: EscModel, frames: list[WireFrame]) -> None:
        """One ESC's frames, in due order, onto the bus: lateness counted per frame."""
        if esc.state.bitrate != self.bitrate:
            self.counters["tx_other_bitrate"] += len(frames)
            return
        t_send = time.monotonic()
        due_stamps = self.stamp == "due"
        # a frame is stamped at its end, as SocketCAN stamps a frame it received (and socketcand passes it on): its
        # start (when it was due, or sent) plus its time on the bus at the bench's bit rate; or (frame_stamp "start")
        # at its start, as an adapter stamping the start of frame does
        bit_s = 1.0 / self.bitrate if self.frame_stamp == "end" else 0.0
        sc = self._socketcand
        if sc is not None and sc.conns:
            data = b"".join(fmt_frame(w, (w.timestamp if due_stamps else t_send) + frame_bits(len(w.data)) * bit_s + self.offset)
                            for w in frames)
            sc.to_clients(data, t_send)
        for w in frames:
            if self.bus is not None:
                t_send = time.monotonic()
                self._bus_send(w, (w.timestamp if due_stamps else t_send) + frame_bits(len(w.data)) * bit_s + self.offset)
            self.lateness.add(max(t_send - w.timestamp, 0.0))
        self.counters["tx"] += len(frames)

    def _bus_send(self, wire: WireFrame, stamp: float) -> None:
        msg = can.Message(timestamp=stamp, arbitration_id=wire.arbitration_id, is_extended_id=wire.is_extended_id,
                          data=wire.data)
        try:
            self.bus.send(msg)  # type: ignore[union-attr]
        except can.CanError as exc:
            self.counters["tx_errors"] += 1
            if self.counters["tx_errors"] in (1, 10, 100, 1000) or self.counters["tx_errors"] % 10000 == 0:
                self._log(f"bus send failed ({self.counters['tx_errors']} so far): {exc}")

    # ------------------------------------------------------------------ host input

    def _bus_input(self, msg: can.Message, t_read: float) -> None:
        """A frame read from the python-can bus (loop thread)."""
        if msg.is_error_frame:
            return
        t = t_read
        stamp = getattr(msg, "timestamp", 0.0) or 0.0
        if stamp:
            t_bus = stamp - self.offset
            if t_read - PLAUSIBLE_RX_STAMP_S <= t_bus <= t_read:
                t = t_bus
        wire = WireFrame(msg.arbitration_id, bytes(msg.data), 0.0, is_extended_id=msg.is_extended_id)
        self._host_input(t, msg, wire, self.bus)

    def _host_input(self, t: float, msg: can.Message, wire: WireFrame, origin: Any) -> None:
        """A frame from the host (the bus or a socketcand client) heard at ``t``: fed to the ESCs in :meth:`_process`."""
        self._inputs.append(_Input(t, msg, wire, origin))

    def _host_frame(self, item: _Input, t: float) -> None:
        """A host frame heard at ``t``, unless it is held or lost while no ESC acknowledges it (--host-alone hold, and
        whatever it says while a bus fault and its recovery last: :mod:`.hub_can`)."""
        if not self.can.quiet:  # the ESCs' controllers at work (a held queue going back to back): one wire, in order
            self._can_poll(t)
            t = self.can.place_host(t, len(item.wire.data))
        hold = self.can.disturbing or bool(self.host_alone.held)
        if self.host_alone.mode == "deliver" and not hold:
            self._host_delivered(item, t)
            return
        out = self.host_alone.take(item, self._acknowledged(t), hold=hold)
        if not out and self.can.fault is not None:  # held in a fault: its adapter tries it (hub_can.host_poll)
            self.can.host_waiting(item.origin, t, len(item.wire.data))
        for held in out:
            self._host_delivered(held, t)
        self.counters.update(self.host_alone.counters)

    def _host_delivered(self, item: _Input, t: float) -> None:
        self.counters["rx"] += 1
        self.can.host_sent(item.origin, t)
        self.bench.deliver(item.msg, t, self.bitrate)
        self._deadlines_stale = True
        if item.origin is not self.bus and self.bus is not None:  # bridge: a socketcand client's frame
            self._bus_send(item.wire, t + self.offset)
        sc = self._socketcand
        if sc is not None and sc.conns and not getattr(item.msg, "is_remote_frame", False):
            origin = item.origin if isinstance(item.origin, Conn) else None
            # heard at t, its end; stamped at its start one frame earlier where the bench stamps frame starts
            start = frame_bits(len(item.wire.data)) / self.bitrate if self.frame_stamp == "start" else 0.0
            sc.to_clients(fmt_frame(item.wire, t - start + self.offset), time.monotonic(), origin)

    def _read_bus(self) -> None:
        """Helper thread for buses without a file descriptor: only reads and queues."""
        bus = self.bus
        assert bus is not None
        while not self._stopping:
            try:
                msg = bus.recv(READER_POLL_S)
            except Exception as exc:  # noqa: BLE001 - a dead bus must not kill the process silently
                if not self._stopping:
                    self._posted.append((self._log, (f"reading the bus failed, frames from the host are no longer heard: {exc}",)))
                    self._wake()
                return
            if msg is not None:
                self._rx_queue.append((msg, time.monotonic()))
                self._wake()

    # ------------------------------------------------------------------ control

    def _submit(self, req: Any, reply: Reply) -> None:
        """A control request, from the control channel or :meth:`request`: answered in :meth:`_process`."""
        self._posted.append((self._dispatch, (req, reply)))

    def _dispatch(self, req: Any, reply: Reply) -> None:
        """One control request, in the loop thread. ``reply`` is called once (maybe later: power cycle)."""
        dispatch(self._commands, req, reply)

    # ------------------------------------------------------------------ shutdown

    def _shutdown(self) -> None:
        now = time.monotonic()
        self._cancel_power_on("the emulator stopped")
        try:
            if self.bench.powered:
                self.bench.power_off(now)
            else:
                self.bench.persist()
        finally:
            if self._control is not None:  # answers already queued (e.g. to "stop") still go out
                self._control.send_pending()
            self._stopping = True
            if self._reader is not None:
                self._reader.join(READER_POLL_S * 5)
            self._close_sockets()
            if self._own_bus and self.bus is not None:
                self.bus.shutdown()

    def _close_sockets(self) -> None:
        for server in (self._socketcand, self._control):
            if server is not None:
                server.close()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
        self._wake_r = self._wake_w = -1
