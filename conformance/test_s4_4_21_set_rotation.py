"""Spec section 4.4.21: Set Rotation (213) - motor direction 0 forward / 1 reverse, 0xFF queries.

What is in force is read back with the 0xFF query and with Get Major Configuration (242, ``direction``);
tests whose verdict rests on 242 also cite 4.4.28-1.
Each setting is reached from the other direction, so a command that does nothing shows. The ``dut``
fixture restores (and verifies) the direction it found.
"""

import pytest

from ckesc.harness.verdict import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.codecs import codec_for
from ckesc.protocol.frame import classify
from ckesc.protocol.ids import Kind
from ckesc.protocol.legality import illegal_cases

SECTION = "4.4.21"
REPORT_IDS = frozenset(s.type_id for s in cat.CATALOGUE if any(lay.name == "report" for lay in s.layouts))
SPEC = cat.spec("set_rotation")
DIRECTIONS = sorted(SPEC.response.field("rotation").codes)  # 0 forward, 1 reverse
QUERY = next(v for v, name in SPEC.request.field("rotation").codes.items() if name == "query")  # 0xFF
ILLEGAL = illegal_cases(SPEC)  # R10: anything but 0, 1 and 0xFF
_12B = cat.spec("raw_command_12b").layouts[0]
PER_GROUP = len(codec_for(_12B).decode(bytes(_12B.size))["channels"])  # 4.4.16-3: four channels per group
#: a modest throttle whose 12-bit packing is the same in both nibble orders (bits 11..8 and 3..0 zero),
#: so that running the motor does not depend on R4
RUN_VALUE = 0xF0
STOP_TIMEOUT_S = 5.0  # how long a motor may take to spin down; not a protocol fact


def _name(direction):
    return SPEC.response.field("rotation").codes.get(direction, hex(direction))


def _other(direction):
    return DIRECTIONS[(DIRECTIONS.index(direction) + 1) % len(DIRECTIONS)] if direction in DIRECTIONS else DIRECTIONS[0]


def _query(dut):
    ex = dut.request("set_rotation", {"rotation": QUERY})
    assert ex.response is not None, "no answer to the Set Rotation query (0xFF)"
    return ex.response.fields["rotation"]


def _direction(dut):
    return dut.settings()["rotation"]


def _set(dut, direction):
    """Set ``direction`` and check the answer, the query and 242 show it."""
    ex = dut.request("set_rotation", {"rotation": direction})
    assert ex.response is not None, f"no answer to Set Rotation {direction}"
    assert ex.response.fields["rotation"] == direction, f"Set Rotation {direction} answered {ex.response.fields}"
    assert _query(dut) == direction, f"after Set Rotation {direction} the query answers {_query(dut)}"
    assert _direction(dut) == direction, f"after Set Rotation {direction} 242 shows {_direction(dut)}"


def _ensure(dut, direction):
    """Setup: the DUT at ``direction`` (Inconclusive if Set Rotation cannot get it there: that is what
    test_direction_is_set judges)."""
    dut.request("set_rotation", {"rotation": direction})
    if _direction(dut) != direction:
        raise Inconclusive(f"Set Rotation {direction} did not take with reporting on and the motor stopped "
                           "(see test_direction_is_set): this test cannot be judged")


def _running(f):
    """MSG1 shows the motor running: the run bit, or a speed (either will do: R7 is 4.4.4's business)."""
    return bool(f.fields["status"] & cat.Status.RUNNING) or f.fields["speed"] > 0


def _stopped(f):
    return f.fields["speed"] == 0 and f.fields["pwm"] == 0


def _wait_stopped(dut):
    """Zero throttle, then until MSG1 shows the motor stopped (or STOP_TIMEOUT_S, when it cannot be seen)."""
    dut.zero_throttle()
    dut.wait_for("msg1", STOP_TIMEOUT_S, where=_stopped)


