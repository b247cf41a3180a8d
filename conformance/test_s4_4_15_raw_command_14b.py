"""Spec section 4.4.15: RawCommand_14b (20100) - four 14-bit throttle channels 1..4 in one broadcast.

The observable is MSG1's ``pwm`` (the throttle output, 4.4.4) of the DUT while a stream of commands
runs. Every frame carries a different value on each channel, so a wrong channel, a wrong packing
(R3) or a wrong byte order shows as a wrong output. Channels other than the DUT's own are reached by
moving the DUT there with Set ID inside the 120 s window of a proven power cycle (R11), and back.
What the three RawCommand sections check alike is written once, in ``conformance/throttle.py``.
"""

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.codecs import codec_for

from . import throttle
from .throttle import RawCommand, rotated

SECTION = "4.4.15"
NAME = "raw_command_14b"
_CODEC = codec_for(cat.spec(NAME).layouts[0])
_SIZE = cat.spec(NAME).layouts[0].size
N_CHANNELS = len(_CODEC.decode(bytes(_SIZE))["channels"])  # 4.4.15-4: channels 1..4
RAW_MAX = max(_CODEC.decode(b"\xff" * _SIZE)["channels"])  # 4.4.15-2: 14 bits, 0..16383
FORMAT = RawCommand(NAME, per_frame=N_CHANNELS, requirement="4.4.15-4")
#: one distinct value per channel, well inside 0..2000: a wrong channel or packing shows
VALUES = {c: 505 + 397 * (c - 1) for c in FORMAT.channels}
escs_on_channels = throttle.escs_on_channels  # fixture: multi_dut with each ESC's channel and MSG1 interval
motor_stopped = throttle.motor_stopped  # autouse fixture: the motor stopped before and after each test


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.15-1")
def test_throttle_is_not_answered(dut):
    """A RawCommand is a broadcast without an answer: while a 400 Hz stream runs the DUT sends its
    reports at their intervals and nothing else."""
    FORMAT.check_not_answered(dut, VALUES)


@pytest.mark.requirement("4.4.15-1", "R3", "4.4.18-6", "4.4.4-T")
def test_every_esc_parses_the_same_frame(escs_on_channels):
    """All ESCs on the bus take their own channel's value from the one broadcast frame."""
    FORMAT.check_every_esc(escs_on_channels, VALUES)


@pytest.mark.requirement("4.4.15-2", "4.4.15-4", "R3", "4.4.4-T")
@pytest.mark.parametrize("shift", range(N_CHANNELS), ids=lambda s: f"values{s}")
def test_own_channel_follows_its_value(dut, shift):
    """The DUT outputs its own channel's value, whichever channel carries which value."""
    FORMAT.check_follows(dut, rotated(VALUES, shift), FORMAT.own_channel(dut))


@pytest.mark.requirement("4.4.15-4", "R3", "4.4.18-6", "4.4.4-T")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", range(1, N_CHANNELS + 1), ids=lambda c: f"channel{c}")
def test_each_channel_takes_its_value(dut, channel):
    """On each of channels 1..4 the DUT outputs that channel's value of the frame."""
    FORMAT.check_on_channel(dut, VALUES, channel)


@pytest.mark.requirement("4.4.15-4", "4.4.18-6")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", [N_CHANNELS + 1, max(cat.THROTTLE_CHANNELS)], ids=lambda c: f"channel{c}")
def test_channels_beyond_the_frame_ignore_it(dut, channel):
    """'the throttle channels are fixed to 1-4': an ESC on another channel is not commanded by it."""
    FORMAT.check_on_channel(dut, VALUES, channel)


@pytest.mark.requirement("4.4.15-3", "R3", "4.4.4-T")
def test_document_worked_example(dut):
    """The document's example: 1000 on all four channels, sent as E8 0F A0 3E 80 FA 03."""
    channel = FORMAT.own_channel(dut)
    example = dict.fromkeys(FORMAT.channels, cat.THROTTLE_MAX // 2)  # 1000 (0x03E8) on every channel
    dut.record.observe("payload sent", dut.proto.message(NAME, FORMAT.frames(example)[0]).data[:_SIZE].hex(" ").upper())
    FORMAT.check_follows(dut, example, channel, note=" (the document's example)")


@pytest.mark.requirement("4.4.15-2", "4.4.23-5", "R3", "4.4.4-T")
@pytest.mark.parametrize("value", [0, 1, cat.THROTTLE_MAX - 1, cat.THROTTLE_MAX], ids=lambda v: f"value{v}")
def test_valid_range_is_output(dut, value):
    """Every value of the valid range 0..2000 is output as sent (the other channels carry other values)."""
    FORMAT.check_value_is_output(dut, VALUES, value)


@pytest.mark.requirement("R6")
@pytest.mark.parametrize("value", [cat.THROTTLE_MAX + 1, RAW_MAX], ids=lambda v: f"value{v}")
def test_observe_values_above_2000(dut, value):
    """Above the valid range (up to 16383): what the DUT outputs is recorded, never failed."""
    FORMAT.check_above_valid_range(dut, VALUES, value)
