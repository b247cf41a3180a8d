"""The exploration loop: Hypothesis generates programs, runs them on the DUT (through :class:`Session`), and
shrinks each disagreement with the oracle on the DUT itself to the shortest program that still shows it.

The budget is spent in rounds of :data:`ROUND` programs, each a Hypothesis run seeded from ``(seed, round)``:
the same seed gives the same programs, round after round. The database (``database``, a directory) keeps every
finding's shrunk program, and the next exploration runs those first (ours: Hypothesis's own example database
stores choice sequences, which a change of the action strategy reinterprets; a program is what a person reads). A problem already found (its
:attr:`ExploreFinding.key`) is not found again: a later program that shows only known problems passes, so each round
looks for something new. The budget bounds the whole exploration, shrinking included: a problem shown late is
shrunk for what is left of it (the program found so far is kept, shrunk or not, and :attr:`Found.cut` says so), and
``say`` is told when shrinking starts. The problems are returned in the order they were first seen.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..bench.errors import RestoreFailed
from .actions import Action, program_from_json, program_json, programs
from .runner import ExploreOutcome, Session

ROUND = 25  # programs per Hypothesis run (a round); shrinking comes on top
PAST = "past-findings.json"  # in the database directory: every finding's program, run first next time


@dataclass
class Found:
    """One problem: the shortest program found that shows it, and how long it took to find."""

    program: list[Action]
    outcome: ExploreOutcome
    key: str
    programs_before: int  # programs run before the first that showed it
    steps_before: int
    seconds_before: float  # wall seconds of exploration before it was first seen
    lane_seconds_before: float
    shrink_runs: int = 0
    also: list[str] = field(default_factory=list)  # problems seen only beside this one, in a longer program (folded in)
    #: shrinking was cut short by the budget: a shorter program may show it too
    cut: bool = False

    @property
    def finding(self):
        return next(f for f in self.outcome.findings if f.key == self.key)


@dataclass
class Stats:
    programs: int = 0
    steps: int = 0
    wall: float = 0.0
    lane: float = 0.0
    pairs: set[tuple[str, str]] = field(default_factory=set)
    features: set[str] = field(default_factory=set)

    def add(self, outcome: ExploreOutcome) -> None:
        self.programs += 1
        self.steps += len(outcome.program)
        self.lane += outcome.seconds
        feats = [a.feature for a in outcome.program]
        self.features.update(feats)
        self.pairs.update((a, b) for i, a in enumerate(feats) for b in feats[i + 1:] if a != b)

    def line(self) -> str:
        rate = self.steps / self.wall if self.wall else 0.0
        return (f"explore: {self.programs} programs, {self.steps} steps ({rate:.1f} steps/s), lane time {self.lane:.0f} s, "
                f"{len(self.features)} features, {len(self.pairs)} feature pairs exercised, {self.wall:.0f} s")


class _Shows(Exception):
    """A program showed a new problem (raised to Hypothesis, which shrinks it)."""


def explore(session: Session, *, budget_s: float, seed: int = 0, database: str | None = None, shrink_s: float | None = None,
            max_size: int = 12, stop_at_first: bool = False, max_programs: int | None = None, progress: Callable[[Stats], None] | None = None,
            clock: Callable[[], float] = time.monotonic, say: Callable[[str], None] | None = None) -> tuple[list[Found], Stats]:
    """Explore for ``budget_s`` wall seconds, shrinking included (a program running when it ends is finished);
    returns the problems found (shrunk), in the order first seen, and the stats. A round's problems are shrunk for
    at most ``shrink_s`` (default: whatever is left of the budget). ``max_programs``: also stop generating after that
    many programs (a budget that does not depend on the machine). ``clock``: the wall clock the budget is measured on
    (a budget is a person's time, not the lane's). ``say``: told, in one line, when a problem shows and its
    shrinking starts."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hseed

    stats = Stats()
    start = clock()
    found: list[Found] = []
    known: set[str] = set()
    strategy = programs(session.bench, max_size=max_size)
    last_progress = [start]

    shrinking_since: list[float] = []  # when this round's first problem showed

    def over() -> bool:
        return clock() - start >= budget_s or (max_programs is not None and stats.programs >= max_programs)

    def spent() -> bool:
        """No more shrinking: the budget is spent (or the round's shrinking time, ``shrink_s``)."""
        now = clock()
        return bool(broken) or now - start >= budget_s or (
            shrink_s is not None and bool(shrinking_since) and now - shrinking_since[0] >= shrink_s)

    broken: list[RestoreFailed] = []
    for program in _past(database):  # the findings of earlier explorations first, as they were shrunk
        if over():
            break
        outcome = session.run(program)
        stats.wall = clock() - start
        stats.add(outcome)
        new = sorted((f for f in outcome.findings if f.key not in known), key=lambda f: f.at)
        if new:
            known.add(new[0].key)
            found.append(Found(list(program), outcome, new[0].key, stats.programs - 1, stats.steps - len(program),
                               stats.wall, stats.lane - outcome.seconds))
    round_no = 0
    current: dict[str, Found] = {}  # what this round found (being shrunk)
    while not over() and not (stop_at_first and found) and not broken:

        def check(program: list[Action]) -> None:
            if spent() if current else (broken or over()):
                return  # the budget is spent: what is being shrunk stays as found so far
            try:
                outcome = session.run(program)
            except RestoreFailed as exc:  # the explorer's problem, not a finding: stop
                broken.append(exc)
                return
            stats.wall = clock() - start
            stats.add(outcome)
            if progress is not None and clock() - last_progress[0] >= 5.0:
                last_progress[0] = clock()
                progress(stats)
            # the first disagreement in time first: a later one may be its consequence (a DUT left suspended refuses
            # the settings after it)
            new = sorted((f for f in outcome.findings if f.key not in known), key=lambda f: f.at)
            if not new:
                return
            key = current_key(current, new)
            f = current.get(key)
            if f is None:
                current[key] = Found(list(program), outcome, key, stats.programs - 1, stats.steps - len(program),
                                     stats.wall, stats.lane - outcome.seconds)
                shrinking_since[:] = shrinking_since or [clock()]
                if say is not None:
                    left = budget_s - (clock() - start)
                    if shrink_s is not None:
                        left = min(left, shrink_s - (clock() - shrinking_since[0]))
                    say(f"explore: {key} shows after {stats.programs - 1} programs, {stats.wall:.0f} s: shrinking its "
                        f"{len(program)}-step program on the DUT, for at most {max(left, 0.0):.0f} s (the rest of the budget)")
            else:
                f.shrink_runs += 1
                if (len(program), _cost(program)) <= (len(f.program), _cost(f.program)):
                    f.program, f.outcome = list(program), outcome
            raise _Shows(key)

        test = given(strategy)(check)
        test._hypothesis_internal_add_digest = f"ckesc-explore-{session.profile.name}".encode()
        test = settings(max_examples=ROUND, deadline=None, database=None, derandomize=False, print_blob=False,
                        report_multiple_bugs=False, suppress_health_check=list(HealthCheck),
                        phases=(Phase.explicit, Phase.generate, Phase.shrink))(test)
        test = hseed(seed * 100_003 + round_no)(test)
        try:
            test()
        except _Shows:
            pass
        except Exception as exc:  # noqa: BLE001 - a flaky DUT (the shrunk program passed once): keep what showed it
            if not current or type(exc).__name__ not in ("Flaky", "FlakyFailure", "FlakyReplay"):
                raise
        for f in current.values():  # Hypothesis deletes whole items (an episode is one): now single steps
            f.cut = not _one_minimal(session, f, stats, spent)
        known.update(current)
        found.extend(sorted(fold(list(current.values())), key=lambda f: f.programs_before))  # in the order first seen
        current.clear()
        shrinking_since.clear()
        round_no += 1
    stats.wall = clock() - start
    _remember(database, found)
    if broken:
        raise broken[0]
    return found, stats


