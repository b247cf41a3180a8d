"""One way to build a bench from its options, below any command: the pytest plugin (its preflight,
``ckesc/session/preflight.py``, from ``config.getoption``), ``ckesc explore`` and ``ckesc profile`` (from their
argparse namespace, ``ckesc/explore/runner.py``) and ``ckesc soak`` (``ckesc/soak/runner.py``) all call :func:`build`.

:class:`BenchOptions` is plain data: one field per bench option (the device under test, its lane, bus, power and
profile), made from the rows :data:`BENCH_ROWS`, which ``ckesc/session/options.py`` lists among the run's other
options (pytest's flags, ``ckesc run``'s and a rig file's keys are made from the same rows: an option is declared
once). :func:`build` checks them (:func:`.checks.check`: one :class:`.errors.PreflightError` line per mistake),
opens the power control (labgrid's place acquired before its bus is touched) and, on a real bus, opens the bus once
within its bound (:func:`.checks.open_bus`), and returns a :class:`Station`: the DUT profile (with the defaults a
real bus takes, and what an emulated ESC's variant declares), the DUT's lane, the ``multi_dut`` bench, the bench
proof (:mod:`.proof`) and :meth:`Station.close`.

Why *station*: "bench" already names the benchmarks folder, this package, the emulator's simulated bench, a rig
file's benches and two fixtures; a test station is the place set up to test one device, its bus, power and
profile, and the word means nothing else here (``Rig`` is a rig file's; a ``TestBench`` pytest would try to
collect as a test class).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..emulator import variants
from . import checks, proof
from .checks import BUS_OPEN_TIMEOUT_S
from .lanes import BusLane, Lane, SimLane
from .link import echo_probe
from .power import POWER_COMMAND_TIMEOUT_S, PowerControl, Prompt, open_power
from .power import names as power_names
from .profile import DEFAULT_BUS_ERROR_S, DutProfile
from .realtime_lane import RealtimeEmulatorLane
from .traffic_player import PlayerStats, TrafficPlayer

#: the ``ckesc run --help`` group of the bench options (``ckesc/session/options.py`` names the others)
DUT = "device under test"
SAME = object()  # ``ckesc run``'s flag or default: the same as pytest's

#: The private bench of the ``multi_dut`` fixture in the emulator lanes: node ids chosen so that
#: node_id % 32 covers 1, 2 and wraps (33 -> slot 1).
MULTI_NODES = (1, 2, 33)


@dataclass(frozen=True)
class Option:
    """One run option: a row of the run's option table (``ckesc/session/options.py``, whose docstring says what
    each field is)."""

    dest: str
    help: str
    group: str = DUT
    type: Callable[[str], Any] | None = None
    choices: tuple[str, ...] | None = None
    action: str = "store"  # "store", "store_true" or "append"
    default: Any = None
    metavar: str | None = None
    #: pytest's flag (``--<dest with dashes>`` when SAME), or None: ``ckesc run``'s own
    pytest: str | None | object = SAME
    #: ``ckesc run``'s flags (pytest's, or ``--<dest with dashes>``, when SAME), or None: pytest's only (``ckesc run``
    #: sets it itself)
    run: tuple[str, ...] | None | object = SAME
    #: ``ckesc run``'s default where it differs from pytest's
    run_default: Any = SAME
    #: the rig file key that sets it per bench (``bus.interface``): with ``--rig`` it is not a command-line option
    rig: str | None = None

    @property
    def pytest_flag(self) -> str | None:
        return self._flag if self.pytest is SAME else self.pytest  # type: ignore[return-value]

    @property
    def run_flags(self) -> tuple[str, ...]:
        if self.run is SAME:
            return (self.pytest_flag or self._flag,)
        return self.run or ()  # type: ignore[return-value]

    @property
    def _flag(self) -> str:
        return "--" + self.dest.replace("_", "-")

    def default_on(self, *, run: bool = False) -> Any:
        """The default under pytest, or (``run``) under ``ckesc run``."""
        return self.default if not run or self.run_default is SAME else self.run_default

    def arguments(self, *, run: bool = False) -> dict[str, Any]:
        """argparse's (and pytest's ``addoption``'s) keyword arguments for this option on one side."""
        default = self.default_on(run=run)
        kwargs: dict[str, Any] = {"dest": self.dest, "help": self.help, "action": self.action,
                                  "default": list(default) if self.action == "append" else default}
        for key in ("type", "choices", "metavar"):
            if getattr(self, key) is not None:
                kwargs[key] = getattr(self, key)
        return kwargs



