"""What changed in the DUT's settings, said in a verdict: every changed setting with its old and new
value, ``msg2_interval 50 -> 9, msg1_interval 10 -> 20`` - never a dict's repr (the failures-by-cause
grouping drops parenthesised parts, so ``{'msg1_interval': (10, 20)}`` read ``{'msg1_interval':}``) nor
pytest's truncated explanation of an ``==`` (``{'msg1_interv...nterval': 200}``). Not a section: no tests.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any


def listed(values: Mapping[str, Any]) -> str:
    """Settings and their values, as a message says them: ``msg1_interval 20, msg2_interval 9``."""
    return ", ".join(f"{k} {v}" for k, v in values.items())


def change(name: str, old: Any, new: Any) -> str:
    """One setting, from what to what: ``rotation 0 -> 1``."""
    return f"{name} {old} -> {new}"


def changes(before: Mapping[str, Any], after: Mapping[str, Any], keys: Iterable[str] | None = None) -> str:
    """Every setting among ``keys`` (default: ``before``'s then ``after``'s, in order) whose value differs
    between ``before`` and ``after``, as :func:`change`, joined by ``, ``; ``""`` when none differs (so
    ``assert not (d := changes(a, b)), f"... changed {d}"``). A setting one side lacks shows as ``none``."""
    names = list(dict.fromkeys(keys if keys is not None else [*before, *after]))
    return ", ".join(change(k, before.get(k, "none"), after.get(k, "none")) for k in names
                     if before.get(k, "none") != after.get(k, "none"))
