"""The ``ckesc`` command line.

Each subcommand is one ``add_<name>_command(subparsers)`` function that declares its arguments and
sets ``handler`` (a function ``(args) -> exit code``); :data:`COMMANDS` lists them and :func:`main`
builds the parser from that list. Adding a command (emulate, run, check-log, ...) is one function and
one entry in :data:`COMMANDS`; nothing else here needs to change.

Exit codes: 0 success; 1 the input had frames that do not decode (``decode``), the emulator
answered a control request with an error (``control``) or could not write its flash file at the end
(``emulate``); 2 usage or input the wire format cannot carry (``encode``), or the emulator cannot start
(``emulate``: port in use, unreadable flash file, bus that does not open); 3 no emulator answers on
the control port (``control``); 130 interrupted; 141 stdout closed early (``| head``).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
from typing import IO, Any, Callable, Sequence

import can

from .. import __version__
from ..evidence.candump import decode_lines
from ..evidence.checklog import add_check_log_command
from ..harness.html_report import add_report_command
from ..protocol import catalogue as cat
from ..protocol.assignments import AssignmentError, chosen_layout, encode_warnings, parse_assignments, parse_int
from ..protocol.errors import EncodeError
from ..protocol.frame import FALLBACK_PRIORITY, Decoder, encode
from ..protocol.ids import Kind, Priority
from ..run import add_run_command
from ..selftest import add_selftest_command

EXIT_OK = 0
EXIT_FRAMES_FAILED = 1
EXIT_USAGE = 2
EXIT_UNREACHABLE = 3
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, what a shell reports for a writer killed by `| head`


# ---------------------------------------------------------------------------------------------------
# Parser plumbing


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``ckesc encode: error: ... (see ckesc encode --help)``."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class UsageError(Exception):
    """Bad command-line input found after parsing; printed as one line, exit 2."""


Handler = Callable[[argparse.Namespace], int]


def _int_arg(text: str) -> int:
    try:
        return parse_int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r} (decimal or 0x-hex)") from None


def _priority_arg(text: str) -> int:
    try:
        return parse_int(text)
    except ValueError:
        pass
    try:
        return int(Priority[text.strip().upper()])
    except KeyError:
        names = ", ".join(p.name for p in Priority)
        raise argparse.ArgumentTypeError(f"not a priority: {text!r} (0..31 or one of {names})") from None


# ---------------------------------------------------------------------------------------------------
# ckesc decode


def _open_input(path: str | None) -> tuple[IO[str], Callable[[], None]]:
    """The text stream to read and how to let go of it (stdin is detached, not closed)."""
    if path is None or path == "-":
        buffer = getattr(sys.stdin, "buffer", None)
        if buffer is None:  # already a text stream (tests, embedding)
            return sys.stdin, lambda: None
        # undecodable bytes become U+FFFD and that line fails to parse, instead of a UnicodeDecodeError
        wrapper = io.TextIOWrapper(buffer, encoding="utf-8", errors="replace")
        return wrapper, wrapper.detach
    try:
        stream = open(path, encoding="utf-8", errors="replace")  # universal newlines: CRLF logs are fine
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror or exc}") from None
    return stream, stream.close


def _run_decode(args: argparse.Namespace) -> int:
    stream, release = _open_input(args.file)
    decoder = Decoder(nibble_order=args.nibble_order)
    failed = 0
    write = sys.stdout.write
    dumps = json.JSONEncoder().encode
    try:
        for record in decode_lines(stream, decoder):  # streamed: one line in memory at a time
            if "error" in record:
                failed += 1
            write(dumps(record) + "\n")
    finally:
        release()
    return EXIT_FRAMES_FAILED if failed else EXIT_OK


def add_decode_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "decode",
        help="decode candump lines into JSON, one object per line",
        description="Read candump lines (candump -L log, candump display form, or bare ID#DATA) from FILE or stdin "
        "and print one JSON object per frame line. A line that does not decode prints "
        '{"error": ..., "line": N, ...}. Exit 0 when every line decoded, 1 otherwise.',
    )
    p.add_argument("file", nargs="?", metavar="FILE", help="candump log; '-' or nothing: stdin")
    p.add_argument(
        "--nibble-order",
        choices=("lsb", "swapped"),
        default="lsb",
        help="RawCommand_12b nibble order (R4; 'swapped' is the one alternative a DUT profile may select)",
    )
    p.set_defaults(handler=_run_decode)


# ---------------------------------------------------------------------------------------------------
# ckesc encode


def _run_encode(args: argparse.Namespace) -> int:
    try:
        spec = cat.spec(args.name)
    except KeyError:
        raise UsageError(f"no frame {args.name!r}; see 'ckesc frames' (names: {', '.join(cat.BY_NAME)})") from None
    try:
        values = parse_assignments(spec, args.fields)
    except AssignmentError as exc:
        raise UsageError(str(exc)) from None
    kind = Kind.RESPONSE if args.response else (Kind.REQUEST if spec.service else Kind.MESSAGE)
    if spec.service and args.destination is None:
        raise UsageError(f"{spec.name} is a service ({spec.type_id}): give --destination N (the node id it goes to)")
    if not spec.service and args.destination is not None:
        raise UsageError(f"{spec.name} is a message ({spec.type_id}): messages are broadcast, --destination does not apply")
    try:
        wire = encode(
            spec,
            values,
            kind=kind,
            source=args.source,
            destination=args.destination,
            transfer_id=args.transfer_id,
            priority=args.priority,
            layout=args.layout,
            nibble_order=args.nibble_order,
        )
    except EncodeError as exc:
        text = str(exc)
        raise UsageError(text if text.startswith(spec.name) else f"{spec.name} {text}") from None
    except (TypeError, ValueError) as exc:  # defensive: never a traceback for bad input
        raise UsageError(f"{spec.name}: cannot encode {values}: {exc}") from None
    layout = chosen_layout(spec, kind, wire.data, values, args.layout)
    for warning in encode_warnings(spec, layout, values, args.source, args.destination):
        print(f"ckesc encode: warning: {warning}", file=sys.stderr)
    print(wire)
    return EXIT_OK


def add_encode_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "encode",
        help="build one frame and print it as ID#DATA",
        description="Build one frame from field values and print it as candump/cansend ID#DATA. Values are decimal or "
        "0x-hex, lists comma-separated (channels=1000,1000,1000,1000), or a code name (option=write). Values outside "
        "the document's legal range print a warning and are still encoded; values the wire cannot carry exit 2.",
        epilog="examples: ckesc encode set_freq option=1 msg1_interval=10 msg2_interval=50 msg3_interval=250 --destination 1\n"
        "          ckesc encode raw_command_12b channels=1000,1000,1000,1000 group=1",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("name", metavar="NAME", help="catalogue name (set_freq), type id (214) or title; see 'ckesc frames'")
    p.add_argument("fields", nargs="*", metavar="KEY=VALUE", help="field values")
    p.add_argument("--source", type=_int_arg, default=0, metavar="N", help="source node id (default 0, the host: 4.4.18 note 8)")
    p.add_argument("--destination", type=_int_arg, metavar="N", help="destination node id (services only; required for them)")
    p.add_argument("--transfer-id", type=_int_arg, default=0, metavar="N", help="transfer id 0..31 (default 0)")
    p.add_argument(
        "--priority",
        type=_priority_arg,
        metavar="N|NAME",
        help=f"0..31 or HIGHEST/HIGH/MEDIUM/LOW/LOWEST (default: the table's, else {FALLBACK_PRIORITY.name})",
    )
    p.add_argument("--response", action="store_true", help="a service response (default: a request)")
    p.add_argument("--layout", metavar="NAME", help="layout by name where several fit (20013 query/reply, 241 response_option_N)")
    p.add_argument("--nibble-order", choices=("lsb", "swapped"), default="lsb", help="RawCommand_12b nibble order (R4)")
    p.set_defaults(handler=_run_encode)


# ---------------------------------------------------------------------------------------------------
# ckesc frames


def _frame_rows() -> list[dict[str, Any]]:
    rows = []
    for s in cat.CATALOGUE:
        rows.append(
            {
                "id": s.type_id,
                "name": s.name,
                "kind": s.kind_label,
                "priority": None if s.priority is None else int(s.priority),
                "priority_name": None if s.priority is None else s.priority.name,
                "section": s.section,
                "title": s.title,
            }
        )
    return rows


def _run_frames(args: argparse.Namespace) -> int:
    rows = _frame_rows()
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return EXIT_OK
    table = [("ID", "NAME", "KIND", "PRIORITY", "SECTION", "TITLE")]
    for r in rows:
        prio = "-" if r["priority"] is None else f"{r['priority_name']} ({r['priority']})"
        table.append((str(r["id"]), r["name"], r["kind"], prio, r["section"], r["title"]))
    widths = [max(len(row[i]) for row in table) for i in range(len(table[0]) - 1)]
    for row in table:
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)) + "  " + row[-1])
    print(f"\n'-': the table lists no priority (F5: OBSERVE); encode uses {FALLBACK_PRIORITY.name} ({int(FALLBACK_PRIORITY)}).")
    return EXIT_OK


def add_frames_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("frames", help="list the frame catalogue", description="List every frame of the CKESC 2.1 catalogue.")
    p.add_argument("--json", action="store_true", help="one JSON object per frame")
    p.set_defaults(handler=_run_frames)


# ---------------------------------------------------------------------------------------------------
# ckesc emulate


def _node_ids(text: str) -> list[int]:
    """"1,2,3" or "1-20" or a mix; each 1..0x7D (F7) and given once."""
    nodes: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        lo, dash, hi = part.partition("-")
        try:
            first, last = (parse_int(lo), parse_int(hi)) if dash else (parse_int(part), parse_int(part))
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a node id list: {text!r} (e.g. 1,2,3 or 1-20)") from None
        nodes.extend(range(first, last + 1))
    if not nodes:
        raise argparse.ArgumentTypeError("no node ids given")
    bad = [n for n in nodes if not 1 <= n <= 0x7D]
    if bad:
        raise argparse.ArgumentTypeError(f"node ids must be 1..125 (F7), not {bad[0]}")
    if len(set(nodes)) != len(nodes):
        raise argparse.ArgumentTypeError(f"a node id is given twice in {text!r}")
    return nodes


def _fault_spec(text: str | None, nodes: list[int]) -> list[str] | dict[int, list[str]]:
    """"a,b" (every ESC) with "name@node" for one ESC only."""
    if not text:
        return []
    everywhere: list[str] = []
    per_node: dict[int, list[str]] = {}
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        name, at, node_text = item.partition("@")
        if not at:
            everywhere.append(name)
            continue
        try:
            node = parse_int(node_text)
        except ValueError:
            raise UsageError(f"--faults {item!r}: {node_text!r} is not a node id") from None
        if node not in nodes:
            raise UsageError(f"--faults {item!r}: there is no ESC with node id {node} (--nodes {','.join(map(str, nodes))})")
        per_node.setdefault(node, []).append(name)
    if not per_node:
        return everywhere
    return {n: everywhere + per_node.get(n, []) for n in nodes}


def _open_bus(args: argparse.Namespace) -> can.BusABC:
    kwargs: dict[str, Any] = {}
    for item in args.bus_arg or ():
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise UsageError(f"--bus-arg {item!r} is not key=value")
        kwargs[key.strip()] = can.util.cast_from_string(value)
    if args.interface == "virtual":
        kwargs.setdefault("preserve_timestamps", True)  # the due-time stamps reach the other buses
    try:
        return can.Bus(interface=args.interface, channel=args.channel, bitrate=args.bitrate, ignore_config=True, **kwargs)
    except (can.CanError, ValueError, TypeError, OSError, ImportError) as exc:
        raise UsageError(f"cannot open the {args.interface} bus on channel {args.channel!r}: {exc}") from None


def _run_emulate(args: argparse.Namespace) -> int:
    import signal
    import threading
    import time

    from ..emulator.bench import Bench
    from ..emulator.flash import FlashError
    from ..emulator.realtime import RealtimeEmulator, stagger_boot

    if args.socketcand is None and args.interface is None:
        raise UsageError("give --socketcand PORT (a hub for python-can's socketcand client) or --interface/--channel (a python-can bus)")
    if args.interface is not None and args.channel is None:
        raise UsageError(f"--interface {args.interface} needs --channel")
    if args.boot_spread < 0 or (args.duration is not None and args.duration < 0):
        raise UsageError("--boot-spread and --duration are seconds, 0 or more")
    if args.rt_priority is not None and not 1 <= args.rt_priority <= 99:
        raise UsageError(f"--rt-priority must be 1..99 (SCHED_FIFO), not {args.rt_priority}")
    faults = _fault_spec(args.faults, args.nodes)
    try:
        bench = Bench(args.nodes, faults=faults, flash=args.flash_path, seed=args.seed)
    except FlashError as exc:
        raise UsageError(str(exc)) from None
    except ValueError as exc:  # unknown fault names, listed with the known ones
        raise UsageError(str(exc)) from None
    except OSError as exc:
        raise UsageError(f"cannot read the flash file {args.flash_path}: {exc.strerror or exc}") from None
    stagger_boot(bench, args.boot_spread)
    bus = _open_bus(args) if args.interface is not None else None
    try:
        emulator = RealtimeEmulator(bench, bus=bus, own_bus=True, socketcand_port=args.socketcand, control_port=args.control,
                                    bitrate=args.bitrate, stamp=args.stamp, echo_own=not args.no_echo_own,
                                    rt_priority=args.rt_priority)
    except OSError as exc:
        if bus is not None:
            bus.shutdown()
        which = " or ".join(f"--{name} {port}" for name, port in (("socketcand", args.socketcand), ("control", args.control))
                            if port is not None)
        raise UsageError(f"cannot listen on 127.0.0.1 ({which}): {exc.strerror or exc}") from None
    for key, address in (("socketcand", emulator.socketcand_address), ("control", emulator.control_address)):
        if address is not None:
            print(f"{key} {address[0]}:{address[1]}")
    if bus is not None:
        print(f"bus {args.interface} {args.channel}")
    print(f"ready nodes={','.join(str(esc.node_id) for esc in bench.escs)} bitrate={args.bitrate}", flush=True)

    def on_signal(signum: int, frame: Any) -> None:
        emulator.stop()

    handled = (signal.SIGINT, signal.SIGTERM)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = {sig: signal.signal(sig, on_signal) for sig in handled}
    started = time.monotonic()
    try:
        emulator.run(duration=args.duration, power_on=not args.unpowered)
    except OSError as exc:  # the flash file could not be written at power-off
        print(f"ckesc emulate: error: {exc}", file=sys.stderr)
        return EXIT_FRAMES_FAILED
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    late = emulator.lateness.summary()
    flash = f"; flash saved to {args.flash_path}" if args.flash_path else ""
    print(f"ckesc emulate: stopped after {time.monotonic() - started:.1f} s: {emulator.counters['tx']} frames sent, "
          f"{emulator.counters['rx']} heard; lateness p50 {late['p50_us']} us, p99 {late['p99_us']} us, "
          f"max {late['max_us']} us{flash}", file=sys.stderr)
    return EXIT_OK


def add_emulate_command(sub: argparse._SubParsersAction) -> None:
    from ..protocol.catalogue import DEFAULT_BITRATE

    p = sub.add_parser(
        "emulate",
        help="run emulated ESCs in real time (socketcand hub or a python-can bus)",
        description="Run a bench of emulated ESCs on one power supply in real time, until SIGINT/SIGTERM (or --duration). "
        "With --socketcand PORT it serves the socketcand protocol on 127.0.0.1, for can.Bus(interface='socketcand', "
        "host='127.0.0.1', port=PORT, channel='can0'); with --interface/--channel it sits on a python-can bus. "
        "It prints one line per listening socket ('socketcand 127.0.0.1:PORT', 'control 127.0.0.1:PORT'; PORT 0 picks a "
        "free one) and then 'ready ...' on stdout, flushed. On stop it powers the bench off and writes the flash file. "
        "Exit 0 on a clean stop, 2 when it cannot start.",
        epilog="examples: ckesc emulate --nodes 1,2,3 --socketcand 0 --control 0 --flash-path esc-flash.json\n"
        "          ckesc emulate --nodes 1-20 --interface socketcan --channel vcan0 --control 29536\n"
        "          ckesc control --port 29536 power cycle --off-time 1.0",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--nodes", type=_node_ids, default=[1], metavar="IDS", help="node ids of factory-fresh ESCs: 1,2,3 or 1-20 (default 1)")
    p.add_argument("--faults", metavar="NAMES", help="faults for every ESC, name@node for one (see ckesc.emulator.faults)")
    p.add_argument("--flash-path", metavar="FILE", help="flash file: settings and counters persist across runs (default: none)")
    p.add_argument("--seed", type=_int_arg, default=0, metavar="N", help="seed of the models' noise (default 0)")
    p.add_argument("--socketcand", type=_int_arg, metavar="PORT", help="serve socketcand on 127.0.0.1:PORT (0: a free port)")
    p.add_argument("--interface", metavar="NAME", help="python-can interface to sit on (socketcan, virtual, ...)")
    p.add_argument("--channel", metavar="NAME", help="python-can channel (vcan0, ...)")
    p.add_argument("--bitrate", type=_int_arg, default=DEFAULT_BITRATE, metavar="BIT/S",
                   help=f"bit rate of the emulated bus; ESCs at another rate neither hear nor are heard (default {DEFAULT_BITRATE})")
    p.add_argument("--bus-arg", action="append", metavar="KEY=VALUE", help="extra python-can bus argument (repeatable)")
    p.add_argument("--control", type=_int_arg, metavar="PORT", help="control channel on 127.0.0.1:PORT (0: a free port); see ckesc control")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (default: run until SIGINT/SIGTERM)")
    p.add_argument("--stamp", choices=("due", "send"), default="due",
                   help="bus timestamp of ESC frames: the time they were due (default) or the time they were sent")
    p.add_argument("--boot-spread", type=float, default=0.02, metavar="S",
                   help="ESC k of n boots k/n x S later than the first, so that their reports are not in lockstep, as on a "
                   "real bench (default 0.02: one MSG1 interval; 0: all at once, as the simulated lane)")
    p.add_argument("--rt-priority", type=_int_arg, metavar="N",
                   help="run the scheduler thread SCHED_FIFO at priority N (1..99; needs CAP_SYS_NICE, else a warning): "
                   "on a loaded machine this keeps other processes from delaying frames by milliseconds")
    p.add_argument("--no-echo-own", action="store_true", help="socketcand: do not echo a client's frames back to it")
    p.add_argument("--unpowered", action="store_true", help="start with the power off (switch it on with ckesc control)")
    p.set_defaults(handler=_run_emulate)


# ---------------------------------------------------------------------------------------------------
# ckesc control


def _control_port(args: argparse.Namespace) -> int:
    if args.port is not None:
        return args.port
    env = os.environ.get("CKESC_CONTROL_PORT")
    if env:
        try:
            return parse_int(env)
        except ValueError:
            raise UsageError(f"CKESC_CONTROL_PORT={env!r} is not a port number") from None
    raise UsageError("give --port P (the emulator's --control port) or set CKESC_CONTROL_PORT")


def _control_request(args: argparse.Namespace) -> dict[str, Any]:
    action = args.action
    if action == "power":
        req: dict[str, Any] = {"cmd": "power", "action": args.state}
        if args.state == "cycle":
            req["off_time"] = args.off_time
        elif args.off_time is not None:
            raise UsageError("--off-time applies to 'power cycle' only")
        return req
    if action == "fault":
        return {"cmd": "fault", "name": args.name, "on": args.state == "on", "node": args.node}
    if action == "bitrate":
        return {"cmd": "bitrate", "bitrate": args.bitrate}
    if action == "stats":
        return {"cmd": "stats", "reset": args.reset}
    return {"cmd": action}


def _run_control(args: argparse.Namespace) -> int:
    from ..emulator.realtime import ControlError, control_request

    if args.action == "power" and args.state == "cycle" and args.off_time is None:
        args.off_time = 1.0
    req = _control_request(args)
    port = _control_port(args)
    try:
        answer = control_request(port, req, timeout=args.timeout)
    except ControlError as exc:
        print(f"ckesc control: error: {exc}", file=sys.stderr)
        return EXIT_UNREACHABLE if exc.unreachable else EXIT_FRAMES_FAILED
    print(json.dumps(answer, indent=1 if args.action in ("status", "faults") else None))
    return EXIT_OK


def add_control_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "control",
        help="switch the power, faults and bit rate of a running 'ckesc emulate'",
        description="Send one request to a running 'ckesc emulate --control PORT' and print its JSON answer. Usable as a "
        "harness's power commands: 'ckesc control --port P power off' / 'power on' / 'power cycle --off-time 1.0' (which "
        "returns once the power is back on). Exit 0 done, 1 the emulator refused (the message says why), 3 no emulator "
        "answers on that port.",
        epilog="examples: ckesc control --port 29536 status\n"
        "          ckesc control --port 29536 fault answer_late on --node 3\n"
        "          CKESC_CONTROL_PORT=29536 ckesc control power cycle --off-time 0.5",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--port", type=_int_arg, metavar="P", help="the emulator's control port (default: $CKESC_CONTROL_PORT)")
    p.add_argument("--timeout", type=float, metavar="S", help="seconds to wait for the answer (default 10, plus the off time)")
    actions = p.add_subparsers(dest="action", metavar="ACTION", parser_class=_Parser, required=True)
    actions.add_parser("status", help="power state, bit rate, per-ESC node ids, faults and counters, timing")
    power = actions.add_parser("power", help="power off / on / cycle")
    power.add_argument("state", choices=("off", "on", "cycle"))
    power.add_argument("--off-time", type=float, metavar="S", help="cycle: seconds without power (default 1.0)")
    fault = actions.add_parser("fault", help="switch a fault on or off")
    fault.add_argument("name", metavar="NAME", help="fault name (ckesc control faults lists them)")
    fault.add_argument("state", choices=("on", "off"))
    fault.add_argument("--node", type=_int_arg, metavar="N", help="only the ESC with this node id (default: every ESC)")
    actions.add_parser("faults", help="list the known faults")
    bitrate = actions.add_parser("bitrate", help="set the emulated bus's bit rate")
    bitrate.add_argument("bitrate", type=_int_arg, metavar="BIT/S")
    stats = actions.add_parser("stats", help="frame lateness (send - due) and wake-up lateness")
    stats.add_argument("--reset", action="store_true", help="start counting afresh")
    actions.add_parser("save", help="write the flash file now")
    actions.add_parser("stop", help="stop the emulator (power off, flash saved)")
    p.set_defaults(handler=_run_control)


# ---------------------------------------------------------------------------------------------------
# main

#: The subcommands, in help order. Each adds its parser and sets ``handler``.
COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [
    add_run_command,
    add_selftest_command,
    add_report_command,
    add_decode_command,
    add_check_log_command,
    add_encode_command,
    add_frames_command,
    add_emulate_command,
    add_control_command,
]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="ckesc", description="Tools for the CKESC UAVCAN Protocol 2.1 conformance suite.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for add in COMMANDS:
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, usage errors: a return code, as for every other outcome
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    handler: Handler | None = getattr(args, "handler", None)
    if handler is None:
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    try:
        return handler(args)
    except UsageError as exc:
        print(f"ckesc {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE


def _silence_stdout() -> None:
    """After the reader of our stdout went away (``| head``), point stdout at /dev/null so that the
    interpreter's final flush does not print a second BrokenPipeError (Python docs, 'Note on SIGPIPE')."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        pass

