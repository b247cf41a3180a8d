"""Spec section 4.4.21: Set Rotation (213) - motor direction 0 forward / 1 reverse, 0xFF queries.

What is in force is read back with the 0xFF query and with Get Major Configuration (242, ``direction``);
tests whose verdict rests on 242 also cite 4.4.28-1.
Each setting is reached from the other direction, so a command that does nothing shows. The ``dut``
fixture restores (and verifies) the direction it found.
"""

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.legality import illegal_cases

from . import throttle
from .settings import ROTATION, change, changes, listed

SECTION = "4.4.21"
SPEC = cat.spec("set_rotation")
DIRECTIONS = list(ROTATION.values)  # 0 forward, 1 reverse
QUERY = next(v for v, name in SPEC.request.field("rotation").codes.items() if name == "query")  # 0xFF
ILLEGAL = illegal_cases(SPEC)  # R10: anything but 0, 1 and 0xFF
motor_stopped = throttle.motor_stopped  # autouse fixture: the motor stopped before and after each test


def _name(direction):
    return SPEC.response.field("rotation").codes.get(direction, hex(direction))


def _query(dut):
    ex = dut.request("set_rotation", {"rotation": QUERY})
    assert ex.response is not None, "no answer to the Set Rotation query (0xFF)"
    return ex.response.fields["rotation"]


def _shown_changes(dut, want):
    """Where the query and 242 show another direction than ``want``: ``242 rotation 0 -> 1``; "" if nowhere."""
    shown = {"query": _query(dut), "242 rotation": ROTATION.current(dut)}
    return changes(dict.fromkeys(shown, want), shown)


def _set(dut, direction):
    """Set ``direction`` and check the answer, the query and 242 show it."""
    ex = dut.request("set_rotation", {"rotation": direction})
    assert ex.response is not None, f"no answer to Set Rotation {direction}"
    assert ex.response.fields["rotation"] == direction, f"Set Rotation {direction} answered {listed(ex.response.fields)}"
    assert _query(dut) == direction, f"after Set Rotation {direction} the query answers {_query(dut)}"
    assert ROTATION.current(dut) == direction, f"after Set Rotation {direction} 242 shows {ROTATION.current(dut)}"


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.21-1", "4.4.21-T", "4.4.28-1")
@pytest.mark.parametrize("direction", DIRECTIONS, ids=_name)
def test_direction_is_set(dut, direction):
    """Set Rotation 0 / 1 is answered with the direction, and the query and 242 show it - reached
    from the other direction."""
    _set(dut, ROTATION.other(direction))
    _set(dut, direction)


@pytest.mark.requirement("4.4.21-T", "4.4.28-1")
@pytest.mark.parametrize("direction", DIRECTIONS, ids=_name)
def test_query_answers_the_direction_and_changes_nothing(dut, direction):
    """0xFF 'queries the current direction of rotation': answered with it, twice, nothing changed."""
    _set(dut, ROTATION.other(direction))
    _set(dut, direction)
    answers = [_query(dut), _query(dut)]
    assert answers == [direction, direction], f"the query answered {answers[0]} then {answers[1]}, the direction set is {direction}"
    now = ROTATION.current(dut)
    assert now == direction, f"the query changed the direction: 242 {change('rotation', direction, now)}"


@pytest.mark.requirement("R10", "R10-answer", "4.4.21-T", "4.4.28-1")
@pytest.mark.parametrize("start", DIRECTIONS, ids=lambda d: f"from-{_name(d)}")
@pytest.mark.parametrize("case", ILLEGAL, ids=lambda c: c.id)
def test_illegal_value_changes_nothing(dut, case, start):
    """A value other than 0, 1, 0xFF is ignored, whichever direction is in force."""
    ROTATION.ensure(dut, start)
    ex = dut.request("set_rotation", {"rotation": case.value})
    dut.record.observe("answer to the illegal value (R10-answer)", ex.response.fields if ex.response else "none")
    assert not (d := _shown_changes(dut, start)), f"Set Rotation {case.value:#04x} changed the direction: {d}"


