"""The host's own CAN adapter as the bus tells it (R20, issue #36): its controller's state, read from the error frames
it hands the host (SocketCAN's, with ``berr-reporting`` for each bus error; :func:`~ckesc.protocol.canbus.reported_state`)
and from python-can's ``bus.state`` where the interface keeps one (polled). A bus-off, or an error-passive while the
ESC is up (the host is not alone on the bus, :attr:`.lanes.Lane.alone`), is the bench's failure under the test: a
:class:`~.lanes.BusFault` (an ERROR) whose one line names it, never a FAIL of the DUT. Error-passive while the host is
alone is what a lone host's unacknowledged frames do (R20): nothing is said.

A bus-off adapter is recovered where the interface can: its automatic restart is waited for
(:data:`ADAPTER_RECOVERY_S`: SocketCAN's ``restart-ms``, set by ``ip link``), else the interface's own restart is
called where it has one (python-can has no generic one; ``ckesc-sim``'s ``restart()``, PCAN's ``reset()``). An adapter
that stays bus-off ends the run (:class:`~.lanes.BenchGone`), its line saying how to make it recover.

A test that disturbs the bus on purpose (``--bus-fault-cmd``, :mod:`.bus_fault`) excuses what its fault does to the
host's adapter until the fault and the adapter's recovery are over (:meth:`AdapterWatch.excuse`).
"""

from __future__ import annotations

import math
import time
from typing import Any

import can

from ..protocol.canbus import ErrorState, reported_state

#: how long the lane waits for a bus-off adapter to restart by itself (SocketCAN's ``restart-ms`` is typically
#: 100 ms) before it tries the interface's own restart
ADAPTER_RECOVERY_S = 1.0
#: how often the lane reads python-can's ``bus.state`` (a USB adapter may ask its hardware)
STATE_POLL_S = 0.1
#: how long an error-passive adapter must stay so before it is said (a short takes it through error-passive to bus-off
#: within milliseconds: that is a bus-off)
PASSIVE_HOLD_S = 0.05
#: python-can's view of a controller's state
_FROM_PYTHON_CAN = {can.BusState.ACTIVE: ErrorState.ACTIVE, can.BusState.PASSIVE: ErrorState.PASSIVE,
                    can.BusState.ERROR: ErrorState.BUS_OFF}
#: what an operator does about an adapter that does not recover, in the one line that says so
RESTART_ADVICE = ("python-can has no generic restart: on SocketCAN let the kernel restart it, `ip link set CHANNEL type "
                  "can bitrate N restart-ms 100` (with the link down), or restart it by hand, `ip link set CHANNEL type "
                  "can restart`")
_FINE = (ErrorState.ACTIVE, ErrorState.WARNING)