@pytest.fixture(autouse=True)
def _motor_stopped(request):
    """The motor stopped before each test (settings need it, R12) and after it (the DUT left as found)."""
    if "dut" not in request.fixturenames:
        yield
        return
    dut = request.getfixturevalue("dut")
    _wait_stopped(dut)
    yield
    _wait_stopped(dut)


def _run_motor(dut):
    """Throttle on the DUT's own channel (RawCommand_12b of its group) until MSG1 says it runs."""
    channel = dut.settings()["throttle_channel"]
    group, pos = (channel - 1) // PER_GROUP + 1, (channel - 1) % PER_GROUP
    dut.throttle_stream("raw_command_12b", {"channels": [RUN_VALUE if i == pos else 0 for i in range(PER_GROUP)],
                                            "group": group})
    if dut.wait_for("msg1", STOP_TIMEOUT_S, where=_running) is None:
        dut.zero_throttle()
        dut.wait_for("msg1", STOP_TIMEOUT_S, where=_stopped)  # let it spin down, seen or not
        raise Inconclusive("the motor did not start (no MSG1 showed it running): the test cannot be judged")


def _stop_motor(dut):
    dut.zero_throttle()
    if dut.wait_for("msg1", STOP_TIMEOUT_S, where=_stopped) is None:
        raise Inconclusive(f"the motor still runs {STOP_TIMEOUT_S} s after zero throttle (MSG1 speed, pwm)")


def _reports_heard(dut, seconds):
    """How many report frames the DUT sends in the next ``seconds``, decoded or not (their format is
    4.4.4 - 4.4.14's business; here only whether it reports counts)."""
    start = dut.now()
    dut.wait(seconds)
    heard = [f for f in dut.frames(source=dut.node_id, kind=Kind.MESSAGE, since=start) if f.type_id in REPORT_IDS]
    heard += [g for g in dut.garbled if (g.msg.timestamp or 0.0) > start and (g.msg.arbitration_id & 0x7F) == dut.node_id
              and classify(g.msg.arbitration_id)[:2] in {(Kind.MESSAGE, t) for t in REPORT_IDS}]
    return len(heard)


def _report_interval(dut):
    return dut.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S


def _suspend(dut):
    """MSG Control 0x55555555; INCONCLUSIVE unless the reports stop (that is 4.4.2's business)."""
    interval = _report_interval(dut)
    dut.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND})
    dut.wait(cat.ANSWER_DELAY_MAX_S)
    if _reports_heard(dut, 2 * interval):
        _resume(dut)
        raise Inconclusive("MSG Control 0x55555555 did not stop the reports (see 4.4.2): suspension cannot be tested")


def _resume(dut):
    """MSG Control 0xAAAAAAAA; if the reports do not come back (4.4.2's business) the DUT is power-cycled
    back to reporting (suspension is not kept, R13) and the test is INCONCLUSIVE."""
    dut.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
    dut.wait(cat.ANSWER_DELAY_MAX_S)
    if _reports_heard(dut, 2 * _report_interval(dut)):
        return
    if dut.lane.power.available:
        dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    raise Inconclusive("MSG Control 0xAAAAAAAA did not bring the reports back (see 4.4.2): this test cannot be judged")


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.21-1", "4.4.21-T", "4.4.28-1")
@pytest.mark.parametrize("direction", DIRECTIONS, ids=_name)
def test_direction_is_set(dut, direction):
    """Set Rotation 0 / 1 is answered with the direction, and the query and 242 show it - reached
    from the other direction."""
    _set(dut, _other(direction))
    _set(dut, direction)


@pytest.mark.requirement("4.4.21-T", "4.4.28-1")
@pytest.mark.parametrize("direction", DIRECTIONS, ids=_name)
def test_query_answers_the_direction_and_changes_nothing(dut, direction):
    """0xFF 'queries the current direction of rotation': answered with it, twice, nothing changed."""
    _set(dut, _other(direction))
    _set(dut, direction)
    assert [_query(dut), _query(dut)] == [direction, direction]
    assert _direction(dut) == direction, f"the query changed the direction: 242 shows {_direction(dut)}"


