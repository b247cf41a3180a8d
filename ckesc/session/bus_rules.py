"""The live bus rules: the rules that hold at all times (``ckesc/evidence/rules.py``) watch every frame of every
lane the plugin opens, and a rule broken while a test runs is that test's FAIL (:func:`judge`), or, while a SKIPPED
test ran, the rule's own failure (it fails the run)."""

from __future__ import annotations

import pytest

from ..bench.lanes import Lane
from ..evidence.live import LaneRules, causes, failure_text
from .collection import is_conformance
from .state import state

_WATCHERS = pytest.StashKey[list]()  # the bus rules on every lane the plugin opens (LaneRules)
_RULES = pytest.StashKey[list]()  # requirement ids of the bus rules broken while the test ran
_CAUSES = pytest.StashKey[list]()  # the distinct problems among them (evidence.live.causes)
_TEARDOWN = pytest.StashKey[bool]()  # the bus rules failed the test at teardown (a FAIL, not an ERROR)


def _watchers(config: pytest.Config) -> list[LaneRules]:
    return config.stash.setdefault(_WATCHERS, [])


def watch_lane(config: pytest.Config, lane: Lane) -> LaneRules:
    """The bus rules that hold at all times (ckesc/evidence/rules.py) over every frame the lane reads (returned)."""
    profile = state(config).profile
    watcher = LaneRules(lane, jitter=profile.jitter_s if profile is not None else 0.0)
    lane.listeners.append(watcher)
    _watchers(config).append(watcher)
    return watcher


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    if is_conformance(item):
        watchers = _watchers(item.config)
        watchers[:] = [w for w in watchers if not w.closed]  # multi_dut's private benches are gone
        for watcher in watchers:
            watcher.begin()


def rules_of(item: pytest.Item) -> list[str]:
    """The requirement ids of the bus rules broken while ``item`` ran."""
    return item.stash.get(_RULES, [])


def causes_of(item: pytest.Item) -> list[dict]:
    """The distinct problems among them (``evidence.live.causes``)."""
    return item.stash.get(_CAUSES, [])


def failed_at_teardown(item: pytest.Item) -> bool:
    """Whether the bus rules failed ``item`` at its teardown (a FAIL, not an ERROR)."""
    return item.stash.get(_TEARDOWN, False)


def judge(item: pytest.Item, rep: pytest.TestReport, skipped: bool) -> None:
    """A test during which the bus broke a rule fails, whatever its own verdict, with the frames quoted; but
    a test SKIPPED (not claimed, R9b; a capability the profile lacks) is not run, so not judged: it stays
    SKIPPED and keeps the rules it saw, which are the rules' failure (causes.rule_failures), and fail the run.
    ``skipped``: whether the test's own verdict is SKIPPED."""
    if rep.when not in ("call", "teardown"):
        return
    found, count = [], 0
    for watcher in _watchers(item.config):
        f, c = watcher.take()
        found, count = found + f, count + c
    if not count:
        return
    text, ids = failure_text(found, count)
    item.stash[_RULES] = list(dict.fromkeys(rules_of(item) + ids))
    known = {c["key"]: c for c in causes_of(item)}
    for c in causes(found):
        if c["key"] in known:
            known[c["key"]]["count"] += c["count"]
            known[c["key"]]["rules"] = list(dict.fromkeys(known[c["key"]]["rules"] + c["rules"]))
        else:
            known[c["key"]] = c
    item.stash[_CAUSES] = list(known.values())
    if rep.failed or skipped:
        rep.sections.append(("bus rules", text))
        return
    rep.outcome, rep.longrepr = "failed", text
    if rep.when == "teardown":
        item.stash[_TEARDOWN] = True
