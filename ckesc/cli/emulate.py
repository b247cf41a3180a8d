"""``ckesc emulate``: emulated ESCs in real time, on a socketcand hub or a python-can bus."""

from __future__ import annotations

import argparse
import sys
from typing import Any

import can

from ..emulator import variants
from ..emulator.host_alone import HOST_ALONE, TX_QUEUE_LEN
from ..emulator.socketcand import HANDLES
from ..protocol.assignments import parse_int
from ..reporting.exits import ExitStatus
from .common import UsageError, check_faults, check_file, int_arg, non_negative_float, port_arg, positive_float


def _node_ids(text: str) -> list[int]:
    """"1,2,3" or "1-20" or a mix; each 1..0x7D (F7) and given once. "none": no ESC at all, a bare socketcand
    hub that other processes (an ESC of another make, a second host) join as clients."""
    if text.strip().lower() == "none":
        return []
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
    except (can.CanError, ValueError, TypeError, OSError, ImportError, NotImplementedError) as exc:  # unknown interface: NotImplementedError
        raise UsageError(f"cannot open the {args.interface} bus on channel {args.channel!r}: {exc}") from None


def _run_emulate(args: argparse.Namespace) -> int:
    import signal
    import threading
    import time

    from ..emulator.emulated_bench import EmulatedBench
    from ..emulator.flash import FlashError
    from ..emulator.realtime import RealtimeEmulator
    from ..emulator.realtime_timing import stagger_boot, summary

    if args.list_variants:
        print(variants.table())
        return ExitStatus.OK
    if args.socketcand is None and args.interface is None:
        raise UsageError("give --socketcand PORT (a hub for python-can's socketcand client) or --interface/--channel (a python-can bus)")
    if args.interface is not None and args.channel is None:
        raise UsageError(f"--interface {args.interface} needs --channel")
    check_file(args.flash_path, "--flash-path", "flash file")
    check_faults(args.faults, "--faults")
    if args.rt_priority is not None and not 1 <= args.rt_priority <= 99:
        raise UsageError(f"--rt-priority must be 1..99 (SCHED_FIFO), not {args.rt_priority}")
    image = _image(args.firmware)
    faults = _fault_spec(",".join([*(image.faults if image else ()), *([args.faults] if args.faults else [])]), args.nodes)
    try:
        bench = EmulatedBench(args.nodes, faults=faults, flash=args.flash_path, seed=args.seed, config=_model_options(args, image))
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
                                    bitrate=args.bitrate, stamp=args.stamp, frame_stamp=args.frame_stamp,
                                    echo_own=not args.no_echo_own, handles=args.handles, host_alone=args.host_alone,
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
        return ExitStatus.FAILED
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    late = summary(emulator.lateness)
    flash = f"; flash saved to {args.flash_path}" if args.flash_path else ""
    print(f"ckesc emulate: stopped after {time.monotonic() - started:.1f} s: {emulator.counters['tx']} frames sent, "
          f"{emulator.counters['rx']} heard; lateness p50 {late['p50_us']} us, p99 {late['p99_us']} us, "
          f"max {late['max_us']} us{flash}", file=sys.stderr)
    return ExitStatus.OK


def _image(path: str | None):
    """``--firmware IMAGE``: the emulator image every ESC runs (:mod:`ckesc.bench.firmware`), or None."""
    from ..bench import firmware
    from ..bench.errors import PreflightError

    if path is None:
        return None
    try:
        image = firmware.load(path)
    except PreflightError as exc:
        raise UsageError(str(exc)) from None
    if not image.emulated:
        raise UsageError(f"--firmware {path}: not an emulator image (a TOML file with an [esc_information] table)")
    return image


def _model_options(args: argparse.Namespace, image: Any = None) -> dict[str, Any]:
    """The EscConfig fields the command line sets for every ESC: --boot-time, --report-delay, --report-timer, an
    emulator image's 240 answer, then the conforming combination --variants SEED draws, then the image's options and
    each --option NAME=VALUE."""
    out = {"boot_time": args.boot_time, "report_delay": args.report_delay, "report_timer": args.report_timer,
           **(image.esc_config if image else {})}
    try:
        return {**out, **variants.combination([*(image.options if image else ()), *(args.option or ())], args.variants)}
    except variants.VariantError as exc:
        raise UsageError(f"--option: {exc}") from None


