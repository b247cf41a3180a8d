"""Spec section 4.4.23: Throttle Select (215) - throttle source 0 CAN / 1 PWM+CAN, set at zero throttle.

What is in force is read back with Get Major Configuration (242, ``throttle_source``), so the tests
also cite 4.4.28-1. Each setting
is reached from the other source, so a command that does nothing shows. The valid throttle ranges of
clarification 5 (4.4.23-5) are checked by the RawCommand modules (4.4.15 - 4.4.17). The PWM input of
clarification 6 is driven through the simulated lane's bench (``dut.lane.sim.bench.set_pwm_input``);
lanes without such a control skip those tests. The ``dut`` fixture restores (and verifies) the source
it found.
"""

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.legality import illegal_cases

from . import throttle
from .settings import SOURCE, change, listed

SECTION = "4.4.23"
SPEC = cat.spec("throttle_select")
SOURCES = list(SOURCE.values)  # 0 CAN, 1 PWM+CAN
CAN, PWM_CAN = (next(v for v, n in SPEC.request.field("source").codes.items() if n == name) for name in ("CAN", "PWM+CAN"))
ILLEGAL = illegal_cases(SPEC)  # R10: anything but 0 and 1
motor_stopped = throttle.motor_stopped  # autouse fixture: the motor stopped before and after each test


def _name(source):
    return SPEC.request.field("source").codes.get(source, hex(source))


def _select(dut, source):
    """Select ``source`` and check the answer and 242 show it."""
    ex = dut.request("throttle_select", {"source": source})
    assert ex.response is not None, f"no answer to Throttle Select {source}"
    assert ex.response.fields["source"] == source, f"Throttle Select {source} answered {listed(ex.response.fields)}"
    assert SOURCE.current(dut) == source, f"after Throttle Select {source} 242 shows {SOURCE.current(dut)}"


@pytest.fixture
def pwm_input(dut):
    """Sets the DUT's analog throttle input (0..2000 as the lane models it; None: no signal); the
    input is removed after the test."""
    bench = getattr(getattr(dut.lane, "sim", None), "bench", None)
    if bench is None:
        pytest.skip(f"the {dut.lane.name} lane has no control of the DUT's PWM input")

    def set_input(value):
        bench.set_pwm_input(value, node=dut.node_id)

    try:
        yield set_input
    finally:
        set_input(None)
        dut.wait_motor_stopped()  # let the motor spin down, seen or not


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.23-1", "4.4.28-1")
@pytest.mark.parametrize("source", SOURCES, ids=_name)
def test_source_is_selected(dut, source):
    """Throttle Select 0 / 1 is answered with the source and 242 shows it - reached from the other."""
    _select(dut, SOURCE.other(source))
    _select(dut, source)


@pytest.mark.requirement("4.4.23-3", "R12", "4.4.28-1")
@pytest.mark.spins_motor
def test_not_selected_while_the_throttle_is_not_zero(dut):
    """'To set this command, set it at zero throttle': with the motor running, nothing changes (not
    later either). First shown to work at zero throttle."""
    before = SOURCE.current(dut)
    SOURCE.ensure(dut, SOURCE.other(before))
    SOURCE.ensure(dut, before)
    throttle.start_motor(dut)
    try:
        ex = dut.request("throttle_select", {"source": SOURCE.other(before)})
        dut.record.observe("answer at non-zero throttle", ex.response.fields if ex.response else "none")
        during = SOURCE.current(dut)
    finally:
        dut.stop_motor()
    assert during == before, f"Throttle Select at non-zero throttle took effect: 242 {change('throttle_source', before, during)}"
    now = SOURCE.current(dut)
    assert now == before, f"Throttle Select sent at non-zero throttle took effect later: 242 {change('throttle_source', before, now)}"


@pytest.mark.requirement("R12", "4.4.2-3", "4.4.28-1")
def test_not_selected_while_reporting_is_suspended(dut):
    """'parameter changes do not take effect when the active data reporting command is suspended' (not
    even once reporting resumes). First shown to work with reporting on."""
    before = SOURCE.current(dut)
    SOURCE.ensure(dut, SOURCE.other(before))
    SOURCE.ensure(dut, before)
    dut.suspend_reporting()
    try:
        ex = dut.request("throttle_select", {"source": SOURCE.other(before)})
        dut.record.observe("answer while suspended", ex.response.fields if ex.response else "none")
    finally:
        dut.resume_reporting()
    now = SOURCE.current(dut)
    assert now == before, f"Throttle Select while suspended took effect: 242 {change('throttle_source', before, now)}"