@pytest.mark.requirement("R10", "R10-answer", "4.4.21-T", "4.4.28-1")
@pytest.mark.parametrize("start", DIRECTIONS, ids=lambda d: f"from-{_name(d)}")
@pytest.mark.parametrize("case", ILLEGAL, ids=lambda c: c.id)
def test_illegal_value_changes_nothing(dut, case, start):
    """A value other than 0, 1, 0xFF is ignored, whichever direction is in force."""
    _ensure(dut, start)
    ex = dut.request("set_rotation", {"rotation": case.value})
    dut.record.observe("answer to the illegal value (R10-answer)", ex.response.fields if ex.response else "none")
    assert (_query(dut), _direction(dut)) == (start, start), (
        f"Set Rotation {case.value:#04x} changed the direction from {start}: query {_query(dut)}, 242 {_direction(dut)}")


@pytest.mark.requirement("R10", "4.4.21-4", "R13", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.parametrize("case", ILLEGAL, ids=lambda c: c.id)
def test_illegal_value_changes_nothing_after_power_cycle(dut, case):
    """Nothing of an illegal value surfaces after a power cycle either."""
    start = DIRECTIONS[0]
    _ensure(dut, start)
    dut.request("set_rotation", {"rotation": case.value})
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    assert (_query(dut), _direction(dut)) == (start, start), f"after {case.value:#04x} and a power cycle: {_direction(dut)}"


@pytest.mark.requirement("4.4.21-2", "4.4.2-3", "R12", "4.4.28-1")
def test_not_set_while_reporting_is_suspended(dut):
    """'only ... when data reporting is on': suspended, Set Rotation takes no effect (not even once
    reporting resumes). First shown to work with reporting on, so that a command that never works
    does not pass."""
    before = _direction(dut)
    _ensure(dut, _other(before))
    _ensure(dut, before)
    _suspend(dut)
    try:
        ex = dut.request("set_rotation", {"rotation": _other(before)})
        dut.record.observe("answer while suspended", ex.response.fields if ex.response else "none")
    finally:
        _resume(dut)
    assert _direction(dut) == before, f"Set Rotation while suspended took effect: 242 shows {_direction(dut)}"


@pytest.mark.requirement("4.4.21-2", "R12", "4.4.28-1")
@pytest.mark.spins_motor
def test_not_set_while_the_motor_runs(dut):
    """'only ... when ... the motor is stopped': running, Set Rotation takes no effect (not later either).
    First shown to work with the motor stopped."""
    before = _direction(dut)
    _ensure(dut, _other(before))
    _ensure(dut, before)
    _run_motor(dut)
    try:
        ex = dut.request("set_rotation", {"rotation": _other(before)})
        dut.record.observe("answer while running", ex.response.fields if ex.response else "none")
        running = (_query(dut), _direction(dut))
    finally:
        _stop_motor(dut)
    assert running == (before, before), f"Set Rotation while the motor ran took effect: query, 242 = {running}"
    assert _direction(dut) == before, f"Set Rotation sent while running took effect later: 242 shows {_direction(dut)}"


@pytest.mark.requirement("4.4.21-4", "R13", "4.4.28-1")
@pytest.mark.power_cycle
def test_direction_persists_across_power_cycle(dut):
    """'This parameter will be saved in FLASH ... will not be lost when power is turned off.'"""
    direction = _other(_direction(dut))
    _ensure(dut, direction)
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    assert (_query(dut), _direction(dut)) == (direction, direction), f"after a power cycle: 242 {_direction(dut)}"


@pytest.mark.requirement("4.4.21-3")
def test_observe_current_direction(dut):
    """'Default positive rotation': the DUT's direction is recorded (a DUT in the field may differ)."""
    direction = _direction(dut)
    dut.record.observe("direction", _name(direction))
    assert direction == DIRECTIONS[0], "not at the factory default (forward)"
