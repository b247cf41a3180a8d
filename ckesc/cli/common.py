"""What every ``ckesc`` command shares: the parser class, the usage error, argument types (the exit statuses are
:class:`ckesc.reporting.exits.ExitStatus`)."""

from __future__ import annotations

import argparse
import sys
from typing import Callable

from ..protocol.assignments import parse_int
from ..reporting.exits import ExitStatus


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``ckesc encode: error: ... (see ckesc encode --help)``.

    ``split_at_dashes=True`` (``ckesc run``): the command's arguments end at the first ``--``. Before it, its
    options; the other arguments, in their order, in ``args.free`` (unknown options among them, for the command
    to name); after it, everything untouched in ``args.after_dashes``."""

    def __init__(self, *args, split_at_dashes: bool = False, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.split_at_dashes = split_at_dashes

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        if not self.split_at_dashes:
            return super().parse_known_args(args, namespace)
        tokens = list(sys.argv[1:] if args is None else args)
        cut = tokens.index("--") if "--" in tokens else len(tokens)
        namespace, free = super().parse_known_args(tokens[:cut], namespace)
        namespace.free, namespace.after_dashes = free, tokens[cut + 1:]
        return namespace, []

    def error(self, message: str):  # type: ignore[override]
        self.exit(ExitStatus.USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class UsageError(Exception):
    """Bad command-line input found after parsing; printed as one line, exit 2."""


Handler = Callable[[argparse.Namespace], int]


def int_arg(text: str) -> int:
    try:
        return parse_int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r} (decimal or 0x-hex)") from None
