"""The fixtures a conformance test uses (``ckesc_lane``, ``dut``, ``multi_dut``, ``record``, ``ckesc_run``) and the
run's safety: no test before the DUT reports, its settings snapshotted and restored, zero throttle on every way out
of a test and of the run (Ctrl-C and SIGTERM: the signal guard), and the abort when the DUT does not answer."""

from __future__ import annotations

import dataclasses
import signal
import sys
from typing import Any

import pytest

from ..bench import statement
from ..bench.dut import Dut, DutError, DutUnreachable
from ..bench.lanes import BenchGone, BusLane, Lane
from ..bench.link import Link
from ..bench.outcomes import Inconclusive
from ..bench.profile import DutProfile
from ..emulator import variants
from ..protocol import catalogue as cat
from ..protocol import functions
from ..reporting.exits import ExitStatus
from .bus_rules import watch_lane
from .cold_boots import restore_point
from .collection import check_claims, lacking, preflight
from .safety import zero_throttle_now
from .state import state
from .trace_hooks import trace_lane

#: Frames kept across the run for the run-wide checks (4.1): a whole suite in real time is ~70,000; a
#: DUT that floods the bus must not grow memory without bound
RUN_FRAMES_KEPT = 150_000

_DUT = pytest.StashKey[Dut]()
_READY = pytest.StashKey[bool]()  # the DUT has been seen reporting (no test starts before: _await_ready)


def dut_of(item: pytest.Item) -> Dut | None:
    """The ``Dut`` (or ``multi_dut``) the test ``item`` was given, if any."""
    return item.stash.get(_DUT, None)


@pytest.fixture(scope="session")
def ckesc_lane(request: pytest.FixtureRequest):
    config = request.config
    st = state(config)
    if st.station is None:  # a session whose command line did not name the suite: built now
        preflight(config)
    station = st.station
    assert station is not None
    profile = station.profile  # with what an emulated ESC's variant declares (its vendor would state it)
    watchers = []

    def listen(lane) -> None:  # before the echo probe: the frames it reads go to the listeners
        trace_lane(config, lane, "")
        watchers.append(watch_lane(config, lane))

    lane = station.open_lane(on_open=listen)
    st.lane, st.profile = lane, profile
    (watcher,) = watchers
    _check_profile(config, lane, profile)
    watcher.begin()  # what the set-up provoked (the echo probe's answers, the profile check's) is no test's
    st.info.update(dut=config.getoption("dut"), lane=lane.name, clock=lane.clock, profile=profile.name,
                   bitrate=lane.bitrate, power=lane.power.name, timing_error_s=lane.timing_error,
                   jitter_s=profile.jitter_s, not_claimed=functions.not_claimed_text(profile.absent),
                   faults=config.getoption("emulator_faults") or "", **echo_info(lane))
    if config.getoption("dut") == "emulator":  # the conforming variant the emulator played, to replay a verdict
        st.info.update(emulator_variants=variants.describe(station.played),
                       emulator_variants_seed=config.getoption("emulator_variants"))
    if station.foreign is not None:  # said from the start: an aborted run's reports still say the bus was not quiet
        st.info["foreign_traffic"] = station.foreign.report()
    _install_signal_guard(config)
    opened = lane.now()
    yield lane
    st.info["lane_seconds"] = round(lane.now() - opened, 3)  # the whole run on the lane's clock (benchmarks/suite.py)
    try:
        if st.node_id is not None:
            Link(lane, profile, node_id=st.node_id).zero_throttle()
    except BenchGone:  # the run was aborted for it already (and says so): nothing reaches the DUT now
        pass
    finally:
        if isinstance(lane, BusLane):
            st.info["bus_recoveries"] = list(lane.recoveries)
        try:
            station.close_lane()
        finally:
            if station.foreign is not None:  # what the foreign traffic reached, once it stopped
                st.info["foreign_traffic"] = station.foreign.report()


def echo_info(lane: Lane) -> dict[str, Any]:
    """What the reports say about the host's own frames: whether the bench echoes them, and so which
    clock times them (results.json and JUnit carry these keys; summary.txt and report.html say them)."""
    return {"echo": lane.echo, "echo_note": lane.echo_note, "own_frames_clock": lane.own_clock,
            "own_frames_error_s": round(lane.own_error, 9)}


def _check_profile(config: pytest.Config, lane: Lane, profile: DutProfile) -> None:
    """The profile as a conformance statement, checked against the DUT before the first test with reads only
    (:mod:`ckesc.bench.statement`): a claim the DUT contradicts is a WARNING on the console and in the reports
    (``profile_warnings``), never a verdict. A DUT that does not answer is left to the ``dut`` fixture (it aborts)."""
    st = state(config)
    try:
        link = Link(lane, dataclasses.replace(profile, absent=()), node_id=config.getoption("node_id"))
        observed = statement.observe(link, full=False)
    except (DutError, BenchGone) as exc:
        st.info["profile_check"] = f"not made: {exc}"
        return
    st.info["profile_check"] = "; ".join(f"{name}: {seen.how}" for name, seen in observed.functions.items())
    st.info["profile_warnings"] = statement.contradictions(profile, observed, bus=config.getoption("dut") == "bus")