#: The bench options, in ``--help``'s order: :class:`BenchOptions`' fields
BENCH_ROWS: tuple[Option, ...] = (
    Option("dut", choices=("emulator", "bus"), default="emulator", rig="dut",
           help="emulator (default): the ckesc emulator; bus: a device on a python-can bus"),
    Option("lane", choices=("simulated", "realtime"), default="simulated", rig="lane",
           help="for --dut emulator: simulated time (default, exact) or `ckesc emulate` in its own process through "
                "socketcand (real time)"),
    Option("can_interface", rig="bus.interface", help="python-can interface for --dut bus (else can.conf / CAN_INTERFACE)"),
    Option("can_channel", rig="bus.channel", help="python-can channel, e.g. can0 (else can.conf / CAN_CHANNEL)"),
    Option("can_bitrate", type=int, rig="bus.bitrate", help="bit rate of the host's bus (else can.conf / CAN_BITRATE)"),
    Option("can_config", action="append", default=[], metavar="KEY=VALUE", rig="bus.<any other key>",
           help="extra python-can bus argument (repeatable)"),
    Option("can_bitrate_cmd", metavar="CMD", rig="bitrate_cmd",
           help="--dut bus: command that moves the bus to another bit rate when a test needs it (Set Baud); {bitrate} is "
                "replaced. python-can cannot set a SocketCAN bit rate: e.g. a script running `ip link set can0 down; ip link "
                "set can0 type can bitrate {bitrate}; ip link set can0 up`, or `ckesc control --port P bitrate {bitrate}` "
                "for the emulator on vcan0"),
    Option("host_send_error", type=float, default=DEFAULT_BUS_ERROR_S * 1000, run_default=None, metavar="MS",
           rig="host_send_error_ms",
           help="--dut bus, an adapter that does not echo the host's frames: how much later than the host clock at send a "
                "frame may reach the bus (driver, USB, TX queue), in ms; the error of every time taken from the host's own "
                f"frames (default {DEFAULT_BUS_ERROR_S * 1000:g})"),
    Option("bus_open_timeout", type=float, default=BUS_OPEN_TIMEOUT_S, metavar="S",
           help="--dut bus: how long the preflight waits for the bus to open (a socketcand daemon or adapter that does not "
                f"answer) before it stops the run with exit 2 (default {BUS_OPEN_TIMEOUT_S:g})"),
    Option("node_id", type=int, rig="node_id", help="the DUT's node id (default: discovered with GET_ESC_ID)"),
    Option("nodes", rig="emulator.nodes", help="emulator: node ids of the emulated bench (default 1); the DUT is the first"),
    Option("profile", rig="profile",
           help="DUT profile: a shipped one by name (emulator, ckesc-generic, vcan-vm), a name in ./fixtures/duts, or a "
                "path (default: emulator / ckesc-generic)"),
    Option("power", choices=power_names(), rig="power",
           help="power control (default: emulator for --dut emulator, none for --dut bus)"),
    Option("power_off_cmd", rig="power.command.off", help="--power command: shell command that switches the DUT off"),
    Option("power_on_cmd", rig="power.command.on", help="--power command: shell command that switches the DUT on"),
    Option("power_cmd_timeout", type=float, default=POWER_COMMAND_TIMEOUT_S, metavar="S",
           help="--power command: a power command still running after S seconds has failed (default "
                f"{POWER_COMMAND_TIMEOUT_S:g})"),
    Option("labgrid_env", metavar="FILE", rig="power.labgrid.env",
           help="--power labgrid: labgrid environment file whose target has a power driver (PowerProtocol)"),
    Option("labgrid_target", metavar="NAME", rig="power.labgrid.target",
           help="--power labgrid: the target in --labgrid-env (default: its only one)"),
    Option("labgrid_place", metavar="NAME", rig="place",
           help="--power labgrid: acquire this labgrid place for the run, release it at the end (default: the target's "
                "RemotePlace, if any)"),
    Option("labgrid_coordinator", metavar="HOST:PORT",
           help="--power labgrid: the labgrid coordinator (default: the env file's coordinator_address, LG_COORDINATOR, "
                "127.0.0.1:20408)"),
    Option("allow_motor_spin", action="store_true", default=None, rig="allow_motor_spin",
           help="allow non-zero throttle (default: only for the emulator). PROPELLERS OFF."),
    Option("foreign_traffic", choices=("ardupilot",),
           help="other nodes' traffic played on the DUT's bus during the whole run, every frame encoded by the dronecan "
                "package: ardupilot (a flight controller at node 10 and a smart battery at node 40: SafetyState, "
                "NodeStatus, GET_ESC_ID, a ZERO RawCommand, BatteryCells; docs/robustness.md); default: none, a quiet bus"),
    Option("emulator_faults", default="", rig="emulator.faults", help="emulator: comma-separated fault names to switch on"),
    Option("emulator_seed", type=int, default=0, rig="emulator.seed", help="emulator: random seed"),
    Option("emulator_option", action="append", default=[], metavar="NAME=VALUE", rig="emulator.options",
           help="emulator: one conforming variant for every emulated ESC (repeatable; the names, values and the requirements "
                "that allow each: ckesc emulate --list-variants): " + ", ".join(variants.FREEDOMS)),
    Option("emulator_variants", type=int, metavar="SEED", rig="emulator.variants",
           help="emulator: every emulated ESC plays the conforming combination drawn from SEED (--emulator-option wins over "
                "the draw); the run's reports name the combination"),
)


