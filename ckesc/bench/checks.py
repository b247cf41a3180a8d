"""The checks a bench's options pass before anything is opened (:func:`check`: node ids, emulator faults and
variants, option combinations, the DUT profile, the power commands, labgrid's options, the bit-rate command), and
the bus's own (:func:`bus_kwargs`: python-can's arguments resolved; :func:`open_bus`: opened once within
:data:`BUS_OPEN_TIMEOUT_S` and closed again, with the way out named for a kernel without SocketCAN). Each mistake
is one :class:`.errors.PreflightError` line naming it and, where there is one, the way out (exit status 2).

:func:`.station.build` runs them; the session's preflight (``ckesc/session/preflight.py``) adds what is not the
bench's (the reports directory).
"""

from __future__ import annotations

import errno
import logging
import os
import shlex
import shutil
import socket
import sys
from typing import Any

from ..emulator import variants
from ..emulator.faults import FAULTS, onsets_in
from ..protocol.ids import ESC_NODE_IDS
from . import labgrid_relay
from .errors import PreflightError
from .labgrid_power import labgrid_options
from .options import BUS_OPEN_TIMEOUT_S, BenchOptions
from .profile import DutProfile, ProfileError


def node_id(text: str | int, what: str = "node id") -> int:
    """A node id an ESC can have (F7: 1..0x7D), from ``5`` or ``0x05``."""
    try:
        value = text if isinstance(text, int) else int(str(text).strip(), 0)
    except ValueError:
        raise PreflightError(f"{what} {text!r} is not a number") from None
    if value not in ESC_NODE_IDS:
        raise PreflightError(f"{what} {value} is out of range: an ESC's node id is {ESC_NODE_IDS.start}.."
                             f"{ESC_NODE_IDS.stop - 1} (0 is the host's; 126 and 127 are reserved, F7)")
    return value


def node_list(text: str) -> list[int]:
    ids = [node_id(part, "--nodes: node id") for part in text.split(",") if part.strip()]
    if not ids:
        raise PreflightError(f"--nodes {text!r} names no node id")
    dupes = sorted({n for n in ids if ids.count(n) > 1})
    if dupes:
        raise PreflightError(f"--nodes names node id {dupes[0]} twice: two ESCs with one node id cannot be told apart")
    return ids


def fault_names(text: str, option: str = "--emulator-faults") -> list[str]:
    """--emulator-faults: fault names, each maybe ``NAME=SECONDS`` (a soak fault's onset moved), checked (a mistake
    said in the same words for every option that takes fault names: ``option``)."""
    names = [f.strip() for f in text.split(",") if f.strip()]
    unknown = [f for f in names if f.partition("=")[0].strip() not in FAULTS]
    if unknown:
        import difflib

        close = difflib.get_close_matches(unknown[0], list(FAULTS), n=3)
        raise PreflightError(f"{option}: unknown fault {unknown[0]!r}"
                             + (f" (did you mean {', '.join(close)}?)" if close else "")
                             + "; `ckesc control faults` or ckesc/emulator/faults.py lists them")
    try:
        onsets_in(names)
    except ValueError as exc:
        raise PreflightError(f"{option}: {exc}") from None
    return names


def emulator_options(items: list[str] | tuple[str, ...], seed: int | None = None) -> dict[str, Any]:
    """--emulator-option NAME=VALUE over the combination --emulator-variants SEED draws, checked: {EscConfig
    field: value}. The names and their conforming values are ckesc/emulator/variants.py's."""
    try:
        return variants.combination(list(items), seed)
    except variants.VariantError as exc:
        raise PreflightError(f"--emulator-option: {exc}") from None


