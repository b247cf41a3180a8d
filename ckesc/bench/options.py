"""The bench's options, declared once: :data:`BENCH_ROWS`, one :class:`Option` row per option (the device under
test, its lane, bus, power and profile), from which pytest's flags, ``ckesc run``'s and a rig file's keys are made
(``ckesc/session/options.py`` lists them among the run's other options), and :class:`BenchOptions`, plain data with
one field per row. Below the checks that read them (:mod:`.checks`) and the station built from them
(:mod:`.station`), which both import them from here."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..emulator import variants
from .arguments import non_negative_float, positive_float, positive_int
from .firmware import FLASH_TIMEOUT_S
from .power import POWER_COMMAND_TIMEOUT_S
from .power import names as power_names
from .profile import DEFAULT_BUS_ERROR_S

#: the ``ckesc run --help`` group of the bench options (``ckesc/session/options.py`` names the others)
DUT = "device under test"
SAME = object()  # ``ckesc run``'s flag or default: the same as pytest's

#: How long the preflight waits for python-can to open the bus before it names the bus as not answering: a
#: socketcand client retries its connection for 10 s and then may wait for the daemon's greeting for ever; a USB
#: adapter that is not there fails at once. ``--bus-open-timeout`` gives another.
BUS_OPEN_TIMEOUT_S = 5.0


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
    Option("can_bitrate", type=positive_int, rig="bus.bitrate", help="bit rate of the host's bus (else can.conf / CAN_BITRATE)"),
    Option("can_config", action="append", default=[], metavar="KEY=VALUE", rig="bus.<any other key>",
           help="extra python-can bus argument (repeatable)"),
    Option("can_bitrate_cmd", metavar="CMD", rig="bitrate_cmd",
           help="--dut bus: command that moves the bus to another bit rate when a test needs it (Set Baud); {bitrate} is "
                "replaced. python-can cannot set a SocketCAN bit rate: e.g. a script running `ip link set can0 down; ip link "
                "set can0 type can bitrate {bitrate}; ip link set can0 up`, or `ckesc control --port P bitrate {bitrate}` "
                "for the emulator on vcan0"),
    Option("bus_fault_cmd", metavar="CMD",
           help="--dut bus: command that disturbs the DUT's bus for the robustness section's R20 tests and returns when it "
                "has ended; {seconds} is replaced (how long), {kind} (if given) by short or other_bitrate: e.g. a script "
                "closing a relay across CANH-CANL for {seconds}; labgrid: the relay driver (DigitalOutputProtocol) of "
                "--labgrid-env's target (docs/bench/bus-fault.md). Without it those tests SKIP; the emulator's bus is "
                "disturbed by the suite itself"),
    Option("host_send_error", type=non_negative_float, default=DEFAULT_BUS_ERROR_S * 1000, run_default=None, metavar="MS",
           rig="host_send_error_ms",
           help="--dut bus, an adapter that does not echo the host's frames: how much later than the host clock at send a "
                "frame may reach the bus (driver, USB, TX queue), in ms; the error of every time taken from the host's own "
                f"frames (default {DEFAULT_BUS_ERROR_S * 1000:g})"),
    Option("bus_open_timeout", type=positive_float, default=BUS_OPEN_TIMEOUT_S, metavar="S",
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
    Option("power_cmd_timeout", type=positive_float, default=POWER_COMMAND_TIMEOUT_S, metavar="S",
           help="--power command: a power command still running after S seconds has failed (default "
                f"{POWER_COMMAND_TIMEOUT_S:g})"),
    Option("labgrid_env", metavar="FILE", rig="power.labgrid.env",
           help="--power labgrid, --flash-cmd labgrid, --bus-fault-cmd labgrid: labgrid environment file whose target has "
                "a power driver (PowerProtocol), a flashing driver, a relay driver (DigitalOutputProtocol) or several"),
    Option("labgrid_target", metavar="NAME", rig="power.labgrid.target",
           help="--power / --flash-cmd / --bus-fault-cmd labgrid: the target in --labgrid-env (default: its only one)"),
    Option("labgrid_place", metavar="NAME", rig="place",
           help="--power labgrid: acquire this labgrid place for the run, release it at the end (default: the target's "
                "RemotePlace, if any)"),
    Option("labgrid_coordinator", metavar="HOST:PORT",
           help="--power labgrid: the labgrid coordinator (default: the env file's coordinator_address, LG_COORDINATOR, "
                "127.0.0.1:20408)"),
    Option("firmware", rig="firmware", metavar="IMAGE",
           help="the firmware image under test: flashed with --flash-cmd before the bench proof, then proven to be the one "
                "running by ESC Information (240) against IMAGE.toml, firmware.toml beside it or --expect-firmware; --dut "
                "emulator: an emulator image (a TOML file: its 240 answer, faults and options; docs/firmware.md)"),
    Option("flash_cmd", rig="flash_cmd", metavar="CMD",
           help="--firmware: the command that writes the image into the DUT, {image} replaced by its path (run without a "
                "shell); a non-zero exit or a hang is exit 2 before any test. --dut emulator: none needed (builtin). labgrid: the "
                "flashing driver of --labgrid-env's target (FlashromDriver, OpenOCDDriver, FlashScriptDriver, ...)"),
    Option("flash_timeout", rig="flash_timeout", type=positive_float, default=FLASH_TIMEOUT_S, metavar="S",
           help=f"--flash-cmd: a flash still running after S seconds has failed and is killed (default {FLASH_TIMEOUT_S:g})"),
    Option("expect_firmware", rig="expect_firmware", metavar="KEY=VALUE,...",
           help="--firmware: what 240 must answer (firmware_date=YYYY-MM-DD, protocol_version, hardware_version), over the "
                "image's sidecar"),
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