def _frozen(value: Any) -> Any:
    return tuple(value) if isinstance(value, list) else value


class _Options:
    """:class:`BenchOptions`' methods (its fields are :data:`BENCH_ROWS`)."""

    @classmethod
    def of(cls, get: Callable[[str], Any]) -> BenchOptions:
        """The bench options from a getter by name (pytest's ``config.getoption``, ``vars(args).get`` of an argparse
        namespace, a dict's ``get``): an unset one (None) takes its default; lists become tuples."""
        return cls(**{o.dest: _frozen(o.default if (v := get(o.dest)) is None else v) for o in BENCH_ROWS})

    def get(self, name: str) -> Any:
        """An option by name, as a power backend's factory asks for it (``factory(get, prompt)``)."""
        return getattr(self, name)


BenchOptions = dataclasses.make_dataclass(
    "BenchOptions", [(o.dest, Any, dataclasses.field(default=_frozen(o.default))) for o in BENCH_ROWS],
    bases=(_Options,), frozen=True,
    namespace={"__module__": __name__, "__doc__": "The bench's options, plain data: one field per row of "
               ":data:`BENCH_ROWS` (``BenchOptions(dut='bus', can_interface='socketcand')``; :meth:`of` from a getter)."})


def console_prompt(text: str) -> None:
    """Asks the operator (``--power manual``) at the console."""
    input(f"\n>>> {text} ")


def build(options: BenchOptions, *, prompt: Prompt = console_prompt,
          before_opening: Callable[[], None] | None = None) -> Station:
    """The bench ``options`` describe: checked (:func:`.checks.check`), then, on a real bus, its power control
    opened (labgrid's place acquired first: a shared place is locked before its bus is opened) and the bus opened
    once within ``--bus-open-timeout`` and closed again. ``before_opening``: the caller's own checks, run after the
    bench's and before anything is opened (the session's reports directory). A mistake is a
    :class:`.errors.PreflightError`; nothing is left open by one."""
    profile = checks.check(options)
    if before_opening is not None:
        before_opening()
    power: PowerControl | None = None
    kwargs: dict[str, Any] | None = None
    if options.dut == "bus":
        power = open_power(options.power or "none", options.get, prompt)
        try:
            kwargs = checks.bus_kwargs(options)
            checks.open_bus(kwargs, options.bus_open_timeout or BUS_OPEN_TIMEOUT_S)
        except BaseException:
            _close_power(power)
            raise
    return Station(options, profile, power, kwargs)


def _close_power(power: PowerControl | None) -> None:
    close = getattr(power, "close", None)  # labgrid's: its drivers deactivated, its place released
    if close is not None:
        close()


