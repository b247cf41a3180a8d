"""The catalogue's codes by their labels (not a section: no tests here): :func:`code`, for requests and
answers spelled as the document names their values ("query", "read", "CAN", ...)."""

from __future__ import annotations

from ckesc.protocol import catalogue as cat


def code(frame: str, field_name: str, label: str, *, layout: str = "request") -> int:
    """The catalogue's code for ``label`` of one field (e.g. Set Rotation's "query")."""
    spec = cat.spec(frame)
    lay = spec.request if layout == "request" else next(x for x in spec.all_layouts if x.name == layout)
    assert lay is not None
    codes = lay.field(field_name).codes or {}
    return next(k for k, v in codes.items() if v == label)
