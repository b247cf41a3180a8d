"""Lanes: where the DUT lives and which clock the suite measures with.

* :class:`SimLane` - the emulator in simulated time (``ckesc-sim``): exact timing, clock "simulated".
* :class:`BusLane` - a real python-can bus (a real ESC on SocketCAN, or ``ckesc emulate`` behind
  socketcand): the clock is the bus timestamps (the host's own frames come back through
  ``receive_own_messages`` or the socketcand echo), with the DUT profile's stated measurement error.

Tests never read the wall clock or sleep: they ask the lane (through the ``dut`` fixture).
"""

from __future__ import annotations

import itertools
import math
import os
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import time
from abc import ABC, abstractmethod
from collections import deque
from typing import Any

import can

from ..emulator import sim_bus
from ..protocol.catalogue import DEFAULT_BITRATE

_SIM_CHANNELS = itertools.count()


class PowerControl(ABC):
    """Switches the DUT's supply. ``available`` False: tests that need a power cycle are skipped."""

    name = "power"
    available = True

    @abstractmethod
    def off(self) -> None: ...

    @abstractmethod
    def on(self) -> None: ...


class Lane(ABC):
    name: str
    clock: str  # the verdict clock label: "simulated" or "bus timestamp"
    timing_error: float = 0.0  # seconds: margins smaller than this are INCONCLUSIVE
    can_change_bitrate: bool = True  # reopen() really moves the host to another bit rate (Set Baud's tests)
    bus: can.BusABC
    power: PowerControl
    bitrate: int

    @abstractmethod
    def now(self) -> float:
        """Lane time in the bus's time base (what frame timestamps are compared with)."""

    @abstractmethod
    def wait_power(self, seconds: float) -> None:
        """Let ``seconds`` pass while the DUT is unpowered (no frames to read)."""

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
            for listener in self.listeners:
                listener.on_message_received(msg)
        return msg

    def recv(self, timeout: float) -> can.Message | None:
        return self.heard(self.bus.recv(timeout=max(timeout, 0.0)))

    @abstractmethod
    def reopen(self, bitrate: int) -> None:
        """Reopen the host's bus at another bit rate (after Set Baud)."""

    def close(self) -> None:
        self.bus.shutdown()


# ------------------------------------------------------------------------------------------ simulated


class EmulatorPower(PowerControl):
    name = "emulator"

    def __init__(self, lane: SimLane) -> None:
        self.lane = lane

    def off(self) -> None:
        self.lane.sim.power_off()

    def on(self) -> None:
        self.lane.sim.power_on()


class SimLane(Lane):
    name = "simulated"
    clock = "simulated"
    timing_error = 0.0

    def __init__(self, *, nodes=(1,), faults=None, flash_path: str | None = None, seed: int = 0,
                 bitrate: int = DEFAULT_BITRATE, esc_config: dict[str, Any] | None = None) -> None:
        self.channel = f"ckesc-suite-{os.getpid()}-{next(_SIM_CHANNELS)}"
        self.bitrate = bitrate
        self.bus = self.sim = can.Bus(interface="ckesc-sim", channel=self.channel, nodes=list(nodes), faults=faults,
                                      flash_path=flash_path, seed=seed, bitrate=bitrate, esc_config=esc_config,
                                      receive_own_messages=True, ignore_config=True)
        self.power = EmulatorPower(self)

    def now(self) -> float:
        return self.sim.now()

    def wait_power(self, seconds: float) -> None:
        self.sim.advance(seconds)

    def reopen(self, bitrate: int) -> None:
        old = self.sim
        self.bus = self.sim = can.Bus(interface="ckesc-sim", channel=self.channel, bitrate=bitrate,
                                      receive_own_messages=True, ignore_config=True)
        old.shutdown()
        self.bitrate = bitrate

    def close(self) -> None:
        self.sim.shutdown()
        sim_bus.discard(self.channel)


# ------------------------------------------------------------------------------------------ real bus


class CommandPower(PowerControl):
    """Runs shell commands (e.g. a lab PSU's CLI, or ``ckesc control ... power off``)."""

    name = "command"

    def __init__(self, off_cmd: str, on_cmd: str) -> None:
        if not off_cmd or not on_cmd:
            raise ValueError("--power command needs both --power-off-cmd and --power-on-cmd")
        self.off_cmd, self.on_cmd = off_cmd, on_cmd

    def _run(self, cmd: str) -> None:
        done = subprocess.run(shlex.split(cmd), capture_output=True, text=True, timeout=60)
        if done.returncode != 0:
            raise RuntimeError(f"power command {cmd!r} failed ({done.returncode}): {done.stderr.strip()}")

    def off(self) -> None:
        self._run(self.off_cmd)

    def on(self) -> None:
        self._run(self.on_cmd)