def _one_minimal(session: Session, f: Found, stats: Stats, spent: Callable[[], bool]) -> bool:
    """Delete single steps of ``f``'s program, on the DUT, while what it shows still shows (delta debugging's
    1-minimal program: no one step can go). Hypothesis shrinks the choices that drew the program, and an episode
    (several steps drawn as one item) goes whole or not at all; a firmware engineer reads the steps. Returns
    whether it got there (False: ``spent`` or the bench stopped it)."""
    deleted = True
    while deleted:  # passes until one deletes nothing: a step needed beside a later one may go once that one went
        deleted, i = False, 0
        while i < len(f.program) and len(f.program) > 1 and not spent():
            candidate = f.program[:i] + f.program[i + 1:]
            try:
                outcome = session.run(candidate)
            except RestoreFailed:
                return False
            stats.add(outcome)
            f.shrink_runs += 1
            if any(g.key == f.key for g in outcome.findings):
                f.program, f.outcome, deleted = candidate, outcome, True
            else:
                i += 1
        if spent() and i < len(f.program) and len(f.program) > 1:
            return False
    return True


def _past(database: str | None) -> list[list[Action]]:
    path = Path(database, PAST) if database else None
    if path is None or not path.exists():
        return []
    return [program_from_json(p) for p in json.loads(path.read_text())]


def _remember(database: str | None, found: list[Found]) -> None:
    """Add the programs of ``found`` to the database's past findings (each once)."""
    if not database or not found:
        return
    path = Path(database, PAST)
    path.parent.mkdir(parents=True, exist_ok=True)
    known = json.loads(path.read_text()) if path.exists() else []
    for f in found:
        p = program_json(f.program)
        if p not in known:
            known.append(p)
    path.write_text(json.dumps(known, indent=1) + "\n")


def fold(round_found: list[Found]) -> list[Found]:
    """A problem first seen in a longer program beside one shrunk shorter in the same round is most likely its
    consequence (a DUT left suspended refuses the settings after it): it is listed under that one, not alone."""
    kept: list[Found] = []
    for f in sorted(round_found, key=lambda f: (len(f.program), _cost(f.program))):
        root = next((k for k in kept if k.key in {g.key for g in f.outcome.findings}), None)
        if root is not None:
            root.also.append(f.key)
        else:
            kept.append(f)
    return kept


def current_key(current: dict[str, Found], new: list) -> str:
    """The problem a failing program is counted for: one already being shrunk in this round if it shows it
    (Hypothesis shrinks towards the same failure), else its first new one."""
    keys = [f.key for f in new]
    return next((k for k in keys if k in current), keys[0])


def _cost(program: list[Action]) -> float:
    """Lane seconds a program costs, roughly (a tie-break between two equally long ones)."""
    return sum(a.seconds if a.op == "wait" else 120.0 if a.op == "window" else 1.0 if a.op == "power"
               else 2.0 if a.op == "alone" else a.seconds + 1.0 if a.op == "short" else 0.1  # (a short: its settling too)
               for a in program)


def replay(session: Session, program: list[Action]) -> ExploreOutcome:
    """Run one program once (``ckesc explore --replay``, the generated tests)."""
    return session.run(program)