class Station:
    """A bench built from its options (:func:`build`): what every command that drives a DUT needs of it.

    ``profile``: the DUT profile (a real bus's defaults taken; on the emulator, the timing its variant declares);
    ``power``: the power control of a real bus (None for the emulator, whose lanes switch their own);
    :meth:`open_lane` the DUT's lane, :meth:`multi_lane` the ``multi_dut`` fixture's private bench, :meth:`prove`
    the bench proof; :meth:`close` closes the lane and releases the power control (idempotent)."""

    def __init__(self, options: BenchOptions, profile: DutProfile, power: PowerControl | None,
                 bus_kwargs: dict[str, Any] | None) -> None:
        self.options = options
        self.emulated = options.dut == "emulator"
        #: the conforming variant the emulated ESCs play ({EscConfig field: value}; checked by :func:`build`)
        self.played: dict[str, Any] = (checks.emulator_options(options.emulator_option, options.emulator_variants)
                                       if self.emulated else {})
        for key, value in variants.declared(self.played).items():  # what the emulated ESC's vendor would state
            if value > getattr(profile, key):
                profile = dataclasses.replace(profile, **{key: value})
        self.profile = profile
        self.power = power
        self.bus_kwargs = bus_kwargs
        self.lane: Lane | None = None
        #: the foreign traffic playing on the DUT's lane (``--foreign-traffic``): what it is and what it reached
        self.foreign: ForeignPlay | None = None

    # ------------------------------------------------------------------ lanes
    def open_lane(self, on_open: Callable[[Lane], None] | None = None) -> Lane:
        """The DUT's lane, opened once and kept (:attr:`lane`) until :meth:`close_lane`: ``on_open(lane)`` first (the
        caller's listeners: its trace and live rules read every frame from the first), then on a real bus whether the
        host's own frames come back (:meth:`.lanes.BusLane.find_echo`), and only then the foreign traffic
        (``--foreign-traffic``), so that without an echo every frame it plays is handed out from its first."""
        if self.lane is None:
            self.lane = self._new_lane()
            try:
                if on_open is not None:
                    on_open(self.lane)
                if isinstance(self.lane, BusLane):
                    self.lane.find_echo(echo_probe(nibble_order=self.profile.nibble_order))
                if self.options.foreign_traffic:
                    self.foreign = ForeignPlay(self.options.foreign_traffic, self.lane)
            except BaseException:
                self.close_lane()
                raise
        return self.lane

    def _new_lane(self) -> Lane:
        o, profile = self.options, self.profile
        if self.emulated:
            faults = checks.fault_names(o.emulator_faults)
            nodes = checks.node_list(o.nodes or "1")
            if o.lane == "realtime":
                return RealtimeEmulatorLane(nodes=nodes, faults=faults, temp_flash=True, esc_options=self.played,
                                            seed=o.emulator_seed, timing_error=max(profile.error_s, DEFAULT_BUS_ERROR_S))
            # in one process the emulated ESCs keep their flash contents across power cycles: no file needed
            lane = SimLane(nodes=nodes, faults=faults, seed=o.emulator_seed, esc_config={"boot_time": 0.25, **self.played})
            # exact timestamps; a profile may still state a bench's error (0 for the emulator's own): margins below it
            # are then INCONCLUSIVE as on that bench, e.g. to see what a 2 ms bench can tell
            lane.timing_error = profile.error_s
            return lane
        assert self.power is not None and self.bus_kwargs is not None  # opened by build()
        return BusLane(self.bus_kwargs, self.power, timing_error=profile.error_s, bitrate_cmd=o.can_bitrate_cmd,
                       host_send_error=o.host_send_error / 1000, stamp=profile.stamp)

    def multi_lane(self, timing_error: float) -> Lane:
        """The emulator lanes' private bench of :data:`MULTI_NODES` (the main DUT stays alone, as Set ID needs); the
        caller closes it."""
        o = self.options
        if o.lane == "realtime":
            return RealtimeEmulatorLane(nodes=MULTI_NODES, timing_error=timing_error, esc_options=self.played)
        lane = SimLane(nodes=MULTI_NODES, faults=checks.fault_names(o.emulator_faults), seed=o.emulator_seed,
                       esc_config={"boot_time": 0.25, **self.played})
        lane.timing_error = timing_error  # the profile's stated error, as on the DUT's lane
        return lane

    def close_lane(self) -> None:
        lane, self.lane = self.lane, None
        try:
            if self.foreign is not None:
                self.foreign.stop()  # its figures stay (``foreign.report()``) for the run's reports
        finally:
            if lane is not None:
                lane.close()

    def close(self) -> None:
        """The DUT's lane closed, then the power control released (labgrid's place); idempotent."""
        try:
            self.close_lane()
        finally:
            power, self.power = self.power, None
            _close_power(power)

    # ------------------------------------------------------------------ the proof
    def prove(self, *, cycles_power: bool) -> list[str]:
        """--dut bus: the bench proven before the DUT is judged (:mod:`.proof`), on a lane of its own: who answers
        GET_ESC_ID, the node id given among them, and where the run may cycle power (``cycles_power``) and a switch
        is given (not manual: an operator is the proof), the switch itself. A failure is a
        :class:`.errors.PreflightError`; returns what was proven, for the run to say."""
        if self.emulated:
            return []
        o = self.options
        lane = self._new_lane()
        assert isinstance(lane, BusLane)
        try:
            where = checks.bus_where(lane.bus_kwargs)
            link = proof.discover(lane, self.profile, o.node_id, where)
            said = [f"bench: {', '.join(f'node {n}' for n in link.nodes)} answered GET_ESC_ID on the bus ({where}); the "
                    f"DUT is node {link.node_id}"]
            kind = o.power or "none"
            if lane.power.available and kind != "manual" and cycles_power:
                named = ({"off": f"--power-off-cmd {o.power_off_cmd!r}", "on": f"--power-on-cmd {o.power_on_cmd!r}"}
                         if kind == "command" else
                         {"off": f"power off ({lane.power.name})", "on": f"power on ({lane.power.name})"})
                said.append(f"bench: power switch ({kind}) {proof.prove_power(link, named)}")
            return said
        finally:
            lane.close()