def _allow_spin(config: pytest.Config) -> bool:
    flag = config.getoption("allow_motor_spin")
    return bool(flag) if flag is not None else config.getoption("dut") == "emulator"


@pytest.fixture
def dut(request: pytest.FixtureRequest, ckesc_lane: Lane):
    """The device under test, with its settings snapshotted before and restored (and verified)
    after the test, and zero throttle on every exit path."""
    config = request.config
    st = state(config)
    profile = st.profile
    assert profile is not None
    check_claims(request.node, profile)
    if (lacks := lacking(request.node, profile)) is not None:
        pytest.skip(f"the DUT profile {profile.name!r} lacks capability '{lacks[1]}' ({lacks[0]})")
    if request.node.get_closest_marker("power_cycle") and not ckesc_lane.power.available:
        pytest.skip("needs a power cycle; no power control (--power none)")
    node = config.getoption("node_id") or st.node_id
    since = ckesc_lane.now()
    try:
        d = Dut(ckesc_lane, profile, node_id=node, allow_motor_spin=_allow_spin(config))
    except DutUnreachable as exc:
        _abort(config, f"the DUT did not answer: {exc}")
    if not config.stash.get(_READY, False):
        _await_ready(config, d, since)
    st.node_id = d.node_id
    st.info.setdefault("node_id", d.node_id)
    if "esc_information" not in st.info:
        ex = d.request("esc_information", {"option": 0})
        st.info["esc_information"] = ex.response.physical() if ex.response else None
    started = ckesc_lane.now()
    d.zero_throttle()
    snapshot = d.settings()
    request.node.stash[_DUT] = d
    try:
        yield d
    finally:
        d.lane_seconds = ckesc_lane.now() - started
        d.zero_throttle()
        if d.throttled:  # a motor still coasting refuses setting changes (R12): the next test must not meet it
            d.wait_motor_stopped()
        keep_segment(config, [f for f in d.trace if f.source == d.node_id])
        if d.node_id != st.node_id:
            st.node_id = d.node_id
        snapshot = restore_point(config, request.node.nodeid, snapshot)
        try:
            problems = d.restore(snapshot)
        except (DutError, Inconclusive) as exc:
            if not (st.stopped or "").startswith("interrupted"):
                raise
            # Ctrl-C / SIGTERM may have come while the DUT was switched off: the run ends INTERRUPTED (exit
            # 130, reports written), and says what was left undone instead of a traceback
            st.info.setdefault("not_restored", []).append({"test": request.node.nodeid, "why": str(exc)})
            return
        if problems:
            raise RuntimeError("settings could not be restored after the test: " + "; ".join(problems))


def keep_segment(config: pytest.Config, frames: list) -> None:
    """Keep one test's frames of the DUT for the run-wide checks (``dut_segments``), up to RUN_FRAMES_KEPT in
    the run; what is not kept is counted in the run's info (``run_frames_not_kept``), which the reports show."""
    st = state(config)
    room = RUN_FRAMES_KEPT - sum(len(s) for s in st.dut_segments)
    if len(frames) > room:
        st.info["run_frames_not_kept"] = st.info.get("run_frames_not_kept", 0) + len(frames) - max(room, 0)
        frames = frames[:max(room, 0)]
    st.dut_segments.append(frames)


class RunView:
    """What a conformance module may know of the run (the ``ckesc_run`` fixture): the lane and profile, the
    DUT's node id once known, the DUT's frames of the tests so far (one list per test), and a way to add its
    own frames to that record. Conformance modules reach the run through it, never the plugin's state."""

    def __init__(self, config: pytest.Config) -> None:
        self._config = config

    @property
    def lane(self) -> Lane | None:
        return state(self._config).lane

    @property
    def profile(self) -> DutProfile | None:
        return state(self._config).profile

    @property
    def node_id(self) -> int | None:
        """The DUT's node id: ``--node-id``, else the one discovered so far (None before)."""
        return self._config.getoption("node_id") or state(self._config).node_id

    @node_id.setter
    def node_id(self, node: int | None) -> None:
        state(self._config).node_id = node

    @property
    def segments(self) -> list[list]:
        return state(self._config).dut_segments

    def keep(self, frames: list) -> None:
        keep_segment(self._config, frames)


@pytest.fixture(scope="session")
def ckesc_run(request: pytest.FixtureRequest) -> RunView:
    """The run as a conformance module sees it (:class:`RunView`)."""
    return RunView(request.config)


