"""The bisect's judgement, sans IO (issue #37, ``ckesc bisect``): :class:`Bisection` is told each run's outcome and
says which image to run next, until it names the first bad image or says why it cannot.

The images are in build order, oldest first: the first is known good, the last known bad. A **step** runs one
image up to ``tries`` times; it is decided when one verdict has a majority of ``tries`` (more than half: 2 of 3),
so a step stops as soon as the rest of its tries could not change the majority, and a step whose tries are spent
without one (2 tries that disagree) is **undecided**: the bisect stops there and says so, never guessing. A bench
error (a flash that failed, an image that is not the one running, a bench that went away) stops it at once.

The **canary** is a step of the known-good image: at the end (``canary="end"``, after the first bad image is found)
and, with ``canary="every"``, after every step. A known-good image that now fails means the bench kept state
between runs (OpenTitan's lesson): the bisect says so instead of blaming a build.

:func:`majority` is the one rule of a step's verdict.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

#: the canary's choices: after the first bad image is found only, or after every step too
CANARY_CHOICES = ("end", "every")


class Outcome(StrEnum):
    """What one run of the selection on one image said."""

    GOOD = "good"  # the selection passed
    BAD = "bad"  # the selection failed
    ERROR = "bench error"  # the run could not judge the image: flash, proof or bench


class Ending(StrEnum):
    """How a bisect ended."""

    FOUND = "found"  # the first bad image is named
    UNDECIDED = "undecided"  # a step never reached a majority
    STATE_KEPT = "bench kept state"  # the canary (the known-good image) failed
    BENCH_ERROR = "bench error"


@dataclass
class Step:
    """One image's step: its tries' outcomes and, once decided, its verdict (GOOD or BAD; None: not decided)."""

    image: int
    canary: bool = False
    outcomes: list[Outcome] = field(default_factory=list)
    verdict: Outcome | None = None


@dataclass(frozen=True)
class BisectEnd:
    """The end: how it ended, the first bad image (FOUND), the images still between a good and a bad one (``good``,
    ``bad``: the last image known good and the first known bad when it stopped) and the one line that says it."""

    ending: Ending
    good: int
    bad: int
    first_bad: int | None
    reason: str


def majority(outcomes: list[Outcome], tries: int) -> Outcome | None:
    """The verdict of a step's ``outcomes`` out of ``tries``: the verdict more than half of the tries gave (GOOD or
    BAD), or None while no verdict has one (not yet, or, its tries spent, never)."""
    for verdict in (Outcome.GOOD, Outcome.BAD):
        if outcomes.count(verdict) * 2 > tries:
            return verdict
    return None


class Bisection:
    """The state machine: :attr:`next_image` is the image to run (None once :attr:`result` is set); :meth:`record`
    takes that run's outcome. ``count`` images, 0 known good and ``count - 1`` known bad (indices from 0; the lines
    that say it number the images from 1, as a list is read)."""

    def __init__(self, count: int, *, tries: int = 1, canary: str = "end") -> None:
        if count < 2:
            raise ValueError(f"a bisect needs a known-good and a known-bad image, not {count} image(s)")
        if tries < 1:
            raise ValueError(f"tries must be 1 or more, not {tries}")
        if canary not in CANARY_CHOICES:
            raise ValueError(f"canary is one of {CANARY_CHOICES}, not {canary!r}")
        self.tries, self.canary = tries, canary
        self.good, self.bad = 0, count - 1
        self.steps: list[Step] = []
        self.result: BisectEnd | None = None
        self._open = self._new_step(canary=self.bad - self.good <= 1)  # two images: only the canary is left to run

    # ------------------------------------------------------------------------------------------- what to run
    @property
    def next_image(self) -> int | None:
        return None if self.result is not None else self._open.image

    @property
    def step(self) -> Step:
        """The step the next run belongs to (the last one once the bisect ended)."""
        return self._open

    def _new_step(self, *, canary: bool = False) -> Step:
        step = Step(image=0 if canary else (self.good + self.bad) // 2, canary=canary)
        self.steps.append(step)
        return step

    # ------------------------------------------------------------------------------------------- what happened
    def record(self, outcome: Outcome) -> Step | None:
        """The next run's outcome; returns the step when this run decided (or ended) it, else None."""
        if self.result is not None:
            raise RuntimeError("the bisect has ended: nothing more to record")
        step = self._open
        step.outcomes.append(Outcome(outcome))
        if outcome is Outcome.ERROR:
            return self._end(Ending.BENCH_ERROR, f"image {step.image + 1}: the bench could not judge it (flash, proof or "
                                                 "bench error): no verdict is guessed", step)
        step.verdict = majority(step.outcomes, self.tries)
        if step.verdict is None:
            if len(step.outcomes) < self.tries:
                return None
            return self._end(Ending.UNDECIDED, f"image {step.image + 1}: {self._votes(step)} in {self.tries} tries, no "
                                               "majority: the step never decided, and is not guessed", step)
        if step.canary:
            if step.verdict is Outcome.BAD:
                return self._end(Ending.STATE_KEPT, f"the known-good image {step.image + 1} now fails ({self._votes(step)}):"
                                                    " the bench kept state between runs, no build is blamed", step)
        elif step.verdict is Outcome.GOOD:
            self.good = step.image
        else:
            self.bad = step.image
        self._advance(after_canary=step.canary)
        return step

    def _advance(self, *, after_canary: bool) -> None:
        narrowed = self.bad - self.good <= 1
        canary_due = not after_canary and (self.canary == "every" or narrowed)
        if canary_due:
            self._open = self._new_step(canary=True)
        elif narrowed:
            self.result = BisectEnd(Ending.FOUND, self.good, self.bad, self.bad,
                                 f"image {self.bad + 1} is the first bad image (image {self.good + 1} the last good)")
        else:
            self._open = self._new_step()

    def _end(self, ending: Ending, reason: str, step: Step) -> Step:
        self.result = BisectEnd(ending, self.good, self.bad, None, reason)
        return step

    @staticmethod
    def _votes(step: Step) -> str:
        return ", ".join(f"{step.outcomes.count(o)} {o.value}" for o in (Outcome.GOOD, Outcome.BAD))
