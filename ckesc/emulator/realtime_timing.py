"""Timing helpers of the real-time emulator: the thread's timer slack, the offset between the monotonic
clock and bus stamps, staggered boots of a bench's ESCs, and the lateness histograms its statistics report."""

from __future__ import annotations

import bisect
import ctypes
import itertools
import math
import sys
import time
from typing import Any

from .emulated_bench import EmulatedBench

_PR_SET_TIMERSLACK = 29
_PR_GET_TIMERSLACK = 30


# ---------------------------------------------------------------------------------------------------
# small helpers


def set_timer_slack(ns: int) -> int | None:
    """Set the calling thread's timer slack (Linux); the previous value, or None where unsupported."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        prctl = libc.prctl
    except (OSError, AttributeError):
        return None
    prctl.restype = ctypes.c_int
    prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
    old = prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0)
    if old < 0 or prctl(_PR_SET_TIMERSLACK, ns, 0, 0, 0) != 0:
        return None
    return old


def stagger_boot(bench: EmulatedBench, spread: float) -> None:
    """Make ESC k of n boot ``k/n x spread`` seconds later than the first (its ``boot_time``), every
    power-up. Real ESCs on one supply do not boot in lockstep; identical models would report in
    lockstep forever, and a batch of n reports due at the same instant leaves the last one late by
    n poll times. ``spread`` = one MSG1 interval (0.02 s) spaces their reports evenly."""
    n = len(bench.escs)
    for k, esc in enumerate(bench.escs):
        esc.config.boot_time += spread * k / n


def clock_offset() -> float:
    """``time.time() - time.monotonic()``, read so that the two clocks are sampled together."""
    best = None
    for _ in range(5):
        a = time.monotonic()
        w = time.time()
        b = time.monotonic()
        if best is None or b - a < best[0]:
            best = (b - a, w - (a + b) / 2)
    return best[1]  # type: ignore[index]


class Histogram:
    """Durations in 1 µs bins up to 10 ms, 1 ms bins up to 1 s (the exact maximum is kept): O(1) to
    add and cheap to summarise, so a status query never stalls the scheduler with a sort."""

    FINE = 10_000  # 1 µs bins: 0 .. 10 ms
    COARSE = 990  # 1 ms bins: 10 ms .. 1 s, then one overflow bin

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.counts = [0] * (self.FINE + self.COARSE + 1)
        self.n = 0
        self.max = 0.0
        self.total = 0.0

    def add(self, seconds: float) -> None:
        if seconds < 0.0:
            seconds = 0.0
        us = int(seconds * 1e6)
        if us < self.FINE:
            self.counts[us] += 1
        else:
            self.counts[self.FINE + min(us // 1000 - 10, self.COARSE)] += 1
        self.n += 1
        self.total += seconds
        if seconds > self.max:
            self.max = seconds

    def _upper_edge(self, i: int) -> float:
        if i < self.FINE:
            return (i + 1) * 1e-6
        return (i - self.FINE + 11) * 1e-3 if i < self.FINE + self.COARSE else math.inf

    def summary(self) -> dict[str, Any]:
        """count, mean, p50/p90/p99/p99.9 (the upper edge of the bin, never above the maximum) and max
        in µs; over_1ms / over_5ms: how many took 1 ms / 5 ms or more."""
        out: dict[str, Any] = {"count": self.n}
        cum = list(itertools.accumulate(self.counts))
        for key, q in (("p50_us", 0.5), ("p90_us", 0.9), ("p99_us", 0.99), ("p999_us", 0.999)):
            if not self.n:
                out[key] = None
                continue
            i = bisect.bisect_left(cum, max(1, math.ceil(q * self.n)))
            out[key] = round(min(self._upper_edge(i), self.max) * 1e6, 1)
        out["mean_us"] = round(self.total / self.n * 1e6, 1) if self.n else None
        out["max_us"] = round(self.max * 1e6, 1) if self.n else None
        out["over_1ms"] = self.n - cum[999]
        out["over_5ms"] = self.n - cum[4999]
        return out
