"""What the settings sections (4.4.20 - 4.4.23, 4.4.28) share. Not a section: no tests.

- What changed in the DUT's settings, said in a verdict: every changed setting with its old and new
  value, ``msg2_interval 50 -> 9, msg1_interval 10 -> 20`` - never a dict's repr (the failures-by-cause
  grouping drops parenthesised parts, so ``{'msg1_interval': (10, 20)}`` read ``{'msg1_interval':}``) nor
  pytest's truncated explanation of an ``==`` (``{'msg1_interv...nterval': 200}``).
- :class:`Setting`: one persisted setting as its section sets it up: read it back (242), the next legal value
  (each setting is reached from another, so a command that does nothing shows), and the set-up write that
  makes a test INCONCLUSIVE, not FAILed, when it does not take (whether it takes is another test's verdict).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ckesc.bench.verdict import Inconclusive


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


@dataclass(frozen=True)
class Setting:
    """One persisted setting, written by ``request``'s ``field`` and read back as ``dut.settings()[key]`` (242)."""

    request: str  # the request that writes it: "set_rotation"
    field: str  # its field in that request
    key: str  # its name in dut.settings()
    title: str  # as the document names the request: "Set Rotation"
    values: tuple[int, ...]  # its legal values, in order
    judged_by: str  # the test whose verdict is whether a write takes
    conditions: str  # the conditions of a set-up write, as a message says them: "at zero throttle with reporting on"

    def current(self, dut) -> int:
        return dut.settings()[self.key]

    def other(self, value: int) -> int:
        """The next legal value after ``value`` (the first, for one that is not legal)."""
        return self.values[(self.values.index(value) + 1) % len(self.values)] if value in self.values else self.values[0]

    def ensure(self, dut, value: int) -> None:
        """Set-up: the DUT at ``value``; INCONCLUSIVE when the write does not take (:attr:`judged_by` judges that)."""
        dut.request(self.request, {self.field: value})
        if self.current(dut) != value:
            raise Inconclusive(f"{self.title} {value} did not take {self.conditions} (see {self.judged_by}): this test "
                               "cannot be judged")
