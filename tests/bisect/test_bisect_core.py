"""The bisect's judgement (ckesc/bisect/core.py, issue #37 item 3), driven by a scripted history of outcomes: the
first bad image in log2 steps, a majority of tries deciding a flaky image, a step that never decides reported and
not guessed, a canary that fails (the bench kept state) blamed on the bench, a bench error stopping at once."""

from __future__ import annotations

import itertools
import math

import pytest

from ckesc.bisect.core import Bisection, Ending, Outcome, majority

G, B, E = Outcome.GOOD, Outcome.BAD, Outcome.ERROR


def drive(b: Bisection, judge, limit: int = 200) -> list[int]:
    """Run ``b`` to its end, ``judge(image, run_number)`` giving each run's outcome; the images run, in order."""
    ran = []
    for n in range(limit):
        if b.next_image is None:
            return ran
        ran.append(b.next_image)
        b.record(judge(b.next_image, n))
    raise AssertionError("the bisect did not end")


def first_bad_at(k: int):
    return lambda image, _n: B if image >= k else G


@pytest.mark.parametrize("count,k", [(2, 1), (3, 1), (3, 2), (32, 18), (32, 1), (32, 31), (33, 7), (100, 64)])
def test_the_first_bad_image_is_found_in_log2_steps_and_the_canary_runs_last(count, k):
    b = Bisection(count)
    ran = drive(b, first_bad_at(k))
    assert b.result.ending is Ending.FOUND and b.result.first_bad == k, b.result
    assert ran[-1] == 0 and b.steps[-1].canary, "the known-good image is run again at the end"
    assert len(ran) - 1 <= math.ceil(math.log2(count - 1)), ran


def test_32_images_with_the_fault_from_image_19_take_5_steps():
    b = Bisection(32)
    ran = drive(b, first_bad_at(18))
    assert [i + 1 for i in ran] == [16, 24, 20, 18, 19, 1]
    assert "image 19 is the first bad image" in b.result.reason


@pytest.mark.parametrize("outcomes,tries,verdict", [
    ([G], 1, G), ([B], 1, B), ([G, B], 3, None), ([G, B, B], 3, B), ([B, G, G], 3, G), ([G, G], 3, G),
    ([G, B], 2, None), ([G, G], 2, G), ([B, B, G, G], 5, None), ([B, B, G, B], 5, B),
])
def test_a_step_is_decided_by_more_than_half_of_its_tries(outcomes, tries, verdict):
    assert majority(outcomes, tries) is verdict


def test_a_flaky_image_is_decided_by_the_majority_of_its_tries():
    """Image 18 (index 17, the last good) fails one run in three; with --tries 3 its step still says good, and the first bad image
    is still found."""
    flaky_runs = itertools.count()

    def judge(image, _n):
        if image == 17:
            return B if next(flaky_runs) % 3 == 0 else G
        return first_bad_at(18)(image, _n)

    b = Bisection(32, tries=3)
    drive(b, judge)
    assert b.result.first_bad == 18
    flaky = [s for s in b.steps if s.image == 17]
    assert flaky and flaky[0].outcomes == [B, G, G] and flaky[0].verdict is G


def test_a_step_stops_as_soon_as_its_majority_is_reached():
    b = Bisection(32, tries=3)
    drive(b, first_bad_at(18))
    assert all(len(s.outcomes) == 2 for s in b.steps), "two agreeing tries of three decide; the third is not run"


def test_the_same_history_without_retries_blames_the_wrong_image():
    """The same flaky image with one try: a run that shows the fault is believed (why --tries exists)."""
    b = Bisection(32)
    drive(b, lambda image, n: B if image >= 17 else G)  # image 18's one run showed the fault
    assert b.result.first_bad == 17


def test_a_step_that_never_decides_is_reported_never_guessed():
    b = Bisection(32, tries=2)
    drive(b, lambda image, n: (G, B)[n % 2] if image == 15 else first_bad_at(18)(image, n))
    r = b.result
    assert r.ending is Ending.UNDECIDED and r.first_bad is None
    assert "image 16: 1 good, 1 bad in 2 tries, no majority" in r.reason
    assert (r.good, r.bad) == (0, 31), "the range it narrowed to when it stopped"


def test_a_canary_that_fails_at_the_end_blames_the_bench_not_a_build():
    bad_seen = False

    def judge(image, _n):  # once a bad image ran, every image fails: the bench keeps the fault
        nonlocal bad_seen
        bad_seen = bad_seen or image >= 18
        return B if bad_seen else G

    b = Bisection(32)
    drive(b, judge)
    r = b.result
    assert r.ending is Ending.STATE_KEPT and r.first_bad is None
    assert r.reason.startswith("the known-good image 1 now fails") and "kept state" in r.reason


def test_the_canary_between_steps_stops_at_the_first_step_after_the_bench_kept_state():
    bad_seen = False

    def judge(image, _n):
        nonlocal bad_seen
        verdict = B if bad_seen or image >= 18 else G
        bad_seen = bad_seen or image >= 18
        return verdict

    b = Bisection(32, canary="every")
    ran = drive(b, judge)
    assert [i + 1 for i in ran] == [16, 1, 24, 1], "the canary after the first bad step already fails"
    assert b.result.ending is Ending.STATE_KEPT


def test_the_canary_between_steps_costs_a_run_per_step_on_a_clean_bench():
    b = Bisection(32, canary="every")
    ran = drive(b, first_bad_at(18))
    assert b.result.first_bad == 18
    assert [i + 1 for i in ran] == [16, 1, 24, 1, 20, 1, 18, 1, 19, 1]


def test_a_bench_error_stops_the_bisect_at_once():
    b = Bisection(32, tries=3)
    ran = drive(b, lambda image, n: E if image == 23 else first_bad_at(18)(image, n))
    assert b.result.ending is Ending.BENCH_ERROR and ran[-1] == 23
    assert b.next_image is None
    with pytest.raises(RuntimeError):
        b.record(G)


def test_two_images_need_only_the_canary():
    b = Bisection(2)
    assert drive(b, first_bad_at(1)) == [0]
    assert b.result.first_bad == 1


@pytest.mark.parametrize("kwargs", [dict(count=1), dict(count=5, tries=0), dict(count=5, canary="never")])
def test_what_cannot_be_bisected_is_refused(kwargs):
    with pytest.raises(ValueError):
        Bisection(**kwargs)
