"""What the settings sections (4.4.20 - 4.4.23, 4.4.28) share. Not a section: no tests.

- What changed in the DUT's settings, said in a verdict: every changed setting with its old and new
  value, ``msg2_interval 50 -> 9, msg1_interval 10 -> 20`` - never a dict's repr (the failures-by-cause
  grouping drops parenthesised parts, so ``{'msg1_interval': (10, 20)}`` read ``{'msg1_interval':}``) nor
  pytest's truncated explanation of an ``==`` (``{'msg1_interv...nterval': 200}``).
- :class:`Setting`: one persisted setting as its section sets it up: read it back (242), the next legal value
  (each setting is reached from another, so a command that does nothing shows), and the set-up write that
  makes a test INCONCLUSIVE, not FAILed, when it does not take (whether it takes is another test's verdict).
- The neighbour check (R13 across settings): ``neighbours_moved`` moves every other persisted setting, the section
  saves its own, ``check_neighbours_kept`` reads them all back at once and after a proven power cycle - a save that
  rewrites a whole flash block clobbers a neighbour, and no single-setting test sees it.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.judgements import Differs, r13_read_back


def listed(values: Mapping[str, Any]) -> str:
    """Settings and their values, as a message says them: ``msg1_interval 20, msg2_interval 9``."""
    return ", ".join(f"{k} {v}" for k, v in values.items())


def change(name: str, old: Any, new: Any) -> str:
    """One setting, from what to what: ``rotation 0 -> 1`` (as :func:`changes` and R13's read-back say it)."""
    return str(Differs(name, old, new))


def changes(before: Mapping[str, Any], after: Mapping[str, Any], keys: Iterable[str] | None = None) -> str:
    """Every setting among ``keys`` (default: ``before``'s then ``after``'s, in order) whose value differs
    between ``before`` and ``after``, as :func:`change`, joined by ``, ``; ``""`` when none differs (so
    ``assert not (d := changes(a, b)), f"... changed {d}"``). A setting one side lacks shows as ``none``."""
    return ", ".join(str(d) for d in r13_read_back(before, after, keys, missing="none"))


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

    def write(self, dut, value: int) -> None:
        """Send the request that sets ``value`` (nothing checked)."""
        dut.request(self.request, {self.field: value})

    def ensure(self, dut, value: int) -> None:
        """Set-up: the DUT at ``value``; INCONCLUSIVE when the write does not take (:attr:`judged_by` judges that)."""
        self.write(dut, value)
        if self.current(dut) != value:
            raise Inconclusive(f"{self.title} {value} did not take {self.conditions} (see {self.judged_by}): this test "
                               "cannot be judged")

    def check_save_keeps_neighbours(self, dut) -> None:
        """The neighbour check (R13 across settings) of this setting's own save: the others moved
        (:func:`neighbours_moved`), this one set to another value, all read back at once and after a proven power
        cycle (:func:`check_neighbours_kept`)."""
        with neighbours_moved(dut, but=self.key) as moved:
            value = self.other(moved[self.key])
            self.ensure(dut, value)
            check_neighbours_kept(dut, moved, f"{self.title} {value}", {self.key: value})


#: Set Rotation's direction and Throttle Select's source: the persisted settings with one field each
ROTATION = Setting("set_rotation", "rotation", "rotation", "Set Rotation",
                   tuple(sorted(cat.spec("set_rotation").response.field("rotation").codes)),  # 0 forward, 1 reverse
                   "test_direction_is_set", "with reporting on and the motor stopped")
SOURCE = Setting("throttle_select", "source", "throttle_source", "Throttle Select",
                 tuple(sorted(cat.spec("throttle_select").request.field("source").codes)),  # 0 CAN, 1 PWM+CAN
                 "test_source_is_selected", "at zero throttle with reporting on")


# ------------------------------------------------------------------------------------------ neighbours (R13)
#: Report intervals to move to: each set differs from the other and from the defaults (10, 50, 250).
_INTERVALS = ({"msg1_interval": 20, "msg2_interval": 60, "msg3_interval": 80},
              {"msg1_interval": 25, "msg2_interval": 70, "msg3_interval": 90})
#: A saved LED to move to: neither is the factory default (green, not blinking).
_LEDS = ({"led_color": 4, "led_blink": 1}, {"led_color": 1, "led_blink": 2})  # red blinking, blue blinking fast

#: The persisted settings (R13) a test can move at once, outside the 120 s window and with the motor stopped: what
#: a settings section's save must leave as it is (``neighbours_moved``'s ``but`` names the one a section saves), with
#: the settings each is read back as and the request that saves it.
NEIGHBOURS = {s.name: (s.keys, s.label) for s in cat.PERSISTED_SETTINGS if not s.window}
#: the DUT capability a neighbour needs (without it, it is neither moved nor checked)
_NEEDS = {"led": "led"}


def _other(current: Mapping[str, Any], choices: tuple[dict[str, int], ...]) -> dict[str, int]:
    return choices[all(current[k] == v for k, v in choices[0].items())]


def other_intervals(current: Mapping[str, Any]) -> dict[str, int]:
    """Report intervals none of which is ``current``'s or a default (for a Set Freq write that must show)."""
    return _other(current, _INTERVALS)


#: where each neighbour moves to from the settings read (its read-back names and values): a setting the catalogue's
#: table adds without its way here fails at import
_TARGETS = {
    "rotation": lambda s: {"rotation": ROTATION.other(s["rotation"])},
    "throttle_source": lambda s: {"throttle_source": SOURCE.other(s["throttle_source"])},
    "led": lambda s: _other(s, _LEDS),
    "intervals": other_intervals,
}
if missing := sorted(set(NEIGHBOURS) ^ set(_TARGETS)):
    raise KeyError(f"persisted settings {missing}: say in conformance/settings.py where a neighbour check moves them")


def move_request(name: str, s: Mapping[str, int]) -> dict[str, int]:
    """The fields of persisted setting ``name``'s own request (with its save fields) that would move it from the
    settings ``s`` to a value it is not at: a write whose taking shows in the settings read."""
    setting = cat.PERSISTED[name]
    field_of = {key: f for f, key in setting.fields.items()}
    return {**setting.save, **{field_of[k]: v for k, v in _TARGETS[name](s).items()}}


def _has(dut, name: str) -> bool:
    return name not in _NEEDS or dut.profile.has(_NEEDS[name])


def _save(dut, name: str, values: Mapping[str, int]) -> None:
    """Write and save ``values`` (read-back names) of persisted setting ``name`` with its own request (nothing checked)."""
    setting = cat.PERSISTED[name]
    field_of = {key: f for f, key in setting.fields.items()}
    dut.request(setting.writer, {**setting.save, **{field_of[k]: v for k, v in values.items()}})


@contextmanager
def neighbours_moved(dut, but: str = "") -> Iterator[dict[str, int]]:
    """Setup of a neighbour check: a proven power cycle (so the copy of the settings an ESC reads at power-up is the
    settings as they are), then every setting of :data:`NEIGHBOURS` but ``but`` moved to a value it is not at, each
    saved by its own request (Set Rotation, Throttle Select, Set LED option 1 when the DUT has an LED, Set Freq), away
    from the factory defaults: so a save that rewrites its neighbours from the copy read at power-up, or from the
    defaults, shows after the next power cycle. Gives the settings then (242 and Set/Get Freq read); INCONCLUSIVE
    when one did not take (its own section judges that). On leaving, every one of them (the section's own too) is
    written back to what it read before, whatever the reads say then: a DUT whose read-back is wrong (which the ``dut`` fixture's restore
    goes by) is still left as found for the tests after."""
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    s = dut.settings()
    try:
        yield _move(dut, s, but)
    finally:  # the section's own setting too: all of them as read before
        for name, (keys, _) in NEIGHBOURS.items():
            if _has(dut, name):
                _save(dut, name, {k: s[k] for k in keys})


def _move(dut, s: Mapping[str, int], but: str) -> dict[str, int]:
    want: dict[str, int] = {}
    for name in NEIGHBOURS:
        if name != but and _has(dut, name):
            want.update(values := _TARGETS[name](s))
            _save(dut, name, values)
    after = dut.settings()
    if missed := changes(want, {k: after[k] for k in want}):
        raise Inconclusive(f"moving the other persisted settings did not take ({missed}, set -> read): their own "
                           "sections judge that; the neighbours of this save cannot be judged")
    return after


def check_neighbours_kept(dut, moved: Mapping[str, int], save: str, saved: Mapping[str, int]) -> None:
    """R13 across settings: after ``save`` (what the test saved, as a message says it; ``saved`` its settings as
    written), made once :func:`neighbours_moved` had ``moved`` the others, every setting read back (242 and Set/Get
    Freq read) is as moved and saved - at once and after a proven power cycle: the save left its neighbours, in
    RAM and in flash, as it found them (a save rewriting a whole flash block from stale or default values does not)."""
    expected = {**moved, **saved}
    moves = ", ".join(request for name, (keys, request) in NEIGHBOURS.items()
                      if not set(keys) & set(saved) and _has(dut, name))
    at_once = changes(expected, dut.settings())
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    after = changes(expected, dut.settings())
    assert not (at_once or after), (f"{save}, made after the other settings were saved ({moves}), changed settings: "
                                    + "; ".join(f"{when} {d}" for when, d in (("at once", at_once),
                                                ("after a power cycle", after)) if d) + " (expected -> read)")
