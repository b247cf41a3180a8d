"""The pytest plugin (entry point ``pytest11``): DUT selection, lanes, the ``dut`` fixture, the
``requirement`` marker, verdicts, and the run's reports.

It stays inert in a pytest run that collects no conformance test (the project's own tests): the
options exist, but nothing is opened and no report is written.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from ..bench.dut import Dut, DutError, DutUnreachable, echo_probe
from ..bench.epochs import PowerEpoch, unusable
from ..bench.errors import PreflightError
from ..bench.lanes import HOST_SEND_ERROR_S, BenchGone, BusFault, BusLane, Lane, SimLane
from ..bench.power import PowerControl, open_power
from ..bench.power import names as power_names
from ..bench.profile import DutProfile
from ..bench.realtime_lane import RealtimeEmulatorLane
from ..bench.verdict import Inconclusive, NotClaimed
from ..emulator import variants
from ..evidence.live import LaneRules, causes, failure_text
from ..evidence.timing import evidence
from ..protocol import catalogue as cat
from ..protocol import functions
from ..protocol.requirements import REQUIREMENTS, requirement, section_heading, strongest
from ..reporting import report as _report
from ..reporting.causes import broken_outside_a_fail
from ..reporting.results import Result
from . import preflight
from .progress import ProgressReporter
from .schedule import LEAD_S, Plan
from .traces import TRACE_FORMATS, TestTraces

CONFORMANCE_PACKAGE = "conformance"

#: exit status of a run aborted because the DUT did not answer or the bench went away (pytest's own
#: statuses are 0-5; ``ckesc run`` passes this one on)
EXIT_ABORTED = 3
#: a DUT that did not send one frame in this many tests in a row, each of which ERRORed, has stopped
#: answering: the run is aborted rather than every remaining test ERRORing the same way
SILENT_TESTS_TO_ABORT = 3


# ----------------------------------------------------------------------------------------- options
def pytest_addoption(parser: pytest.Parser) -> None:
    g = parser.getgroup("ckesc", "CKESC conformance: device under test")
    g.addoption("--dut", choices=("emulator", "bus"), default="emulator",
                help="emulator (default): the ckesc emulator; bus: a device on a python-can bus")
    g.addoption("--lane", choices=("simulated", "realtime"), default="simulated",
                help="for --dut emulator: simulated time (default, exact) or `ckesc emulate` in its own process "
                     "through socketcand (real time)")
    g.addoption("--can-interface", help="python-can interface for --dut bus (else can.conf / CAN_INTERFACE)")
    g.addoption("--can-channel", help="python-can channel, e.g. can0 (else can.conf / CAN_CHANNEL)")
    g.addoption("--can-bitrate", type=int, help="bit rate of the host's bus (else can.conf / CAN_BITRATE)")
    g.addoption("--can-config", action="append", default=[], metavar="KEY=VALUE",
                help="extra python-can bus argument (repeatable)")
    g.addoption("--can-bitrate-cmd", metavar="CMD",
                help="--dut bus: command that moves the bus to another bit rate when a test needs it (Set Baud); "
                     "{bitrate} is replaced. python-can cannot set a SocketCAN bit rate: e.g. a script running "
                     "`ip link set can0 down; ip link set can0 type can bitrate {bitrate}; ip link set can0 up`, or "
                     "`ckesc control --port P bitrate {bitrate}` for the emulator on vcan0")
    g.addoption("--host-send-error", type=float, default=HOST_SEND_ERROR_S * 1000, metavar="MS",
                help="--dut bus, an adapter that does not echo the host's frames: how much later than the host clock "
                     "at send a frame may reach the bus (driver, USB, TX queue), in ms; the error of every time taken "
                     f"from the host's own frames (default {HOST_SEND_ERROR_S * 1000:g})")
    g.addoption("--node-id", type=int, help="the DUT's node id (default: discovered with GET_ESC_ID)")
    g.addoption("--nodes", help="emulator: node ids of the emulated bench (default 1); the DUT is the first")
    g.addoption("--profile", help="DUT profile: a shipped one by name (emulator, ckesc-generic, vcan-vm), a name in ./fixtures/duts, or a path (default: emulator / ckesc-generic)")
    g.addoption("--power", choices=power_names(),
                help="power control (default: emulator for --dut emulator, none for --dut bus)")
    g.addoption("--power-off-cmd", help="--power command: shell command that switches the DUT off")
    g.addoption("--power-on-cmd", help="--power command: shell command that switches the DUT on")
    g.addoption("--labgrid-env", metavar="FILE",
                help="--power labgrid: labgrid environment file whose target has a power driver (PowerProtocol)")
    g.addoption("--labgrid-target", metavar="NAME", help="--power labgrid: the target in --labgrid-env (default: its only one)")
    g.addoption("--labgrid-place", metavar="NAME",
                help="--power labgrid: acquire this labgrid place for the run (default: the target's RemotePlace, if any)")
    g.addoption("--labgrid-coordinator", metavar="HOST:PORT",
                help="--power labgrid: the labgrid coordinator (default: the env file's coordinator_address, "
                     "LG_COORDINATOR, 127.0.0.1:20408)")
    g.addoption("--allow-motor-spin", action="store_true", default=None,
                help="allow non-zero throttle (default: only for the emulator). PROPELLERS OFF.")
    g.addoption("--emulator-faults", default="", help="emulator: comma-separated fault names to switch on")
    g.addoption("--emulator-seed", type=int, default=0, help="emulator: random seed")
    g.addoption("--emulator-option", action="append", default=[], metavar="NAME=VALUE",
                help="emulator: one conforming variant for every emulated ESC (repeatable; the names, values and the "
                     "requirements that allow each: ckesc emulate --list-variants): " + ", ".join(variants.FREEDOMS))
    g.addoption("--emulator-variants", type=int, default=None, metavar="SEED",
                help="emulator: every emulated ESC plays the conforming combination drawn from SEED (--emulator-option "
                     "wins over the draw); the run's reports name the combination")
    g.addoption("--ckesc-reports", default=None, metavar="DIR",
                help="write JUnit, JSON and text reports under DIR/<timestamp>/ (ckesc run sets reports/)")
    g.addoption("--ckesc-summary", action="store_true", default=False,
                help="print the per-section summary at the end (ckesc run sets it)")
    g.addoption("--ckesc-no-html", action="store_true", default=False,
                help="with --ckesc-reports: no report.html (machine readers only, e.g. ckesc selftest's runs)")
    g.addoption("--ckesc-trace-format", choices=TRACE_FORMATS, default="blf",
                help="with --ckesc-reports: each test's CAN traffic in <run>/traces/, written by python-can: blf "
                     "(default; Vector BLF), asc (Vector ASCII), log (candump -L, `ckesc decode` reads it), none")
    g.addoption("--ckesc-durations", default=None, metavar="RESULTS_JSON",
                help="time left: expect each test to take the lane time it took in this earlier run (its results.json; "
                     "default: the suite's own table of a faultless simulated run, conformance/durations.json)")
    g.addoption("--ckesc-progress", choices=("on", "off"), default="on",
                help="a line per section with the protocol time planned, elapsed and an estimate of what is left "
                     "(on a terminal also after pytest's counter); off: none")
    g.addoption("--ckesc-order", choices=("overlap", "collection"), default="overlap",
                help="overlap (default): tests that neither power-cycle nor reconfigure the DUT run while a 120 s "
                     "Set ID / Set Baud window elapses, and each window test runs at its moment; collection: "
                     "every test in collection order, each window test sitting its window out")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "requirement(*ids): the requirement ids (requirements.toml) a test checks")
    config.addinivalue_line("markers", "power_cycle: the test cycles the DUT's power")
    config.addinivalue_line("markers", "spins_motor: the test commands non-zero throttle")
    config.addinivalue_line("markers", "last: run after every other conformance test (run-wide checks)")
    config.addinivalue_line("markers", "may_power_cycle: on some benches the test power-cycles or sends Set ID (e.g. "
                            "answer slots on a coarse bench): never run while a Set ID / Set Baud window elapses")
    config.addinivalue_line("markers", "cold_boot(write, touches=setting): needs a cold boot between write(dut, "
                            "**params) and its read (cold_boot fixture); the run order may share one power cycle")
    config.addinivalue_line("markers", "window(kind): acts at a moment of the 120 s Set ID / Set Baud window "
                            "(kind 'inside' or 'after'; the run order overlaps the window with other tests)")
    config.stash[_STATE] = _State()
    _print_ids_as_reported(config)
    st = config.stash[_STATE]
    config.pluginmanager.register(ProgressReporter(config, lambda: st.lane.peek_now() if st.lane is not None else None,
                                                   _section_title, _is_conformance), "ckesc-progress")


def _print_ids_as_reported(config: pytest.Config) -> None:
    """The console names a conformance test by its id as the reports write it (``conformance/test_...``), from
    any directory and any install: pytest would print it relative to the directory it was started in
    (``../../site-packages/conformance/...`` from elsewhere, or against an editable install)."""
    relative = config.cwd_relative_nodeid

    def as_reported(nodeid):
        return nodeid if str(nodeid).startswith("conformance/") else relative(nodeid)  # a str, or pytest 9.2+'s NodeId

    config.cwd_relative_nodeid = as_reported  # type: ignore[method-assign]


@dataclass
class _State:
    results: dict[str, Result] = field(default_factory=dict)
    conformance: bool = False
    lane: Lane | None = None
    profile: DutProfile | None = None
    node_id: int | None = None
    #: every frame the DUT sent in the run (4.1 checks), one list per test: frames between two tests
    #: (restoring settings, other fixtures) are in none, so only frames of one list are known adjacent
    dut_segments: list[list] = field(default_factory=list)
    started: float = field(default_factory=time.time)
    info: dict[str, Any] = field(default_factory=dict)
    report_dir: Path | None = None  # reports/<run>/, made at the first test that writes into it
    traces: TestTraces | None = None  # the per-test trace writer, on every lane the plugin opens
    bus_rules: list[LaneRules] = field(default_factory=list)  # the bus rules on every lane the plugin opens
    preflight_done: bool = False
    #: the run's tests as collected (after -k / -m deselection), and what deselection left out
    selected: list[pytest.Item] = field(default_factory=list)
    deselected: list[str] = field(default_factory=list)
    #: why the run stopped early: "aborted: ..." (the DUT did not answer, the bench went away) or
    #: "interrupted" (Ctrl-C, SIGTERM); None while it runs or when it ran to its end
    stopped: str | None = None
    silent_errors: int = 0  # tests in a row that ERRORed without a frame from the DUT
    ready: bool = False  # the DUT has been seen reporting (no test starts before: _await_ready)
    cold_boots: dict[str, Any] = field(default_factory=dict)  # test id -> its shared power cycle (_ColdBoot)


_STATE = pytest.StashKey[_State]()


def state(config: pytest.Config) -> _State:
    return config.stash[_STATE]


# ----------------------------------------------------------------------------------------- collection
def _is_conformance(item: pytest.Item) -> bool:
    mod = getattr(item, "module", None)
    return mod is not None and (mod.__name__.split(".")[0] == CONFORMANCE_PACKAGE)


def item_requirements(item: pytest.Item) -> list[str]:
    ids: list[str] = []
    for m in item.iter_markers("requirement"):
        ids.extend(m.args)
    return list(dict.fromkeys(ids))


def conformance_dir() -> Path | None:
    """The installed ``conformance`` package's directory (a checkout, or site-packages of a wheel)."""
    spec = importlib.util.find_spec(CONFORMANCE_PACKAGE)
    locations = list(spec.submodule_search_locations or []) if spec else []
    return Path(locations[0]).resolve() if locations else None


