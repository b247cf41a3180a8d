"""Spec section 4.4.15: RawCommand_14b (20100) - four 14-bit throttle channels 1..4 in one broadcast.

The observable is MSG1's ``pwm`` (the throttle output, 4.4.4) of the DUT while a stream of commands
runs. Every frame carries a different value on each channel, so a wrong channel, a wrong packing
(R3) or a wrong byte order shows as a wrong output. Channels other than the DUT's own are reached by
moving the DUT there with Set ID inside the 120 s window of a proven power cycle (R11), and back.
"""

from contextlib import contextmanager

import pytest

from ckesc.harness.dut import DutError
from ckesc.harness.verdict import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.codecs import codec_for
from ckesc.protocol.frame import classify
from ckesc.protocol.ids import Kind

SECTION = "4.4.15"
NAME = "raw_command_14b"
_CODEC = codec_for(cat.spec(NAME).layouts[0])
_SIZE = cat.spec(NAME).layouts[0].size
N_CHANNELS = len(_CODEC.decode(bytes(_SIZE))["channels"])  # 4.4.15-4: channels 1..4
RAW_MAX = max(_CODEC.decode(b"\xff" * _SIZE)["channels"])  # 4.4.15-2: 14 bits, 0..16383
#: one distinct value per channel, well inside 0..2000: a wrong channel or packing shows
VALUES = [505 + 397 * i for i in range(N_CHANNELS)]
STOP_TIMEOUT_S = 5.0  # how long a motor may take to spin down; not a protocol fact
SETTLE_S = 0.2  # time given to the output to follow a new command (a real ESC may ramp); not a protocol fact
REPORTS = frozenset(s.name for s in cat.CATALOGUE if any(lay.name == "report" for lay in s.layouts))
#: what an ESC sends on its own or to answer the broadcasts of 4.4.1 - 4.4.3 (judged there, and such
#: an answer may come late into the window): not an answer to a RawCommand
NOT_ANSWERS = REPORTS | {"can_test", "msg_control", "get_esc_id"}
NOT_ANSWER_IDS = frozenset(cat.spec(name).type_id for name in NOT_ANSWERS)


# ------------------------------------------------------------------------------------------ helpers
def _expected(channel, values):
    """What the DUT on ``channel`` must output for a frame carrying ``values`` (None: not addressed)."""
    return values[channel - 1] if 1 <= channel <= len(values) else None


def _msg1_interval(dut, node=None):
    node = dut.node_id if node is None else node
    freq = dut.ask("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0},
                   destination=node)
    return freq["msg1_interval"] * cat.INTERVAL_UNIT_S


def _outputs(dut, frames, nodes=None):
    """Stream each field dict of ``frames`` (in that order, every period), let the output settle and
    return {node: [MSG1 pwm, ...]} of the reports that followed."""
    nodes = [dut.node_id] if nodes is None else nodes
    known = getattr(dut, "intervals", {})  # the bench fixture read them
    interval = max(known[n] if n in known else _msg1_interval(dut, n) for n in nodes)
    for fields in frames:
        dut.throttle_stream(NAME, fields)
    try:
        dut.wait(SETTLE_S + interval)
        start = dut.now()
        dut.wait(3 * interval + cat.INTERVAL_UNIT_S)
    finally:
        dut.stop_throttle()
    out = {n: [f.fields["pwm"] for f in dut.frames("msg1", since=start, source=n)] for n in nodes}
    for n, pwms in out.items():
        if not pwms:
            raise Inconclusive(f"no MSG1 decoded from node {n} while the throttle ran: its output cannot be read (see 4.4.4)")
    return out


def _output(dut, values):
    return _outputs(dut, [{"channels": list(values)}])[dut.node_id]


def _could_answer(msg):
    """A malformed frame that may be an answer: a message of no type in NOT_ANSWERS (a malformed report
    is 4.4.4 - 4.4.14's business)."""
    kind, type_id = classify(msg.arbitration_id)[:2]
    return kind is Kind.MESSAGE and type_id not in NOT_ANSWER_IDS