def add_emulate_command(sub: argparse._SubParsersAction) -> None:
    from ..emulator.model import REPORT_TIMERS, EscConfig
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
    p.add_argument("--nodes", type=_node_ids, default=[1], metavar="IDS", help="node ids of factory-fresh ESCs: 1,2,3 or 1-20 (default 1); none: a bare hub for other clients")
    p.add_argument("--faults", metavar="NAMES", help="faults for every ESC, name@node for one (see ckesc.emulator.faults)")
    p.add_argument("--firmware", metavar="IMAGE",
                   help="an emulator image (a TOML file: its ESC Information 240 answer, faults and options; "
                   "docs/firmware.md) every ESC runs")
    p.add_argument("--flash-path", metavar="FILE", help="flash file: settings and counters persist across runs (default: none)")
    p.add_argument("--seed", type=int_arg, default=0, metavar="N", help="seed of the models' noise (default 0)")
    p.add_argument("--socketcand", type=port_arg, metavar="PORT", help="serve socketcand on 127.0.0.1:PORT (0: a free port)")
    p.add_argument("--interface", metavar="NAME", help="python-can interface to sit on (socketcan, virtual, ...)")
    p.add_argument("--channel", metavar="NAME", help="python-can channel (vcan0, ...)")
    p.add_argument("--bitrate", type=int_arg, default=DEFAULT_BITRATE, metavar="BIT/S",
                   help=f"bit rate of the emulated bus; ESCs at another rate neither hear nor are heard (default {DEFAULT_BITRATE})")
    p.add_argument("--bus-arg", action="append", metavar="KEY=VALUE", help="extra python-can bus argument (repeatable)")
    p.add_argument("--control", type=port_arg, metavar="PORT", help="control channel on 127.0.0.1:PORT (0: a free port); see ckesc control")
    p.add_argument("--duration", type=positive_float, metavar="S", help="stop after S seconds (default: run until SIGINT/SIGTERM)")
    p.add_argument("--stamp", choices=("due", "send"), default="due",
                   help="bus timestamp of ESC frames: their end (as SocketCAN stamps), had they started when they were due (default) or when they were sent")
    p.add_argument("--frame-stamp", choices=("end", "start"), default="end",
                   help="which end of a frame its bus timestamp marks: end (default, as SocketCAN stamps, and socketcand "
                   "passes on) or start (as an adapter stamping the start of frame: its DUT profile says [timing] stamp = "
                   "\"start\")")
    p.add_argument("--boot-spread", type=non_negative_float, default=0.02, metavar="S",
                   help="ESC k of n boots k/n x S later than the first, so that their reports are not in lockstep, as on a "
                   "real bench (default 0.02: one MSG1 interval; 0: all at once, as the simulated lane)")
    p.add_argument("--boot-time", type=non_negative_float, default=EscConfig.boot_time, metavar="S",
                   help=f"power-on to the first answer: the ESC hears nothing before (default {EscConfig.boot_time})")
    p.add_argument("--report-delay", type=non_negative_float, default=0.0, metavar="S",
                   help="boot to the first report: an ESC that answers before it reports (default 0)")
    p.add_argument("--report-timer", choices=REPORT_TIMERS, default="restart",
                   help="when reporting comes back (a resume, leaving CAN Test or MSG_EXP mode): restart (default: the first "
                   "report at once, the next ones an interval apart), grid (one report at once, then the old grid goes on), "
                   "next_tick (the first at the old grid's next point) or one_interval (the first one interval later); all "
                   "conformant (R9a)")
    p.add_argument("--option", action="append", metavar="NAME=VALUE",
                   help="one conforming variant for every ESC (repeatable): a behaviour the document leaves free, "
                   "e.g. report_timer=grid; --list-variants lists them with the requirements that allow each")
    p.add_argument("--variants", type=int_arg, metavar="SEED",
                   help="play the conforming combination drawn from SEED (every freedom at a random conforming value; "
                   "--option wins over it)")
    p.add_argument("--list-variants", action="store_true",
                   help="list the conforming variants (name, values, the requirements that allow it) and exit")
    p.add_argument("--rt-priority", type=int_arg, metavar="N",
                   help="run the scheduler thread SCHED_FIFO at priority N (1..99; needs CAP_SYS_NICE, else a warning): "
                   "on a loaded machine this keeps other processes from delaying frames by milliseconds")
    p.add_argument("--no-echo-own", action="store_true", help="socketcand: do not echo a client's frames back to it")
    p.add_argument("--handles", choices=HANDLES, default="shared",
                   help="socketcand: which clients hear each other; the name a client opens is its adapter: shared "
                   "(default: every client hears every other, as SocketCAN's loopback), separate (the clients that opened "
                   "one name are handles of one adapter and do not hear each other's frames, as most USB adapters; a "
                   "client that opened another name, the DUT's own, hears them all) or one (a name is open on one client "
                   "at a time, a second is refused, as an adapter that allows one handle)")
    p.add_argument("--host-alone", choices=HOST_ALONE, default="deliver",
                   help="the host's frames while no ESC is powered (or still booting) to acknowledge them: deliver "
                   "(default: they reach the bus all the same), or hold as SocketCAN does: the first and up to "
                   f"{TX_QUEUE_LEN} more (its transmit queue) are held and reach the ESC, stamped then, when its "
                   "controller comes up; the rest are lost (status: host_held, host_lost)")
    p.add_argument("--unpowered", action="store_true", help="start with the power off (switch it on with ckesc control)")
    p.set_defaults(handler=_run_emulate)
