"""Bus-fault control (R20, issue #36): how a test disturbs the DUT's CAN bus for a while and frees it again.

A test asks :func:`bus_fault_control` for its lane's control and calls ``cause(kind, seconds)``; it returns once the
fault has ended. Kinds: ``"short"`` (CANH to CANL, every bit dominant: every transmitter meets bit errors and goes
bus-off), ``"other_bitrate"`` (a node at another bit rate sending: each of its frames is a run of errors to every
other node, and a frame another node tries meanwhile meets a bit error). A lane without a control gives None: the
test SKIPs (:data:`NO_CONTROL`), never PASSes.

- The simulated lane: its world's :meth:`~ckesc.emulator.sim_can.CanNodes.short`, on the lane's CAN model
  (acknowledgement and error confinement, ``SIM_CAN`` in :mod:`.sim_lane`); after the fault the control runs the bus
  until every controller is error-active again with an empty queue (:meth:`SimBusFault.settle`). A lane opened
  without the model (``CKESC_SIM_ACK=0``, for measuring its cost) has no control: nothing on it can go bus-off.
  A node at another bit rate is played as what the others meet: a short of :data:`FOREIGN_FRAME_S` (a frame at 250
  kbit/s) every :data:`FOREIGN_PERIOD_S` (the CAN model does not mix bit rates on its wires).
- The real-time emulator (``--lane realtime``): its control channel's ``bus_fault`` request (``ckesc control bus``),
  which answers when the fault has ended, with its end in bus time; its hub plays the ESCs' controllers through the
  fault (:mod:`ckesc.emulator.hub_can`). :meth:`EmulatorBusFault.settle` waits for them to be back.
- A real bench: ``--bus-fault-cmd "CMD {seconds}"`` (a relay across CANH-CANL closed for ``{seconds}``; with
  ``{kind}`` in it, the command is asked for ``other_bitrate`` too, else only ``short``), run as the
  power commands are (:mod:`.power`): a command that fails or outlives ``seconds`` plus ``--power-cmd-timeout`` is a
  bench error (:class:`~.errors.PowerFailed`'s kind: :class:`BusFaultFailed`).
"""

from __future__ import annotations

import math
from typing import Any

from ..emulator.hub_can import FOREIGN_FRAME_S, FOREIGN_PERIOD_S, KINDS
from .errors import BenchError, PowerFailed
from .power import POWER_COMMAND_TIMEOUT_S, run_command
from .realtime_lane import RealtimeEmulatorLane

#: the skip of a test whose lane cannot disturb the bus
NO_CONTROL = "no bus-fault control: give --bus-fault-cmd"
#: how long the real-time emulator's control may take beyond the fault to answer (a loaded machine)
CONTROL_SLACK_S = 10.0
#: how long the simulated control waits, after a fault, for every controller to settle (recovered, queue empty)
SETTLE_S = 0.5


class BusFaultFailed(BenchError):
    """The bus-fault command could not be run, failed, or did not return in time."""


class SimBusFault:
    """The simulated lane's bus faults (see the module docstring)."""

    def __init__(self, lane: Any) -> None:
        self.lane = lane

    @property
    def world(self) -> Any:
        return self.lane.sim.world

    def cause(self, kind: str, seconds: float) -> float | None:
        """Cause the fault for ``seconds``; when it ended, in lane time (None: the lane's time after the call)."""
        if kind not in KINDS:
            raise ValueError(f"bus fault {kind!r}: one of {', '.join(KINDS)}")
        world = self.world
        if kind == "short":
            world.short(seconds)
            self.lane.wait_power(seconds)
        else:
            for _ in range(math.ceil(seconds / FOREIGN_PERIOD_S)):  # (at least ``seconds``)
                world.short(FOREIGN_FRAME_S)
                self.lane.wait_power(FOREIGN_PERIOD_S)
        end = world.now
        self.settle()
        return end

    def can(self, kind: str) -> bool:
        return kind in KINDS

    def settled(self) -> bool:
        """Every controller error-active (or warning) with nothing to send, nothing on the bus."""
        world = self.world
        return world._in_flight is None and not world._parked and all(
            not ctl.size and not ctl.bus_off for ctl in world._ctl.values())

    def settle(self, within: float = SETTLE_S) -> bool:
        """Run the bus until it has settled (at most ``within`` s); whether it did (False: a controller still bus-off
        or holding frames, as the hardware keeps it until a power cycle)."""
        self.world.run_until(self.world.now + within, stop=self.settled)
        return self.settled()


