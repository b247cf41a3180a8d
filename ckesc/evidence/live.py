"""The bus rules in the background of a suite run: one :class:`LaneRules` listener per lane.

The plugin puts one on every lane it opens (``lane.listeners``), so the engine sees every frame the
lane reads, both directions (the host's own frames are their echo, ``is_rx`` False), with the lane's
timestamps. What it finds while a test runs (setup, call and teardown) fails that test:
:meth:`LaneRules.begin` at the start of a test, :meth:`LaneRules.take` when its verdict is made.
"""

from __future__ import annotations

import can

from .rules import BusRules, Violation

#: Violations quoted in a failure message; the rest are counted.
QUOTED = 3
_KEPT = 50


def tolerance_for(lane) -> float:
    """The timing tolerance of a lane: exact in simulated time; elsewhere the lane's stated error plus one
    1 ms report-scheduling tick (what ``Dut.interval_tolerance_ms`` allows a report interval)."""
    return 0.0 if lane.clock == "simulated" else lane.timing_error + 0.001


class LaneRules(can.Listener):
    """The bus rules over one lane's frames, violations kept per test."""

    def __init__(self, lane, *, jitter: float = 0.0) -> None:
        """``jitter``: the DUT's report-interval jitter allowance (seconds; the profile's ``jitter_s``)."""
        self.lane = lane
        # the simulated lane hears every frame on its bus; a real bus or socketcand may drop some
        # the suite's power cycles go through Dut.switch_power, which tells the rules (power_switched)
        self.rules = BusRules(tolerance=tolerance_for(lane), bitrate=lane.bitrate, complete=lane.clock == "simulated",
                              jitter=jitter, power_known=True)
        self.found: list[Violation] = []
        self.count = 0
        self.between = 0  # violations while no test ran (session fixtures)

    def on_message_received(self, msg: can.Message) -> None:
        if self.lane.bitrate != self.rules.bitrate:  # the host reopened at another bit rate (Set Baud's tests)
            self.rules.set_bitrate(self.lane.bitrate)
        found = self.rules.feed_message(msg)
        if found:
            self.count += len(found)
            room = _KEPT - len(self.found)
            if room > 0:
                self.found.extend(found[:room])

    def power_switched(self, when: float) -> None:
        """The host switched the DUT's power at lane time ``when`` (see BusRules.power_switched)."""
        self.rules.power_switched(when)

    def begin(self) -> None:
        """A test starts: what was found before it is nobody's test's."""
        self.between += self.count
        self.found, self.count = [], 0

    def take(self) -> tuple[list[Violation], int]:
        """What was found since :meth:`begin` or the last take: (the first few, how many in all)."""
        found, count = self.found, self.count
        self.found, self.count = [], 0
        return found, count

    @property
    def closed(self) -> bool:
        return bool(getattr(self.lane.bus, "_is_shutdown", False))


def failure_text(found: list[Violation], count: int) -> tuple[str, list[str]]:
    """The failure message of a test during which the bus broke rules, and the requirement ids named."""
    ids = list(dict.fromkeys(rid for v in found for rid in v.rules))
    head = f"[bus rules {' '.join(ids)}] {count} violation(s) of the rules that hold at all times while this test ran"
    shown = "\n".join(str(v) for v in found[:QUOTED])
    more = f"\n... {count - QUOTED} more" if count > QUOTED else ""
    return f"{head}:\n{shown}{more}", ids