@pytest.fixture
def multi_dut(request: pytest.FixtureRequest, ckesc_lane: Lane):
    """Several ESCs on one bus. With the emulator: a private bench of ``station.MULTI_NODES`` (the main
    DUT stays alone, as Set ID needs); on a real bus: the bus as it is (capability multi_node), with
    ``dut.nodes`` the node ids that answered GET_ESC_ID. Settings are not snapshotted: tests using it
    must change nothing persistent on a real bus."""
    config = request.config
    st = state(config)
    profile = st.profile
    assert profile is not None
    check_claims(request.node, profile)
    if config.getoption("dut") == "emulator":
        station = state(config).station
        assert station is not None
        lane = station.multi_lane(ckesc_lane.timing_error)
        trace_lane(config, lane, "bench")
        watch_lane(config, lane)
        own = True
    else:
        if not profile.has("multi_node"):
            pytest.skip(f"the DUT profile {profile.name!r} lacks capability 'multi_node' (several ESCs on the bus)")
        lane, own = ckesc_lane, False
    since = lane.now()
    d = Dut(lane, profile, node_id=None, allow_motor_spin=_allow_spin(config))  # discovery lists every ESC
    d.await_reports(since, since + d.ready_bound_s())  # no test starts before the (first) ESC reports
    request.node.stash[_DUT] = d
    try:
        yield d
    finally:
        d.zero_throttle()
        keep_segment(config, [f for f in d.trace if f.source != d.host_node])
        if own:
            lane.close()


@pytest.fixture
def record(dut: Dut):
    """The current test's measurement record (same as ``dut.record``)."""
    return dut.record


def _await_ready(config: pytest.Config, d: Dut, since: float) -> None:
    """No test starts before the DUT reports: after discovery, wait for its first MSG1..MSG3 (at most
    Dut.ready_bound_s from ``since``, the profile's boot time on top of one longest report interval). A
    DUT that answers but does not report is sent MSG Control 0xAAAAAAAA once (an earlier run may have left
    it suspended); if it still sends nothing the run is aborted: every report test would fail for it."""
    st = state(config)
    heard = d.await_reports(since, since + d.ready_bound_s())
    if not heard:
        d.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
        t = d.now()
        heard = d.await_reports(t, t + d.ready_bound_s(0.0))
        st.info["readiness"] = ("reported only after MSG Control 0xAAAAAAAA (an earlier run left it suspended?)" if heard
                                else "no report")
    if not heard:
        _abort(config, f"node {d.node_id} answers but sent no report (MSG1..MSG3, MSG_EXP, CAN Test) within "
                       f"{d.ready_bound_s():.2f} s of discovery (the profile's boot_s {d.profile.boot_s} s and one longest "
                       "report interval), nor after MSG Control 0xAAAAAAAA: is it in CAN Test mode or suspended? "
                       "Power-cycle it, or raise [timing] boot_s in its profile")
    config.stash[_READY] = True
    st.info["first_reports_s"] = {name: round(t - since, 4) for name, t in sorted(heard.items())}


def _abort(config: pytest.Config, why: str) -> None:
    """Stop the run now: no further test can reach the DUT. The reports say ABORTED with ``why`` and
    list every test not run; the exit status is :attr:`~ckesc.reporting.exits.ExitStatus.ABORTED`."""
    state(config).stopped = f"aborted: {why}"
    pytest.exit(f"ABORTED: {why}", returncode=ExitStatus.ABORTED)


def _install_signal_guard(config: pytest.Config) -> None:
    """Ctrl-C / SIGTERM: stop throttle before anything else happens, then stop the run (pytest
    tears the fixtures down, zero throttle again, and the reports say INTERRUPTED).

    Only the first signal stops the run. A later one (a second Ctrl-C, or a batch worker's second SIGINT: its
    terminal's process group and then the batch controller) zeroes the throttle again and lets the teardown
    that is under way finish: raising again would cut a fixture's teardown before its own zero throttle and
    its settings restore."""

    signals: list[int] = []

    def handler(signum, frame):  # noqa: ARG001
        st = state(config)
        first = not signals
        signals.append(signum)
        st.stopped = st.stopped or f"interrupted ({signal.Signals(signum).name})"
        zero_throttle_now(config)  # no read here: the test's trace gets the zero as the test unwinds (tracing)
        if first and st.shield.depth:  # a trace file being written out: raised when it is (state.Shield)
            st.shield.held = True
        elif first:
            raise KeyboardInterrupt
        print(f"ckesc: {signal.Signals(signum).name} again: zero throttle sent; finishing the teardown (settings "
              "restore) and the reports (kill -9 abandons them)", file=sys.stderr, flush=True)

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(sig, handler)
        except ValueError:  # not the main thread
            pass
