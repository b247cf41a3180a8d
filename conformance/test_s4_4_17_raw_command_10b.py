"""Spec section 4.4.17: RawCommand_10b (20102) - six 10-bit throttle channels 1..6 over all 8 bytes.

The observable is MSG1's ``pwm`` (the throttle output, 4.4.4) of the DUT while a stream of commands
runs: 0..1000 doubled to 0..2000 (R5). Every frame carries a different value on each channel, so a
wrong channel or packing shows as a wrong output. The high nibble of payload[7] (where the host
writes start=1 end=1 toggle=0, R5) is sent with every value and must make no difference.
Channels other than the DUT's own are reached by moving the DUT there with Set ID inside the 120 s
window of a proven power cycle (R11), and back.
What the three RawCommand sections check alike is written once, in ``conformance/throttle.py``.
"""

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.codecs import codec_for

from . import throttle
from .throttle import RawCommand, rotated

SECTION = "4.4.17"
NAME = "raw_command_10b"
_CODEC = codec_for(cat.spec(NAME).layouts[0])
_SIZE = cat.spec(NAME).layouts[0].size
N_CHANNELS = len(_CODEC.decode(bytes(_SIZE))["channels"])  # 4.4.17-4: channels 1..6
_ALL_ONES = _CODEC.decode(b"\xff" * _SIZE)
RAW_MAX = max(_ALL_ONES["channels"])  # 4.4.17-2: 10 bits, 0..1023
TAIL_NIBBLES = range(_ALL_ONES["tail_bits"] + 1)  # every value of payload[7]'s high nibble
DOUBLING = cat.THROTTLE_MAX // cat.THROTTLE_10B_MAX  # 4.4.17-2: 0..1000 -> 0..2000
FORMAT = RawCommand(NAME, per_frame=N_CHANNELS, scale=DOUBLING, requirement="4.4.17-4")
#: one distinct value per channel, inside 0..1000: a wrong channel or packing shows
VALUES = {c: 130 + 140 * (c - 1) for c in FORMAT.channels}
escs_on_channels = throttle.escs_on_channels  # fixture: multi_dut with each ESC's channel and MSG1 interval
motor_stopped = throttle.motor_stopped  # autouse fixture: the motor stopped before and after each test


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.17-1")
def test_throttle_is_not_answered(dut):
    """A RawCommand is a broadcast without an answer: while a 400 Hz stream runs the DUT sends its
    reports at their intervals and nothing else."""
    FORMAT.check_not_answered(dut, VALUES)


@pytest.mark.requirement("4.4.17-1", "R5", "4.4.18-6", "4.4.4-T")
def test_every_esc_parses_the_same_frame(escs_on_channels):
    """All ESCs on the bus take their own channel's value from the one broadcast frame."""
    FORMAT.check_every_esc(escs_on_channels, VALUES)


@pytest.mark.requirement("4.4.17-2", "4.4.17-4", "R5", "4.4.4-T")
@pytest.mark.parametrize("shift", range(N_CHANNELS), ids=lambda s: f"values{s}")
def test_own_channel_follows_its_value_doubled(dut, shift):
    """The DUT outputs twice its own channel's value, whichever channel carries which value."""
    FORMAT.check_follows(dut, rotated(VALUES, shift), FORMAT.own_channel(dut))


@pytest.mark.requirement("4.4.17-3", "R5", "4.4.4-T")
@pytest.mark.parametrize("tail_bits", TAIL_NIBBLES, ids=lambda t: f"nibble{t:04b}")
def test_high_nibble_of_payload7_is_ignored(dut, tail_bits):
    """'the high 4 bits of payload[7] are invalid': whatever they hold, the command is obeyed."""
    FORMAT.check_follows(dut, VALUES, FORMAT.own_channel(dut), tail_bits=tail_bits,
                         note=f" with payload[7] high nibble {tail_bits:04b}")


@pytest.mark.requirement("4.4.17-4", "R5", "4.4.18-6", "4.4.4-T")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", range(1, N_CHANNELS + 1), ids=lambda c: f"channel{c}")
def test_each_channel_takes_its_value(dut, channel):
    """On each of channels 1..6 the DUT outputs twice that channel's value of the frame."""
    FORMAT.check_on_channel(dut, VALUES, channel)


@pytest.mark.requirement("4.4.17-4", "4.4.18-6")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", [N_CHANNELS + 1, max(cat.THROTTLE_CHANNELS)], ids=lambda c: f"channel{c}")
def test_channels_beyond_the_frame_ignore_it(dut, channel):
    """'the throttle channels are fixed to 1-6': an ESC on another channel is not commanded by it."""
    FORMAT.check_on_channel(dut, VALUES, channel)


@pytest.mark.requirement("4.4.17-2", "4.4.23-5", "R5", "4.4.4-T")
@pytest.mark.parametrize("value", [0, 1, cat.THROTTLE_10B_MAX - 1, cat.THROTTLE_10B_MAX], ids=lambda v: f"value{v}")
def test_valid_range_is_output_doubled(dut, value):
    """Every value of the valid range 0..1000 is output doubled (the other channels carry other values)."""
    FORMAT.check_value_is_output(dut, VALUES, value)


@pytest.mark.requirement("R6")
@pytest.mark.parametrize("value", [cat.THROTTLE_10B_MAX + 1, RAW_MAX], ids=lambda v: f"value{v}")
def test_observe_values_above_1000(dut, value):
    """Above the valid range (up to 1023): what the DUT outputs is recorded, never failed."""
    FORMAT.check_above_valid_range(dut, VALUES, value)
