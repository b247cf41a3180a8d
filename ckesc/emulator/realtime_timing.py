"""Timing helpers of the real-time emulator: the thread's timer slack, the offset between the monotonic
clock and bus stamps, staggered boots of a bench's ESCs, and the lateness histograms its statistics report."""

from __future__ import annotations

import ctypes
import os
import sys
import time
from typing import Any, Callable

from ..protocol.histogram import Histogram
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


def set_rt_priority(priority: int | None, log: Callable[[str], None]) -> tuple[tuple[int, Any] | None, str]:
    """SCHED_FIFO at ``priority`` for the calling thread when asked (and permitted): the policy to restore (None:
    nothing changed) and the scheduling in words."""
    if priority is None:
        return None, "normal"
    if not hasattr(os, "sched_setscheduler"):
        log("--rt-priority: this platform has no SCHED_FIFO; running at normal priority")
        return None, "normal"
    old = (os.sched_getscheduler(0), os.sched_getparam(0))
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError) as exc:
        log(f"--rt-priority {priority}: SCHED_FIFO not permitted ({exc.strerror or exc}); running at normal priority")
        return None, "normal"
    return old, f"SCHED_FIFO {priority}"


def stagger_boot(bench: EmulatedBench, spread: float) -> None:
    """Make ESC k of n boot ``k/n x spread`` seconds later than the first (its ``boot_time``), every
    power-up. Real ESCs on one supply do not boot in lockstep; identical models would report in
    lockstep forever, and a batch of n reports due at the same instant leaves the last one late by
    n poll times. ``spread`` = one MSG1 interval (0.02 s) spaces their reports evenly."""
    n = len(bench.escs)
    for k, esc in enumerate(bench.escs):
        esc.config.boot_time += spread * k / n


#: how often the emulator reads :func:`clock_offset` again: its frames' stamps are the wall clock's (``time.time()``,
#: as SocketCAN's and the host's), and a wall clock that NTP slews moved 5 ms a second against the monotonic clock on
#: this machine (a bench whose stamps kept the offset read at start drifted 7.5 s from the host's in 15 minutes):
#: read every 0.1 s, a slew of that rate puts at most 0.5 ms between them
OFFSET_REFRESH_S = 0.1


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


#: the lateness histograms' bins: 1 µs up to 10 ms, 1 ms up to 1 s, then one bin beyond (the exact maximum is kept)
FINE_BIN_S, FINE_BINS = 1e-6, 10_000
COARSE_BIN_S, COARSE_BINS = 0.001, 990


def durations() -> Histogram:
    """A lateness histogram (:data:`FINE_BIN_S`, :data:`COARSE_BIN_S`): O(1) to add and cheap to summarise, so a status
    query never stalls the scheduler with a sort. Durations below 0 are added as 0 by the caller."""
    return Histogram(FINE_BIN_S, FINE_BINS, (COARSE_BIN_S, COARSE_BINS))


def summary(h: Histogram) -> dict[str, Any]:
    """A lateness histogram in µs: count, p50/p90/p99/p99.9 (the upper edge of the bin, never above the maximum),
    mean and max; over_1ms / over_5ms: how many took 1 ms / 5 ms or more."""
    def us(v: float | None) -> float | None:
        return None if v is None else round(v * 1e6, 1)

    out: dict[str, Any] = {"count": h.n}
    for key, q in (("p50_us", 0.5), ("p90_us", 0.9), ("p99_us", 0.99), ("p999_us", 0.999)):
        out[key] = us(h.quantile(q))
    out["mean_us"] = us(h.total / h.n) if h.n else None
    out["max_us"] = us(h.hi) if h.n else None
    out["over_1ms"] = h.beyond(COARSE_BIN_S)
    out["over_5ms"] = h.beyond(5 * COARSE_BIN_S)
    return out
