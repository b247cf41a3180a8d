"""Power-up epochs: where the 120 s Set ID / Set Baud window (R11) stands, so that tests can share it.

Every power-up the harness makes (``Dut.switch_power``) starts a :class:`PowerEpoch`: the lane time just
before power was switched on (the window cannot have started earlier), the time the DUT was heard from
again (it cannot have started later), whether the power-up counter proved the cycle (``Dut.power_cycle``),
the node id and bit rate the DUT booted at, and every Set ID / Set Baud request sent since. A window
test (``@pytest.mark.window``) acts at its moment of the current epoch if :func:`unusable` finds
nothing against it, and opens a fresh window with a proven power cycle otherwise; the run-order
scheduler (``schedule.py``) runs other tests while the window elapses. Plain data and functions: no
clock is read here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..protocol import catalogue as cat

#: the configuration requests the window governs (R11): sending one inside a window may change the DUT
WINDOW_REQUESTS = frozenset({"set_id", "set_baud"})
#: how far inside / outside the 120 s window a window test acts (lane seconds)
WINDOW_MARGIN_S = 1.0
#: an "after the window" test acts at most this much later than its moment, or it opens a fresh window
AFTER_SLACK_S = 10.0
INSIDE, AFTER = "inside", "after"


@dataclass
class PowerEpoch:
    """One power-up of the DUT, as the harness made it."""

    on_earliest: float  # lane time just before the power was switched on
    ready: float  # lane time the DUT had been heard from again (an upper bound of its power-on)
    node_id: int
    bitrate: int
    proven: bool = False  # the power-up counter went up by one (Dut.power_cycle)
    counter: tuple[int | None, int | None] = (None, None)
    opened_by: str = ""  # which test (or the scheduler) switched the power
    config: list[tuple[str, float]] = field(default_factory=list)  # (request name, lane time) sent since

    def moment(self, kind: str, margin: float = WINDOW_MARGIN_S) -> float:
        """When a window test of ``kind`` acts: ``margin`` before the earliest end of the window (inside),
        or ``margin`` after its latest end (after)."""
        if kind == INSIDE:
            return self.on_earliest + cat.CONFIG_WINDOW_S - margin
        return self.ready + cat.CONFIG_WINDOW_S + margin

    def describe(self) -> str:
        return (f"power-up at {self.on_earliest:.3f}-{self.ready:.3f} s lane time, proven by the power-up counter "
                f"{self.counter[0]} -> {self.counter[1]}, switched by {self.opened_by or 'a test'}")


def unusable(epoch: PowerEpoch | None, kind: str, *, now: float, node_id: int, bitrate: int,
             lead: float = 0.0, margin: float = WINDOW_MARGIN_S) -> str | None:
    """Why a window test of ``kind`` cannot act in ``epoch`` if it starts at ``now`` and needs ``lead``
    seconds before it acts; None when it can."""
    if epoch is None:
        return "no power-up made by this run yet"
    if not epoch.proven:
        return "the last power-up was not proven by the power-up counter"
    if (epoch.node_id, epoch.bitrate) != (node_id, bitrate):
        return (f"the DUT booted at node {epoch.node_id}, {epoch.bitrate} bit/s and is now at node {node_id}, "
                f"{bitrate} bit/s")
    window_end = epoch.on_earliest + cat.CONFIG_WINDOW_S
    inside_sent = [name for name, t in epoch.config if kind == INSIDE or t < window_end]
    if inside_sent:
        return f"{', '.join(sorted(set(inside_sent)))} was sent inside its window"
    moment = epoch.moment(kind, margin)
    if kind == INSIDE and now + lead > moment:
        return f"its moment ({moment:.3f} s) is past"
    if kind == AFTER and now + lead > moment + AFTER_SLACK_S:
        return f"its moment ({moment:.3f} s) is more than {AFTER_SLACK_S:g} s past"
    return None