class ManualPower(PowerControl):
    """Asks an operator; works while pytest captures output (the plugin suspends capture)."""

    name = "manual"

    def __init__(self, prompt) -> None:
        self.prompt = prompt  # callable(text) -> None, provided by the plugin

    def off(self) -> None:
        self.prompt("Switch the DUT's power OFF, then press Enter")

    def on(self) -> None:
        self.prompt("Switch the DUT's power ON, then press Enter")


class NoPower(PowerControl):
    name = "none"
    available = False

    def off(self) -> None:
        raise RuntimeError("no power control")

    on = off


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


class _SendTap:
    """A python-can bus whose send() tells the lane when the host sent a frame (everything else is the
    bus's own; periodic tasks send on the bus itself and are not noted)."""

    def __init__(self, bus: can.BusABC, on_send, on_error) -> None:
        self._bus = bus
        self._on_send = on_send
        self._on_error = on_error

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        t = time.time()  # the kernel stamps the frame (and its echo) after this
        try:
            self._bus.send(msg, timeout)
        except (OSError, can.CanError) as exc:
            self._on_error(exc)
            raise
        self._on_send(t)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._bus, name)


class BusLane(Lane):
    name = "bus"
    clock = "bus timestamp"

    def __init__(self, bus_kwargs: dict[str, Any], power: PowerControl, *, timing_error: float,
                 bitrate_cmd: str | None = None) -> None:
        self.bus_kwargs = dict(bus_kwargs)
        self.bus_kwargs.setdefault("receive_own_messages", True)
        self._pending: deque[can.Message] = deque()  # arrived, seen by now(), not yet handed out by recv()
        self._hold: float | None = None  # see now(): after a read -inf, after a send its time, else None
        self.rcvbuf: int | None = None  # a SocketCAN socket's receive buffer, as the kernel granted it
        self.bus = self._open(self.bus_kwargs)
        self.bitrate = int(self.bus_kwargs.get("bitrate") or DEFAULT_BITRATE)
        self.power = power
        self.timing_error = timing_error
        # run by reopen() to move the bus itself to another bit rate ("{bitrate}" is replaced): python-can's
        # socketcan interface cannot (`ip link set can0 type can bitrate N` does), and vcan has none (the
        # emulator's `ckesc control bitrate N` decides who hears whom)
        self.bitrate_cmd = bitrate_cmd

    def _open(self, kwargs: dict[str, Any]) -> Any:
        self._pending.clear()
        self._hold = None
        bus = can.Bus(**kwargs)
        sock = getattr(bus, "socket", None)  # python-can's SocketcanBus
        if isinstance(sock, socket.socket) and sock.family == getattr(socket, "AF_CAN", None):
            self.rcvbuf = enlarge_receive_buffer(sock)
        return _SendTap(bus, self._sent, self._io_failed)

    def _sent(self, t: float) -> None:
        self._hold = t

    def _io_failed(self, exc: BaseException) -> None:
        """A send or receive raised: a lane that can tell the bench is gone raises :class:`BenchGone`."""

    @property
    def can_change_bitrate(self) -> bool:
        """Whether reopen() really moves the host to another bit rate (Set Baud's tests need it)."""
        return bool(self.bitrate_cmd) or self.bus_kwargs.get("interface") != "socketcan"

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
            msg = self.bus.recv(timeout=0)
            if msg is None:
                return wall
            self._pending.append(msg)
        stamp = self._pending[0].timestamp
        return min(wall, max(hold, stamp)) if stamp else wall

    def recv(self, timeout: float) -> can.Message | None:
        try:
            msg = self._pending.popleft() if self._pending else self.bus.recv(timeout=max(timeout, 0.0))
        except (OSError, can.CanError) as exc:
            self._io_failed(exc)
            raise
        self._hold = -math.inf if msg is not None else None
        return self.heard(msg)

    def wait_power(self, seconds: float) -> None:
        while self._pending:
            self.heard(self._pending.popleft())
        self._hold = None
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.heard(self.bus.recv(timeout=left))  # drain whatever a powered-off bus still shows

    def reopen(self, bitrate: int) -> None:
        if not self.can_change_bitrate and bitrate != self.bitrate:
            raise RuntimeError(f"the host cannot move {self.bus_kwargs.get('channel') or 'its SocketCAN interface'} to "
                               f"{bitrate} bit/s: python-can does not set a SocketCAN bit rate (and vcan has none). Give "
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


class RealtimeEmulatorLane(BusLane):
    """``ckesc emulate`` in its own process, reached through python-can's stock socketcand client;
    power through the emulator's control channel."""

    name = "realtime"

    def __init__(self, *, nodes=(1,), faults=None, flash_path: str | None = None, seed: int = 0,
                 timing_error: float = 0.002, temp_flash: bool = False, esc_options: dict[str, Any] | None = None) -> None:
        cmd = [sys.executable, "-m", "ckesc", "emulate", "--nodes", ",".join(map(str, nodes)), "--socketcand", "0",
               "--control", "0", "--seed", str(seed)]
        for key, value in (esc_options or {}).items():  # EscConfig fields: boot_time -> --boot-time
            cmd += [f"--{key.replace('_', '-')}", str(value)]
        if faults:
            cmd += ["--faults", ",".join(faults)]
        # temp_flash: the emulated ESCs keep their flash across power cycles in a file that lives as long as
        # the lane and is removed with it (close(), on every exit path)
        self._flash_dir = tempfile.TemporaryDirectory(prefix="ckesc-flash-") if temp_flash else None
        if self._flash_dir is not None:
            flash_path = os.path.join(self._flash_dir.name, "flash.json")
        if flash_path:
            cmd += ["--flash-path", flash_path]
        # its own session: a Ctrl-C at the terminal (SIGINT to the foreground process group) reaches the
        # suite, which stops the run with zero throttle and then ends the emulator itself (close())
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     start_new_session=True, preexec_fn=_die_with_parent)
        try:
            ports = self._read_ports()
        except BaseException:
            self._end_process()
            raise
        host, port = ports["socketcand"]
        self.control = ports["control"]
        control_cmd = f"{shlex.quote(sys.executable)} -m ckesc control --port {self.control[1]} power"
        power = CommandPower(control_cmd + " off", control_cmd + " on")
        super().__init__({"interface": "socketcand", "host": host, "port": port, "channel": "can0",
                          "ignore_config": True}, power, timing_error=timing_error)

    def _io_failed(self, exc: BaseException | None = None) -> None:
        code = self.proc.poll()
        if code is None:
            return
        err = ""
        if self.proc.stderr is not None:
            try:
                err = " ".join(self.proc.stderr.read().strip().splitlines()[-2:])
            except (OSError, ValueError):
                pass
        how = f"was killed by signal {-code}" if code < 0 else f"exited with status {code}"
        raise BenchGone(f"the emulator process (ckesc emulate, pid {self.proc.pid}) {how} mid-run"
                        + (f": {err}" if err else "")) from exc

    def recv(self, timeout: float) -> can.Message | None:
        msg = super().recv(timeout)
        if msg is None:
            self._io_failed()
        return msg

    def _read_ports(self) -> dict[str, tuple[str, int]]:
        ports: dict[str, tuple[str, int]] = {}
        assert self.proc.stdout is not None
        while len(ports) < 2:
            line = self.proc.stdout.readline()
            if not line:
                err = self.proc.stderr.read() if self.proc.stderr else ""
                raise RuntimeError(f"ckesc emulate exited before listening: {err.strip()}")
            parts = line.split()
            if len(parts) == 2 and parts[0] in ("socketcand", "control"):
                h, p = parts[1].rsplit(":", 1)
                ports[parts[0]] = (h, int(p))
        return ports

    def reopen(self, bitrate: int) -> None:
        # socketcand carries no bit rate: the emulator's bench decides who hears whom
        self.bitrate = bitrate

    def close(self) -> None:
        try:
            super().close()
        finally:
            self._end_process()

    def _end_process(self) -> None:
        try:
            if self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(timeout=10)
            for pipe in (self.proc.stdout, self.proc.stderr):
                if pipe is not None:
                    pipe.close()
        finally:
            if self._flash_dir is not None:
                self._flash_dir.cleanup()


def _die_with_parent() -> None:
    """In the emulator's child process: SIGTERM when the suite's process dies, however it dies (Linux
    prctl PR_SET_PDEATHSIG; elsewhere nothing), so no emulator outlives a killed run."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass
