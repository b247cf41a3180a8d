"""Running a program on the DUT, with the oracle model in lockstep and the live bus rules listening (the IO part).

:class:`Session` builds the bench as ``ckesc run`` does (:func:`ckesc.bench.station.build`: the same options,
checks, lanes and profile), finds the DUT and notes its settings: the *baseline* every program starts from.
:meth:`Session.run` puts the DUT back into that known state (a power cycle where the bench has power control, then
the settings restored and verified, as the suite's ``dut`` fixture does), runs the program step by step, feeds
every host frame and power switch to a fresh :class:`~ckesc.explore.oracle.Oracle` after each step (so that a
request goes to the node id the model says the DUT has), reads the settings back at the end, and returns an
:class:`ExploreOutcome`. A DUT that cannot be put back is the suite's own
:class:`~ckesc.bench.errors.RestoreFailed` (the harness's failure, as in a conformance test): the exploration
stops with it, and it is never a finding.

A load step (R18) puts a :class:`~ckesc.protocol.load.LoadSource` on the simulated lane's bus (its frames contend
by arbitration, as the conformance module's do) and tells the oracle the share, which the judge widens R9 by
(:func:`~ckesc.protocol.judgements.r18_queueing_s`) and, above half, judges nothing under (R18: OBSERVE; the live
bus rules' report timing excused meanwhile, as ``test_above_half_load_is_recorded`` does). A lane that cannot play
a load (real time) draws no load step; one replayed there is skipped, and said so (:attr:`ExploreOutcome.skipped`). Load
steps are drawn only when asked for (``Session(..., load=True)``, ``ckesc explore --load``); a replayed one is
played wherever the lane can.

R20's steps (:mod:`.bus_steps`), drawn when asked for (``Session(..., bus=True)``, ``ckesc explore --bus``): a bus
short through the bench's bus-fault control, where the lane has one (else skipped, and said so), and a power cycle
with the host alone on the bus sending while the ESC is off. A program with a short ends with 241's counters read too
(a recovery that reset the ESC shows there).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import can

from ..bench.bus_fault import bus_fault_control
from ..bench.dut import Dut, DutError, DutUnreachable
from ..bench.errors import PreflightError, RestoreFailed
from ..bench.lanes import BusFault, Lane
from ..bench.outcomes import Inconclusive
from ..bench.station import BENCH_ROWS, BenchOptions, build
from ..evidence.events import EventLog
from ..evidence.live import LaneRules
from ..protocol import catalogue as cat
from ..protocol import malformed as r17
from ..protocol.errors import DecodeError
from ..protocol.frame import Decoder, Frame
from ..protocol.ids import Kind
from ..protocol.judgements import r18_judged
from ..protocol.load import LoadSource
from .actions import ANSWER_READ_S, Action, ProgramBench, stream_fields
from .bus_steps import play_alone, play_short
from .judge import ExploreFinding, Params, cite_r17, cite_r18, judge
from .oracle import SETTING_KEYS, Oracle
from .recovery import cite_r20

#: The bench options by name (:class:`~ckesc.bench.station.BenchOptions`' fields, ``ckesc run``'s bench options)
OPTION_NAMES: tuple[str, ...] = tuple(o.dest for o in BENCH_ROWS)
#: The read-back every program ends with: a setting clobbered anywhere in it shows here (242, 214, GET_ESC_ID)
PROBE = (Action("send", "get_major_configuration", {"option": 0}),
         Action("send", "set_freq", dict(cat.FREQ_READ)),
         Action("send", "get_esc_id", {"option": 0}))
#: and after a program that sent malformed frames or shorted the bus: the counters of 241, whose power-up count shows a
#: reset (R17, R20)
PROBE_COUNTERS = Action("send", "maintenance_information", {"option": 2})
STREAM_PERIOD_S = 0.01
POWER_SETTLE_S = 0.3  # read after a power-up: the reports that should flow (or not) show before the next step
SETTLE_S = 0.6  # read after the last step, so that what it did shows (MSG1 and MSG2 judged after the settle)
#: after settings were restored: twice the longest report interval (a restart allowance, R9a, and a late one), and a little
RESTORE_SETTLE_S = 2 * cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S + 0.1
#: restores (each followed by a power cycle where the bench has power control) until the settings hold
RESTORE_TRIES = 3
#: what the live bus rules do not hold a DUT to while a load above half plays (R18: OBSERVE): its report timing
UNJUDGED_ABOVE_HALF = frozenset({"R9", "R9a"})



class Recorder(can.Listener):
    """Every frame the lane reads (both directions) and every power switch, with lane times."""

    def __init__(self, lane: Lane) -> None:
        self.lane = lane
        self.messages: list[can.Message] = []
        self.power: list[tuple[float, bool]] = []
        self.powered = True

    def on_message_received(self, msg: can.Message) -> None:
        self.messages.append(msg)

    def power_switched(self, when: float) -> None:
        self.powered = not self.powered
        self.power.append((when, self.powered))


@dataclass
class ExploreOutcome:
    program: list[Action]
    findings: list[ExploreFinding]
    t0: float
    t_end: float
    messages: list[can.Message]  # the whole trace of the program (BLF)
    dut: list[Frame]  # the DUT's frames, decoded
    model: list[Frame]  # the oracle's frames
    steps: list[tuple[float, float]] = field(default_factory=list)  # each step's start and end (lane s from t0)
    features: set[str] = field(default_factory=set)
    #: the steps the lane could not play (a load in real time), each said why
    skipped: list[str] = field(default_factory=list)

    @property
    def seconds(self) -> float:
        return self.t_end - self.t0


class Session:
    """One bench, open for a whole exploration (many programs)."""

    def __init__(self, options: BenchOptions | Mapping[str, Any], *, load: bool = False, bus: bool = False) -> None:
        """Build the bench of ``options`` (:func:`~ckesc.bench.station.build`, as ``ckesc run`` does: a set-up
        mistake is a :class:`PreflightError`) and open its lane; a bench option left out (or None) takes its
        default. ``load``: programs draw foreign-load steps (R18, ``ckesc explore --load``) where the lane can play
        them (off by default: the programs a seed gives stay those the self-test's counts were made with). ``bus``:
        programs draw R20's steps (``ckesc explore --bus``: bus shorts where the lane can cause one, power cycles with
        the host alone where it has power control; off by default for the same reason)."""
        self.draw_load = load
        self.draw_bus = bus
        opts = options if isinstance(options, BenchOptions) else BenchOptions.of(dict(options).get)
        if opts.power == "labgrid":
            raise PreflightError("ckesc explore: --power labgrid is not supported yet (use command)")
        self.options = opts
        self.station = build(opts)
        try:
            self._open()
        except BaseException:
            self.station.close()
            raise

    def _listen(self, lane: Lane) -> None:
        """The explorer's readers of the lane, before anything is sent on it (the echo probe's answers included)."""
        self.recorder = Recorder(lane)
        self.rules = LaneRules(lane, jitter=self.profile.jitter_s)
        #: what the reader tells of each program (its pairing, reports, MSG1 flags): the judge's, cleared per program
        self.heard = self.rules.rules.events = EventLog()
        lane.listeners.extend([self.recorder, self.rules])

    def _open(self) -> None:
        opts, profile = self.options, self.station.profile
        self.profile = profile
        self.lane = self.station.open_lane(on_open=self._listen)  # (the echo found, then any foreign traffic)
        self.dut = Dut(self.lane, profile, node_id=opts.node_id, allow_motor_spin=bool(opts.allow_motor_spin))
        self.baseline_node = self.dut.node_id
        self.baseline = self.dut.settings()
        self.baud_code = next((c for c, r in cat.BAUD_RATES.items() if r == self.lane.bitrate), cat.DEFAULT_BAUD_CODE)
        #: programs may move the DUT to another bit rate (Set Baud, into force at a power-up) and the host follows it:
        #: where the host can change its own bit rate (the simulated lane; a real one with --can-bitrate-cmd) and a
        #: power cycle moves the DUT back inside a program's reset (never left at another rate for a later power-up)
        self.bitrates = self.lane.can_change_bitrate and self.lane.power.available
        #: the last program sent Set Baud: the reset looks for the DUT at every rate before anything else
        self._baud_sent = False
        self._dirty = False  # a program ran since the last reset: close() puts the DUT back
        #: the malformed frames sent and not yet heard back (their echo), by (CAN id, data): how the oracle is to take
        #: each (its frame type, class and words; for a single frame with toggle 1, whether the DUT took it)
        self._malformed: dict[tuple[int, bytes], list[tuple[str, str, str, bool]]] = {}
        #: why close() could not put the DUT back into its starting state (None: it did, or nothing ran)
        self.left: str | None = None
        #: the foreign load playing (R18), where the lane can play one (the simulated lane's bus model)
        self._world = getattr(getattr(self.lane, "sim", None), "world", None)
        self._load: LoadSource | None = None
        self._loads = 0  # load sources put on the bus (each its own name)
        self._skipped: list[str] = []
        self._current_load: dict[str, Any] = {}  # the load step in force (a load for a step's seconds only: not)
        self._load_nodes: set[int] = set()
        #: said once where load steps were asked for and the lane cannot play them (none is drawn)
        self.load_note = (f"explore: no load step drawn: the {self.lane.name} lane cannot play a foreign load as R18 "
                          "judges it (only the simulated lane's bus queues it)") if self.draw_load and self._world is None else ""
        #: R20: the bus-fault control (looked for at the first short), the stream running (a short stops it, and it
        #: goes on after), the settings writes sent alone on the bus the DUT did not take (kept from the oracle)
        self._bus_control: Any = False
        self.streaming: str | None = None
        self.stream_period = STREAM_PERIOD_S
        self.unheld: list[tuple[int, bytes]] = []
        self.bus_note = (f"explore: no bus short drawn: the {self.lane.name} lane has no bus-fault control (give "
                         "--bus-fault-cmd)") if self.draw_bus and self.bus_control() is None else ""
        self.params = Params(error=self.lane.timing_error, own_error=self.lane.own_error, jitter=profile.jitter_s, boot_s=profile.boot_s,
                             bitrate=self.lane.bitrate, host_node=self.dut.host_node)

    @property
    def bench(self) -> ProgramBench:
        return ProgramBench(power=self.lane.power.available, node_id=self.baseline_node, baud_code=self.baud_code,
                     window_waits=self.lane.clock == "simulated", bitrates=self.bitrates,
                     settings=tuple(sorted(self.baseline.items())),
                     absent=frozenset(self.profile.absent), load=self.draw_load and self._world is not None,
                     shorts=self.draw_bus and self.bus_control() is not None, alone=self.draw_bus)

    def bus_control(self) -> Any:
        """The lane's bus-fault control that causes a short (R20; :func:`~ckesc.bench.bus_fault.bus_fault_control`),
        or None."""
        if self._bus_control is False:
            opts = self.options
            control = bus_fault_control(self.lane, opts.bus_fault_cmd, opts.power_cmd_timeout)
            self._bus_control = control if control is not None and control.can("short") else None
        return self._bus_control

    def close(self) -> None:
        """Zero throttle, then, after any program, the DUT back into the state the exploration found it in (its
        bit rate, node id and settings, as every program's start puts it: an exploration leaves the bench as it
        found it). What could not be put back is kept in :attr:`left` (the command says so) rather than raised:
        the lane is closed either way."""
        try:
            self._set_load(None)
            try:
                self.dut.zero_throttle()
                unsent = None
            except BusFault as exc:  # nobody takes the host's frames: a program left the DUT off or at another rate
                unsent = exc
            if self._dirty:
                try:
                    self._reset()
                    self._dirty = False
                except RestoreFailed as exc:
                    self.left = str(exc)
            if unsent is not None:  # the DUT put back: zero throttle again, where it now listens
                try:
                    self.dut.zero_throttle()
                except BusFault:
                    self.left = "; ".join(filter(None, [self.left, f"zero throttle not sent: {unsent}"]))
        finally:
            self.station.close()

    # ---------------------------------------------------------------- known state
    def _reset(self) -> float:
        """Put the DUT back to the baseline: power cycle (else leave CAN Test, resume), node id, settings.
        Returns the lane time of its current power-up (its 120 s window's start)."""
        dut = self.dut
        dut.trace.clear()  # what the Dut has read (its lookups scan it): this program's only
        self._set_load(None)
        dut.stop_throttle()
        powered_at = self.lane.now() - cat.CONFIG_WINDOW_S - 10.0  # no power control: the window is long gone
        try:
            if self.lane.power.available:
                powered_at = dut.switch_power(self.profile.off_s, self.profile.boot_s)
            powered_at = self._back_to_baseline_rate() or powered_at
            self._leave_modes()
            try:
                node = dut.discover()
            except DutUnreachable:
                if not self.bitrates:
                    raise
                # not at the baseline's rate though the last program sent no Set Baud (a DUT that moved by itself)
                powered_at = self._back_to_baseline_rate(force=True) or powered_at
                self._leave_modes()
                node = dut.discover()
            dut.node_id = node
            if node != self.baseline_node or dut.settings()["throttle_channel"] != self.baseline["throttle_channel"]:
                # a program moved it (Set ID): back, inside this power-up's window
                if self.lane.now() - powered_at > cat.CONFIG_WINDOW_S - 5:
                    raise RestoreFailed(f"the DUT is at node {node}, not {self.baseline_node}, and no power control "
                                       "opens a Set ID window to move it back")
                dut.ask("set_id", {"node_id": self.baseline_node, "throttle_channel": self.baseline["throttle_channel"]})
                dut.node_id = self.baseline_node
                if self.lane.power.available:  # the program starts on a power-up at the baseline's node id: what the
                    # DUT took from the id it booted with (an answer slot) is then the same in every program
                    powered_at = dut.switch_power(self.profile.off_s, self.profile.boot_s)
            for attempt in range(RESTORE_TRIES + 1):
                if (now := dut.settings()) == self.baseline:
                    break
                if attempt == RESTORE_TRIES:
                    raise RestoreFailed(f"the DUT's settings restored did not hold across {RESTORE_TRIES} power cycles "
                                       f"(R13): {now} against {self.baseline}")
                left = dut.restore(self.baseline)
                if left:
                    raise RestoreFailed(f"could not restore the DUT's settings: {'; '.join(left)}")
                if not self.lane.power.available:  # a Set Freq write restarts the report timers (R9a): let that pass
                    dut.wait(RESTORE_SETTLE_S)
                    break
                # the program starts on a power-up whose flash holds the baseline: a restore one save undid in flash
                # (a save that clobbers its neighbour) would otherwise show in the next program's power cycle, a
                # finding its own steps cannot reproduce
                powered_at = dut.switch_power(self.profile.off_s, self.profile.boot_s)
        except (DutError, Inconclusive, AssertionError) as exc:
            raise RestoreFailed(f"could not put the DUT back into its starting state: {exc}") from None
        return powered_at

    def _leave_modes(self) -> None:
        """CAN Test off and resume, where the DUT does not report (a mode a program left it in, or one it kept
        across the power cycle): a suspended DUT refuses the settings the reset writes (R12)."""
        if not self.dut.frames("msg1", since=self.lane.now() - 1.0, source=self.dut.node_id):
            self.dut.broadcast("can_test", {"option": cat.CAN_TEST_OFF, "count": 0})
            self.dut.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
            self.dut.wait(cat.ANSWER_DELAY_MAX_S * 2)

    def _back_to_baseline_rate(self, force: bool = False) -> float | None:
        """After a program that moved the DUT to another bit rate (Set Baud, then a power-up): find it at its rate
        (the host's, the baseline's, then every legal one), and if that is not the baseline's, Set Baud back in the
        window of the power-up just made and power-cycle into it. Returns that power-up's time (the 120 s window
        the program starts in), or None when the DUT was not moved."""
        baseline = cat.BAUD_RATES[self.baud_code]
        if not self.bitrates or not (self._baud_sent or force) or (self.lane.bitrate == baseline and self._answering() is not None):
            return None  # no program can have moved it, the last one sent no Set Baud, or it answers where it should
        for rate in dict.fromkeys([self.lane.bitrate, baseline, *cat.BAUD_RATES.values()]):
            self.lane.reopen(rate)
            if (node := self._answering()) is not None:
                break
        else:
            self.lane.reopen(baseline)
            return None  # nobody answers at any rate: discovery says so next
        if rate == baseline:
            return None
        self.dut.node_id = node
        self._leave_modes()  # (a DUT that booted suspended refuses Set Baud, R12)
        self.dut.ask("set_baud", {"baud": self.baud_code})
        self.lane.reopen(baseline)  # before the power-up, as a program's power step does: heard from its boot on
        on = self.dut.switch_power(self.profile.off_s, self.profile.boot_s)
        self.dut.wait(POWER_SETTLE_S)
        return on

    def _answering(self) -> int | None:
        """The node id the DUT answers GET_ESC_ID from at the host's current bit rate (discovery), or None."""
        try:
            return self.dut.discover()
        except DutUnreachable:
            return None

    def _oracle(self, powered_at: float, t0: float) -> Oracle:
        counters = self.dut.ask("maintenance_information", {"option": 2})
        baseline = {"node_id": self.baseline_node, "baud": self.baud_code, **{k: self.baseline[k] for k in SETTING_KEYS},
                    "power_ups": counters.get("power_ups"), "stops": counters.get("stops")}
        return Oracle(baseline, powered_at, start=t0, host_node=self.dut.host_node)

    # ---------------------------------------------------------------- one program
    def run(self, program: Sequence[Action]) -> ExploreOutcome:
        try:
            powered_at = self._reset()
        except RestoreFailed:  # once more (a real-time bench may lose a frame under load, issue #21); then it stands
            powered_at = self._reset()
        self._baud_sent = any(a.op == "send" and a.name == "set_baud" for a in program)
        self._dirty = True
        oracle = self._oracle(powered_at, self.lane.now())
        dut, rec = self.dut, self.recorder
        rec.messages.clear()
        rec.power.clear()
        self.rules.begin()
        self.heard.clear()
        self.rules.excuse(frozenset())  # (a program cut short under a load above half left it excusing)
        t0 = self.lane.now()
        fed = 0
        power_fed = 0
        steps: list[tuple[float, float]] = []
        self._malformed.clear()
        self._skipped = []
        self._current_load = {}
        self._load_nodes = set()  # the load's foreign nodes: their frames are neither the DUT's nor the host's
        self.streaming = None
        self.unheld = []
        foreign: set[int] = set()  # the echoes of the malformed frames: the host's, never the DUT's (for the judge)

        def feed(step: int | None) -> None:
            nonlocal fed, power_fed
            events: list[tuple[float, int, Any]] = []
            for msg in rec.messages[fed:]:
                sent = self._malformed.get((msg.arbitration_id, bytes(msg.data)))
                if sent and not msg.is_error_frame:  # a malformed frame of ours (a response frame has another source)
                    name, form, what, taken = sent.pop(0)
                    foreign.add(id(msg))
                    if taken:  # a single frame with toggle 1 the DUT took (it answered): the model takes it too
                        data = bytearray(msg.data)
                        data[-1] &= ~0x20
                        events.append((msg.timestamp, 1, can.Message(timestamp=msg.timestamp, arbitration_id=msg.arbitration_id,
                                                                     data=bytes(data), is_extended_id=True)))
                    else:
                        events.append((msg.timestamp, 1, (msg, name, form, what)))
                    continue
                if self.unheld and (msg.arbitration_id, bytes(msg.data)) in self.unheld and not msg.is_error_frame:
                    self.unheld.remove((msg.arbitration_id, bytes(msg.data)))  # sent alone, not taken by the DUT (R20)
                    continue
                # the host's own frames, by their source node (an echo is is_rx False in the simulated lane and on
                # SocketCAN, True through socketcand)
                if msg.is_extended_id and (msg.arbitration_id & 0x7F) == dut.host_node \
                        and not msg.is_error_frame and not msg.is_remote_frame:
                    events.append((msg.timestamp, 1, msg))
            for when, on in rec.power[power_fed:]:
                events.append((when, 0, on))
            fed, power_fed = len(rec.messages), len(rec.power)
            for when, kind, what in sorted(events, key=lambda e: (e[0], e[1])):
                if kind and isinstance(what, tuple):
                    oracle.malformed_frame(*what, step=step)
                elif kind:
                    oracle.host_frame(what, step)
                else:
                    oracle.power(what, when, step)
            dut.node_id = oracle.node_id  # where the model says the DUT is now (Set ID)

        full = list(program) + list(PROBE) + ([PROBE_COUNTERS] if any(a.op in ("malformed", "short") for a in program) else [])
        for i, action in enumerate(full):
            start = self.lane.now()
            switches = len(rec.power)
            self._do(action, oracle, powered_at, i, feed)
            feed(i)
            if len(rec.power) > switches:  # a power step (or a short's power cycle: a DUT that did not recover)
                powered_at = rec.power[-1][0]
                oracle.mark(self.lane.now(), "ready", i)  # the DUT reported again (or its boot bound passed)
                dut.wait(POWER_SETTLE_S)  # what it does after a power-up shows before the next step
                feed(i)
            steps.append((start - t0, self.lane.now() - t0))
            if i == len(program) - 1:
                dut.stop_throttle()
        dut.wait(SETTLE_S)
        feed(len(full) - 1)
        t_end = self.lane.now()
        self._set_load(None)
        oracle.finish(t_end)
        frames = _decode([m for m in rec.messages if id(m) not in foreign
                          and not (self._load_nodes and m.is_extended_id and m.arbitration_id & 0x7F in self._load_nodes)])
        findings = judge(oracle, frames, t0, t_end, self.params, heard=self.heard)
        found, _count = self.rules.take()
        for v in found:
            at = v.timestamp - t0
            findings.append(ExploreFinding("bus_rule", list(v.rules) or ["4.1.1-1"], f"bus rule {v.check}: {v.message}",
                                    str(v), "the rule holds", at, None, strength=v.strength,
                                    subject=f"{' '.join(v.rules)} {v.check}"))
        findings = [f for f in cite_r20(cite_r18(cite_r17(findings, oracle, t0, self.params.host_late), oracle, t0), oracle, t0)
                    if f.strength != "OBSERVE"]
        return ExploreOutcome(list(program), findings, t0, t_end, list(rec.messages), frames, list(oracle.out), steps,
                       {a.feature for a in program}, list(self._skipped))

    def _set_load(self, fields: Mapping[str, Any] | None, step: int | None = None) -> None:
        """The foreign load from now on (R18): ``fields`` a load step's (share 0 or None: none), its seed the step's
        (the same program plays the same load)."""
        if self._load is not None:
            self._world.remove_source(self._load)
            self._load = None
        share = (fields or {}).get("share", 0)
        if share and self._world is not None:
            priority = fields.get("priority", "mixed")
            self._loads += 1
            self._load = LoadSource(share, self.lane.bitrate, priority=priority,
                                    seed=zlib.crc32(f"explore {step} {share} {priority}".encode()),
                                    exclude_nodes=[*self.dut.nodes, self.dut.node_id, self.dut.host_node],
                                    name=f"explore-load-{self._loads}")
            self._load_nodes.update(fn.node for fn in self._load.nodes)
            self._world.add_source(self._load)

    def _play_load(self, action: Action, oracle: Oracle, step: int, feed) -> None:
        """A load step: the load from now on (the oracle told the share: the judge widens R9 by it); with ``seconds``
        only that long, then the load before it again, the live rules' report timing excused while a load above half
        plays and until every report has come once after it (R18: OBSERVE above half)."""
        if self._world is None:
            self._skipped.append(f"step {step + 1}, {action.describe()}: skipped, the {self.lane.name} lane cannot "
                                 "play a foreign load as R18 judges it (only the simulated lane's bus queues it)")
            return
        before = dict(self._current_load)
        above = not r18_judged(action.fields.get("share", 0))
        if above:
            self.rules.excuse(UNJUDGED_ABOVE_HALF)
        self._set_load(action.fields, step)
        oracle.load(self.lane.now(), action.fields.get("share", 0), step)
        if not action.seconds:
            self._current_load = dict(action.fields)
            return
        self.dut.wait(action.seconds)
        self._set_load(before or None, step)
        if above:  # every report once more after it (one dropped meanwhile makes the gap across its end long)
            intervals = oracle.states[-1].intervals
            self.dut.wait(max(intervals.values()) + ANSWER_READ_S)
            feed(step)
            self.rules.excuse(frozenset())  # (what it excused: OBSERVE, not kept)
        oracle.load(self.lane.now(), before.get("share", 0), step)

    def _do(self, action: Action, oracle: Oracle, powered_at: float, step: int = 0, feed=None) -> None:
        dut = self.dut
        if action.op == "send":
            spec = cat.spec(action.name)
            if spec.service:
                dut.request(action.name, action.fields, destination=oracle.node_id)
            else:
                dut.broadcast(action.name, action.fields, **({"layout": "query"} if action.name == "get_esc_id" else {}))
                dut.wait(ANSWER_READ_S + 2 * self.lane.timing_error)
        elif action.op == "malformed":
            self._send_malformed(action, oracle)
        elif action.op == "stream":
            dut.stop_throttle()
            dut.throttle_stream(action.name, stream_fields(action.name), period=STREAM_PERIOD_S)
            self.streaming = action.name
            dut.wait(0.05)
        elif action.op == "stop":
            dut.stop_throttle()
            self.streaming = None
            dut.wait(0.01)
        elif action.op in ("power", "alone"):
            if self.lane.power.available:
                # a Set Baud write comes into force at this power-up (4.4.19): the host moves with the DUT as it
                # goes off, so that it hears the DUT from its boot on (the model's stored code: the document's)
                rate = cat.BAUD_RATES.get(oracle.model.nvm["baud"], self.lane.bitrate)
                if self.bitrates and rate != self.lane.bitrate:
                    self.lane.reopen(rate)
                    if self._load is not None:  # the load's share is of the bus's capacity at its new bit rate
                        self._set_load(self._current_load, step)
            if action.op == "alone":
                play_alone(self, action, oracle, step, feed or (lambda _step: None))
            elif self.lane.power.available:
                self.streaming = None
                dut.switch_power(self.profile.off_s, self.profile.boot_s)
        elif action.op == "short":
            play_short(self, action, oracle, step, feed or (lambda _step: None))
        elif action.op == "wait":
            dut.wait(action.seconds)
        elif action.op == "load":
            self._play_load(action, oracle, step, feed or (lambda _step: None))
        elif action.op == "window":
            dut.read_until(max(self.lane.now(), powered_at + cat.CONFIG_WINDOW_S + 1.0 + 2 * self.lane.timing_error))
        else:
            raise ValueError(f"unknown action {action.op!r}")


    def _send_malformed(self, action: Action, oracle: Oracle) -> None:
        """Send ``action``'s command in its R17 class (to the node id the model says the DUT has, each frame with
        the next transfer id of its type, so that an answer names it), then wait for what it may answer. A single
        frame with toggle 1 (R17-toggle: taking it is free) counts as taken when the DUT answered it."""
        dut = self.dut
        spec = cat.spec(action.name)
        kind = Kind.REQUEST if spec.service else Kind.MESSAGE
        node = oracle.node_id

        def tid(destination: int | None) -> int:  # one counter for the step's frames, whatever their destination:
            return dut.proto.tids.next((kind, action.name), node if spec.service else None)  # an answer names its frame

        bads = r17.build(action.name, action.fields, action.form, source=dut.host_node, node_id=node,
                         others=r17.other_nodes(node, dut.nodes), transfer_id=tid,
                         nibble_order=self.profile.nibble_order)
        heard = len(dut.trace)
        keys = []
        command = action.describe().split(" sent as: ")[0]
        for bad in bads:
            for w in bad.frames:
                keys.append((w.arbitration_id, bytes(w.data)))
                self._malformed.setdefault(keys[-1], []).append(
                    (action.name, action.form, f"{command} as {bad}", False))
                dut.send_wire(w)
        dut.wait(ANSWER_READ_S + 2 * self.lane.timing_error)
        if action.form == r17.TOGGLE and bads:
            b = bads[0]
            answered = any(f.source != dut.host_node and f.name == action.name  # (Set ID answers from its new id) and f.kind is not Kind.REQUEST
                           and (f.kind is Kind.MESSAGE or f.transfer_id == b.transfer_id) for f in dut.trace[heard:])
            entries = self._malformed.get(keys[0], [])
            if answered and entries:
                entries[-1] = (*entries[-1][:3], True)


def _decode(messages) -> list[Frame]:
    decoder = Decoder()
    out = []
    for m in messages:
        try:
            out.append(decoder.decode(m))
        except DecodeError:
            continue  # what does not decode is the bus rules' (4.1) business
    return out