def _check(pwms, expected, what):
    want = 0 if expected is None else expected
    assert all(p == want for p in pwms), (
        f"{what}: MSG1 pwm {pwms}, expected {want}" + (" (a frame not addressed to the DUT's channel)" if expected is None else ""))


@contextmanager
def _on_channel(dut, channel):
    """The DUT on throttle ``channel`` for the block: Set ID (same node id) inside the 120 s window of a
    proven power cycle (R11); the original channel is put back and verified afterwards."""
    before = dut.settings()["throttle_channel"]
    if channel == before:
        yield
        return
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)  # the Set ID window opens now (R11)
    try:
        dut.request("set_id", {"node_id": dut.node_id, "throttle_channel": channel})
        now = dut.settings()["throttle_channel"]
        if now != channel:
            raise Inconclusive(f"Set ID did not move the DUT to throttle channel {channel} (it is on {now}): "
                               "that channel cannot be tested (see the 4.4.18 results)")
        yield
    finally:
        dut.zero_throttle()
        dut.request("set_id", {"node_id": dut.node_id, "throttle_channel": before})
        if dut.settings()["throttle_channel"] != before:
            raise DutError(f"could not put the DUT back on throttle channel {before}")


def _own_channel(dut):
    channel = dut.settings()["throttle_channel"]
    if not 1 <= channel <= N_CHANNELS:
        pytest.skip(f"the DUT is on throttle channel {channel}, which RawCommand_14b does not carry (4.4.15-4); "
                    "the power-cycle tests below move it")
    return channel


@pytest.fixture
def bench(multi_dut):
    """``multi_dut`` with ``bench.channels`` (each ESC's throttle channel) and ``bench.intervals`` (its
    MSG1 interval), read here: an ESC that cannot say is a setup error, not a verdict."""
    multi_dut.channels = {n: multi_dut.ask("get_major_configuration", {"option": 0}, destination=n)["throttle_channel"]
                          for n in multi_dut.nodes}
    multi_dut.intervals = {n: _msg1_interval(multi_dut, n) for n in multi_dut.nodes}
    return multi_dut


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


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.15-1")
def test_throttle_is_not_answered(dut):
    """A RawCommand is a broadcast without an answer: while a 400 Hz stream runs the DUT sends its
    reports at their intervals and nothing else."""
    interval = _msg1_interval(dut)
    span = 10 * interval
    start = dut.now()
    dut.throttle_stream(NAME, {"channels": VALUES})
    try:
        dut.wait(span)
    finally:
        dut.stop_throttle()
    end = dut.now()
    # since= is inclusive and now() right after a request is its answer's timestamp: strictly after start
    own = [f for f in dut.frames(since=start, until=end, source=dut.node_id) if f.timestamp > start]
    # a RawCommand is a message: an answer would be a message too (a response answers some request)
    answers = [f for f in own if f.kind is Kind.MESSAGE and f.name not in NOT_ANSWERS]
    garbled = [g.msg for g in dut.garbled if (g.msg.arbitration_id & 0x7F) == dut.node_id
               and start < (g.msg.timestamp or 0.0) <= end
               and _could_answer(g.msg)]
    assert not answers and not garbled, f"the DUT answered a RawCommand_14b stream: {answers or garbled}"
    msg1 = [f for f in own if f.name == "msg1"]
    limit = 2 * int(span / interval) + 1  # room for any report jitter (R9's business); an answer per command is 8x
    assert len(msg1) <= limit, (f"{len(msg1)} MSG1 in {span * 1000:.0f} ms at a {interval * 1000:.0f} ms interval "
                                f"(at most {limit}): the commands are being answered")


