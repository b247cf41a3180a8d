"""Bus-fault control (R20, issue #36): how a test disturbs the DUT's CAN bus for a while and frees it again.

A test asks :func:`bus_fault_control` for its lane's control and calls ``cause(kind, seconds)``; it returns once the
fault has ended. Kinds: ``"short"`` (CANH to CANL, every bit dominant: every transmitter meets bit errors and goes
bus-off), ``"other_bitrate"`` (a node at another bit rate sending: each of its frames is a run of errors to every
other node, and a frame another node tries meanwhile meets a bit error). A lane without a control gives None: the
test SKIPs (:data:`NO_CONTROL`), never PASSes.

- The simulated lane: its world's :meth:`~ckesc.emulator.sim_can.CanNodes.short`. The lane runs without
  acknowledgement (``SIM_CAN`` in :mod:`.sim_lane`), where nothing can go bus-off; the control turns the CAN model's
  acknowledgement and error confinement on for the fault and its recovery only (from an idle bus), and back off once
  every controller is error-active again with an empty queue, so the rest of the suite keeps its bus. A controller
  that does not recover by itself keeps it on until :meth:`SimBusFault.settle` after a power cycle.
  A node at another bit rate is played as what the others meet: a short of :data:`FOREIGN_FRAME_S` (a frame at 250
  kbit/s) every :data:`FOREIGN_PERIOD_S` (the CAN model does not mix bit rates on its wires).
- A real bench: ``--bus-fault-cmd "CMD {seconds}"`` (a relay across CANH-CANL closed for ``{seconds}``; with
  ``{kind}`` in it, the command is asked for ``other_bitrate`` too, else only ``short``), run as the
  power commands are (:mod:`.power`): a command that fails or outlives ``seconds`` plus ``--power-cmd-timeout`` is a
  bench error (:class:`~.errors.PowerFailed`'s kind: :class:`BusFaultFailed`).
"""

from __future__ import annotations

from typing import Any

from .errors import BenchError, PowerFailed
from .power import POWER_COMMAND_TIMEOUT_S, run_command

#: the skip of a test whose lane cannot disturb the bus
NO_CONTROL = "no bus-fault control: give --bus-fault-cmd"
#: the kinds of fault a control may cause
KINDS = ("short", "other_bitrate")
#: ``other_bitrate`` in the simulated lane: how long each frame of the node at another bit rate holds the bus (an
#: 8-byte extended frame at 250 kbit/s) and how often it sends one (1 kHz: a babbling node)
FOREIGN_FRAME_S = 0.0005
FOREIGN_PERIOD_S = 0.001
#: how long the simulated control waits, after a fault, for every controller to settle (recovered, queue empty)
SETTLE_S = 0.5


class BusFaultFailed(BenchError):
    """The bus-fault command could not be run, failed, or did not return in time."""


class SimBusFault:
    """The simulated lane's bus faults (see the module docstring)."""

    def __init__(self, lane: Any) -> None:
        self.lane = lane
        self._opened = False  # whether this control turned acknowledgement on (and must turn it off again)

    @property
    def world(self) -> Any:
        return self.lane.sim.world

    def cause(self, kind: str, seconds: float) -> float | None:
        """Cause the fault for ``seconds``; when it ended, in lane time (None: the lane's time after the call)."""
        if kind not in KINDS:
            raise ValueError(f"bus fault {kind!r}: one of {', '.join(KINDS)}")
        world = self.world
        if not world.ack:
            # the bus without acknowledgement holds its frames in one heap: let it empty, then hand the nodes
            # their controllers (every frame from now on goes through its sender's queue)
            world.run_until(world.now + SETTLE_S, stop=lambda: not world._ready and world._in_flight is None)
            world.ack = self._opened = True
        if kind == "short":
            world.short(seconds)
            self.lane.wait_power(seconds)
        else:
            for _ in range(round(seconds / FOREIGN_PERIOD_S)):
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
        """Run the bus until it has settled (at most ``within`` s), then give the lane its bus without
        acknowledgement back; whether it settled (False: a controller still bus-off or holding frames: the
        acknowledgement stays on, as the hardware would keep it silent, until a power cycle and another call)."""
        world = self.world
        if not self._opened:
            return True
        world.run_until(world.now + within, stop=self.settled)
        if not self.settled():
            return False
        for node in list(world._ctl):
            world._forget(node)
        world.ack = self._opened = False
        return True


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


def bus_fault_control(lane: Any, cmd: str | None = None, timeout: float = POWER_COMMAND_TIMEOUT_S) -> SimBusFault | CommandBusFault | None:
    """``lane``'s bus-fault control, kept on it: ``cmd`` (``--bus-fault-cmd``, run with ``timeout``:
    ``--power-cmd-timeout``), else the simulated lane's own, else None."""
    given = lane.__dict__.get("bus_fault")
    if given is not None:
        return given
    if cmd:
        control = lane.__dict__["bus_fault"] = CommandBusFault(cmd, timeout, lane)
        return control
    if hasattr(lane, "sim") and hasattr(lane.sim, "world"):
        control = lane.__dict__["bus_fault"] = SimBusFault(lane)
        return control
    return None
