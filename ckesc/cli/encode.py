"""``ckesc encode``: one frame from field values, printed as candump/cansend ``ID#DATA``."""

from __future__ import annotations

import argparse
import sys

from ..protocol import catalogue as cat
from ..protocol.assignments import AssignmentError, chosen_layout, encode_warnings, parse_assignments, parse_int
from ..protocol.errors import EncodeError
from ..protocol.frame import FALLBACK_PRIORITY, encode
from ..protocol.ids import Kind, Priority
from ..reporting.exits import ExitStatus
from .common import UsageError, int_arg


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
    return ExitStatus.OK


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
    p.add_argument("--source", type=int_arg, default=0, metavar="N", help="source node id (default 0, the host: 4.4.18 note 8)")
    p.add_argument("--destination", type=int_arg, metavar="N", help="destination node id (services only; required for them)")
    p.add_argument("--transfer-id", type=int_arg, default=0, metavar="N", help="transfer id 0..31 (default 0)")
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