def targets_conformance(config: pytest.Config) -> bool:
    """Whether the command line names the conformance suites (``--pyargs conformance[.module]``, or a
    path inside the package), so that set-up mistakes are found before pytest even collects."""
    where = conformance_dir()
    for arg in config.args:
        head = arg.split("::")[0]
        if config.option.pyargs and head.split(".")[0] == CONFORMANCE_PACKAGE:
            return True
        path = Path(head).resolve()
        if where is not None and (path == where or where in path.parents):
            return True
    return False


def _preflight(config: pytest.Config) -> None:
    st = state(config)
    if st.preflight_done:
        return
    st.preflight_done = True
    try:
        st.profile = preflight.run(config.getoption, bus_kwargs=lambda: _bus_kwargs(config),
                                   labgrid=lambda: _open_labgrid(config))
    except preflight.PreflightError as exc:
        raise pytest.UsageError(f"preflight: {exc}") from None


_LABGRID = pytest.StashKey[PowerControl]()


def _open_labgrid(config: pytest.Config) -> None:
    """--power labgrid: its driver (and place, acquired), released by pytest's cleanup on every way out."""
    power = open_power("labgrid", config.getoption, _prompt(config))
    config.add_cleanup(power.close)
    config.stash[_LABGRID] = power
    state(config).info["power_labgrid"] = power.where


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    """Set-up mistakes end the run here, before pytest's header, collection or any report."""
    if targets_conformance(session.config):
        _preflight(session.config)