def command(cmd: str | None, option: str) -> None:
    """A command line given to the suite: not empty, splits like a shell line, its program exists."""
    if not cmd:
        raise PreflightError(f"{option} is empty")
    try:
        argv = shlex.split(cmd)
    except ValueError as exc:
        raise PreflightError(f"{option} {cmd!r}: {exc}") from None
    if not argv:
        raise PreflightError(f"{option} is empty")
    program = argv[0]
    if os.sep in program:
        if not (os.path.isfile(program) and os.access(program, os.X_OK)):
            raise PreflightError(f"{option}: {program!r} is not an executable file")
    elif shutil.which(program) is None:
        raise PreflightError(f"{option}: program {program!r} not found on PATH (the command is run without a shell: "
                             "wrap pipes and redirections in sh -c '...')")


def bus_fault_command(options: BenchOptions) -> None:
    """``--bus-fault-cmd``: a real bench's (the emulator's faults are the suite's own), ``labgrid`` with its
    environment file, or a command that names ``{seconds}`` and can be run."""
    cmd = options.bus_fault_cmd
    if options.dut != "bus":
        raise PreflightError("--bus-fault-cmd is for --dut bus; the emulator's bus is disturbed by the suite itself "
                             "(ckesc control bus)")
    if cmd == labgrid_relay.LABGRID:
        labgrid_relay.check(options.labgrid_env)
        return
    if "{seconds}" not in cmd:
        raise PreflightError(f"--bus-fault-cmd {cmd!r} needs {{seconds}} (how long the relay shorts the bus), or is "
                             "labgrid")
    command(cmd.replace("{seconds}", "0.5").replace("{kind}", "short"), "--bus-fault-cmd")


def load_profile(options: BenchOptions) -> DutProfile:
    """The run's DUT profile: ``--profile``, else the emulator's or the generic one; on a real bus with the limits it
    leaves out taken from their named defaults (:meth:`.profile.DutProfile.on_a_real_bus`)."""
    name = options.profile or ("emulator" if options.dut == "emulator" else "ckesc-generic")
    try:
        loaded = DutProfile.load(name)
    except ProfileError as exc:
        raise PreflightError(str(exc)) from None
    # a real bus is never taken as exact: the limits the profile leaves out are the named defaults, said by the run
    return loaded.on_a_real_bus() if options.dut == "bus" else loaded


def bus_where(kwargs: dict[str, Any]) -> str:
    """The bus as the user gave it: its interface, channel, address (host, port) and bit rate."""
    keys = ("interface", "channel", "host", "port", "bitrate")
    return ", ".join(f"{k}={kwargs[k]}" for k in keys if kwargs.get(k) is not None)


def open_bus_bounded(kwargs: dict[str, Any], timeout: float = BUS_OPEN_TIMEOUT_S) -> Any:
    """``can.Bus(**kwargs)``, given at most ``timeout`` s (a :class:`PreflightError` naming the interface and the
    address otherwise): python-can opens a bus in its constructor and some backends retry or block there (a
    socketcand daemon nobody runs, a network adapter that does not answer). The open runs in a daemon thread; one
    that never returns is abandoned (the run stops with exit 2), one that returns late is shut down."""
    import threading

    import can

    if kwargs.get("interface") == "socketcand":
        _reach(kwargs, timeout)
    box: dict[str, Any] = {}
    late = threading.Event()

    def opener() -> None:
        try:
            bus = can.Bus(**kwargs)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller below
            box["error"] = exc
            return
        if late.is_set():  # the caller gave up on it: nobody will close it otherwise
            _shutdown(bus)
        else:
            box["bus"] = bus

    thread = threading.Thread(target=opener, name="ckesc-bus-open", daemon=True)
    thread.start()
    thread.join(timeout)
    if thread.is_alive():
        late.set()
        if "bus" in box:  # it opened just now
            return box["bus"]
        # what the abandoned open still logs (python-can's socketcand client warns at every retry) goes nowhere: the
        # run ends with the one line below, not hundreds of warnings after it
        logging.getLogger("can").addHandler(logging.NullHandler())
        raise PreflightError(f"cannot open the CAN bus ({bus_where(kwargs)}): no answer within {timeout:g} s (is the "
                             "adapter plugged in, the socketcand daemon or `ckesc emulate` running at that address and "
                             "port? --bus-open-timeout gives it longer)")
    if "error" in box:
        exc = box["error"]
        cause = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        hint = ""
        if getattr(exc, "errno", None) == errno.EAFNOSUPPORT or "Address family not supported" in str(exc) or (
                kwargs.get("interface") == "socketcan" and not hasattr(socket, "AF_CAN")):
            hint = (" - this kernel has no SocketCAN (AF_CAN): run the suite on a Linux host with can0/vcan0, or in "
                    "the VM lane (tools/vm-lane)")
        elif isinstance(exc, can.CanInterfaceNotImplementedError) or "Unknown interface" in str(exc):
            hint = f" - known interfaces: {', '.join(sorted(can.interfaces.VALID_INTERFACES))}"
        raise PreflightError(f"cannot open the CAN bus ({bus_where(kwargs)}): {' '.join(cause.split())}{hint}") from None
    return box["bus"]


