"""A duration as a person reads it, exactly (issue #38): ``1 min 30 s``, ``7 min 37 s``, ``8 h``, ``42.5 s``. Every
place that says how long something took or will take (the soak's console and statement, ``ckesc compare``'s soak
lines, an interrupted run, ``ckesc explore``'s budget, ``ckesc selftest``'s onsets) says it with
:func:`duration_text`, so that 90 s is never "1 min" in one place and "90 s" in another."""

from __future__ import annotations


def duration_text(seconds: float) -> str:
    """``90`` -> ``1 min 30 s``; ``457.3`` -> ``7 min 37 s``; ``5400`` -> ``1 h 30 min``; ``3605`` -> ``1 h 0 min 5 s``;
    ``28800`` -> ``8 h``; ``42.5`` -> ``42.5 s``; ``0`` -> ``0 s``.

    Under a minute to a tenth of a second, from a minute on to the second (rounded, never cut: 59.96 s is ``1 min``);
    the units below the largest are said down to the smallest one that is not zero."""
    sign = "-" if seconds < 0 else ""
    seconds = abs(seconds)
    if round(seconds, 1) < 60:
        return f"{sign}{round(seconds, 1):g} s"
    whole = round(seconds)
    h, rest = divmod(whole, 3600)
    m, s = divmod(rest, 60)
    parts = [(h, "h"), (m, "min"), (s, "s")]
    first = next(i for i, (n, _) in enumerate(parts) if n)
    last = max(i for i, (n, _) in enumerate(parts) if n)
    return sign + " ".join(f"{n} {unit}" for n, unit in parts[first:last + 1])