def pytest_deselected(items: list[pytest.Item]) -> None:
    if items:
        st = state(items[0].config)
        st.deselected += [it.nodeid for it in items if _is_conformance(it)]


def pytest_collection_finish(session: pytest.Session) -> None:
    st = state(session.config)
    st.selected = [it for it in session.items if _is_conformance(it)]
    if st.selected:
        _preflight(session.config)  # collected from a path the command line did not name as the suites


def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config, items: list[pytest.Item]) -> None:
    st = state(config)
    problems = []
    for item in items:
        if not _is_conformance(item):
            continue
        st.conformance = True
        ids = item_requirements(item)
        if not ids:
            problems.append(f"{item.nodeid}: no @pytest.mark.requirement(...)")
        for i in ids:
            if i not in REQUIREMENTS:
                problems.append(f"{item.nodeid}: unknown requirement id {i!r}")
    if problems:
        raise pytest.UsageError("conformance tests must cite known requirements:\n  " + "\n  ".join(problems))
    # run-wide checks (4.1 framing over every frame of the run) go last
    items.sort(key=lambda it: 1 if it.get_closest_marker("last") else 0)


# ----------------------------------------------------------------------------------------- run order
def _kind(item: pytest.Item) -> str:
    """How the run-order plan (schedule.py) treats a test."""
    if not _is_conformance(item):
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
    return PlanRunner(st, plan)


class PlanRunner:
    """Runs the plan one test at a time, for pytest's loop (the plugin's) or anyone else's (a batch's xdist
    worker, ``batch.py``): :meth:`before` a test (stages a shared cold boot; returns what pytest is to be told
    comes next), then the test's protocol, then :meth:`after` (learns its time, chooses the next test, opens a
    window when one is due)."""

    def __init__(self, st: _State, plan: Plan) -> None:
        self.st, self.plan = st, plan
        self.start: float | None = None
        self.hint: pytest.Item | None = None
        self.epoch: PowerEpoch | None = None

    def first(self) -> pytest.Item | None:
        return self.plan.first()

    def before(self, item: pytest.Item) -> pytest.Item | None:
        st, plan = self.st, self.plan
        lane = st.lane
        if (group := plan.group_of(item)) is not None:
            _stage(st, group)
        self.start = lane.now() if lane is not None else None
        if self.start is not None:
            self.hint = plan.hint(item, self.start + plan.estimates.get(_function_key(item)), _moment(st, plan))
        else:
            self.hint = plan.hint(item, None, None)
        self.epoch = lane.epoch if lane is not None else None
        return self.hint

    def after(self, item: pytest.Item) -> pytest.Item | None:
        st, plan, hint = self.st, self.plan, self.hint
        lane = st.lane
        if lane is None or hint is None:
            return plan.choose(0.0, lambda w, now: float("inf"), _shares(item, hint)) if hint is not None else None
        now = lane.now()
        if self.start is not None:
            plan.learn(item, now - self.start)
        if lane.epoch is not None and lane.epoch is not self.epoch and not lane.epoch.opened_by:
            lane.epoch.opened_by = item.nodeid
        nxt = plan.choose(now, _moment(st, plan), _shares(item, hint))
        if nxt is not None and plan.needs_epoch_before(nxt):
            _open_epoch(st, plan)
        return nxt


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


# ----------------------------------------------------------------------------------------- shared cold boots
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


def _params(item: pytest.Item) -> dict[str, Any]:
    callspec = getattr(item, "callspec", None)
    return dict(callspec.params) if callspec is not None else {}


def _stage(st: _State, group: list[pytest.Item]) -> None:
    """Each test's write, in collection order, each in its own trace file and record, then one proven power cycle
    (its own trace). The tests then run one after another, each reading back its own (``cold_boot``); a group that
    cannot be staged (no lane yet, a failed power cycle) is simply not shared: its tests run alone."""
    lane, profile = st.lane, st.profile
    if lane is None or profile is None or st.node_id is None or not lane.power.available:
        return
    if any(_lacking(it, profile) for it in group):
        return  # one would be skipped: nothing of it may run first
    name = f"shared power cycle {len(st.info.setdefault('cold_boots', [])) + 1}"
    traces = st.traces
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
    boot.epoch = _traced_power_cycle(st, name, entry)
    boot.power_up = entry.get("power_up", "")
    for it in group:
        st.cold_boots[it.nodeid] = boot


@pytest.fixture
def cold_boot(request: pytest.FixtureRequest, dut: Dut):
    """``cold_boot()`` in a ``@pytest.mark.cold_boot(write, touches=...)`` test: ``write(dut, **params)`` has been
    made and then a proven power cycle; returns what ``write`` returned (and raises what it raised). When the run
    order staged the test (schedule.py) its write was made before a power cycle shared with other tests' writes
    (each touching another setting), its observations and trace are the test's own, and the cycle is said; else
    the write and a proven power cycle are made now, as a test alone does."""
    item = request.node
    st = state(request.config)

    def boot() -> Any:
        group = st.cold_boots.get(item.nodeid)
        if group is not None and not group.dissolved and group.epoch is not None and dut.lane.epoch is group.epoch:
            written = group.written[item.nodeid]
            written.used = True
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
        st = state(pyfuncitem.config)
        group = st.cold_boots.get(pyfuncitem.nodeid)
        if group is None or not group.written[pyfuncitem.nodeid].used or group.dissolved:
            raise
        group.dissolved = True
        d: Dut = pyfuncitem.funcargs["dut"]
        d.record.observe("after the shared power cycle", f"{type(exc).__name__}: {str(exc)[:300]}; run again alone")
        d.restore(group.before)
        return pyfuncitem.ihook.pytest_pyfunc_call(pyfuncitem=pyfuncitem)


