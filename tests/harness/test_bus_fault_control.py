"""The bus-fault control (ckesc/bench/bus_fault.py): a real bench's command, and the simulated lane's own."""

from __future__ import annotations

import sys

import pytest

from ckesc.bench.bus_fault import NO_CONTROL, BusFaultFailed, CommandBusFault, SimBusFault, bus_fault_control
from ckesc.bench.sim_lane import SimLane


def test_the_command_gets_the_seconds_and_the_kind():
    ok = f"{sys.executable} -c \"import sys; sys.exit(sys.argv[1:] != ['0.5', 'short'])\" {{seconds}} {{kind}}"
    control = CommandBusFault(ok, 10.0)
    assert control.cause("short", 0.5) is None
    assert control.can("other_bitrate")


def test_a_failing_command_is_the_benchs_error_naming_it():
    control = CommandBusFault(f"{sys.executable} -c \"import sys; sys.exit(3)\" {{seconds}}", 10.0)
    assert not control.can("other_bitrate")  # (no {kind}: a short only)
    with pytest.raises(BusFaultFailed, match="exit status 3"):
        control.cause("short", 0.5)


def test_a_command_needs_its_seconds():
    with pytest.raises(ValueError, match="seconds"):
        CommandBusFault("relay on", 10.0)


class _Lane:  # a lane that is neither simulated nor given a command
    pass


def test_a_lane_without_a_control_has_none():
    assert bus_fault_control(_Lane()) is None
    assert "--bus-fault-cmd" in NO_CONTROL


def test_the_simulated_lane_shorts_its_bus_and_returns_once_every_controller_recovered():
    lane = SimLane(esc_config={"boot_time": 0.25})
    try:
        lane.wait_power(0.5)
        control = bus_fault_control(lane)
        assert isinstance(control, SimBusFault) and bus_fault_control(lane) is control
        world = lane.sim.world
        end = control.cause("short", 0.2)
        assert end == pytest.approx(0.7)
        assert control.settled()  # every controller recovered and its queue sent
        assert world.stats["retries"] > 0  # the short did meet the ESC's tries
        assert all(ctl.counts["recovered"] for node, ctl in world._ctl.items() if ctl.counts["bus_off"])
    finally:
        lane.close()


def test_a_simulated_lane_without_the_can_model_has_no_control(monkeypatch):
    from ckesc.bench import sim_lane

    monkeypatch.setattr(sim_lane, "SIM_CAN", {"ack": False, "txqueuelen": None})  # (CKESC_SIM_ACK=0)
    lane = SimLane()
    try:
        assert bus_fault_control(lane) is None  # nothing on a bus without acknowledgement goes bus-off
    finally:
        lane.close()
