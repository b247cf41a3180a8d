"""What every ``ckesc`` command shares: exit statuses, the parser class, the usage error, argument types."""

from __future__ import annotations

import argparse
from typing import Callable

from ..protocol.assignments import parse_int

EXIT_OK = 0
EXIT_FRAMES_FAILED = 1
EXIT_USAGE = 2
EXIT_UNREACHABLE = 3
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, what a shell reports for a writer killed by `| head`


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``ckesc encode: error: ... (see ckesc encode --help)``."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class UsageError(Exception):
    """Bad command-line input found after parsing; printed as one line, exit 2."""


Handler = Callable[[argparse.Namespace], int]


def int_arg(text: str) -> int:
    try:
        return parse_int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r} (decimal or 0x-hex)") from None