def _moment(st: _State, plan: Plan):
    """``moment(w, end)`` for the plan: when window test ``w`` acts if the test before it ends at ``end``."""
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


def _open_epoch(st: _State, plan: Plan) -> None:
    """Open a 120 s window with a proven power cycle between two tests, unless the current one still
    serves the next window test. A failure here is recorded, not raised: the window test then opens its own
    window (and meets the problem as its own)."""
    lane, profile = st.lane, st.profile
    w = plan.pending_window()
    if lane is None or profile is None or st.node_id is None or w is None or not lane.power.available:
        return
    if unusable(lane.epoch, plan.window_kind(w), now=lane.now(), node_id=st.node_id, bitrate=lane.bitrate,
                lead=LEAD_S) is None:
        return
    name = f"power-up epoch {len(st.info['epochs']) + 1}"
    entry: dict[str, Any] = {"name": name, "for": w.nodeid, "at": round(lane.now(), 3)}
    st.info["epochs"].append(entry)
    _traced_power_cycle(st, name, entry)


def _traced_power_cycle(st: _State, name: str, entry: dict[str, Any]) -> PowerEpoch | None:
    """A proven power cycle between two tests, in a trace of its own named ``name``; ``entry`` (the run's record of
    it) gets its trace files and the power-up, or the error: that is recorded, not raised (the tests that were to
    use the power-up meet the problem as their own). Returns the power-up's epoch, None when it failed."""
    lane, profile, traces = st.lane, st.profile, st.traces
    assert lane is not None and profile is not None
    if traces is not None:
        traces.begin(name)
    try:
        Dut(lane, profile, node_id=st.node_id).power_cycle(profile.off_s, profile.boot_s)
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


# ----------------------------------------------------------------------------------------- lane / dut
def _bus_kwargs(config: pytest.Config) -> dict[str, Any]:
    import can

    kwargs: dict[str, Any] = {}
    if config.getoption("can_interface"):
        kwargs["interface"] = config.getoption("can_interface")
    if config.getoption("can_channel"):
        kwargs["channel"] = config.getoption("can_channel")
    if config.getoption("can_bitrate"):
        kwargs["bitrate"] = config.getoption("can_bitrate")
    for kv in config.getoption("can_config"):
        key, sep, value = kv.partition("=")
        if not sep:
            raise preflight.PreflightError(f"--can-config takes KEY=VALUE, got {kv!r}")
        kwargs[key] = can.util.cast_from_string(value)
    try:
        resolved = can.util.load_config(config=kwargs)  # explicit options, then CAN_* and can.conf
    except (can.CanInterfaceNotImplementedError, ValueError, TypeError) as exc:
        raise preflight.PreflightError(f"the CAN bus configuration {kwargs}: {exc} (known interfaces: "
                                       f"{', '.join(sorted(can.interfaces.VALID_INTERFACES))})") from None
    if not resolved.get("interface"):
        raise preflight.PreflightError("--dut bus needs --can-interface (or CAN_INTERFACE / can.conf)")
    return dict(resolved)


def _prompt(config: pytest.Config):
    def ask(text: str) -> None:
        capman = config.pluginmanager.getplugin("capturemanager")
        with capman.global_and_fixture_disabled() if capman else _null():
            input(f"\n>>> {text} ")

    return ask


class _null:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def emulator_options(config: pytest.Config) -> dict[str, Any]:
    """The conforming variant the emulated ESCs play: --emulator-variants SEED's draw with --emulator-option
    NAME=VALUE on top, checked (preflight): {EscConfig field: value}."""
    return preflight.emulator_options(config.getoption("emulator_option"), config.getoption("emulator_variants"))


def emulator_faults(config: pytest.Config) -> list[str]:
    return preflight.fault_names(config.getoption("emulator_faults"))


def make_lane(config: pytest.Config, profile: DutProfile) -> Lane:
    dut_kind = config.getoption("dut")
    faults = emulator_faults(config)
    nodes = preflight.node_list(config.getoption("nodes") or "1")
    options = emulator_options(config)
    if dut_kind == "emulator":
        if config.getoption("lane") == "realtime":
            return RealtimeEmulatorLane(nodes=nodes, faults=faults, temp_flash=True, esc_options=options,
                                        seed=config.getoption("emulator_seed"), timing_error=max(profile.error_s, 0.002))
        # in one process the emulated ESCs keep their flash contents across power cycles: no file needed
        lane = SimLane(nodes=nodes, faults=faults, seed=config.getoption("emulator_seed"),
                       esc_config={"boot_time": 0.25, **options})
        # exact timestamps; a profile may still state a bench's error (0 for the emulator's own): margins below it
        # are then INCONCLUSIVE as on that bench, e.g. to see what a 2 ms bench can tell
        lane.timing_error = profile.error_s
        return lane
    power_kind = config.getoption("power") or "none"
    if power_kind == "labgrid":
        power = config.stash[_LABGRID]  # opened by the preflight
    else:
        try:
            power = open_power(power_kind, config.getoption, _prompt(config))
        except PreflightError as exc:
            raise pytest.UsageError(str(exc)) from None
    return BusLane(_bus_kwargs(config), power, timing_error=profile.error_s, bitrate_cmd=config.getoption("can_bitrate_cmd"),
                   host_send_error=config.getoption("host_send_error") / 1000)