class EmulatorBusFault:
    """The real-time emulator's bus faults, through its control channel (``host``, ``port``)."""

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port

    def can(self, kind: str) -> bool:
        return kind in KINDS

    def _ask(self, req: dict, seconds: float) -> dict:
        from ..emulator.control import ControlError, control_request

        try:
            return control_request(self.port, req, host=self.host, timeout=seconds + CONTROL_SLACK_S)
        except ControlError as exc:
            raise BusFaultFailed(f"the emulator's bus fault {req}: {exc}") from None

    def cause(self, kind: str, seconds: float) -> float | None:
        if kind not in KINDS:
            raise ValueError(f"bus fault {kind!r}: one of {', '.join(KINDS)}")
        return float(self._ask({"cmd": "bus_fault", "kind": kind, "seconds": seconds}, seconds)["ended"])

    def settle(self, within: float = SETTLE_S) -> bool:
        return bool(self._ask({"cmd": "bus_settle", "within": within}, within)["settled"])


class CommandBusFault:
    """A real bench's fault: ``cmd`` with ``{seconds}`` replaced (a relay across CANH-CANL for that long)."""

    def __init__(self, cmd: str, timeout: float, lane: Any = None) -> None:
        if "{seconds}" not in cmd:
            raise ValueError("--bus-fault-cmd needs {seconds} (how long the relay shorts the bus)")
        self.cmd, self.timeout, self.lane = cmd, timeout, lane

    def can(self, kind: str) -> bool:
        """Whether the command causes ``kind`` (it names ``{kind}``, or ``kind`` is a short)."""
        return kind == "short" or "{kind}" in self.cmd

    def cause(self, kind: str, seconds: float) -> float | None:
        if kind not in KINDS:
            raise ValueError(f"bus fault {kind!r}: one of {', '.join(KINDS)}")
        cmd = self.cmd.replace("{seconds}", f"{seconds:g}").replace("{kind}", kind)
        adapter = getattr(self.lane, "adapter", None)  # the host's own adapter goes bus-off in a short too: expected
        if adapter is not None:
            adapter.excuse(f"the bus fault ({kind}) this test caused", seconds + self.timeout)
        try:  # (the bench's one way to run a command: no shell, killed with all it started at the limit)
            run_command(cmd, seconds + self.timeout, what="bus-fault command", longer="--power-cmd-timeout")
        except PowerFailed as exc:
            raise BusFaultFailed(str(exc)) from None
        return None  # it ended as the command returned

    def settle(self, within: float = 0.0) -> bool:
        return True


def bus_fault_control(lane: Any, cmd: str | None = None, timeout: float = POWER_COMMAND_TIMEOUT_S) -> Any:
    """``lane``'s bus-fault control, kept on it: the one its bench gave it (``lane.bus_fault``), else ``cmd``
    (``--bus-fault-cmd``, run with ``timeout``: ``--power-cmd-timeout``), else the emulator's own (simulated or
    real-time), else None."""
    given = lane.__dict__.get("bus_fault")
    if given is not None:
        return given
    if cmd:
        control = lane.__dict__["bus_fault"] = CommandBusFault(cmd, timeout, lane)
        return control
    if hasattr(lane, "sim") and getattr(getattr(lane.sim, "world", None), "ack", False):
        control = lane.__dict__["bus_fault"] = SimBusFault(lane)
        return control
    if isinstance(lane, RealtimeEmulatorLane):
        control = lane.__dict__["bus_fault"] = EmulatorBusFault(*lane.control)
        return control
    return None
