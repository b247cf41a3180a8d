"""Legal and illegal values, generated from the catalogue (never written by hand in a test).

:func:`illegal_fields` says which values of a request the document forbids; :func:`illegal_cases`
lists, for one field, the boundary values (min, max) and the illegal neighbours (min-1, max+1,
unassigned codes) that the reject tests (R10) parametrize over.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterator, Mapping

from .catalogue import Field, FrameSpec, Layout


@dataclass(frozen=True)
class IllegalCase:
    frame: str
    field: str
    value: int
    legal: bool
    why: str  # 'min', 'max', 'min-1', 'max+1', 'code', 'unassigned code'
    rule: str | None  # the rule that makes an illegal value "ignored" (R10); None: OBSERVE

    @property
    def id(self) -> str:  # a stable pytest id
        return f"{self.field}={self.value}({self.why})"


def illegal_fields(layout: Layout, values: Mapping[str, Any]) -> list[tuple[Field, int]]:
    """The (field, value) pairs of ``values`` that the document does not allow."""
    out = []
    for f in layout.fields:
        if f.name in values and isinstance(values[f.name], int) and not f.is_legal(values[f.name]):
            out.append((f, values[f.name]))
    return out


def field_cases(spec: FrameSpec, f: Field) -> Iterator[IllegalCase]:
    """Boundary and illegal values of one field, deduplicated, within its wire width."""
    seen: set[int] = set()

    def case(value: int, why: str) -> Iterator[IllegalCase]:
        if 0 <= value <= f.mask and value not in seen:
            seen.add(value)
            yield IllegalCase(spec.name, f.name, value, f.is_legal(value), why, f.rejected_by)

    if f.codes is not None:
        codes = sorted(f.codes)
        for c in codes:
            yield from case(c, "code")
        gaps = [c + 1 for c in codes if c + 1 not in f.codes] + [c - 1 for c in codes if c - 1 not in f.codes]
        for g in sorted(set(gaps)):
            yield from case(g, "unassigned code")
        yield from case(f.mask, "unassigned code")
    if f.legal is not None:
        lo, hi = f.legal
        yield from case(lo, "min")
        yield from case(hi, "max")
        yield from case(lo - 1, "min-1")
        yield from case(hi + 1, "max+1")
        yield from case(f.mask, "max+1")


def illegal_cases(spec: FrameSpec, *, only_enforced: bool = True) -> list[IllegalCase]:
    """Illegal request values of ``spec`` (those some rule says must be ignored, unless
    ``only_enforced=False``)."""
    if spec.request is None:
        return []
    out = []
    for f in spec.request.fields:
        if only_enforced and f.rejected_by is None:
            continue
        out.extend(c for c in field_cases(spec, f) if not c.legal)
    return out