@pytest.fixture(scope="session")
def ckesc_lane(request: pytest.FixtureRequest):
    config = request.config
    st = state(config)
    profile = st.profile or preflight.profile(config.getoption)  # loaded by the preflight, before any test
    played = emulator_options(config) if config.getoption("dut") == "emulator" else {}
    for key, value in variants.declared(played).items():  # what the emulated ESC's vendor would state in its profile
        if value > getattr(profile, key):
            profile = dataclasses.replace(profile, **{key: value})
    lane = make_lane(config, profile)
    st.lane, st.profile = lane, profile
    _trace_lane(config, lane, "")
    _watch_lane(config, lane)
    if isinstance(lane, BusLane):  # do the host's own frames come back? (the frames it reads go to the listeners)
        lane.find_echo(echo_probe(nibble_order=profile.nibble_order))
    st.info.update(dut=config.getoption("dut"), lane=lane.name, clock=lane.clock, profile=profile.name,
                   bitrate=lane.bitrate, power=lane.power.name, timing_error_s=lane.timing_error,
                   jitter_s=profile.jitter_s, not_claimed=functions.not_claimed_text(profile.absent),
                   faults=config.getoption("emulator_faults") or "", **echo_info(lane))
    if config.getoption("dut") == "emulator":  # the conforming variant the emulator played, to replay a verdict
        st.info.update(emulator_variants=variants.describe(played), emulator_variants_seed=config.getoption("emulator_variants"))
    _install_signal_guard(config)
    opened = lane.now()
    yield lane
    st.info["lane_seconds"] = round(lane.now() - opened, 3)  # the whole run on the lane's clock (bench_suite.py)
    try:
        if st.node_id is not None:
            Dut(lane, profile, node_id=st.node_id).zero_throttle()
    except BenchGone:  # the run was aborted for it already (and says so): nothing reaches the DUT now
        pass
    finally:
        if isinstance(lane, BusLane):
            st.info["bus_recoveries"] = list(lane.recoveries)
        lane.close()


def echo_info(lane: Lane) -> dict[str, Any]:
    """What the reports say about the host's own frames: whether the bench echoes them, and so which
    clock times them (results.json and JUnit carry these keys; summary.txt and report.html say them)."""
    return {"echo": lane.echo, "echo_note": lane.echo_note, "own_frames_clock": lane.own_clock,
            "own_frames_error_s": round(lane.own_error, 9)}


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
    _check_claims(request.node, profile)
    if (lacks := _lacking(request.node, profile)) is not None:
        pytest.skip(f"the DUT profile {profile.name!r} lacks capability '{lacks[1]}' ({lacks[0]})")
    if request.node.get_closest_marker("power_cycle") and not ckesc_lane.power.available:
        pytest.skip("needs a power cycle; no power control (--power none)")
    node = config.getoption("node_id") or st.node_id
    since = ckesc_lane.now()
    try:
        d = Dut(ckesc_lane, profile, node_id=node, allow_motor_spin=_allow_spin(config))
    except DutUnreachable as exc:
        _abort(config, f"the DUT did not answer: {exc}")
    if not st.ready:
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
        group = st.cold_boots.get(request.node.nodeid)
        if group is not None and (group.dissolved or group.members[-1] == request.node.nodeid):
            snapshot = group.before  # the group's writes are put back after its last test (or once it broke up)
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


_DUT = pytest.StashKey[Dut]()


def _lacking(item: pytest.Item, profile: DutProfile) -> tuple[str, str] | None:
    """(requirement id, capability) of the first requirement ``item`` cites whose capability the profile lacks."""
    for rid in item_requirements(item):
        cap = requirement(rid).capability
        if cap and not profile.has(cap):
            return rid, cap
    return None


def _check_claims(item: pytest.Item, profile: DutProfile) -> None:
    """A test of a function the profile declares absent is SKIPPED before it starts: not claimed (R9b)."""
    absent = functions.of_requirements(item_requirements(item), profile.absent)
    if absent:
        raise NotClaimed(absent[0].name, profile.name)


#: Frames kept across the run for the run-wide checks (4.1): a whole suite in real time is ~70,000; a
#: DUT that floods the bus must not grow memory without bound
RUN_FRAMES_KEPT = 150_000


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


#: The private bench of :func:`multi_dut` in the emulator lanes: node ids chosen so that
#: node_id % 32 covers 1, 2 and wraps (33 -> slot 1).
MULTI_NODES = (1, 2, 33)


@pytest.fixture
def multi_dut(request: pytest.FixtureRequest, ckesc_lane: Lane):
    """Several ESCs on one bus. With the emulator: a private bench of :data:`MULTI_NODES` (the main
    DUT stays alone, as Set ID needs); on a real bus: the bus as it is (capability multi_node), with
    ``dut.nodes`` the node ids that answered GET_ESC_ID. Settings are not snapshotted: tests using it
    must change nothing persistent on a real bus."""
    config = request.config
    st = state(config)
    profile = st.profile
    assert profile is not None
    _check_claims(request.node, profile)
    if config.getoption("dut") == "emulator":
        if config.getoption("lane") == "realtime":
            lane: Lane = RealtimeEmulatorLane(nodes=MULTI_NODES, timing_error=ckesc_lane.timing_error,
                                              esc_options=emulator_options(config))
        else:
            lane = SimLane(nodes=MULTI_NODES, faults=emulator_faults(config), seed=config.getoption("emulator_seed"),
                           esc_config={"boot_time": 0.25, **emulator_options(config)})
            lane.timing_error = ckesc_lane.timing_error  # the profile's stated error, as on the DUT's lane
        _trace_lane(config, lane, "bench")
        _watch_lane(config, lane)
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
    st.ready = True
    st.info["first_reports_s"] = {name: round(t - since, 4) for name, t in sorted(heard.items())}


def _abort(config: pytest.Config, why: str) -> None:
    """Stop the run now: no further test can reach the DUT. The reports say ABORTED with ``why`` and
    list every test not run; the exit status is :data:`EXIT_ABORTED`."""
    state(config).stopped = f"aborted: {why}"
    pytest.exit(f"ABORTED: {why}", returncode=EXIT_ABORTED)


def _install_signal_guard(config: pytest.Config) -> None:
    """Ctrl-C / SIGTERM: stop throttle before anything else happens, then stop the run (pytest
    tears the fixtures down, zero throttle again, and the reports say INTERRUPTED)."""

    def handler(signum, frame):  # noqa: ARG001
        st = state(config)
        st.stopped = st.stopped or f"interrupted ({signal.Signals(signum).name})"
        if st.lane is not None and st.profile is not None and st.node_id is not None:
            try:
                Dut(st.lane, st.profile, node_id=st.node_id).zero_throttle()
            except Exception:  # noqa: BLE001 - best effort on the way out
                pass
        raise KeyboardInterrupt

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(sig, handler)
        except ValueError:  # not the main thread
            pass