@pytest.mark.requirement("R10", "R10-answer", "4.4.23-1", "4.4.28-1")
@pytest.mark.parametrize("start", SOURCES, ids=lambda s: f"from-{_name(s)}")
@pytest.mark.parametrize("case", ILLEGAL, ids=lambda c: c.id)
def test_illegal_source_changes_nothing(dut, case, start):
    """A source other than 0 / 1 is ignored, whichever source is in force."""
    SOURCE.ensure(dut, start)
    try:
        ex = dut.request("throttle_select", {"source": case.value})
        dut.record.observe("answer to the illegal source (R10-answer)", ex.response.fields if ex.response else "none")
        now = SOURCE.current(dut)
        assert now == start, f"Throttle Select {case.value:#04x} changed the source: 242 {change('throttle_source', start, now)}"
    finally:
        dut.request("throttle_select", {"source": start})  # whatever the DUT stored, a legal value again


def _write_illegal(dut, case):
    start = SOURCE.other(case.value & 1)
    SOURCE.ensure(dut, start)
    dut.request("throttle_select", {"source": case.value})
    return start


@pytest.mark.requirement("R10", "4.4.23-4", "R13", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.parametrize("case", ILLEGAL, ids=lambda c: c.id)
@pytest.mark.cold_boot(_write_illegal, touches="throttle_source")
def test_illegal_source_changes_nothing_after_power_cycle(dut, cold_boot, case):
    """Nothing of an illegal source surfaces after a power cycle either (from the source the illegal
    value's low bit does not name, so a device that keeps only bit 0 shows)."""
    try:
        start = cold_boot()
        now = SOURCE.current(dut)
        assert now == start, f"after {case.value:#04x} and a power cycle the source changed: 242 {change('throttle_source', start, now)}"
    finally:
        dut.request("throttle_select", {"source": SOURCE.other(case.value & 1)})  # whatever the DUT stored, a legal value


def _write_other_source(dut):
    source = SOURCE.other(SOURCE.current(dut))
    SOURCE.ensure(dut, source)
    return source


@pytest.mark.requirement("4.4.23-4", "R13", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.cold_boot(_write_other_source, touches="throttle_source")
def test_source_persists_across_power_cycle(dut, cold_boot):
    """'This parameter will be saved in FLASH ... will not be lost when power is turned off.'"""
    source = cold_boot()
    now = SOURCE.current(dut)
    assert now == source, f"a power cycle changed the source selected: 242 {change('throttle_source', source, now)}"


@pytest.mark.requirement("4.4.23-6", "4.4.23-1", "4.4.4-T", "4.4.28-1")
@pytest.mark.spins_motor
@pytest.mark.parametrize("value", [cat.THROTTLE_MAX // 4, cat.THROTTLE_MAX], ids=lambda v: f"pwm{v}")
def test_pwm_input_drives_the_output_with_source_pwm_can(dut, pwm_input, value):
    """With PWM+CAN selected and no CAN throttle, the analog input (1..2 ms = 0..2000) is the output."""
    _select(dut, PWM_CAN)
    pwm_input(value)
    pwms = dut.read_output()[dut.node_id]
    assert all(p == value for p in pwms), f"PWM input {value} with source PWM+CAN: MSG1 pwm {pwms}"


@pytest.mark.requirement("4.4.23-6", "4.4.23-1", "4.4.4-T", "4.4.28-1")
@pytest.mark.spins_motor
def test_pwm_input_is_ignored_with_source_can(dut, pwm_input):
    """With CAN selected the analog input commands nothing; the CAN throttle does."""
    _select(dut, CAN)
    pwm_input(cat.THROTTLE_MAX)
    pwms = dut.throttle_output("raw_command_12b", [throttle.run_command(dut)])[dut.node_id]
    assert all(p == throttle.RUN_VALUE for p in pwms), (
        f"source CAN, CAN throttle {throttle.RUN_VALUE}, PWM input {cat.THROTTLE_MAX}: MSG1 pwm {pwms}")


@pytest.mark.requirement("4.4.23-2")
def test_observe_current_source(dut):
    """'Default CAN digital throttle': the DUT's source is recorded (a DUT in the field may differ)."""
    source = SOURCE.current(dut)
    dut.record.observe("throttle source", _name(source))
    assert source == CAN, "not at the factory default (CAN)"


@pytest.mark.requirement("R13", "4.4.23-4", "4.4.21-4", "4.4.22-6", "4.4.22-2", "4.4.28-1")
@pytest.mark.power_cycle
def test_select_leaves_the_other_settings(dut):
    """Throttle Select rewrites nothing else: the other persisted settings, moved since this power-up, are as they
    were, at once and after a power cycle (a save rewriting a whole flash block can clobber them)."""
    SOURCE.check_save_keeps_neighbours(dut)
