"""``ckesc control``: one request to the control channel of a running ``ckesc emulate``."""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from ..emulator.hub_can import KINDS
from ..protocol.assignments import parse_int
from ..reporting.exits import ExitStatus
from .common import Parser, UsageError, int_arg, non_negative_float, port_arg, positive_float


def _seconds_or_switch(text: str) -> float | bool:
    """``on`` / ``off``, or seconds above 0."""
    if text in ("on", "off"):
        return text == "on"
    return positive_float(text)


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
    if action == "bus":
        if isinstance(args.how, bool):
            return {"cmd": "bus_fault", "kind": args.kind, "on": args.how}
        return {"cmd": "bus_fault", "kind": args.kind, "seconds": args.how}
    if action == "stats":
        return {"cmd": "stats", "reset": args.reset}
    return {"cmd": action}


def _run_control(args: argparse.Namespace) -> int:
    from ..emulator.control import ControlError, control_request

    if args.action == "power" and args.state == "cycle" and args.off_time is None:
        args.off_time = 1.0
    req = _control_request(args)
    port = _control_port(args)
    timeout = args.timeout
    if timeout is None and isinstance(req.get("seconds"), float):  # answered when the fault has ended
        timeout = 10.0 + req["seconds"]
    try:
        answer = control_request(port, req, timeout=timeout)
    except ControlError as exc:
        print(f"ckesc control: error: {exc}", file=sys.stderr)
        return ExitStatus.ABORTED if exc.unreachable else ExitStatus.FAILED
    print(json.dumps(answer, indent=1 if args.action in ("status", "faults") else None))
    return ExitStatus.OK


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
        "          CKESC_CONTROL_PORT=29536 ckesc control power cycle --off-time 0.5\n"
        "          ckesc control --port 29536 bus short 0.5",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--port", type=port_arg, metavar="P", help="the emulator's control port (default: $CKESC_CONTROL_PORT)")
    p.add_argument("--timeout", type=positive_float, metavar="S", help="seconds to wait for the answer (default 10, plus the off time)")
    actions = p.add_subparsers(dest="action", metavar="ACTION", parser_class=Parser, required=True)
    actions.add_parser("status", help="power state, bit rate, per-ESC node ids, faults and counters, timing")
    power = actions.add_parser("power", help="power off / on / cycle")
    power.add_argument("state", choices=("off", "on", "cycle"))
    power.add_argument("--off-time", type=non_negative_float, metavar="S", help="cycle: seconds without power (default 1.0)")
    fault = actions.add_parser("fault", help="switch a fault on or off")
    fault.add_argument("name", metavar="NAME", help="fault name (ckesc control faults lists them)")
    fault.add_argument("state", choices=("on", "off"))
    fault.add_argument("--node", type=int_arg, metavar="N", help="only the ESC with this node id (default: every ESC)")
    actions.add_parser("faults", help="list the known faults")
    bus = actions.add_parser("bus", help="disturb the emulated bus: a short or a node at another bit rate, for S seconds "
                             "(answered when it has ended) or on / off (a relay)",
                             description="A bus fault on the emulator's hub (R20): every ESC that tries to send meets "
                             "errors and goes bus-off, and recovers 128 x 11 bits after the bus is free; the host's "
                             "frames wait (10 behind the first) until an ESC listens again. As --bus-fault-cmd: "
                             "'ckesc control --port P bus {kind} {seconds}'.")
    bus.add_argument("kind", choices=KINDS, help="short (CANH-CANL: all dominant) or other_bitrate (a node "
                     "at another bit rate sending at about 1 kHz)")
    bus.add_argument("how", type=_seconds_or_switch, metavar="SECONDS|on|off",
                     help="how long, in seconds; or on (until off)")
    bitrate = actions.add_parser("bitrate", help="set the emulated bus's bit rate")
    bitrate.add_argument("bitrate", type=int_arg, metavar="BIT/S")
    stats = actions.add_parser("stats", help="frame lateness (send - due) and wake-up lateness")
    stats.add_argument("--reset", action="store_true", help="start counting afresh")
    actions.add_parser("save", help="write the flash file now")
    actions.add_parser("stop", help="stop the emulator (power off, flash saved)")
    p.set_defaults(handler=_run_control)