# ----------------------------------------------------------------------------------------- traces
def report_dir(config: pytest.Config) -> Path | None:
    """This run's report directory (made on first use), or None without --ckesc-reports."""
    st = state(config)
    base = config.getoption("ckesc_reports")
    if st.report_dir is None and base:
        st.report_dir = _report.run_dir(Path(base), st.started)
    return st.report_dir


def _traces(config: pytest.Config) -> TestTraces | None:
    st = state(config)
    if st.traces is None and config.getoption("ckesc_trace_format") != "none" and (out := report_dir(config)):
        st.traces = TestTraces(out / "traces", config.getoption("ckesc_trace_format"))
    return st.traces


def _trace_lane(config: pytest.Config, lane: Lane, name: str) -> None:
    traces = state(config).traces
    if traces is not None:
        lane.listeners.append(traces.listener(name))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    """A conformance test's trace spans its setup, call and teardown; it is closed on every way out
    (failure, timeout, Ctrl-C)."""
    traces = _traces(item.config) if _is_conformance(item) else None
    if traces is None:
        return (yield)
    traces.begin(item.nodeid)
    try:
        return (yield)
    finally:
        paths = traces.end_relative()
        st = state(item.config)
        res = st.results.get(item.nodeid)
        if res is not None:
            res.traces = dict(paths)
            group = st.cold_boots.get(item.nodeid)
            if group is not None and group.written[item.nodeid].used:  # its write, made before the shared cycle
                res.traces.update(group.written[item.nodeid].traces)


# ----------------------------------------------------------------------------------------- bus rules
_BUS_RULES = pytest.StashKey[list]()  # requirement ids of the bus rules broken while the test ran
_BUS_CAUSES = pytest.StashKey[list]()  # the distinct problems among them (evidence.live.causes)
_BUS_TEARDOWN = pytest.StashKey[bool]()  # the bus rules failed the test at teardown (a FAIL, not an ERROR)


def _watch_lane(config: pytest.Config, lane: Lane) -> None:
    """The bus rules that hold at all times (ckesc/evidence/rules.py) over every frame the lane reads."""
    profile = state(config).profile
    watcher = LaneRules(lane, jitter=profile.jitter_s if profile is not None else 0.0)
    lane.listeners.append(watcher)
    state(config).bus_rules.append(watcher)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    if _is_conformance(item):
        st = state(item.config)
        st.bus_rules = [w for w in st.bus_rules if not w.closed]  # multi_dut's private benches are gone
        for watcher in st.bus_rules:
            watcher.begin()


def _bus_rules_verdict(item: pytest.Item, rep: pytest.TestReport) -> None:
    """A test during which the bus broke a rule fails, whatever its own verdict, with the frames quoted; but
    a test SKIPPED (not claimed, R9b; a capability the profile lacks) is not run, so not judged: it stays
    SKIPPED and keeps the rules it saw, which are the rules' failure (causes.rule_failures), and fail the run."""
    if rep.when not in ("call", "teardown"):
        return
    found, count = [], 0
    for watcher in state(item.config).bus_rules:
        f, c = watcher.take()
        found, count = found + f, count + c
    if not count:
        return
    text, ids = failure_text(found, count)
    item.stash[_BUS_RULES] = list(dict.fromkeys(item.stash.get(_BUS_RULES, []) + ids))
    known = {c["key"]: c for c in item.stash.get(_BUS_CAUSES, [])}
    for c in causes(found):
        if c["key"] in known:
            known[c["key"]]["count"] += c["count"]
            known[c["key"]]["rules"] = list(dict.fromkeys(known[c["key"]]["rules"] + c["rules"]))
        else:
            known[c["key"]] = c
    item.stash[_BUS_CAUSES] = list(known.values())
    if rep.failed or _skipped(item, rep):
        rep.sections.append(("bus rules", text))
        return
    rep.outcome, rep.longrepr = "failed", text
    if rep.when == "teardown":
        item.stash[_BUS_TEARDOWN] = True


def _skipped(item: pytest.Item, rep: pytest.TestReport) -> bool:
    """Whether the test's own verdict is SKIPPED (not INCONCLUSIVE): as this phase's report says, or (at
    teardown) as an earlier phase decided."""
    if rep.when == "call":
        return rep.skipped and "INCONCLUSIVE" not in _longrepr_text(rep)
    res = state(item.config).results.get(item.nodeid)
    return res is not None and res.outcome == "SKIPPED"


# ----------------------------------------------------------------------------------------- verdicts
_DECISIVE = pytest.StashKey[pytest.TestReport]()  # the phase report that decided a test's verdict


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    rep: pytest.TestReport = yield
    if not _is_conformance(item):
        return rep
    ids = item_requirements(item)
    strength = strongest(ids)
    d: Dut | None = item.stash.get(_DUT, None)
    # the bus or the bench failed under the test, not the DUT: an ERROR whatever the requirement's strength
    harness = call.excinfo is not None and isinstance(call.excinfo.value, (BusFault, BenchGone))
    if rep.when == "call" and not harness:
        asserted = call.excinfo is not None and isinstance(call.excinfo.value, AssertionError)
        if rep.failed and strength == "OBSERVE":
            rep.outcome = "passed"
            msg = str(call.excinfo.value) if call.excinfo else ""
            if d is not None:
                d.record.observe("observed deviation", msg)
        elif (rep.failed and asserted) or (not rep.failed and d is not None and d.record.failed):  # INCONCLUSIVE after a failed limit: FAIL
            _judged(item, rep, call, ids, strength, d)
        elif rep.passed and d is not None and d.record.inconclusive:
            rep.outcome = "skipped"
            rep.longrepr = (str(item.path), item.location[1] or 0, "INCONCLUSIVE: " + "; ".join(d.record.inconclusive))
    _bus_rules_verdict(item, rep)
    if not rep.passed and _DECISIVE not in item.stash:
        item.stash[_DECISIVE] = rep
    _collect(item, rep, ids, strength, d)
    if call.excinfo is not None and isinstance(call.excinfo.value, BenchGone):
        _stop(item, f"aborted: {call.excinfo.value}")
    if rep.when == "teardown":
        _watch_silence(item, d)
        _final_report(item, rep)
    return rep


