"""Field values from ``key=value`` words, and what the document says about them (``ckesc encode``).

:func:`parse_assignments` reads ``key=value`` words into the field values :func:`~ckesc.protocol.frame.encode`
takes (decimal or 0x-hex, comma lists, code and flag names), raising :class:`AssignmentError`;
:func:`encode_warnings` lists the values the wire format carries but the document does not allow.
"""

from __future__ import annotations

import re
from typing import Any, Sequence

from . import catalogue as cat
from .catalogue import Field, FrameSpec, Layout
from .frame import pick_response_layout
from .ids import RESERVED_NODE_IDS, Kind
from .legality import illegal_fields


class AssignmentError(ValueError):
    """A ``key=value`` word that gives no field value; the message says why."""


def parse_int(text: str) -> int:
    """Decimal or 0x-hex (also 0b/0o); leading zeros are read as decimal ("08" is 8)."""
    text = text.strip()
    try:
        return int(text, 0)
    except ValueError:
        return int(text, 10)  # "08", "010": decimal; raises ValueError for anything else


_LIST_FIELDS = ("channels", "payload")  # always lists, even with one value
#: Throttle ranges of the document (4.4.15-4.4.17); larger values are encodable, what a device does is OBSERVE (R6).
_THROTTLE_MAX = {"throttle14": cat.THROTTLE_MAX, "throttle12": cat.THROTTLE_MAX, "throttle10": cat.THROTTLE_10B_MAX}


def _candidate_fields(spec: FrameSpec, name: str) -> list[Field]:
    return [f for lay in spec.all_layouts for f in lay.fields if f.name == name]


def _named_value(spec: FrameSpec, key: str, text: str) -> int | None:
    """A code or flag name for a field value: ``option=write``, ``command=suspend``, ``color=red+green``."""
    want = text.strip().lower().replace("_", " ")
    for f in _candidate_fields(spec, key):
        if f.codes is not None:
            for code, label in f.codes.items():
                if label.lower().replace("_", " ") == want:
                    return code
        if f.flags is not None:
            total = 0
            for part in re.split(r"[+|]", text):
                member = f.flags.__members__.get(part.strip().upper())
                if member is None:
                    break
                total |= int(member)
            else:
                return total
    return None


def parse_assignments(spec: FrameSpec, items: Sequence[str]) -> dict[str, Any]:
    """``key=value`` words into field values: decimal or 0x-hex, comma lists, code names."""
    values: dict[str, Any] = {}
    for item in items:
        key, eq, text = item.partition("=")
        key = key.strip()
        if not eq or not key:
            raise AssignmentError(f"{item!r} is not key=value")
        if key in values:
            raise AssignmentError(f"field {key} is given twice")
        try:
            if "," in text or key in _LIST_FIELDS:
                values[key] = [parse_int(part) for part in text.split(",") if part.strip()]
            else:
                values[key] = parse_int(text)
        except ValueError:
            named = None if "," in text else _named_value(spec, key, text)
            if named is None:
                raise AssignmentError(f"{key}={text!r}: not an integer (decimal or 0x-hex) nor a code name of {spec.name}.{key}") from None
            values[key] = named
    return values


def _legal_text(f: Field) -> str:
    if f.codes is not None:
        return "one of " + ", ".join(f"{code} ({label})" for code, label in f.codes.items())
    lo, hi = f.legal if f.legal is not None else (0, f.mask)
    return f"{lo}..{hi}"


def chosen_layout(spec: FrameSpec, kind: Kind, data: bytes, values: dict[str, Any], layout: str | None) -> Layout | None:
    """The layout :func:`encode` used (for the legality warnings)."""
    if kind is Kind.MESSAGE:
        size = len(data) - spec.has_tail
        return spec.message_layout(size)
    if kind is Kind.REQUEST:
        return spec.request
    if layout is not None:
        return next((lay for lay in spec.responses if lay.name == layout), None)
    return pick_response_layout(spec, values)  # encode's own choice, so the warnings name the same fields


def encode_warnings(spec: FrameSpec, layout: Layout | None, values: dict[str, Any], source: int, destination: int | None) -> list[str]:
    """Values the wire format carries but the document does not allow (the suite sends them on purpose)."""
    out = []
    if layout is not None:
        for f, value in illegal_fields(layout, values):
            rule = f"; ignored by rule {f.rejected_by}" if f.rejected_by else ""
            out.append(f"{spec.name}.{f.name}={value} is outside the document's legal range {_legal_text(f)}{rule}")
        top = _THROTTLE_MAX.get(layout.codec)
        if top is not None:
            for i, v in enumerate(values.get("channels") or ()):
                if isinstance(v, int) and v > top:
                    out.append(f"{spec.name}.channels[{i}]={v} is outside the document's throttle range 0..{top} (R6: OBSERVE)")
            group = values.get("group")
            groups = cat.THROTTLE_GROUPS
            if layout.codec == "throttle12" and isinstance(group, int) and group not in groups:
                out.append(f"{spec.name}.group={group} is outside the document's legal range {groups.start}..{groups.stop - 1}")
    for label, node in (("source", source), ("destination", destination)):
        if node in RESERVED_NODE_IDS:
            out.append(f"{label} node id {node} is reserved (F7)")
    return out