def _write_illegal(dut, case):
    start = DIRECTIONS[0]
    ROTATION.ensure(dut, start)
    dut.request("set_rotation", {"rotation": case.value})
    return start


@pytest.mark.requirement("R10", "4.4.21-4", "R13", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.parametrize("case", ILLEGAL, ids=lambda c: c.id)
@pytest.mark.cold_boot(_write_illegal, touches="rotation")
def test_illegal_value_changes_nothing_after_power_cycle(dut, cold_boot, case):
    """Nothing of an illegal value surfaces after a power cycle either."""
    start = cold_boot()
    assert not (d := _shown_changes(dut, start)), f"after {case.value:#04x} and a power cycle the direction changed: {d}"


@pytest.mark.requirement("4.4.21-2", "4.4.2-3", "R12", "4.4.28-1")
def test_not_set_while_reporting_is_suspended(dut):
    """'only ... when data reporting is on': suspended, Set Rotation takes no effect (not even once
    reporting resumes). First shown to work with reporting on, so that a command that never works
    does not pass."""
    before = ROTATION.current(dut)
    ROTATION.ensure(dut, ROTATION.other(before))
    ROTATION.ensure(dut, before)
    dut.suspend_reporting()
    try:
        ex = dut.request("set_rotation", {"rotation": ROTATION.other(before)})
        dut.record.observe("answer while suspended", ex.response.fields if ex.response else "none")
    finally:
        dut.resume_reporting()
    now = ROTATION.current(dut)
    assert now == before, f"Set Rotation while suspended took effect: 242 {change('rotation', before, now)}"


@pytest.mark.requirement("4.4.21-2", "R12", "4.4.28-1")
@pytest.mark.spins_motor
def test_not_set_while_the_motor_runs(dut):
    """'only ... when ... the motor is stopped': running, Set Rotation takes no effect (not later either).
    First shown to work with the motor stopped."""
    before = ROTATION.current(dut)
    ROTATION.ensure(dut, ROTATION.other(before))
    ROTATION.ensure(dut, before)
    throttle.start_motor(dut)
    try:
        ex = dut.request("set_rotation", {"rotation": ROTATION.other(before)})
        dut.record.observe("answer while running", ex.response.fields if ex.response else "none")
        running = _shown_changes(dut, before)
    finally:
        dut.stop_motor()
    assert not running, f"Set Rotation while the motor ran took effect: {running}"
    now = ROTATION.current(dut)
    assert now == before, f"Set Rotation sent while running took effect later: 242 {change('rotation', before, now)}"


def _write_other_direction(dut):
    direction = ROTATION.other(ROTATION.current(dut))
    ROTATION.ensure(dut, direction)
    return direction


@pytest.mark.requirement("4.4.21-4", "R13", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.cold_boot(_write_other_direction, touches="rotation")
def test_direction_persists_across_power_cycle(dut, cold_boot):
    """'This parameter will be saved in FLASH ... will not be lost when power is turned off.'"""
    direction = cold_boot()
    assert not (d := _shown_changes(dut, direction)), f"a power cycle changed the direction saved: {d}"


@pytest.mark.requirement("4.4.21-3")
def test_observe_current_direction(dut):
    """'Default positive rotation': the DUT's direction is recorded (a DUT in the field may differ)."""
    direction = ROTATION.current(dut)
    dut.record.observe("direction", _name(direction))
    assert direction == DIRECTIONS[0], "not at the factory default (forward)"


@pytest.mark.requirement("R13", "4.4.21-4", "4.4.22-6", "4.4.23-4", "4.4.22-2", "4.4.28-1")
@pytest.mark.power_cycle
def test_setting_leaves_the_other_settings(dut):
    """Set Rotation rewrites nothing else: the other persisted settings, moved since this power-up, are as they
    were, at once and after a power cycle (a save rewriting a whole flash block can clobber them)."""
    ROTATION.check_save_keeps_neighbours(dut)