class AdapterWatch:
    """One lane's reading of its adapter (see the module docstring): :meth:`heard` each frame read, :meth:`check` after
    each read (the lane raises what it says)."""

    def __init__(self, lane: Any) -> None:
        self.lane = lane
        self.state = ErrorState.ACTIVE
        self.told_by = "nothing yet"  # what said the state last, for the line
        self._said: ErrorState | None = None  # the bad state already reported (said once until it clears)
        self._excused_until = -math.inf  # monotonic time until which the adapter's trouble is a test's own fault
        self._excuse = ""
        self._polled = -math.inf
        self._passive_since = -math.inf

    # ------------------------------------------------------------------ reading
    def heard(self, msg: can.Message) -> None:
        """A frame the lane read: an error frame may say the adapter's state."""
        if msg.is_error_frame:
            state = reported_state(msg.arbitration_id, bytes(msg.data))
            if state is not None:
                self._set(state, f"SocketCAN error frame {msg.arbitration_id:03X}#{bytes(msg.data).hex().upper()}")

    def _set(self, state: ErrorState, told_by: str) -> None:
        if state is ErrorState.PASSIVE and self.state is not ErrorState.PASSIVE:
            self._passive_since = time.monotonic()
        self.state, self.told_by = state, told_by

    def poll(self, *, now: bool = False) -> None:
        """python-can's ``bus.state``, where the interface keeps one (at most every :data:`STATE_POLL_S`)."""
        t = time.monotonic()
        if not now and t - self._polled < STATE_POLL_S:
            return
        self._polled = t
        raw = self.raw
        if type(raw).state is can.BusABC.state:  # (BusABC's says ACTIVE whatever the hardware is in)
            return
        try:
            state = _FROM_PYTHON_CAN.get(raw.state)
        except Exception:  # noqa: BLE001 - not every interface can tell, nor always
            return
        if state is not None and state is not self.state and (state, self.state) != (ErrorState.ACTIVE, ErrorState.WARNING):
            self._set(state, f"python-can bus.state {raw.state.name}")  # (python-can's ACTIVE includes the warning)

    @property
    def raw(self) -> Any:
        """The python-can bus under the lane's send tap."""
        return getattr(self.lane.bus, "_bus", self.lane.bus)

    def excuse(self, why: str, seconds: float) -> None:
        """The adapter's trouble in the next ``seconds`` (and its recovery within :data:`ADAPTER_RECOVERY_S` after
        them) is ``why``'s, a fault the test causes on purpose: not reported."""
        self._excuse = why
        self._excused_until = time.monotonic() + seconds + ADAPTER_RECOVERY_S

    # ------------------------------------------------------------------ judging
    def check(self) -> tuple[bool, str] | None:
        """The bench's failure the adapter's state is now, said once: (gone, its one line), gone True for a bus-off that
        did not recover (the lane ends the run: :class:`~.lanes.BenchGone`), False for a bus-off recovered or an
        error-passive while the ESC is up (the test's ERROR: :class:`~.lanes.BusFault`); None: nothing to say."""
        self.poll()
        state = self.state
        if state in _FINE:
            self._said = None
            if time.monotonic() >= self._excused_until:
                self._excuse = ""
            return None
        if state is self._said or time.monotonic() < self._excused_until:
            return None
        if state is ErrorState.PASSIVE:
            if self.lane.alone is not None:  # a lone host's frames go unacknowledged (R20): its controller's way then
                self._passive_since = time.monotonic()  # (it counts from when another node is heard)
                return None
            if time.monotonic() - self._passive_since < PASSIVE_HOLD_S:
                return None
            self.poll(now=True)  # the state now, not the last poll's
            if (state := self.state) in _FINE:
                return None
        self._said = state
        told = self.told_by + (f", after {self._excuse}" if self._excuse else "")
        if state is ErrorState.PASSIVE:
            return False, (f"the host's CAN adapter is error-passive under this test ({told}) though the ESC is up: "
                           "its frames meet errors on the bus (termination, a loose wire, a node at another bit rate)")
        recovered = self.recover()
        if recovered is None:
            return True, (f"the host's CAN adapter went bus-off under this test ({told}) and did not recover within "
                          f"{ADAPTER_RECOVERY_S:g} s: {RESTART_ADVICE}")
        return False, f"the host's CAN adapter went bus-off under this test ({told}); {recovered}"

    def recover(self) -> str | None:
        """Bring a bus-off adapter back where the interface can: how it came back, in words, or None."""
        start = time.monotonic()
        while (left := start + ADAPTER_RECOVERY_S - time.monotonic()) > 0:
            self._read(min(left, STATE_POLL_S))
            if self.state is not ErrorState.BUS_OFF:
                return (f"it recovered by itself in {(time.monotonic() - start) * 1000:.0f} ms (the interface's "
                        "automatic restart: SocketCAN's restart-ms)")
        raw = self.raw
        restart = getattr(raw, "restart", None) or getattr(raw, "reset", None)
        if not callable(restart):
            return None
        try:
            restart()
        except Exception:  # noqa: BLE001 - whatever the interface raises, it did not restart
            return None
        self._read(0.0)
        if self.state is ErrorState.BUS_OFF:
            return None
        return (f"it did not restart by itself within {ADAPTER_RECOVERY_S:g} s (no restart-ms?) and the lane restarted "
                f"it (the interface's {restart.__name__}()); {RESTART_ADVICE.split(': ', 1)[1]} to have it recover alone")

    def _read(self, timeout: float) -> None:
        """Read the bus for ``timeout`` s, keeping what came for the lane; the state from error frames and bus.state."""
        msg = self.raw.recv(timeout=timeout)
        while msg is not None:
            self.heard(msg)
            self.lane._pending.append(msg)
            msg = self.raw.recv(timeout=0)
        self.poll(now=True)