def _reach(kwargs: dict[str, Any], timeout: float) -> None:
    """A socketcand daemon's address, tried once before python-can's client (which retries for 10 s): nobody
    listening there is said at once, and is not helped by a longer --bus-open-timeout."""
    host, port = kwargs.get("host"), kwargs.get("port")
    try:
        socket.create_connection((str(host), int(port)), timeout=timeout).close()
    except TimeoutError:
        raise PreflightError(f"cannot open the CAN bus ({bus_where(kwargs)}): {host}:{port} does not answer within "
                             f"{timeout:g} s (a host that drops the connection? --bus-open-timeout gives it longer)") from None
    except (OSError, ValueError, OverflowError) as exc:
        why = "nobody listens there (connection refused)" if isinstance(exc, ConnectionRefusedError) else (
            getattr(exc, "strerror", None) or str(exc))
        raise PreflightError(f"cannot open the CAN bus ({bus_where(kwargs)}): {host}:{port}: {why}; is the socketcand "
                             f"daemon or `ckesc emulate --socketcand PORT` running at that address, and --can-config "
                             "host and port right?") from None


def _shutdown(bus: Any) -> None:
    try:
        bus.shutdown()
    except Exception:  # noqa: BLE001 - it opened; closing is best effort
        pass


def open_bus(kwargs: dict[str, Any], timeout: float = BUS_OPEN_TIMEOUT_S) -> None:
    """Open the bus once and close it: a dead adapter, or an address nobody answers at, is named here (within
    ``timeout`` s), not by every test."""
    _shutdown(open_bus_bounded(kwargs, timeout))


def bus_kwargs(options: BenchOptions) -> dict[str, Any]:
    """python-can's arguments for --dut bus: the options, then CAN_* and can.conf (a mistake: PreflightError)."""
    import can

    kwargs: dict[str, Any] = {}
    if options.can_interface:
        kwargs["interface"] = options.can_interface
    if options.can_channel:
        kwargs["channel"] = options.can_channel
    if options.can_bitrate:
        kwargs["bitrate"] = options.can_bitrate
    for kv in options.can_config:
        key, sep, value = kv.partition("=")
        if not sep:
            raise PreflightError(f"--can-config takes KEY=VALUE, got {kv!r}")
        kwargs[key] = can.util.cast_from_string(value)
    try:
        resolved = can.util.load_config(config=kwargs)  # explicit options, then CAN_* and can.conf
    except (can.CanInterfaceNotImplementedError, ValueError, TypeError) as exc:
        if not kwargs.get("interface") and '"None"' in str(exc):  # none given anywhere: python-can's 'Unknown ... "None"'
            raise PreflightError(no_interface()) from None
        raise PreflightError(f"the CAN bus configuration {kwargs}: {exc} (known interfaces: "
                             f"{', '.join(sorted(can.interfaces.VALID_INTERFACES))})") from None
    if not resolved.get("interface"):
        raise PreflightError(no_interface())
    if resolved["interface"] == "socketcand":  # python-can's own word would be a TypeError about positional arguments
        missing = [k for k in ("host", "port") if resolved.get(k) in (None, "")]
        if missing:
            raise PreflightError("--can-interface socketcand needs the daemon's address: give "
                                 + " ".join(f"--can-config {k}={k.upper()}" for k in missing)
                                 + " (`ckesc emulate --socketcand PORT` serves one on 127.0.0.1)")
    return dict(resolved)


