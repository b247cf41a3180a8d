"""Spec section 4.4.27: Maintance Information (241) - the run-time log: running times and temperature
maxima (option 0), this run (option 1), power-ups, stops and the power-on self-test fault code (option 2).

The counters are read here as the catalogue names them: option 1's "Number of runs" counts motor
starts, option 2's "Number of stops" motor stops (the table of 4.3.2 says "number of startups, number
of normal shutdowns" for the same log), "Number of power-ups" power-ups. The fault code's values are
the attachment's (:mod:`.test_attachment_fault_codes`)."""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat

from .answers import heard_instead
from .motor import run_motor
from .telemetry import INTERVALS

SECTION = "4.4.27"

SPEC = cat.spec("maintenance_information")
OPTIONS = tuple(SPEC.request.field("option").codes or {})  # type: ignore[union-attr]
COUNTERS = SPEC.response_for({"option": 2}).field("power_ups").mask  # type: ignore[union-attr]  # uint16 counters wrap
#: Test allowance: the motor runs this long for the runs/stops counters
RUN_S = 1.0


def ask(dut, option: int) -> dict:
    ex = dut.request("maintenance_information", {"option": option})
    assert ex.response is not None, f"no 7-byte answer to 241 option {option} from node {dut.node_id}" + heard_instead(dut, SPEC)
    return ex.response.fields


@pytest.mark.requirement("4.4.27-T")
@pytest.mark.parametrize("option", OPTIONS, ids=lambda o: f"option{o}")
def test_answer_has_the_option_s_layout(dut, option):
    """Each option is answered with 7 bytes in its own layout: option 0 the accumulated running time
    (uint32 s) and MOS / capacitor temperature maxima; option 1 this run's time (uint32 s) and the number
    of runs; option 2 the power-ups, stops, power-on self-test fault code, and Info_7 = the option.
    This run's time is part of the accumulated time: never more."""
    ex = dut.request("maintenance_information", {"option": option})
    assert ex.response is not None, f"no 7-byte answer to 241 option {option} from node {dut.node_id}" + heard_instead(dut, SPEC)
    layout = ex.response.layout
    assert layout is not None and layout.when == {"option": option}, f"answer decoded with {layout.name if layout else None}"
    fields = ex.response.fields
    dut.record.observe(f"241 option {option}", ex.response.physical())
    if option == 2:
        assert fields["option"] == option, f"Info_7 is {fields['option']}, not the option ({option})"
    elif option == 1:
        total = ask(dut, 0)["total_run_time"]
        assert fields["run_time"] <= total, f"this run's time {fields['run_time']} s exceeds the accumulated running time {total} s"


def _power_cycle_seen(dut, longest: float) -> None:
    """Cycle power with a proof that does not use the counter under test: reporting suspended before
    (MSG Control 0x55555555) comes back by itself after, since suspension is lost at power-off (R13)."""
    dut.stop_throttle()
    dut.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND})
    dut.wait(cat.ANSWER_DELAY_MAX_S)
    if dut.reports("msg1", 2 * longest):
        raise Inconclusive("MSG Control 0x55555555 did not stop MSG1: the power cycle cannot be proven by its end")
    dut.switch_power()  # unproven: the proof is below (it waits for the boot, and tells the live bus rules)
    if dut.wait_for("msg1", 2 * longest) is None:
        raise Inconclusive("no MSG1 after power-up: the ESC did not come back unsuspended, the power cycle is not proven")


@pytest.mark.requirement("4.4.27-T")
@pytest.mark.power_cycle
def test_power_up_counter_counts_each_power_up(dut):
    """Option 2's number of power-ups goes up by exactly one per power cycle (twice)."""
    longest = max(dut.settings()[k] for k in INTERVALS) * cat.INTERVAL_UNIT_S
    counts = [ask(dut, 2)["power_ups"]]
    for _ in range(2):
        _power_cycle_seen(dut, longest)
        counts.append(ask(dut, 2)["power_ups"])
    dut.record.observe("power-ups", counts)
    steps = [(b - a) & COUNTERS for a, b in zip(counts, counts[1:])]
    assert steps == [1, 1], f"number of power-ups {counts} over two power cycles: steps {steps}, expected one each"


@pytest.mark.requirement("4.4.27-T")
@pytest.mark.spins_motor
def test_runs_and_stops_count_motor_starts_and_stops(dut):
    """One motor start and stop adds one to option 1's number of runs and to option 2's number of
    stops (and nothing to the power-ups)."""
    before = {**ask(dut, 1), **ask(dut, 2)}
    if not run_motor(dut, RUN_S):
        pytest.skip("the motor may not spin: needs --allow-motor-spin and capability motor")
    after = {**ask(dut, 1), **ask(dut, 2)}
    steps = {k: (after[k] - before[k]) & COUNTERS for k in ("runs", "stops", "power_ups")}
    dut.record.observe("counters after one start and stop", {k: f"{before[k]} -> {after[k]}" for k in steps})
    assert steps == {"runs": 1, "stops": 1, "power_ups": 0}, (
        f"one motor start and stop changed the counters by {steps} (reading: runs = motor starts, stops = motor stops)")
