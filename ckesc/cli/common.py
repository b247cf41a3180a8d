"""What every ``ckesc`` command shares (issue #38, one front door): the parser class, the usage error, the argument
types that refuse what cannot work (numbers below zero, zero where zero makes no sense, a duration without a known
unit) with the option named, and the one check of where a command will write (the exit statuses are
:class:`ckesc.reporting.exits.ExitStatus`). Every mistake a user can make is one line on stderr and exit 2, in the
same words whichever command meets it, before any work."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Callable

from ..bench.arguments import non_negative_float, positive_float, positive_int
from ..protocol.assignments import parse_int
from ..reporting.exits import ExitStatus
from ..reporting.paths import not_readable, not_writable

__all__ = ["Handler", "Parser", "UsageError", "check_dir", "check_faults", "check_file", "check_images", "check_readable", "check_run", "duration_arg",
           "int_arg", "non_negative_float", "port_arg", "positive_float", "positive_int", "seconds_of"]

#: a value that starts with a minus sign and a digit: a number below zero given to an option, not an option
_NEGATIVE = re.compile(r"^-\.?\d")


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``ckesc encode: error: ... (see ckesc encode --help)``.

    A value below zero after an option (``--duration -5m``) is that option's value, for its type to refuse by name,
    not an unknown option ("expected one argument").

    ``split_at_dashes=True`` (``ckesc run``): the command's arguments end at the first ``--``. Before it, its
    options; the other arguments, in their order, in ``args.free`` (unknown options among them, for the command
    to name); after it, everything untouched in ``args.after_dashes``."""

    def __init__(self, *args, split_at_dashes: bool = False, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.split_at_dashes = split_at_dashes

    def _negatives_joined(self, tokens: list[str]) -> list[str]:
        """``--opt -5`` -> ``--opt=-5`` for each option of this parser that takes one value."""
        out: list[str] = []
        i = 0
        while i < len(tokens):
            token = tokens[i]
            action = self._option_string_actions.get(token)
            if (action is not None and action.nargs is None and action.option_strings and token.startswith("--")
                    and i + 1 < len(tokens) and _NEGATIVE.match(tokens[i + 1]) and action.const is None):
                out.append(f"{token}={tokens[i + 1]}")
                i += 2
                continue
            out.append(token)
            i += 1
        return out

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        tokens = list(sys.argv[1:] if args is None else args)
        if not self.split_at_dashes:
            return super().parse_known_args(self._negatives_joined(tokens), namespace)
        cut = tokens.index("--") if "--" in tokens else len(tokens)
        namespace, free = super().parse_known_args(self._negatives_joined(tokens[:cut]), namespace)
        namespace.free, namespace.after_dashes = free, tokens[cut + 1:]
        return namespace, []

    def error(self, message: str):  # type: ignore[override]
        self.exit(ExitStatus.USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class UsageError(Exception):
    """Bad command-line input found after parsing; printed as one line, exit 2."""


Handler = Callable[[argparse.Namespace], int]


# ------------------------------------------------------------------------------------------- argument types
def int_arg(text: str) -> int:
    try:
        return parse_int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r} (decimal or 0x-hex)") from None


#: a duration: hours, minutes and seconds, each with its unit (a bare number is seconds)
_DURATION = re.compile(r"\s*(?:(\d+(?:\.\d+)?)\s*h)?\s*(?:(\d+(?:\.\d+)?)\s*m(?:in)?)?\s*(?:(\d+(?:\.\d+)?)\s*s?)?\s*")
DURATION_EXAMPLES = "a duration like 90s, 10m, 1h or 1h30m"


def seconds_of(text: str) -> float:
    """``90``, ``90s``, ``10m``, ``1h``, ``1h30m`` -> seconds (0 included: a throttle profile's first step); a ValueError
    says what is wrong."""
    if text.strip().startswith("-"):
        raise ValueError(f"{text} is below zero: give {DURATION_EXAMPLES}")
    m = _DURATION.fullmatch(text)
    if not m or not any(m.groups()):
        raise ValueError(f"{text!r} is not {DURATION_EXAMPLES}")
    h, mins, s = (float(g) if g else 0.0 for g in m.groups())
    return h * 3600 + mins * 60 + s


def duration_arg(text: str) -> float:
    """An option's duration, more than zero (:func:`seconds_of`): ``--duration 0`` would do nothing."""
    try:
        seconds = seconds_of(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if seconds <= 0:
        raise argparse.ArgumentTypeError(f"{text} is zero: give {DURATION_EXAMPLES}")
    return seconds


def port_arg(text: str) -> int:
    """A TCP port, 0..65535 (0: the system picks a free one)."""
    port = int_arg(text)
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{text} is not a port: give 0..65535 (0: a free one)")
    return port


def check_faults(text: str | None, option: str) -> None:
    """Emulator fault names given to ``option`` (comma-separated; ``NAME@NODE`` and ``NAME=SECONDS`` taken as NAME), in
    the words ``ckesc run --emulator-faults`` says them: the unknown one, what it was close to, where they are listed."""
    from ..bench.checks import fault_names
    from ..bench.errors import PreflightError

    names = [n.partition("@")[0] for n in (text or "").split(",") if n.strip() and n.strip() not in ("none", "all")]
    try:
        fault_names(",".join(names), option)
    except PreflightError as exc:
        raise UsageError(str(exc)) from None


# ------------------------------------------------------------------------------------------- what a command reads
def check_readable(path: str | None, option: str, what: str = "file") -> None:
    """A file the command will read: a :class:`UsageError` naming ``option`` when it is not there or not readable
    (``ckesc/reporting/paths.py``, in the shape of the words for what a command cannot write)."""
    if path is not None and path != "-" and (said := not_readable(path, option, what)):
        raise UsageError(said)


def check_images(path: str, option: str) -> list:
    """A bisect's image list (``ckesc bisect --images``): its images, oldest first (:func:`ckesc.bisect.steps.image_list`);
    a :class:`UsageError` when it is missing or unreadable, holds fewer than 2 images or names a missing file."""
    from ..bisect.steps import image_list

    if not Path(path).is_dir():
        check_readable(path, option, "image list")
    try:
        return image_list(path)
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        raise UsageError(str(exc) if isinstance(exc, ValueError) and not isinstance(exc, UnicodeDecodeError)
                         else f"{option} {path}: not a readable list of image paths ({exc})") from None


def check_run(path: str | None, option: str) -> None:
    """An earlier conformance run the command will read (a report directory or its results.json, as ``ckesc compare``
    reads one): a :class:`UsageError` naming ``option`` when it is missing, unreadable or not a run."""
    if path is None:
        return
    from ..reporting.comparing import RunError
    from ..reporting.gate import load

    try:
        load(path)
    except RunError as exc:
        raise UsageError(f"{option} {exc}") from None


# ------------------------------------------------------------------------------------------- where a command writes
def check_dir(path: str | None, option: str, what: str = "reports directory") -> None:
    """A directory the command will write into (made if missing): a :class:`UsageError` when it cannot be, made
    nothing (``ckesc/reporting/paths.py``, the words a run's preflight uses too)."""
    if path is not None and (said := not_writable(path, option, what)):
        raise UsageError(said)


def check_file(path: str | None, option: str, what: str = "output file") -> None:
    """A file the command will write: a :class:`UsageError` when it cannot (its directory missing or not writable, a
    directory in its place); makes nothing."""
    if path is not None and path != "-" and (said := not_writable(path, option, what, file=True)):
        raise UsageError(said)
