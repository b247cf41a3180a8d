"""The argument types of numbers (issue #38): below zero, and zero where zero makes no sense, refused by the parser
with the option named (argparse says ``argument --rate: -3 is below zero: give more than 0``). The bench's own options
(``ckesc/bench/options.py``: timeouts, the bit rate, the host's send error) and every command's
(``ckesc/cli/common.py``) take them from here, so the same mistake reads the same everywhere."""

from __future__ import annotations

import argparse
import math

from ..protocol.assignments import parse_int


def _number(text: str, kind: type, *, zero: bool) -> float:
    try:
        value = kind(text) if kind is float else parse_int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}" if kind is float else f"not an integer: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"not a number: {text!r}")
    if value < 0 or (value == 0 and not zero):
        raise argparse.ArgumentTypeError(f"{text} is {'below zero' if value < 0 else 'zero'}: give "
                                         f"{'0 or more' if zero else 'more than 0'}")
    return value


def positive_float(text: str) -> float:
    """A number more than zero (a rate, a timeout)."""
    return _number(text, float, zero=False)


def non_negative_float(text: str) -> float:
    """A number, 0 or more (a delay, a tolerance)."""
    return _number(text, float, zero=True)


def positive_int(text: str) -> int:
    """An integer more than zero (a count of programs, steps or jobs)."""
    return int(_number(text, int, zero=False))


def percentage(text: str) -> float:
    """A percentage, 0 to 100, as given (a threshold: ``10`` is 10 %)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a percentage: {text!r}") from None
    if not 0 <= value <= 100:  # (NaN too)
        raise argparse.ArgumentTypeError(f"{text} is not between 0 and 100")
    return value
