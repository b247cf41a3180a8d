"""Spec section 4.4.16: RawCommand_12b (20101) - four 12-bit throttle channels of group 1..5 per broadcast.

The observable is MSG1's ``pwm`` (the throttle output, 4.4.4) of the DUT while a stream of commands
runs. Every channel 1..20 carries its own value, and the DUT's own group is sent first, so a wrong
channel, group or nibble order (R4, in the order the DUT profile states) shows as a wrong output.
Channels other than the DUT's own are reached by moving the DUT there with Set ID inside the 120 s
window of a proven power cycle (R11), and back.
"""

from contextlib import contextmanager

import pytest

from ckesc.harness.dut import DutError
from ckesc.harness.verdict import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.codecs import codec_for
from ckesc.protocol.frame import classify
from ckesc.protocol.ids import Kind

SECTION = "4.4.16"
NAME = "raw_command_12b"
_CODEC = codec_for(cat.spec(NAME).layouts[0])
_SIZE = cat.spec(NAME).layouts[0].size
PER_GROUP = len(_CODEC.decode(bytes(_SIZE))["channels"])  # 4.4.16-3: four channels per group
RAW_MAX = max(_CODEC.decode(b"\xff" * _SIZE)["channels"])  # 4.4.16-2: 12 bits, 0..4095
GROUPS = cat.THROTTLE_GROUPS  # 4.4.16-3: group ids 1..5
#: one distinct value per channel 1..20, inside 0..2000, whose nibbles differ across p1/p4 (R4)
VALUES = {c: 198 + 64 * c for c in cat.THROTTLE_CHANNELS}
STOP_TIMEOUT_S = 5.0  # how long a motor may take to spin down; not a protocol fact
SETTLE_S = 0.2  # time given to the output to follow a new command (a real ESC may ramp); not a protocol fact
REPORTS = frozenset(s.name for s in cat.CATALOGUE if any(lay.name == "report" for lay in s.layouts))
#: what an ESC sends on its own or to answer the broadcasts of 4.4.1 - 4.4.3 (judged there, and such
#: an answer may come late into the window): not an answer to a RawCommand
NOT_ANSWERS = REPORTS | {"can_test", "msg_control", "get_esc_id"}
NOT_ANSWER_IDS = frozenset(cat.spec(name).type_id for name in NOT_ANSWERS)


# ------------------------------------------------------------------------------------------ helpers
def _group_of(channel):
    return (channel - 1) // PER_GROUP + 1


def _frame(group, values):
    """The command of ``group`` carrying ``values`` (channel -> value)."""
    first = (group - 1) * PER_GROUP + 1
    return {"channels": [values.get(first + i, 0) for i in range(PER_GROUP)], "group": group}


def _frames(values, own_channel=None, groups=GROUPS):
    """One command per group, the group of ``own_channel`` first: an ESC that ignores the group id
    takes its value from the last frame, which is then not its own."""
    first = [] if own_channel is None else [_group_of(own_channel)]
    return [_frame(g, values) for g in first + [g for g in groups if g not in first]]


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


def _output(dut, frames):
    return _outputs(dut, frames)[dut.node_id]


def _could_answer(msg):
    """A malformed frame that may be an answer: a message of no type in NOT_ANSWERS (a malformed report
    is 4.4.4 - 4.4.14's business)."""
    kind, type_id = classify(msg.arbitration_id)[:2]
    return kind is Kind.MESSAGE and type_id not in NOT_ANSWER_IDS


def _check(pwms, expected, what):
    want = 0 if expected is None else expected
    assert all(p == want for p in pwms), (
        f"{what}: MSG1 pwm {pwms}, expected {want}" + (" (frames not addressed to the DUT's channel)" if expected is None else ""))


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
@pytest.mark.requirement("4.4.16-1")
def test_throttle_is_not_answered(dut):
    """A RawCommand is a broadcast without an answer: while a 400 Hz stream of all five groups runs
    the DUT sends its reports at their intervals and nothing else."""
    interval = _msg1_interval(dut)
    span = 10 * interval
    start = dut.now()
    for fields in _frames(VALUES):
        dut.throttle_stream(NAME, fields)
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
    assert not answers and not garbled, f"the DUT answered a RawCommand_12b stream: {answers or garbled}"
    msg1 = [f for f in own if f.name == "msg1"]
    limit = 2 * int(span / interval) + 1  # room for any report jitter (R9's business); an answer per command is 8x
    assert len(msg1) <= limit, (f"{len(msg1)} MSG1 in {span * 1000:.0f} ms at a {interval * 1000:.0f} ms interval "
                                f"(at most {limit}): the commands are being answered")


