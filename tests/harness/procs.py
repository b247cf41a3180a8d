"""Helpers for the tests that run the tool as a user does: ``ckesc`` processes with a clean environment."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

CKESC = [sys.executable, "-m", "ckesc"]


def one_line_exit_2(done: subprocess.CompletedProcess, took: float, tmp: Path, *phrases: str, within: float) -> str:
    """``ckesc run``'s refusal of a set-up mistake, as a user meets it: exit 2 within ``within`` seconds, one line on
    stderr holding ``phrases``, no traceback, no verdict and no report under ``tmp/reports``; the line."""
    text = done.stdout + done.stderr
    assert done.returncode == 2, text
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, done.stderr
    for phrase in phrases:
        assert phrase in lines[0], lines[0]
    assert took < within, f"{took:.1f} s: {lines[0]}"
    assert "Traceback" not in text and "FAIL" not in text and "PASSED" not in text, text
    assert not (tmp / "reports").exists() or not any((tmp / "reports").iterdir()), "a report was written"
    return lines[0]


def env(tmp: Path) -> dict[str, str]:
    """The environment of a ``ckesc`` process under ``tmp``: its own temp directory, unbuffered output, and
    no python-can configuration from the caller's environment."""
    (tmp / "tmp").mkdir(exist_ok=True)
    out = dict(os.environ, TMPDIR=str(tmp / "tmp"), PYTHONUNBUFFERED="1")
    for key in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        out.pop(key, None)
    return out


class Emulator:
    """``ckesc emulate`` (node 1, and ``args``) in its own process, serving socketcand and its control channel
    on 127.0.0.1: ``port`` (socketcand) and ``control``. A context manager; :meth:`close` ends it."""

    def __init__(self, tmp: Path, *args: str) -> None:
        self.proc = subprocess.Popen([*CKESC, "emulate", "--nodes", "1", "--socketcand", "0", "--control", "0", *args],
                                     cwd=tmp, env=env(tmp), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        ports: dict[str, int] = {}
        assert self.proc.stdout is not None
        while len(ports) < 2:
            line = self.proc.stdout.readline()
            assert line, self.proc.stderr.read() if self.proc.stderr else "emulator died"
            kind, _, addr = line.strip().partition(" ")
            if kind in ("socketcand", "control"):
                ports[kind] = int(addr.rsplit(":", 1)[1])
        self.port, self.control = ports["socketcand"], ports["control"]

    def bench(self, profile: Path) -> list[str]:
        """``ckesc run``'s bench options that reach this emulator as a third-party DUT on a bus: socketcand, node 1,
        ``profile``, its power and bit rate switched through its control channel (``ckesc control``)."""
        control = shlex.join([*CKESC, "control", "--port", str(self.control)])
        return ["--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0",
                "--can-config", "host=127.0.0.1", "--can-config", f"port={self.port}",
                # TCP_NODELAY: python-can's socketcand client otherwise holds a frame back (Nagle)
                "--can-config", "tcp_tune=True", "--node-id", "1", "--profile", str(profile),
                "--power", "command", "--power-off-cmd", f"{control} power off", "--power-on-cmd", f"{control} power on",
                "--can-bitrate-cmd", f"{control} bitrate {{bitrate}}"]

    def close(self) -> None:
        end(self.proc)

    def __enter__(self) -> Emulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def end(proc: subprocess.Popen) -> None:
    """Stop a process: SIGTERM (its clean stop), SIGKILL if it has not
    ended within 30 s; then close its pipes."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=30)
    for pipe in (proc.stdout, proc.stderr):
        if pipe is not None:
            pipe.close()


def realtime_profile(tmp: Path) -> Path:
    """The emulator's profile with the real-time lane's stated error (``--lane realtime`` uses 2 ms): its
    answers are stamped when due, not when their last bit would have gone, so the R2 slot checks sit
    within a fraction of a millisecond of their limits."""
    from ckesc import bench as bench_pkg

    text = (Path(bench_pkg.__file__).parent / "profiles" / "emulator.toml").read_text()
    path = tmp / "emulator-realtime.toml"
    path.write_text(text.replace("error_s = 0.0 ", "error_s = 0.002 "))
    assert "error_s = 0.002" in path.read_text()
    return path