class ForeignPlay:
    """Foreign traffic (:mod:`.foreign`) played on a lane for as long as the lane is open: in the simulated lane a
    source of its bus (:meth:`~ckesc.emulator.sim_bus.SimWorld.add_source`, its frames contending by arbitration),
    on a real bus or the real-time emulator a :class:`.traffic_player.TrafficPlayer` sending on the host's own
    handle (:meth:`.lanes.BusLane.play`): every reader of the lane hears what was played, by its echo or the lane's
    copy, on an adapter whose handles do not hear each other too. :meth:`report` is what the run's reports say:
    what was played and the load and lateness reached."""

    def __init__(self, name: str, lane: Lane) -> None:
        from . import foreign  # imports dronecan (about a second): only when foreign traffic is asked for

        self.name = name
        # the other nodes talk at the run's bit rate, their configuration: while a test moves the ESC and the host
        # to another (Set Baud), nothing of theirs gets through (foreign.AtBitrate)
        self.traffic = foreign.profile(name)
        self.source = foreign.AtBitrate(self.traffic, lane.bitrate, lambda: lane.bitrate)
        self.lane = lane
        self.player: TrafficPlayer | None = None
        self.stats: PlayerStats | None = None
        self._t0 = lane.now()
        self._elapsed: float | None = None
        lane.foreign_traffic = self  # the tests that judge it find it there
        if isinstance(lane, SimLane):
            lane.sim.world.add_source(self.source)
        else:
            assert isinstance(lane, BusLane)
            self.player = TrafficPlayer(lane.play, [self.source], bitrate=lane.bitrate).start()

    def stop(self) -> None:
        if self._elapsed is not None:
            return
        self._elapsed = self.lane.now() - self._t0
        if self.player is not None:
            self.stats = self.player.stop()
        elif isinstance(self.lane, SimLane):
            self.lane.sim.world.remove_source(self.source)

    def report(self) -> dict[str, Any]:
        """What was played (its streams, nodes and rates) and what it reached: frames sent, the share of the bus's
        capacity they took, and (real time) how late the player sent them."""
        out: dict[str, Any] = {"profile": self.name, "streams": self.traffic.describe(), "bitrate": self.source.bitrate,
                               "dropped_at_other_bitrate": self.source.dropped}
        if self.player is not None:
            st = self.stats or self.player.stats
            out.update(frames=st.frames, load=round(st.load, 6), late_mean_ms=round(st.late_mean_s * 1000, 3),
                       late_max_ms=round(st.late_max_s * 1000, 3), send_errors=st.send_errors, seconds=round(st.elapsed_s, 3))
        elif isinstance(self.lane, SimLane):
            sim = self.lane.sim.world.source_stats.get(self.traffic.name, {"frames": 0, "busy_s": 0.0})
            seconds = self._elapsed if self._elapsed is not None else self.lane.now() - self._t0
            out.update(frames=int(sim["frames"]), load=round(sim["busy_s"] / seconds, 6) if seconds > 0 else 0.0,
                       late_mean_ms=0.0, late_max_ms=0.0, send_errors=0, seconds=round(seconds, 3))
        return out
