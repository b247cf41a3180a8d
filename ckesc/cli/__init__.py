"""The ``ckesc`` command line.

Each subcommand is one module of this package (``run``, ``decode``, ``check_log``, ...) with one
``add_<name>_command(subparsers)`` function that declares its arguments and sets ``handler`` (a function
``(args) -> exit code``): it parses the arguments, calls the library and maps its errors to exit codes.
:data:`COMMANDS` lists them and :func:`main` builds the parser from that list. Adding a command is one
module and one entry in :data:`COMMANDS`; nothing else here needs to change. ``common`` holds what the
commands share (the parser class, :class:`UsageError`, argument types); the exit codes are one table,
:class:`ckesc.reporting.exits.ExitStatus`.

The front door (issue #38): every mistake a user can make is found before any work and said in one line that names
the option and what would work, exit 2, in the same words whichever command meets it (``common``: the argument types,
the checks of what a command reads and writes, the unknown fault names); no traceback reaches a user for it.

Exit codes: 0 success; 1 the input had frames that do not decode (``decode``), the emulator
answered a control request with an error (``control``) or could not write its flash file at the end
(``emulate``), or a run regressed (``compare``), or a soak found something (``soak``); 2 usage or input the wire format cannot carry (``encode``), or the emulator cannot start
(``emulate``: port in use, unreadable flash file, bus that does not open); 3 no emulator answers on
the control port (``control``), or the bench could not be used (``explore``, ``profile init`` / ``check``, ``soak``); 1 also
a profile the DUT contradicts (``profile check --strict``); ``bisect``: 0 the first bad image named, 1 no first bad
image (a step without a majority, the canary failed), 2 its arguments or a step's bench error; 130 interrupted; 141 stdout closed early (``| head``).
"""

from __future__ import annotations

import argparse
import io
import os
import sys
from typing import Callable, Sequence

from .. import __version__
from ..reporting.exits import ExitStatus
from .bisect import add_bisect_command
from .check_log import add_check_log_command
from .common import Handler, Parser, UsageError
from .compare import add_compare_command
from .control import add_control_command
from .decode import add_decode_command
from .emulate import add_emulate_command
from .encode import add_encode_command
from .explore import add_explore_command
from .frames import add_frames_command
from .profile import add_profile_command
from .report import add_report_command
from .run import add_run_command
from .selftest import add_selftest_command
from .soak import add_soak_command

#: The subcommands, in help order. Each adds its parser and sets ``handler``.
COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [
    add_run_command,
    add_selftest_command,
    add_explore_command,
    add_soak_command,
    add_profile_command,
    add_report_command,
    add_compare_command,
    add_bisect_command,
    add_decode_command,
    add_check_log_command,
    add_encode_command,
    add_frames_command,
    add_emulate_command,
    add_control_command,
]


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="ckesc", description="Tools for the CKESC UAVCAN Protocol 2.1 conformance suite.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for add in COMMANDS:
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, usage errors: a return code, as for every other outcome
        return exc.code if isinstance(exc.code, int) else ExitStatus.USAGE
    handler: Handler | None = getattr(args, "handler", None)
    if handler is None:
        parser.print_help(sys.stderr)
        return ExitStatus.USAGE
    name = " ".join(["ckesc", args.command, *([args.action] if args.command == "profile" else [])])
    try:
        return handler(args)
    except UsageError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return ExitStatus.USAGE
    except KeyboardInterrupt:
        return ExitStatus.INTERRUPTED
    except BrokenPipeError:
        _silence_stdout()
        return ExitStatus.BROKEN_PIPE
    except OSError as exc:  # a file the user named that went away or filled up after the checks: one line
        if exc.filename is None:
            raise
        print(f"{name}: error: {exc.filename}: {exc.strerror or exc}", file=sys.stderr)
        return ExitStatus.USAGE


def _silence_stdout() -> None:
    """After the reader of our stdout went away (``| head``), point stdout at /dev/null so that the
    interpreter's final flush does not print a second BrokenPipeError (Python docs, 'Note on SIGPIPE')."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        pass