@pytest.mark.requirement("4.4.16-1", "4.4.16-3", "R4", "4.4.18-6", "4.4.4-T")
def test_every_esc_parses_the_same_frames(bench):
    """All ESCs on the bus take their own channel's value from the same broadcast frames."""
    channels = bench.channels
    bench.record.observe("node -> throttle channel", channels)
    got = _outputs(bench, _frames(VALUES), nodes=bench.nodes)
    for node, pwms in got.items():
        _check(pwms, VALUES[channels[node]], f"node {node} on channel {channels[node]}")


@pytest.mark.requirement("4.4.16-2", "4.4.16-3", "4.4.16-4", "R4", "4.4.4-T")
@pytest.mark.parametrize("variant", ["ascending", "descending"])
def test_own_channel_follows_its_value(dut, variant):
    """The DUT outputs its own channel's value out of all five groups (its own group sent first)."""
    channel = dut.settings()["throttle_channel"]
    values = VALUES if variant == "ascending" else dict(zip(VALUES, reversed(VALUES.values())))
    dut.record.observe("nibble order sent (R4, DUT profile)", dut.profile.nibble_order)
    _check(_output(dut, _frames(values, channel)), values[channel], f"channel {channel}")


@pytest.mark.requirement("4.4.16-3", "R4", "4.4.18-6", "4.4.4-T")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", [1, 6, 11, 16, 17, 20], ids=lambda c: f"channel{c}")
def test_each_channel_takes_its_value(dut, channel):
    """Channels of every group and every position in a group (ID*4-3 .. ID*4) take their value."""
    with _on_channel(dut, channel):
        _check(_output(dut, _frames(VALUES, channel)), VALUES[channel], f"channel {channel}")


@pytest.mark.requirement("4.4.16-3", "R4")
@pytest.mark.parametrize("offset", range(1, len(GROUPS)), ids=lambda o: f"own+{o}")
def test_other_groups_do_not_command_it(dut, offset):
    """The frames of the four other groups (sent alone, non-zero) leave the DUT's output at 0."""
    channel = dut.settings()["throttle_channel"]
    group = GROUPS[(_group_of(channel) - 1 + offset) % len(GROUPS)]
    _check(_output(dut, [_frame(group, VALUES)]), None, f"group {group} on channel {channel}")


@pytest.mark.requirement("4.4.16-3", "R4")
@pytest.mark.parametrize("group", [min(GROUPS) - 1, max(GROUPS) + 1, 0xFF], ids=lambda g: f"group{g}")
def test_groups_outside_1_to_5_address_nobody(dut, group):
    """'ID range 1-5': a frame with another group id commands no channel."""
    channel = dut.settings()["throttle_channel"]
    frame = {"channels": [VALUES[c] for c in range(1, PER_GROUP + 1)], "group": group}
    _check(_output(dut, [frame]), None, f"group {group} on channel {channel}")


@pytest.mark.requirement("4.4.16-2", "4.4.23-5", "R4", "4.4.4-T")
@pytest.mark.parametrize("value", [0, 1, cat.THROTTLE_MAX - 1, cat.THROTTLE_MAX], ids=lambda v: f"value{v}")
def test_valid_range_is_output(dut, value):
    """Every value of the valid range 0..2000 is output as sent (the other channels carry other values)."""
    channel = dut.settings()["throttle_channel"]
    values = {**VALUES, channel: value}
    if value == 0:  # from a running output, so that 0 is a change
        _output(dut, _frames(VALUES, channel))
    _check(_output(dut, _frames(values, channel)), value, f"channel {channel}")


@pytest.mark.requirement("R6")
@pytest.mark.parametrize("value", [cat.THROTTLE_MAX + 1, RAW_MAX], ids=lambda v: f"value{v}")
def test_observe_values_above_2000(dut, value):
    """Above the valid range (up to 4095): what the DUT outputs is recorded, never failed."""
    channel = dut.settings()["throttle_channel"]
    pwms = _output(dut, _frames({**VALUES, channel: value}, channel))
    dut.record.observe(f"MSG1 pwm for {value}", sorted(set(pwms)))
    assert set(pwms) <= {cat.THROTTLE_MAX}, f"{value} gave pwm {sorted(set(pwms))} (clamping to 2000 was expected)"


@pytest.mark.requirement("4.4.16-5")
def test_observe_twenty_axes(dut):
    """'suitable for multiple axes ... recommended': twenty channels in five frames per cycle; the
    DUT's output and the bus time one cycle takes are recorded."""
    channel = dut.settings()["throttle_channel"]
    frames = _frames(VALUES, channel)
    start = dut.now()
    pwms = _output(dut, frames)
    sent = [f for f in dut.frames(NAME, since=start) if f.source == dut.host_node]
    dut.record.observe("frames per command cycle", len(frames))
    dut.record.observe("MSG1 pwm", sorted(set(pwms)))
    if len(sent) >= 2:
        dut.record.observe("first to last frame of one 20-channel cycle on the bus (ms)",
                           round((sent[len(frames) - 1].timestamp - sent[0].timestamp) * 1000, 3))
    assert set(pwms) == {VALUES[channel]}
