"""A streaming distribution of durations in bounded memory, sans-IO: the one histogram of the project (the soak's answer
delays, stamp lags and send lateness; the real-time emulator's frame lateness and wake-ups; the bus rules' report
intervals, ``evidence.findings.Intervals``)."""

from __future__ import annotations

import math
from typing import Any


class Histogram:
    """Durations (s): count, total, min, max and fixed bins, O(1) to add. ``bins`` bins of ``width`` from 0, then each
    ``(width, bins)`` of ``coarser`` on from where the one before ends, then one bin for everything beyond (a value
    below 0 counts in the first bin). A percentile is the upper edge of the bin that holds it, never above the
    maximum (the maximum itself for the last bin).

    Two readings of a quantile, one walk: by default the upper edge of its bin (a bound a figure may be held to: the
    soak's and the emulator's); with ``middle`` the bin's middle, within [minimum, maximum] (an estimate half a bin
    either way: the bus rules' intervals, whose figures check-log and the reports have always shown so). ``nudge``
    (a fraction of a bin) is added to a value's place before its bin is taken, so a value on a bin's edge but for
    float noise (20 ms as 0.01999999...) counts in the bin it names."""

    __slots__ = ("width", "middle", "_nudge", "_fine", "_tiers", "_beyond", "counts", "n", "total", "squares", "lo", "hi")

    def __init__(self, width: float, bins: int, *coarser: tuple[float, int], middle: bool = False,
                 nudge: float = 0.0) -> None:
        self.width = width
        self.middle = middle
        self._nudge = nudge
        self._fine = bins
        tiers, start, first = [], width * bins, bins
        for w, n in coarser:  # (where the tier starts, its first bin's index, its width, its bins)
            tiers.append((start, first, w, n))
            start, first = start + w * n, first + n
        self._tiers = tuple(tiers)
        self._beyond = first  # the last bin's index
        self.reset()

    def reset(self) -> None:
        self.counts = [0] * (self._beyond + 1)
        self.n, self.total, self.squares, self.lo, self.hi = 0, 0.0, 0.0, math.inf, -math.inf

    def _index(self, value: float) -> int:
        i = int(value / self.width + self._nudge)
        if i < self._fine:
            return i if i >= 0 else 0
        for start, first, w, n in self._tiers:
            k = int((value - start) / w + self._nudge)
            if k < n:
                return first + (k if k >= 0 else 0)
        return self._beyond

    def add(self, value: float) -> None:
        self.n += 1
        self.total += value
        self.squares += value * value
        if value < self.lo:
            self.lo = value
        if value > self.hi:
            self.hi = value
        i = int(value / self.width + self._nudge)  # (the first tier inline: the hot path)
        self.counts[i if 0 <= i < self._fine else self._index(value)] += 1

    def _edges(self, i: int) -> tuple[float, float]:
        """Bin ``i``'s lower and upper edge (the last bin's upper edge: infinity)."""
        if i < self._fine:
            return i * self.width, (i + 1) * self.width
        for start, first, w, n in self._tiers:
            if i < first + n:
                return start + (i - first) * w, start + (i - first + 1) * w
        return self._edges(i - 1)[1], math.inf

    @property
    def stdev(self) -> float | None:
        """The values' standard deviation (of the population; None: empty)."""
        if not self.n:
            return None
        mean = self.total / self.n
        return math.sqrt(max(self.squares / self.n - mean * mean, 0.0))

    def quantile(self, q: float) -> float | None:
        """The ``q``-quantile (0..1), read from the bin holding it (the class's two readings), at most the maximum
        (None: empty)."""
        if not self.n:
            return None
        need, seen = q * self.n, 0
        for i, c in enumerate(self.counts):
            seen += c
            if seen >= need and c:
                lower, upper = self._edges(i)
                if not self.middle:
                    return min(upper, self.hi)
                mid = (i + 0.5) * self.width if i < self._fine else lower + (upper - lower) / 2
                return min(max(mid, self.lo), self.hi)
        return self.hi

    def percentile(self, p: float) -> float | None:
        """The ``p``-th percentile (:meth:`quantile` of ``p / 100``)."""
        return self.quantile(p / 100)

    def beyond(self, value: float) -> int:
        """How many values fell in the bins from ``value``'s on (those of ``value`` or more, to a bin)."""
        return self.n - sum(self.counts[:self._index(value)])

    def to_json(self) -> dict[str, Any]:
        """In milliseconds, with the bins (the soak's results)."""
        def ms(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else round(v * 1000, 3)

        return {"count": self.n, "min_ms": ms(self.lo), "max_ms": ms(self.hi),
                "mean_ms": ms(self.total / self.n) if self.n else None,
                **{f"p{p}_ms": ms(self.percentile(p)) for p in (50, 90, 99)},
                "bin_ms": self.width * 1000, "bins": self.counts}