@pytest.mark.requirement("4.4.15-1", "R3", "4.4.18-6", "4.4.4-T")
def test_every_esc_parses_the_same_frame(bench):
    """All ESCs on the bus take their own channel's value from the one broadcast frame."""
    channels = bench.channels
    bench.record.observe("node -> throttle channel", channels)
    got = _outputs(bench, [{"channels": VALUES}], nodes=bench.nodes)
    for node, pwms in got.items():
        _check(pwms, _expected(channels[node], VALUES), f"node {node} on channel {channels[node]}")


@pytest.mark.requirement("4.4.15-2", "4.4.15-4", "R3", "4.4.4-T")
@pytest.mark.parametrize("shift", range(N_CHANNELS), ids=lambda s: f"values{s}")
def test_own_channel_follows_its_value(dut, shift):
    """The DUT outputs its own channel's value, whichever channel carries which value."""
    channel = _own_channel(dut)
    values = VALUES[shift:] + VALUES[:shift]
    _check(_output(dut, values), _expected(channel, values), f"channel {channel} of {values}")


@pytest.mark.requirement("4.4.15-4", "R3", "4.4.18-6", "4.4.4-T")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", range(1, N_CHANNELS + 1), ids=lambda c: f"channel{c}")
def test_each_channel_takes_its_value(dut, channel):
    """On each of channels 1..4 the DUT outputs that channel's value of the frame."""
    with _on_channel(dut, channel):
        _check(_output(dut, VALUES), _expected(channel, VALUES), f"channel {channel} of {VALUES}")


@pytest.mark.requirement("4.4.15-4", "4.4.18-6")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", [N_CHANNELS + 1, max(cat.THROTTLE_CHANNELS)], ids=lambda c: f"channel{c}")
def test_channels_beyond_the_frame_ignore_it(dut, channel):
    """'the throttle channels are fixed to 1-4': an ESC on another channel is not commanded by it."""
    with _on_channel(dut, channel):
        _check(_output(dut, VALUES), None, f"channel {channel} of {VALUES}")


@pytest.mark.requirement("4.4.15-3", "R3", "4.4.4-T")
def test_document_worked_example(dut):
    """The document's example: 1000 on all four channels, sent as E8 0F A0 3E 80 FA 03."""
    channel = _own_channel(dut)
    example = [cat.THROTTLE_MAX // 2] * N_CHANNELS  # 1000 (0x03E8) on every channel
    dut.record.observe("payload sent", dut.proto.message(NAME, {"channels": example}).data[:_SIZE].hex(" ").upper())
    _check(_output(dut, example), _expected(channel, example), "the document's example")


@pytest.mark.requirement("4.4.15-2", "4.4.23-5", "R3", "4.4.4-T")
@pytest.mark.parametrize("value", [0, 1, cat.THROTTLE_MAX - 1, cat.THROTTLE_MAX], ids=lambda v: f"value{v}")
def test_valid_range_is_output(dut, value):
    """Every value of the valid range 0..2000 is output as sent (the other channels carry other values)."""
    channel = _own_channel(dut)
    values = list(VALUES)
    values[channel - 1] = value
    if value == 0:  # from a running output, so that 0 is a change
        _output(dut, VALUES)
    _check(_output(dut, values), value, f"channel {channel} of {values}")


@pytest.mark.requirement("R6")
@pytest.mark.parametrize("value", [cat.THROTTLE_MAX + 1, RAW_MAX], ids=lambda v: f"value{v}")
def test_observe_values_above_2000(dut, value):
    """Above the valid range (up to 16383): what the DUT outputs is recorded, never failed."""
    channel = _own_channel(dut)
    values = list(VALUES)
    values[channel - 1] = value
    pwms = _output(dut, values)
    dut.record.observe(f"MSG1 pwm for {value}", sorted(set(pwms)))
    assert set(pwms) <= {cat.THROTTLE_MAX}, f"{value} gave pwm {sorted(set(pwms))} (clamping to 2000 was expected)"