#: interfaces that need no adapter (a daemon over TCP/IP, a process's own buses) or whose detection lists
#: every serial port (serial): not probed, named as always there
_NO_ADAPTER = ("socketcand", "udp_multicast", "virtual")
_NOT_PROBED = (*_NO_ADAPTER, "serial", "ckesc-sim")
#: how long the adapters are looked for (python-can asks each driver in turn)
_PROBE_S = 5.0


def adapters_here() -> list[str]:
    """The CAN adapters python-can finds on this machine (``interface channel``), looked for at most
    :data:`_PROBE_S`; the drivers' complaints about what they lack stay off the console."""
    import logging
    import threading

    import can

    found: list[dict[str, Any]] = []
    names = [n for n in sorted(can.interfaces.VALID_INTERFACES) if n not in _NOT_PROBED]

    def probe() -> None:
        found.extend(can.detect_available_configs(interfaces=names))

    level = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        t = threading.Thread(target=probe, name="ckesc-adapters", daemon=True)
        t.start()
        t.join(_PROBE_S)
    finally:
        logging.disable(level)
    return [f"{c.get('interface')} {c.get('channel')}" for c in list(found)]


def no_interface() -> str:
    """The one line for ``--dut bus`` with no interface given anywhere: what to give, and what there is."""
    found = adapters_here()
    return ("--dut bus needs --can-interface NAME (with its --can-channel / --can-config; or CAN_INTERFACE / can.conf): "
            f"adapters python-can finds here: {', '.join(found) if found else 'none'}; needing no adapter: "
            f"{', '.join(_NO_ADAPTER)} (socketcand: a socketcand daemon, e.g. ckesc emulate --socketcand 0)")


def check(options: BenchOptions) -> DutProfile:
    """Every check of the bench's options that opens nothing, in the order a person fixes them; the first failure
    raises :class:`PreflightError`. Returns the DUT profile (on a real bus with the defaults it leaves out taken)."""
    get = options.get
    dut = options.dut
    if options.node_id is not None:
        node_id(options.node_id, "--node-id")
    if options.nodes:
        if dut != "emulator":
            raise PreflightError("--nodes builds an emulated bench: it needs --dut emulator (give --node-id for a real ESC)")
        node_list(options.nodes)
    if options.emulator_faults:
        if dut != "emulator":
            raise PreflightError("--emulator-faults switches faults of the emulator: it needs --dut emulator")
        fault_names(options.emulator_faults)
    if options.emulator_option or options.emulator_variants is not None:
        if dut != "emulator":
            raise PreflightError("--emulator-option and --emulator-variants set the emulator's ESCs: they need --dut emulator")
        emulator_options(options.emulator_option, options.emulator_variants)
    prof = load_profile(options)
    power = options.power
    labgrid_options(get)
    if options.bus_fault_cmd:
        bus_fault_command(options)
    if dut == "emulator" and power not in (None, "emulator"):
        raise PreflightError(f"--power {power} is for --dut bus; the emulator's power is switched by the suite")
    if dut == "bus":
        if power == "emulator":
            raise PreflightError("--power emulator works only with --dut emulator (for a real ESC: command, labgrid, manual "
                                 "or none)")
        if power == "command":
            if not options.power_off_cmd or not options.power_on_cmd:
                raise PreflightError("--power command needs both --power-off-cmd and --power-on-cmd")
            command(options.power_off_cmd, "--power-off-cmd")
            command(options.power_on_cmd, "--power-on-cmd")
        elif power == "manual" and not sys.stdin.isatty():
            raise PreflightError("--power manual prompts an operator, but standard input is not a terminal "
                                 "(use --power command, or --power none to skip the persistence tests)")
        if options.can_bitrate_cmd:
            command(options.can_bitrate_cmd.replace("{bitrate}", "500000"), "--can-bitrate-cmd")
    return prof