_MESSAGE = pytest.StashKey[str]()  # the test's failure message: what the DUT did (or the harness problem)


def _judged(item: pytest.Item, rep: pytest.TestReport, call: pytest.CallInfo, ids: list[str], strength: str,
            d: Dut | None) -> None:
    """A test that failed an assert or a limit: its message says what the DUT did, the strongest broken
    requirement first and every other failed limit after it (never the traceback's fixture repr; that
    stays below on the console). An assert saying "harness: ..." is the suite's problem: an ERROR."""
    own = ""
    if rep.failed and call.excinfo is not None:
        own = str(call.excinfo.value).strip()
        if "\nassert " in own:  # pytest's explanation of the assert follows the test's own message: reprs
            own = own.split("\nassert ", 1)[0].strip()
        own = own or "assertion failed"
        if not own.startswith("harness:") and not own.startswith("["):
            tagged = [i for i in ids if requirement(i).strength == strength] or ids
            own = f"[{' '.join(tagged)} {strength}] {own}"
    if own.startswith("harness:"):
        limits = d.record.failure_message() if d is not None else ""
        message = own + (f"\nfailed limits before it:\n{limits}" if limits else "")
    else:
        message = d.record.failure_message(own, strength) if d is not None else own
    item.stash[_MESSAGE] = message
    trace = rep.longrepr
    rep.outcome = "failed"
    crash = getattr(trace, "reprcrash", None) if rep.failed else None
    if crash is not None and hasattr(crash, "message"):
        # keep pytest's traceback for the FAILURES section, and make its one-line crash message ours: the
        # short test summary (whole on CI, where pytest does not trim it) then says what the DUT did
        crash.message = message
        rep.sections.append(("ckesc verdict", message))
    elif isinstance(trace, tuple):  # a skip (INCONCLUSIVE) raised after a failed limit: the FAIL, then why it stopped
        rep.longrepr = f"{message}\nthen: {trace[2]}"
    else:
        rep.longrepr = message if trace is None or not rep.failed else f"{message}\n\n{trace}"


def _stop(item: pytest.Item, why: str) -> None:
    """End the run after this test (its teardown still zeroes the throttle)."""
    st = state(item.config)
    st.stopped = st.stopped or why
    item.session.shouldstop = why


def _watch_silence(item: pytest.Item, d: Dut | None) -> None:
    """Abort when the DUT has stopped answering: several tests in a row ERRORed without one frame from it."""
    st = state(item.config)
    res = st.results.get(item.nodeid)
    if res is None:
        return
    heard = d is not None and (any(f.source == d.node_id for f in d.trace)
                               or any(g.msg.arbitration_id & 0x7F == d.node_id for g in d.garbled))
    st.silent_errors = st.silent_errors + 1 if res.outcome == "ERROR" and not heard else 0
    if st.silent_errors >= SILENT_TESTS_TO_ABORT:
        _stop(item, f"aborted: the DUT stopped answering: {st.silent_errors} tests in a row ERRORed and heard no frame "
                    f"from node {st.node_id} (the last: {res.message.splitlines()[0][:200] if res.message else '?'})")


def _final_report(item: pytest.Item, rep: pytest.TestReport) -> None:
    """The teardown report carries the test's one verdict (pytest_report_teststatus): a failure found
    in any phase, the bus rules' at teardown included, is the test's FAIL, counted once."""
    res = state(item.config).results.get(item.nodeid)
    decisive = item.stash.get(_DECISIVE, None)
    if res is None or decisive is None or decisive is rep:
        return
    if res.outcome in ("FAIL", "ERROR") and not rep.failed:
        rep.outcome, rep.longrepr = "failed", decisive.longrepr
        rep.sections = decisive.sections + rep.sections
    elif res.outcome in ("SKIPPED", "INCONCLUSIVE") and rep.passed:
        rep.outcome, rep.longrepr = "skipped", decisive.longrepr


#: how the console counts and prints each verdict (category, letter, word): the same verdicts as
#: summary.txt, JUnit and report.html
_CONSOLE = {"PASS": ("passed", ".", "PASSED"), "FAIL": ("failed", "F", "FAILED"), "ERROR": ("error", "E", "ERROR"),
            "OBSERVED": ("observed", "o", ("OBSERVED", {"blue": True})),
            "INCONCLUSIVE": ("inconclusive", "i", ("INCONCLUSIVE", {"yellow": True})),
            "SKIPPED": ("skipped", "s", "SKIPPED")}


@pytest.hookimpl(tryfirst=True)
def pytest_report_teststatus(report: pytest.TestReport, config: pytest.Config):
    """A conformance test is counted once, at its teardown, by its verdict (setup and call are not
    counted on their own): pytest's closing line and progress words say what summary.txt says."""
    if getattr(report, "when", None) is None:
        return None
    res = state(config).results.get(report.nodeid)
    if res is None:
        return None
    if report.when != "teardown":
        return "", "", ""
    return _CONSOLE.get(res.outcome)


def _collect(item: pytest.Item, rep: pytest.TestReport, ids: list[str], strength: str, d: Dut | None) -> None:
    st = state(item.config)
    res = st.results.get(item.nodeid)
    if res is None:
        section = _section_of(item)
        res = st.results[item.nodeid] = Result(item.nodeid, item.name, section, ids, strength)
    res.duration += rep.duration
    if rep.when == "call" or (rep.when == "setup" and not rep.passed) or (rep.when == "teardown" and rep.failed):
        outcome, message = _outcome(rep, strength, d)
        if rep.when == "call" and _MESSAGE in item.stash:
            message = item.stash[_MESSAGE]
            outcome = "ERROR" if message.startswith("harness:") else "FAIL"
        if rep.when == "teardown" and res.outcome not in ("FAIL",) and not item.stash.get(_BUS_TEARDOWN, False):
            outcome = "ERROR"
        if rep.when != "teardown" or res.outcome != "FAIL":
            res.outcome, res.message = outcome, message
    res.bus_rules = item.stash.get(_BUS_RULES, [])
    res.bus_causes = item.stash.get(_BUS_CAUSES, [])
    if d is not None and rep.when in ("call", "teardown"):
        res.lane_seconds = d.lane_seconds  # set when the dut fixture is torn down
        res.properties = {}
        for n, m in enumerate(d.record.measurements):
            res.properties.update(m.as_properties(n))
        res.observations = [(w, str(v)) for w, v in d.record.observations]
    if d is not None and rep.when == "teardown":
        res.evidence = evidence(d.trace, host=d.host_node, node=d.node_id, comm_loss="R8" in ids)
        st.info.setdefault("interval_tolerance_ms", d.interval_tolerance_ms)


