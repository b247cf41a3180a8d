"""Waits that overlap: the order conformance tests run in, around power-up epochs (issue #14).

A window test (``@pytest.mark.window("inside" | "after")``) acts at a fixed moment of the DUT's 120 s Set
ID / Set Baud window (R11), ~120 s after a power-up: alone, it sits the window out. Here the run goes
epoch by epoch instead: a proven power cycle opens the window (the plugin's opener, between tests, unless
the last power-up is still usable), then tests that neither switch the power nor send Set ID / Set Baud
(the *fillers*: no ``power_cycle`` marker) run while the window elapses, and each window test runs when
its moment comes. Every test still runs once, with its own verdict, trace and measurements; a window
test checks the epoch it acts in itself (``Dut.at_window_moment``), so a filler that ran long, switched
the power or moved the DUT costs time (a fresh window), never a verdict. The tests that power-cycle,
and the fillers left over, run after the epochs in collection order; ``last`` tests stay last.

Which window tests share an epoch: those acting after the window end (they change nothing when the DUT
is right) share one; each one acting inside it changes the DUT and so gets its own. The next test is chosen
when the one before has ended, at the lane time it ended: a filler runs if it is expected to end
:data:`LEAD_S` before the pending window test's moment, judged by the longest lane time its test function
has taken so far in this run (:class:`Estimates`), so it works on any DUT; a function not seen yet is
assumed to take :data:`UNKNOWN_S`. pytest is told the pending window test is next (:meth:`Plan.hint`):
it tears the ended test down to what the two share, and a filler sharing that runs instead when it fits.

Shared cold boots: tests that need only *a* cold boot between their write and their read
(``@pytest.mark.cold_boot(write, touches=setting)``) are grouped, no two in a group touching one setting
(:attr:`Plan.groups`), and each group runs back to back after the other tests: the plugin makes every
write of the group (each in its own trace and record), one proven power cycle, and then each test reads
back its own. A test failing after the shared cycle runs again alone (its write, its own cycle, its read)
and that is its verdict, so a write that disturbs another test's setting can never pass or fail that
test; the group's settings are put back after its last test.

Plain objects, no pytest or clock here: the plugin feeds lane times in and gets items out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Generic, Hashable, TypeVar

from ..bench.epochs import AFTER, INSIDE

T = TypeVar("T", bound=Hashable)

#: lane seconds assumed for a test function that has not run yet in this run
UNKNOWN_S = 10.0
#: lane seconds a window test is started ahead of its moment (its fixtures' set-up: settings, GET_ESC_ID)
LEAD_S = 2.0
#: lane seconds to spare before pytest is told a filler of the same module comes next (then it must)
COMMIT_SLACK_S = 3.0
#: lane seconds before a window test's start from which the longest filler that fits is chosen, not the next
BEST_FIT_S = 30.0
#: what an estimate is stretched by (a test function's cases do not all take the same time)
STRETCH = 1.2


@dataclass
class Estimates:
    """The longest lane time each key (a test function) has taken so far."""

    seen: dict[str, float] = field(default_factory=dict)

    def add(self, key: str, seconds: float) -> None:
        self.seen[key] = max(seconds, self.seen.get(key, 0.0))

    def get(self, key: str) -> float:
        s = self.seen.get(key)
        return UNKNOWN_S if s is None else s * STRETCH + 0.1


@dataclass
class Plan(Generic[T]):
    """The run order, decided one test ahead. ``kind`` of an item: "window-inside", "window-after",
    "filler", "cycle", "cold-boot", "last"; ``key`` names its test function, ``path::name`` (what :class:`Estimates` learns)."""

    items: list[T]
    kind: Callable[[T], str]
    key: Callable[[T], str]
    #: of a "cold-boot" item: the setting its write touches (two tests touching one never share a cycle)
    touches: Callable[[T], str] = lambda item: ""
    estimates: Estimates = field(default_factory=Estimates)

    def __post_init__(self) -> None:
        by = {k: [it for it in self.items if self.kind(it) == k] for k in
              ("window-inside", "window-after", "filler", "cycle", "cold-boot", "last")}
        # tests that need a cold boot between their write and their read: groups that share one power cycle,
        # each group's tests touching different settings, formed in collection order, run one after another
        self.groups: list[list[T]] = []
        for it in by["cold-boot"]:
            group = next((g for g in self.groups if self.touches(it) not in {self.touches(m) for m in g}), None)
            if group is None:
                self.groups.append(group := [])
            group.append(it)
        # acting inside a window changes the DUT: one epoch each; after-window tests share the last one
        self.windows: list[T] = by["window-inside"] + by["window-after"]
        # fillers from a window test's own module last: pytest keeps that module set up after one of them
        # when the window test is next, and then nothing from another module could fill
        window_modules = {self._module(w) for w in self.windows}
        self.fillers: list[T] = sorted(by["filler"], key=lambda it: self._module(it) in window_modules)
        self.rest: list[T] = [it for it in self.items if self.kind(it) in ("filler", "cycle")]
        self.rest += [it for g in self.groups for it in g]
        self.last: list[T] = by["last"]
        self.done: set[T] = set()

    @property
    def overlapping(self) -> bool:
        """Whether there is anything to overlap: a window test, and a filler to run during its window."""
        return bool(self.windows and self.fillers)

    @property
    def useful(self) -> bool:
        """Whether this order differs from collection order in what it saves: waits to overlap, or power
        cycles to share."""
        return self.overlapping or any(len(g) > 1 for g in self.groups)

    def group_of(self, item: T) -> list[T] | None:
        """The cold-boot group ``item`` opens (it is its first test), when the group has more than one."""
        return next((g for g in self.groups if len(g) > 1 and g[0] == item), None)

    def _module(self, item: T) -> str:
        return self.key(item).split("::", 1)[0]

    def window_kind(self, item: T) -> str:
        return INSIDE if self.kind(item) == "window-inside" else AFTER

    def first(self) -> T | None:
        """A filler first when there is a window to overlap: the lane the epochs need exists after it."""
        if self.overlapping:
            return self._take(self.fillers[0])
        return self._next_in_order()

    def hint(self, current: T, end: float | None, moment: Callable[[T, float], float] | None) -> T | None:
        """What pytest is told runs after ``current`` (it tears ``current`` down up to what the two share),
        given that ``current`` is expected to end at lane time ``end``. While a window test is pending:
        the next filler of ``current``'s module when it is expected to end :data:`COMMIT_SLACK_S` before
        the window test must start (so that module's set-up, e.g. a module-scoped capture, is kept), else
        the window test itself (a filler of another module may still run first, see :meth:`choose`).
        Otherwise the next test in order, which is then what runs."""
        w = self.pending_window()
        if w is None:
            return self._peek_in_order()
        same = next((f for f in self.fillers if f not in self.done and self._module(f) == self._module(current)), None)
        if same is not None and end is not None and moment is not None:
            if end + self.estimates.get(self.key(same)) <= moment(w, end) - LEAD_S - COMMIT_SLACK_S:
                return same
        return w

    def choose(self, now: float, moment: Callable[[T, float], float], allowed: Callable[[T], bool]) -> T | None:
        """The test to run at lane time ``now``: while a window test is pending, the first filler (that
        ``allowed`` accepts: pytest kept set up what it shares with the hint) expected to end
        :data:`LEAD_S` before the window test's moment (``moment(w, now)``), else the window test."""
        w = self.pending_window()
        if w is None:
            return self._next_in_order()
        start_by = moment(w, now) - LEAD_S
        candidates = [f for f in self.fillers if f not in self.done and allowed(f)]
        fitting = [f for f in candidates if now + self.estimates.get(self.key(f)) <= start_by]
        if fitting and start_by - now <= BEST_FIT_S:  # the last stretch: the longest that fits, the short ones kept
            return self._take(max(fitting, key=lambda f: self.estimates.get(self.key(f))))
        if fitting:  # in order (a module's tests together), learning how long each function takes
            return self._take(fitting[0])
        if allowed(w) or not candidates:
            return self._take(w)
        return self._take(candidates[0])  # pytest was told this module's next filler comes: it does

    def pending_window(self) -> T | None:
        """The next window test not run yet."""
        return next((w for w in self.windows if w not in self.done), None)

    def _peek_in_order(self) -> T | None:
        return next((it for it in self.windows + self.rest + self.last if it not in self.done), None)

    def _next_in_order(self) -> T | None:
        it = self._peek_in_order()
        return None if it is None else self._take(it)

    def _take(self, item: T) -> T:
        self.done.add(item)
        return item

    def learn(self, item: T, seconds: float) -> None:
        self.estimates.add(self.key(item), seconds)

    def needs_epoch_before(self, item: T) -> bool:
        """Whether a window is to be opened before ``item``: a filler run while window tests wait."""
        return self.kind(item) == "filler" and self.pending_window() is not None
