"""Spec section 4.4.16: RawCommand_12b (20101) - four 12-bit throttle channels of group 1..5 per broadcast.

The observable is MSG1's ``pwm`` (the throttle output, 4.4.4) of the DUT while a stream of commands
runs. Every channel 1..20 carries its own value, and the DUT's own group is sent first, so a wrong
channel, group or nibble order (R4, in the order the DUT profile states) shows as a wrong output.
Channels other than the DUT's own are reached by moving the DUT there with Set ID inside the 120 s
window of a proven power cycle (R11), and back.
What the three RawCommand sections check alike is written once, in ``conformance/throttle.py``.
"""

import pytest

from ckesc.protocol import catalogue as cat

from . import throttle
from .raw_command_12b import FORMAT, GROUPS, NAME, PER_GROUP, RAW_MAX, VALUES
from .throttle import check

SECTION = "4.4.16"
escs_on_channels = throttle.escs_on_channels  # fixture: multi_dut with each ESC's channel and MSG1 interval
motor_stopped = throttle.motor_stopped  # autouse fixture: the motor stopped before and after each test


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.16-1")
def test_throttle_is_not_answered(dut):
    """A RawCommand is a broadcast without an answer: while a 400 Hz stream of all five groups runs
    the DUT sends its reports at their intervals and nothing else."""
    FORMAT.check_not_answered(dut, VALUES)


@pytest.mark.requirement("4.4.16-1", "4.4.16-3", "R4", "4.4.18-6", "4.4.4-T")
def test_every_esc_parses_the_same_frames(escs_on_channels):
    """All ESCs on the bus take their own channel's value from the same broadcast frames."""
    FORMAT.check_every_esc(escs_on_channels, VALUES)


@pytest.mark.requirement("4.4.16-2", "4.4.16-3", "4.4.16-4", "R4", "4.4.4-T")
@pytest.mark.parametrize("variant", ["ascending", "descending"])
def test_own_channel_follows_its_value(dut, variant):
    """The DUT outputs its own channel's value out of all five groups (its own group sent first)."""
    values = VALUES if variant == "ascending" else dict(zip(VALUES, reversed(VALUES.values())))
    dut.record.observe("nibble order sent (R4, DUT profile)", dut.profile.nibble_order)
    FORMAT.check_follows(dut, values, FORMAT.own_channel(dut))


@pytest.mark.requirement("4.4.16-3", "R4", "4.4.18-6", "4.4.4-T")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", [1, 6, 11, 16, 17, 20], ids=lambda c: f"channel{c}")
def test_each_channel_takes_its_value(dut, channel):
    """Channels of every group and every position in a group (ID*4-3 .. ID*4) take their value."""
    FORMAT.check_on_channel(dut, VALUES, channel)


@pytest.mark.requirement("4.4.16-3", "R4")
@pytest.mark.parametrize("offset", range(1, len(GROUPS)), ids=lambda o: f"own+{o}")
def test_other_groups_do_not_command_it(dut, offset):
    """The frames of the four other groups (sent alone, non-zero) leave the DUT's output at 0."""
    channel = dut.settings()["throttle_channel"]
    group = GROUPS[(FORMAT.group_of(channel) - 1 + offset) % len(GROUPS)]
    check(FORMAT.own_output(dut, [FORMAT.frame(group, VALUES)]), None, f"group {group} on channel {channel}")


@pytest.mark.requirement("4.4.16-3", "R4")
@pytest.mark.parametrize("group", [min(GROUPS) - 1, max(GROUPS) + 1, 0xFF], ids=lambda g: f"group{g}")
def test_groups_outside_1_to_5_address_nobody(dut, group):
    """'ID range 1-5': a frame with another group id commands no channel."""
    channel = dut.settings()["throttle_channel"]
    frame = {"channels": [VALUES[c] for c in range(1, PER_GROUP + 1)], "group": group}
    check(FORMAT.own_output(dut, [frame]), None, f"group {group} on channel {channel}")


@pytest.mark.requirement("4.4.16-2", "4.4.23-5", "R4", "4.4.4-T")
@pytest.mark.parametrize("value", [0, 1, cat.THROTTLE_MAX - 1, cat.THROTTLE_MAX], ids=lambda v: f"value{v}")
def test_valid_range_is_output(dut, value):
    """Every value of the valid range 0..2000 is output as sent (the other channels carry other values)."""
    FORMAT.check_value_is_output(dut, VALUES, value)


@pytest.mark.requirement("R6")
@pytest.mark.parametrize("value", [cat.THROTTLE_MAX + 1, RAW_MAX], ids=lambda v: f"value{v}")
def test_observe_values_above_2000(dut, value):
    """Above the valid range (up to 4095): what the DUT outputs is recorded, never failed."""
    FORMAT.check_above_valid_range(dut, VALUES, value)


@pytest.mark.requirement("4.4.16-5")
def test_observe_twenty_axes(dut):
    """'suitable for multiple axes ... recommended': twenty channels in five frames per cycle; the
    DUT's output and the bus time one cycle takes are recorded."""
    channel = dut.settings()["throttle_channel"]
    frames = FORMAT.frames(VALUES, channel)
    start = dut.now()
    pwms = FORMAT.own_output(dut, frames)
    sent = [f for f in dut.frames(NAME, since=start) if f.source == dut.host_node]
    dut.record.observe("frames per command cycle", len(frames))
    dut.record.observe("MSG1 pwm", sorted(set(pwms)))
    if len(sent) >= 2:
        dut.record.observe("first to last frame of one 20-channel cycle on the bus (ms)",
                           round((sent[len(frames) - 1].timestamp - sent[0].timestamp) * 1000, 3))
    assert set(pwms) == {VALUES[channel]}