def _outcome(rep: pytest.TestReport, strength: str, d: Dut | None) -> tuple[str, str]:
    text = _longrepr_text(rep)
    if rep.failed and any(e in text for e in ("DutError", "BusFault", "BenchGone")):
        # the harness could not do what the test needed, or the bus failed under it: no verdict on the DUT
        return "ERROR", text
    if rep.passed:
        if strength == "OBSERVE":
            return "OBSERVED", ""
        return "PASS", ""
    if rep.skipped:
        return ("INCONCLUSIVE" if "INCONCLUSIVE" in text else "SKIPPED"), text
    if rep.when == "setup":
        return "ERROR", text
    return "FAIL", text


def _longrepr_text(rep: pytest.TestReport) -> str:
    lr = rep.longrepr
    if lr is None:
        return ""
    if isinstance(lr, tuple):
        text = str(lr[2])
    else:
        crash = getattr(getattr(lr, "reprcrash", None), "message", None)
        text = crash if crash else str(lr)
    for verdict in (Inconclusive, NotClaimed):  # raised below the test (a helper, a fixture): pytest names the class
        text = text.removeprefix(f"{verdict.__module__}.{verdict.__qualname__}: ")
    return text


# ----------------------------------------------------------------------------------------- reports
def _module_name(nodeid_or_item) -> str:
    mod = getattr(nodeid_or_item, "module", None)
    if mod is not None:
        return mod.__name__.rsplit(".", 1)[-1]
    return Path(str(nodeid_or_item).split("::")[0]).stem


def _completeness(session: pytest.Session, exitstatus: int) -> tuple[str | None, list[dict[str, Any]]]:
    """Why this run is less than the whole suite ("aborted: ...", "interrupted", "stopped: ...",
    "subset: ..."; None: it is the whole suite, run to its end), and the tests it did not run."""
    st = state(session.config)
    reason = st.stopped
    if reason is None and exitstatus == pytest.ExitCode.INTERRUPTED:
        reason = f"stopped: {session.shouldstop}" if isinstance(session.shouldstop, str) else "interrupted"
    if reason is None and session.shouldfail:
        reason = f"stopped: {session.shouldfail} (-x / --maxfail)"
    why_not = {"aborted": "not run: the run was aborted", "interrupted": "not run: the run was interrupted",
               "stopped": "not run: the run stopped early"}.get((reason or "").split(":")[0].split(" ")[0], "not run")
    not_run = [{"nodeid": it.nodeid, "name": it.name, "section": _section_of(it), "requirements": item_requirements(it),
                "reason": why_not} for it in st.selected if it.nodeid not in st.results]
    not_run += [{"nodeid": n, "name": n.split("::")[-1], "section": "", "requirements": [], "reason": "not run: deselected"}
                for n in st.deselected]
    where = conformance_dir()
    suite = {p.stem for p in where.glob("test_*.py")} if where else set()
    ran = {_module_name(it) for it in st.selected} | {_module_name(n) for n in st.deselected}
    left_out = sorted(suite - ran)
    if reason is None and (st.deselected or left_out or any("::" in a for a in session.config.args)):
        parts = []
        if left_out:
            parts.append(f"{len(suite) - len(left_out)} of {len(suite)} section modules selected")
        if st.deselected:
            parts.append(f"{len(st.deselected)} tests deselected")
        reason = "subset: " + ("; ".join(parts) or "single tests selected")
    return reason, not_run


def _section_of(item: pytest.Item) -> str:
    ids = item_requirements(item)
    return getattr(getattr(item, "module", None), "SECTION", None) or (requirement(ids[0]).section if ids else "")


def _section_title(item: pytest.Item) -> str:
    return section_heading(_section_of(item))


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    st = state(session.config)
    if st.traces is not None:
        st.traces.end()
    if not st.conformance or not st.selected:
        return
    reason, not_run = _completeness(session, exitstatus)
    st.info["complete"] = reason is None
    st.info["incomplete"] = reason or ""
    st.info["not_run"] = len(not_run)
    if reason is not None and reason.startswith("aborted"):
        session.exitstatus = EXIT_ABORTED
    elif session.exitstatus == pytest.ExitCode.OK and any(map(broken_outside_a_fail, st.results.values())):
        session.exitstatus = pytest.ExitCode.TESTS_FAILED  # a bus rule broken while a SKIPPED test ran
    out = report_dir(session.config)
    if out is not None:
        _report.write_reports(out, list(st.results.values()), st.info, not_run=not_run,
                               html=not session.config.getoption("ckesc_no_html"))
        st.info["report_dir"] = str(out)
    if session.exitstatus == EXIT_ABORTED:  # pytest prints no terminal summary for this status: ours, then
        tr = session.config.pluginmanager.get_plugin("terminalreporter")
        if tr is not None:
            pytest_terminal_summary(tr, EXIT_ABORTED, session.config)


def pytest_terminal_summary(terminalreporter, exitstatus: int, config: pytest.Config) -> None:
    st = state(config)
    for left in st.info.get("not_restored", []):  # always said, summary or not: the bench needs a look
        terminalreporter.write_line(f"WARNING: the DUT's settings were not restored after {left['test']}: {left['why']}")
    if not st.conformance or not st.selected or not config.getoption("ckesc_summary"):
        return
    terminalreporter.write_sep("=", "CKESC conformance summary")
    terminalreporter.write_line(_report.summary_text(list(st.results.values()), st.info))
    if "report_dir" in st.info:
        terminalreporter.write_line(f"reports: {st.info['report_dir']}")


def results_json(config: pytest.Config) -> str:
    st = state(config)
    return json.dumps([r.__dict__ for r in st.results.values()], indent=1, default=str)


__all__ = ["Inconclusive", "Result", "state"]
