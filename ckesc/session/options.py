"""The run's options, written once: :data:`OPTIONS` is the table from which pytest's options (the plugin's
``pytest_addoption``), ``ckesc run``'s arguments (``ckesc/cli/run.py``), the pytest command line ``ckesc run``
makes of them (:func:`command_line`, ``ckesc/run.py``) and the options a rig file sets per bench
(:data:`BENCH_OPTIONS`, ``ckesc/rigs/rig.py``) are made.

One row per option: its dest (pytest's ``config.getoption`` name, and ``ckesc run``'s ``args`` attribute),
its flags on each side (pytest's, ``ckesc run``'s, either absent where that side has no such option), how
argparse reads it (type, choices, action, default, metavar), its help (the same text on both sides), the
``ckesc run --help`` group it is listed under, and the rig file key that sets it per bench, if one does.
A new option is one row here; its use is where the option is read.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..bench.lanes import HOST_SEND_ERROR_S
from ..bench.power import POWER_COMMAND_TIMEOUT_S
from ..bench.power import names as power_names
from ..emulator import variants
from .preflight import BUS_OPEN_TIMEOUT_S
from .trace_files import TRACE_FORMATS

#: ``ckesc run --help``'s groups, in its order (pytest's ``--help`` lists every option under one "ckesc" group)
RIG, DUT, OUTPUT = ("several benches at once (pytest-xdist: pip install 'ckesc-conformance[rig]')", "device under test",
                    "output")
PYTEST_GROUP = ("ckesc", "CKESC conformance: device under test")
SAME = object()  # ``ckesc run``'s flag or default: the same as pytest's


@dataclass(frozen=True)
class Option:
    """One run option (see the module's docstring)."""

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


def _absolute(text: str) -> str:
    return str(Path(text).expanduser().resolve())


OPTIONS: tuple[Option, ...] = (
    Option("rig", group=RIG, metavar="FILE", pytest=None,
           help="a rig file (fixtures/rigs/*.toml): run on every bench of it at once, one pytest-xdist worker per bench; "
                "each bench's report in <reports>/<timestamp>/<bench>/, and batch.html, batch.json and a merged junit.xml "
                "beside them. The options below are then set per bench by the rig"),
    Option("benches", group=RIG, metavar="A,B", pytest=None, help="--rig: only these benches (default: every bench of the rig)"),
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
    Option("host_send_error", type=float, default=HOST_SEND_ERROR_S * 1000, run_default=None, metavar="MS",
           rig="host_send_error_ms",
           help="--dut bus, an adapter that does not echo the host's frames: how much later than the host clock at send a "
                "frame may reach the bus (driver, USB, TX queue), in ms; the error of every time taken from the host's own "
                f"frames (default {HOST_SEND_ERROR_S * 1000:g})"),
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
    Option("emulator_faults", default="", rig="emulator.faults", help="emulator: comma-separated fault names to switch on"),
    Option("emulator_seed", type=int, default=0, rig="emulator.seed", help="emulator: random seed"),
    Option("emulator_option", action="append", default=[], metavar="NAME=VALUE", rig="emulator.options",
           help="emulator: one conforming variant for every emulated ESC (repeatable; the names, values and the requirements "
                "that allow each: ckesc emulate --list-variants): " + ", ".join(variants.FREEDOMS)),
    Option("emulator_variants", type=int, metavar="SEED", rig="emulator.variants",
           help="emulator: every emulated ESC plays the conforming combination drawn from SEED (--emulator-option wins over "
                "the draw); the run's reports name the combination"),
    Option("ckesc_order", choices=("overlap", "collection"), default="overlap", run=("--order",),
           help="overlap (default): tests that neither power-cycle nor reconfigure the DUT run while a 120 s Set ID / Set "
                "Baud window elapses, and each window test runs at its moment, persistence tests share power cycles; "
                "collection: every test in collection order, each with its own waits and cycles (verdicts are the same)"),
    Option("ckesc_reports", group=OUTPUT, metavar="DIR", run=("--reports",), run_default="reports",
           help="write JUnit, JSON, text and HTML reports under DIR/<timestamp>/, DIR/latest pointing at the newest "
                "(ckesc run: default reports/)"),
    Option("ckesc_summary", group=OUTPUT, action="store_true", default=False, run=None,
           help="print the per-section summary at the end (ckesc run sets it)"),
    Option("ckesc_no_html", group=OUTPUT, action="store_true", default=False, run=None,
           help="with --ckesc-reports: no report.html (machine readers only, e.g. ckesc selftest's runs)"),
    Option("strict", group=OUTPUT, action="store_true", default=False, pytest=None,
           help="INCONCLUSIVE results fail the run too"),
    Option("ckesc_trace_format", group=OUTPUT, choices=TRACE_FORMATS, default="blf", run=("--trace-format",),
           help="each test's CAN traffic in <run>/traces/, written by python-can: blf (default; Vector BLF), asc (Vector "
                "ASCII), log (candump -L, `ckesc decode` reads it), none"),
    Option("quiet", group=OUTPUT, action="store_true", default=False, pytest=None, run=("-q", "--quiet"),
           help="no per-test progress lines"),
    Option("ckesc_progress", group=OUTPUT, choices=("on", "off"), default="on", run=("--progress",),
           help="a line per section with the protocol time planned, elapsed and an estimate of what is left (on a "
                "terminal also after pytest's counter); off: none"),
    Option("ckesc_durations", group=OUTPUT, type=_absolute, metavar="RESULTS_JSON", run=("--time-from",),
           help="time left: expect each test to take the lane time it took in this earlier run of the bench (its "
                "results.json; default: the suite's own table of a faultless simulated run, conformance/durations.json)"),
)

BY_DEST: dict[str, Option] = {o.dest: o for o in OPTIONS}
#: the options a rig file sets per bench, with their defaults (given on the command line with --rig: an error)
BENCH_OPTIONS: dict[str, Any] = {o.dest: o.default for o in OPTIONS if o.rig is not None}


def add_pytest_options(parser) -> None:
    """Every option with a pytest flag, as ``pytest_addoption`` adds them (``parser``: a ``pytest.Parser``)."""
    group = parser.getgroup(*PYTEST_GROUP)
    for o in OPTIONS:
        if o.pytest_flag:
            group.addoption(o.pytest_flag, **o.arguments())


def bench_options() -> tuple[Option, ...]:
    """The options that say which bench the run drives (the device under test, its lane, bus and power): what
    ``ckesc run`` and ``ckesc explore`` share."""
    return tuple(o for o in OPTIONS if o.group == DUT and o.dest != "ckesc_order")


def run_options() -> Iterable[Option]:
    """``ckesc run``'s options, in ``--help``'s order."""
    return (o for o in OPTIONS if o.run_flags)


def command_line(values: Mapping[str, Any]) -> list[str]:
    """The pytest options for ``values`` (dest -> value, in their order; options without a pytest flag and unset
    values, None, "", [] or False, left out): ``--dut bus --can-config a=1 --can-config b=2 --allow-motor-spin``."""
    out: list[str] = []
    for dest, value in values.items():
        o = BY_DEST[dest]
        if o.pytest_flag is None or value is None or value is False or value == "" or value == []:
            continue
        if o.action == "store_true":
            out.append(o.pytest_flag)
        elif o.action == "append":
            for v in value:
                out += [o.pytest_flag, str(v)]
        else:
            out += [o.pytest_flag, str(value)]  # (a seed 0 is a value)
    return out
