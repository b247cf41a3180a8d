"""The real-time emulator lane: ``ckesc emulate`` in its own process, reached through python-can's stock
socketcand client (a :class:`.lanes.BusLane`), power through the emulator's control channel."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from typing import Any

import can

from ..emulator.variants import FREEDOMS
from .lanes import BenchGone, BusLane
from .power import ControlPower
from .profile import DEFAULT_BUS_ERROR_S


class RealtimeEmulatorLane(BusLane):
    """``ckesc emulate`` in its own process, reached through python-can's stock socketcand client;
    power through the emulator's control channel."""

    name = "realtime"

    def __init__(self, *, nodes=(1,), faults=None, flash_path: str | None = None, seed: int = 0,
                 timing_error: float = DEFAULT_BUS_ERROR_S, temp_flash: bool = False, esc_options: dict[str, Any] | None = None,
                 firmware: str | None = None) -> None:
        cmd = [sys.executable, "-m", "ckesc", "emulate", "--nodes", ",".join(map(str, nodes)), "--socketcand", "0",
               "--control", "0", "--seed", str(seed), *(("--firmware", firmware) if firmware else ())]
        for key, value in (esc_options or {}).items():  # conforming variants: --option NAME=VALUE; others (boot_spread):
            cmd += ["--option", f"{key}={value}"] if key in FREEDOMS else [f"--{key.replace('_', '-')}", str(value)]
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
                                     start_new_session=True, preexec_fn=die_with_parent)
        try:
            ports = self._read_ports()
        except BaseException:
            self._end_process()
            raise
        host, port = ports["socketcand"]
        self.control = ports["control"]
        power = ControlPower(*self.control)
        # tcp_tune: python-can's client otherwise lets Nagle's algorithm hold a small frame back behind the one before
        super().__init__({"interface": "socketcand", "host": host, "port": port, "channel": "can0", "tcp_tune": True,
                          "ignore_config": True}, power, timing_error=timing_error)

    def _io_failed(self, exc: BaseException | None = None) -> None:
        """A dead emulator process is :class:`BenchGone`; a failed socketcand connection to a live one is
        reopened as on any bus (:meth:`BusLane._io_failed`)."""
        self._emulator_gone(exc)
        if exc is None:
            return
        try:
            super()._io_failed(exc)
        except BenchGone:
            self._emulator_gone(exc)
            raise

    def _emulator_gone(self, exc: BaseException | None) -> None:
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

    @property
    def can_change_bitrate(self) -> bool:
        return True  # the emulator's own hub: :meth:`reopen` moves the host

    def reopen(self, bitrate: int) -> None:
        # socketcand carries no bit rate: the emulator's bench decides who hears whom
        self.bitrate = bitrate
        self.reopens += 1

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


def die_with_parent() -> None:
    """In the emulator's child process: SIGTERM when the suite's process dies, however it dies (Linux
    prctl PR_SET_PDEATHSIG; elsewhere nothing), so no emulator outlives a killed run."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass
