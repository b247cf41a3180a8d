"""Power control: how the suite switches the DUT's supply, by backend name (``--power NAME``, a rig's
``power``).

The built-in backends are ``emulator`` (the simulated bench's own switch), ``command`` (shell commands,
e.g. a lab PSU's CLI), ``labgrid`` (labgrid's power drivers, :mod:`.labgrid_power`), ``manual`` (an
operator) and ``none``. Another package adds one the way python-can finds interfaces: an entry point in
the ``ckesc.power`` group naming a factory ``factory(get, prompt) -> PowerControl`` (``get``: the bench's
options by name, :meth:`.station.BenchOptions.get`; ``prompt``: asks the operator), e.g. in its pyproject.toml::

    [project.entry-points."ckesc.power"]
    my-psu = "my_package.power:open_psu"

A power cycle is always proven by the DUT's power-up counter (:meth:`.dut.Dut.power_cycle`): a backend
only switches.
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
from collections.abc import Callable
from importlib.metadata import entry_points
from typing import Any

from . import labgrid_power
from .errors import PowerFailed, PreflightError
from .power_control import Option, PowerControl, Prompt

#: the entry-point group other packages register power backends in
ENTRY_POINT_GROUP = "ckesc.power"

#: How long a power command may run before it has failed (``--power-cmd-timeout``): a lab supply's CLI switches in
#: well under a second, a Python script (``ckesc control``) in one or two, several on a loaded host in a few; one
#: that hangs (a network PSU that does not answer) must not hold the run
POWER_COMMAND_TIMEOUT_S = 10.0

def run_command(cmd: str, timeout: float, *, what: str, longer: str) -> str:
    """Run a bench command (a power switch, a flash tool), without a shell, and return its output (stdout and
    stderr together, in their order); a :class:`PowerFailed` naming it as ``what`` when it cannot start, exits
    non-zero (its output's tail said) or is still running after ``timeout`` s: then it is killed with every process
    it started (its own session), so that a child holding its output open cannot hold the run either. ``longer``:
    the option that gives it more time."""
    try:
        proc = subprocess.Popen(shlex.split(cmd), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                errors="replace", start_new_session=True)
    except (OSError, ValueError) as exc:
        raise PowerFailed(f"{what} {cmd!r} could not be run: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        out, _ = proc.communicate(timeout=timeout)
    except BaseException as exc:  # the limit, or Ctrl-C: nothing of it outlives the run
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
        proc.communicate()
        if isinstance(exc, subprocess.TimeoutExpired):
            raise PowerFailed(f"{what} {cmd!r} did not return within {timeout:g} s (killed; {longer} gives it "
                              "longer)") from None
        raise
    if proc.returncode != 0:
        said = output_tail(out, 300)
        raise PowerFailed(f"{what} {cmd!r} failed (exit status {proc.returncode})" + (f": {said}" if said else ""))
    return out


def output_tail(text: str, chars: int) -> str:
    """A command's output as one line: its words, the last ``chars`` characters of them."""
    return " ".join(text.split())[-chars:]


class EmulatorPower(PowerControl):
    name = "emulator"

    def __init__(self, lane: Any) -> None:
        self.lane = lane  # a lane whose ``sim`` is the simulated bench (power_off / power_on)

    def off(self) -> None:
        self.lane.sim.power_off()

    def on(self) -> None:
        self.lane.sim.power_on()


class CommandPower(PowerControl):
    """Runs shell commands (e.g. a lab PSU's CLI, or ``ckesc control ... power off``)."""

    name = "command"

    def __init__(self, off_cmd: str, on_cmd: str, timeout: float = POWER_COMMAND_TIMEOUT_S) -> None:
        if not off_cmd or not on_cmd:
            raise ValueError("--power command needs both --power-off-cmd and --power-on-cmd")
        self.off_cmd, self.on_cmd = off_cmd, on_cmd
        self.timeout = timeout

    def _run(self, cmd: str) -> None:
        run_command(cmd, self.timeout, what="power command", longer="--power-cmd-timeout")

    def off(self) -> None:
        self._run(self.off_cmd)

    def on(self) -> None:
        self._run(self.on_cmd)


class ControlPower(PowerControl):
    """A running ``ckesc emulate``'s power through its control channel, in-process: what ``ckesc control
    --port P power off|on`` sends, without starting a Python process per switch (about 0.2 s each here)."""

    name = "emulator control channel"

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port

    def _switch(self, action: str) -> None:
        from ..emulator.control import control_request

        control_request(self.port, {"cmd": "power", "action": action}, host=self.host)

    def off(self) -> None:
        self._switch("off")

    def on(self) -> None:
        self._switch("on")


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


def _command(get: Option, prompt: Prompt) -> PowerControl:
    return CommandPower(get("power_off_cmd"), get("power_on_cmd"), get("power_cmd_timeout") or POWER_COMMAND_TIMEOUT_S)


def _labgrid(get: Option, prompt: Prompt) -> PowerControl:
    return labgrid_power.open_power(get)  # it imports labgrid, the optional extra `rig`, only here


def _emulator(get: Option, prompt: Prompt) -> PowerControl:
    raise PreflightError("--power emulator works only with --dut emulator")


#: the built-in backends: name -> factory(get, prompt)
BUILT_IN: dict[str, Callable[[Option, Prompt], PowerControl]] = {
    "emulator": _emulator,
    "command": _command,
    "labgrid": _labgrid,
    "manual": lambda get, prompt: ManualPower(prompt),
    "none": lambda get, prompt: NoPower(),
}


def backends() -> dict[str, Callable[[Option, Prompt], PowerControl]]:
    """Every power backend by name: the built-in ones, then those other packages register (``ckesc.power``
    entry points; a registered name never replaces a built-in one)."""
    found: dict[str, Any] = dict(BUILT_IN)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        found.setdefault(ep.name, ep)
    return found


def names() -> tuple[str, ...]:
    """The backend names ``--power`` accepts."""
    return tuple(backends())


def open_power(name: str, get: Option, prompt: Prompt) -> PowerControl:
    """The power backend ``name``, opened with the run's options (a :class:`PreflightError` names an unknown one)."""
    known = backends()
    if name not in known:
        raise PreflightError(f"--power {name}: no such power backend (known: {', '.join(known)}; another package adds "
                             f"one as a {ENTRY_POINT_GROUP!r} entry point)")
    factory = known[name]
    if hasattr(factory, "load"):  # a registered entry point
        factory = factory.load()
    power = factory(get, prompt)
    if not isinstance(power, PowerControl):
        raise PreflightError(f"--power {name}: its factory returned {type(power).__name__}, not a PowerControl")
    return power
