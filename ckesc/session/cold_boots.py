"""Shared cold boots: tests marked ``@pytest.mark.cold_boot(write, touches=setting)`` need a proven power cycle
between their write and their read. The run order (:mod:`.order`) stages a group of them touching different
settings: each test's write, then one power cycle, then the tests one after another each reading its own back
(the ``cold_boot`` fixture). A test that fails after a shared cycle runs again alone before it is judged, so
sharing never changes a verdict. Also here: a proven power cycle between two tests, in a trace of its own."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pytest

from ..bench.dut import Dut, DutError
from ..bench.epochs import PowerEpoch
from ..bench.link import Link
from ..bench.outcomes import Inconclusive
from ..bench.supply import Supply
from . import trace_hooks
from .collection import lacking
from .state import state


@dataclass
class _Written:
    """One test's write, made before the power cycle its group shares."""

    value: Any = None
    error: BaseException | None = None  # what the write raised: raised again in the test, as its own
    observations: list[tuple[str, Any]] = field(default_factory=list)
    traces: dict[str, str] = field(default_factory=dict)
    used: bool = False


@dataclass
class _ColdBoot:
    """Tests sharing one proven power cycle between their writes and their reads (``@pytest.mark.cold_boot``)."""

    members: list[str]
    before: dict[str, int]  # the settings before the first write: what the group's last test puts back
    name: str
    written: dict[str, _Written] = field(default_factory=dict)
    epoch: PowerEpoch | None = None
    power_up: str = ""
    dissolved: bool = False  # a test of it failed after the shared cycle and ran again alone: the rest run alone


_GROUPS = pytest.StashKey[dict]()  # test id -> its shared power cycle (_ColdBoot)


def _groups(config: pytest.Config) -> dict[str, _ColdBoot]:
    return config.stash.setdefault(_GROUPS, {})


def _params(item: pytest.Item) -> dict[str, Any]:
    callspec = getattr(item, "callspec", None)
    return dict(callspec.params) if callspec is not None else {}


def stage(config: pytest.Config, group: list[pytest.Item]) -> None:
    """Each test's write, in collection order, each in its own trace file and record, then one proven power cycle
    (its own trace). The tests then run one after another, each reading back its own (``cold_boot``); a group that
    cannot be staged (no lane yet, a failed power cycle) is simply not shared: its tests run alone."""
    st = state(config)
    lane, profile = st.lane, st.profile
    if lane is None or profile is None or st.node_id is None or not lane.power.available:
        return
    if any(lacking(it, profile) for it in group):
        return  # one would be skipped: nothing of it may run first
    name = f"shared power cycle {len(st.info.setdefault('cold_boots', [])) + 1}"
    traces = trace_hooks.writer(config)
    d = Dut(lane, profile, node_id=st.node_id)
    boot = _ColdBoot([it.nodeid for it in group], d.settings(), name)
    entry: dict[str, Any] = {"name": name, "tests": boot.members}
    st.info["cold_boots"].append(entry)
    for it in group:
        if traces is not None:
            traces.begin(f"{it.nodeid} write")
        w = Dut(lane, profile, node_id=st.node_id)
        written = boot.written[it.nodeid] = _Written()
        try:
            written.value = it.get_closest_marker("cold_boot").args[0](w, **_params(it))
        except (Exception, pytest.skip.Exception) as exc:  # noqa: BLE001 - the test's own outcome, raised in it
            written.error = exc
        finally:
            w.zero_throttle()
            written.observations = list(w.record.observations)
            if traces is not None:
                written.traces = {f"write{'.' + k if k else ''}": p for k, p in traces.end_relative().items()}
    boot.epoch = traced_power_cycle(config, name, entry)
    boot.power_up = entry.get("power_up", "")
    for it in group:
        _groups(config)[it.nodeid] = boot


def traced_power_cycle(config: pytest.Config, name: str, entry: dict[str, Any]) -> PowerEpoch | None:
    """A proven power cycle between two tests, in a trace of its own named ``name``; ``entry`` (the run's record of
    it) gets its trace files and the power-up, or the error: that is recorded, not raised (the tests that were to
    use the power-up meet the problem as their own). Returns the power-up's epoch, None when it failed."""
    st = state(config)
    lane, profile, traces = st.lane, st.profile, trace_hooks.writer(config)
    assert lane is not None and profile is not None
    if traces is not None:
        traces.begin(name)
    try:
        Supply(Link(lane, profile, node_id=st.node_id)).power_cycle(profile.off_s, profile.boot_s)
    except (DutError, Inconclusive) as exc:
        entry["error"] = str(exc)
        return None
    finally:
        if traces is not None:
            entry["traces"] = list(traces.end_relative().values())
    if lane.epoch is not None:
        lane.epoch.opened_by = f"the run-order scheduler between two tests ({name})"
        entry["power_up"] = lane.epoch.describe()
    return lane.epoch


def restore_point(config: pytest.Config, nodeid: str, snapshot: dict[str, int]) -> dict[str, int]:
    """The settings the ``dut`` fixture puts back after test ``nodeid``: its own ``snapshot``, except that a shared
    cold boot's writes are put back after its last test (or once it broke up), to what was before the first."""
    group = _groups(config).get(nodeid)
    if group is not None and (group.dissolved or group.members[-1] == nodeid):
        return group.before
    return snapshot


@pytest.fixture
def cold_boot(request: pytest.FixtureRequest, dut: Dut):
    """``cold_boot()`` in a ``@pytest.mark.cold_boot(write, touches=...)`` test: ``write(dut, **params)`` has been
    made and then a proven power cycle; returns what ``write`` returned (and raises what it raised). When the run
    order staged the test (schedule.py) its write was made before a power cycle shared with other tests' writes
    (each touching another setting), its observations and trace are the test's own, and the cycle is said; else
    the write and a proven power cycle are made now, as a test alone does."""
    item = request.node
    groups = _groups(request.config)

    def boot() -> Any:
        group = groups.get(item.nodeid)
        if group is not None and not group.dissolved and group.epoch is not None and dut.lane.epoch is group.epoch:
            written = group.written[item.nodeid]
            written.used = True
            item.stash[trace_hooks.EARLIER] = written.traces  # its write's trace is the test's own
            dut.record.observations.extend(written.observations)
            others = [m for m in group.members if m != item.nodeid]
            dut.record.observe("power cycle", f"{group.name}, after this test's write and those of {others}: "
                               f"{group.power_up}")
            if written.error is not None:
                raise written.error
            return written.value
        value = item.get_closest_marker("cold_boot").args[0](dut, **_params(item))
        dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
        return value
    return boot


@pytest.hookimpl(wrapper=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function):
    """A test that fails (or is INCONCLUSIVE) after a shared power cycle runs again alone before it is judged: the
    other tests' writes are undone, it writes, power-cycles and reads on its own, and that is its verdict (what it
    met in the shared cycle is recorded). So sharing never changes a verdict, and a write that disturbs another
    test's setting shows as that observation, not as that test's failure."""
    try:
        return (yield)
    except (Exception, Inconclusive) as exc:
        group = _groups(pyfuncitem.config).get(pyfuncitem.nodeid)
        if group is None or not group.written[pyfuncitem.nodeid].used or group.dissolved:
            raise
        group.dissolved = True
        d: Dut = pyfuncitem.funcargs["dut"]
        d.record.observe("after the shared power cycle", f"{type(exc).__name__}: {str(exc)[:300]}; run again alone")
        d.restore(group.before)
        return pyfuncitem.ihook.pytest_pyfunc_call(pyfuncitem=pyfuncitem)
