"""The run order: the conformance run in the order of :mod:`.schedule` (waits that overlap), through pytest's own
loop or a batch worker's (``ckesc/rigs/batch.py``): :func:`overlaps`, :func:`overlap_plan` and :class:`PlanRunner`."""

from __future__ import annotations

import pytest

from ..bench.epochs import PowerEpoch, unusable
from .cold_boots import stage, traced_power_cycle
from .collection import is_conformance
from .schedule import LEAD_S, Plan
from .state import state


def _kind(item: pytest.Item) -> str:
    """How the run-order plan (schedule.py) treats a test."""
    if not is_conformance(item):
        return "cycle"  # not ours: run in collection order with the rest
    if item.get_closest_marker("last"):
        return "last"
    window = item.get_closest_marker("window")
    if window is not None:
        return f"window-{window.args[0]}"
    if item.get_closest_marker("cold_boot") is not None:
        return "cold-boot"
    if item.get_closest_marker("power_cycle") or item.get_closest_marker("may_power_cycle"):
        return "cycle"
    return "filler"


def _touches(item: pytest.Item) -> str:
    mark = item.get_closest_marker("cold_boot")
    return mark.kwargs.get("touches", item.nodeid) if mark is not None else ""


def _function_key(item: pytest.Item) -> str:
    return item.nodeid.split("[", 1)[0]


@pytest.hookimpl(tryfirst=True)
def pytest_runtestloop(session: pytest.Session) -> bool | None:
    """The conformance run in the order of :mod:`schedule` (waits that overlap): pytest's own loop, but
    the next test is chosen one test ahead, and a window is opened between two tests when one is due.
    pytest's loop runs instead with ``--ckesc-order collection``, under pytest-xdist, with nothing to
    overlap, and where the lane has no power control (no window test can run then)."""
    config = session.config
    if hasattr(config, "workerinput") or not overlaps(session):
        return None  # (a batch's worker runs the plan through xdist's own loop: batch.py)
    runner = overlap_plan(session)
    if runner is None:
        return None
    item = runner.first()
    while item is not None:
        hint = runner.before(item)
        item.config.hook.pytest_runtest_protocol(item=item, nextitem=hint)
        if session.shouldfail:
            raise session.Failed(session.shouldfail)
        if session.shouldstop:
            raise session.Interrupted(session.shouldstop)
        item = runner.after(item)
    return True


def overlaps(session: pytest.Session) -> bool:
    """Whether the run takes the plan's order: not with ``--ckesc-order collection``, nothing to overlap (no power
    control: no window test can run), a collection only, or a collection that failed."""
    config = session.config
    return not (config.getoption("ckesc_order") != "overlap" or config.option.collectonly or session.testsfailed
                or config.getoption("power", None) == "none")


def overlap_plan(session: pytest.Session) -> PlanRunner | None:
    """The run order of :mod:`schedule` for ``session``'s tests, or None where it saves nothing."""
    plan = Plan(list(session.items), kind=_kind, key=_function_key, touches=_touches)
    if not plan.useful:
        return None
    st = state(session.config)
    st.info["order"] = "overlap"
    st.info["epochs"] = []
    return PlanRunner(session.config, plan)


class PlanRunner:
    """Runs the plan one test at a time, for pytest's loop (the plugin's) or anyone else's (a batch's xdist
    worker, ``batch.py``): :meth:`before` a test (stages a shared cold boot; returns what pytest is to be told
    comes next), then the test's protocol, then :meth:`after` (learns its time, chooses the next test, opens a
    window when one is due)."""

    def __init__(self, config: pytest.Config, plan: Plan) -> None:
        self.config, self.plan = config, plan
        self.start: float | None = None
        self.hint: pytest.Item | None = None
        self.epoch: PowerEpoch | None = None

    def first(self) -> pytest.Item | None:
        return self.plan.first()

    def before(self, item: pytest.Item) -> pytest.Item | None:
        plan = self.plan
        lane = state(self.config).lane
        if (group := plan.group_of(item)) is not None:
            stage(self.config, group)
        self.start = lane.now() if lane is not None else None
        if self.start is not None:
            self.hint = plan.hint(item, self.start + plan.estimates.get(_function_key(item)), self._moment())
        else:
            self.hint = plan.hint(item, None, None)
        self.epoch = lane.epoch if lane is not None else None
        return self.hint

    def after(self, item: pytest.Item) -> pytest.Item | None:
        plan, hint = self.plan, self.hint
        lane = state(self.config).lane
        if lane is None or hint is None:
            return plan.choose(0.0, lambda w, now: float("inf"), _shares(item, hint)) if hint is not None else None
        now = lane.now()
        if self.start is not None:
            plan.learn(item, now - self.start)
        if lane.epoch is not None and lane.epoch is not self.epoch and not lane.epoch.opened_by:
            lane.epoch.opened_by = item.nodeid
        nxt = plan.choose(now, self._moment(), _shares(item, hint))
        if nxt is not None and plan.needs_epoch_before(nxt):
            self._open_epoch()
        return nxt

    def _moment(self):
        """``moment(w, end)`` for the plan: when window test ``w`` acts if the test before it ends at ``end``."""
        st, plan = state(self.config), self.plan
        lane, profile = st.lane, st.profile
        assert lane is not None and profile is not None

        def moment(w: pytest.Item, end: float) -> float:
            kind = plan.window_kind(w)
            epoch = lane.epoch
            if st.node_id is not None and unusable(epoch, kind, now=end, node_id=st.node_id, bitrate=lane.bitrate) is None:
                assert epoch is not None
                return epoch.moment(kind)
            on = end + profile.off_s  # a fresh epoch opened after the test ending at ``end``
            return PowerEpoch(on, on + profile.boot_s, 0, 0).moment(kind)
        return moment

    def _open_epoch(self) -> None:
        """Open a 120 s window with a proven power cycle between two tests, unless the current one still
        serves the next window test. A failure here is recorded, not raised: the window test then opens its own
        window (and meets the problem as its own)."""
        st, plan = state(self.config), self.plan
        lane, profile = st.lane, st.profile
        w = plan.pending_window()
        if lane is None or profile is None or st.node_id is None or w is None or not lane.power.available:
            return
        if unusable(lane.epoch, plan.window_kind(w), now=lane.now(), node_id=st.node_id, bitrate=lane.bitrate,
                    lead=LEAD_S) is None:
            return
        name = f"power-up epoch {len(st.info['epochs']) + 1}"
        entry = {"name": name, "for": w.nodeid, "at": round(lane.now(), 3)}
        st.info["epochs"].append(entry)
        traced_power_cycle(self.config, name, entry)


def _shares(ended: pytest.Item, hint: pytest.Item | None):
    """Which tests may run after ``ended`` when pytest was told ``hint`` runs next: those whose collector
    chain starts with what the two share (pytest tore down the rest; SetupState keeps that prefix)."""
    if hint is None:
        return lambda item: False
    prefix = []
    for a, b in zip(ended.listchain(), hint.listchain()):
        if a is not b:
            break
        prefix.append(a)
    return lambda item: item.listchain()[: len(prefix)] == prefix
