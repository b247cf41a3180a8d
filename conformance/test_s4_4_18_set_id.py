"""Spec section 4.4.18: Set Id (210) - node id and throttle channel, a pseudo-broadcast valid 120 s after power-up.

Every test opens the 120 s window with a proven power cycle first (R11), so where the window stands
is known, and puts the node id and channel back in a ``finally`` (in a fresh window when needed),
verified with GET_ESC_ID (R1). What the DUT answers at is read with GET_ESC_ID too, so a DUT that
moved to an unexpected id is still found.
"""

import pytest

from ckesc.bench.epochs import AFTER, INSIDE
from ckesc.bench.errors import HarnessError
from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify
from ckesc.protocol.host import HostProtocol
from ckesc.protocol.ids import DEFAULT_ESC_NODE_ID, HOST_NODE_ID, RESERVED_NODE_IDS, Kind
from ckesc.protocol.legality import field_cases, illegal_cases

from .answers import esc_id_replies, esc_ids, original, put_back
from .raw_command_12b import FORMAT as RAW_12B
from .raw_command_12b import VALUES as RAW_12B_VALUES
from .settings import check_neighbours_kept, neighbours_moved
from .telemetry import msg_control

SECTION = "4.4.18"
original = original  # fixture: the DUT's (node id, channel), put back after the test
SPEC = cat.spec("set_id")
NODE_FIELD = SPEC.request.field("node_id")
ID_MIN, ID_MAX = NODE_FIELD.legal  # 4.4.18-5: 1..0x7D
CHANNELS = cat.THROTTLE_CHANNELS
#: 4.4.18-5 / R10: the reserved ids (0, 0x7E, 0x7F) and the catalogue's illegal neighbours
ILLEGAL_IDS = sorted({c.value for c in illegal_cases(SPEC) if c.field == "node_id"} | RESERVED_NODE_IDS | {HOST_NODE_ID})
#: legal targets: the range's ends (the top one, 0x7D, is the silent default: its own test) and a middle one
TARGETS = sorted({c.value for c in field_cases(SPEC, NODE_FIELD) if c.legal and c.value != DEFAULT_ESC_NODE_ID}
                 | {(ID_MIN + ID_MAX) // 2, ID_MAX - 1})
ARDUPILOT_NODE = 10  # F6: the node id ArduPilot sends from (INTERPRETATIONS.md), not a protocol constant
WINDOW_TEST_TIMEOUT_S = int(3 * cat.CONFIG_WINDOW_S)  # they wait the window out: in real time, minutes
REPORT_NAMES = frozenset(cat.ESC_REPORT_FRAMES)
REPORT_IDS = frozenset(cat.spec(name).type_id for name in REPORT_NAMES)


# ------------------------------------------------------------------------------------------ helpers
def _proven_cycle(dut):
    """A power cycle proven by the power-up counter (241 option 2) asked at whichever node id answers
    GET_ESC_ID afterwards: ``dut.power_cycle`` asks at ``dut.node_id``, which is what these tests
    question. Returns the (node id, channel) pairs that answered."""
    if not dut.lane.power.available:
        raise Inconclusive("this test needs a power cycle and no power control was given (--power)")
    before = dut.power_up_count()
    dut.switch_power()
    found = esc_ids(dut)
    after = None
    if len(found) == 1:
        ex = dut.request("maintenance_information", {"option": 2}, destination=found[0][0])
        after = ex.response.fields.get("power_ups") if ex.response is not None else None
    dut.record.observe("power-up counter", f"{before} -> {after} (node ids answering: {found})")
    if before is None or after is None or after != (before + 1) & 0xFFFF:
        raise Inconclusive(f"power cycle not proven: power-up counter {before} -> {after}, GET_ESC_ID answers {found}")
    return found


def _open_window(dut):
    """A window of a proven power-up with nothing sent in it yet (R11): the current one, or a power cycle's."""
    dut.open_window()


def _report_sources(dut, since):
    """Source node ids of the report frames heard since ``since`` (malformed ones too: whose they are is
    what counts here)."""
    out = {f.source for f in dut.frames(since=since) if f.name in REPORT_NAMES and f.source != dut.host_node}
    for g in dut.garbled:
        kind, type_id, source = classify(g.msg.arbitration_id)[:3]
        if (g.msg.timestamp or 0.0) >= since and kind is Kind.MESSAGE and type_id in REPORT_IDS and source != dut.host_node:
            out.add(source)
    return out


def _other_channel(channel):
    return CHANNELS[channel % len(CHANNELS)]  # the next channel, 20 -> 1


def _other_id(node):
    return node + 1 if node + 1 < ID_MAX else ID_MIN


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.18-1", "4.4.18-5", "R11", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.parametrize("target", TARGETS, ids=lambda t: f"id{t}")
def test_set_id_gives_the_dut_its_id_and_channel(dut, original, target):
    """Within the window, Set ID moves the DUT to the node id and channel sent: it answers with them,
    answers GET_ESC_ID and 242 from the new id and reports from it."""
    node, channel = original
    new_channel = _other_channel(channel)
    _open_window(dut)
    ex = dut.request("set_id", {"node_id": target, "throttle_channel": new_channel})
    dut.node_id = target
    assert ex.response is not None, "no answer to Set ID"
    got = (ex.response.source, ex.response.fields["node_id"], ex.response.fields["throttle_channel"])
    assert got == (target, target, new_channel), f"Set ID answer (source, node id, channel) = {got}"
    assert esc_ids(dut) == [(target, new_channel)], f"GET_ESC_ID after Set ID ({target}, {new_channel}): {esc_ids(dut)}"
    assert dut.settings()["throttle_channel"] == new_channel, "242 from the new id shows another channel"
    start = dut.now()
    dut.wait(2 * dut.settings()["msg1_interval"] * cat.INTERVAL_UNIT_S)
    sources = _report_sources(dut, start)
    assert sources == {target}, f"reports came from {sorted(sources)} after Set ID to {target}"


@pytest.mark.requirement("4.4.18-3", "R11")
@pytest.mark.power_cycle
@pytest.mark.parametrize("destination", ["0", "0x7F", "another-id"])
def test_destination_is_ignored(dut, original, destination):
    """Set ID is a pseudo-broadcast: sent to any destination 0..0x7F, the DUT obeys it."""
    node, channel = original
    target = _other_id(node)
    dest = {"0": HOST_NODE_ID, "0x7F": max(RESERVED_NODE_IDS),
            "another-id": next(n for n in range((ID_MIN + ID_MAX) // 2, ID_MAX) if n not in (node, target))}[destination]
    _open_window(dut)
    ex = dut.request("set_id", {"node_id": target, "throttle_channel": channel}, destination=dest)
    dut.node_id = target
    dut.record.observe(f"answer to Set ID sent to {dest}", ex.response.fields if ex.response else "none")
    assert esc_ids(dut) == [(target, channel)], f"Set ID ({target}, {channel}) sent to node {dest} not obeyed: {esc_ids(dut)}"


@pytest.mark.requirement("4.4.18-2", "R11")
@pytest.mark.power_cycle
def test_several_escs_are_set_to_the_same_id(multi_dut, ckesc_lane):
    """'if more than one is connected, they will be uniformly set to the same ID'."""
    if multi_dut.lane is ckesc_lane:
        pytest.skip("only on a private bench: on a real bus this would merge every ESC's node id for good")
    if len(multi_dut.nodes) < 2:
        pytest.skip(f"only {multi_dut.nodes} answered GET_ESC_ID")
    multi_dut.power_cycle(multi_dut.profile.off_s, multi_dut.profile.boot_s)
    if sorted(n for n, _ in esc_id_replies(multi_dut)) != sorted(multi_dut.nodes):
        raise Inconclusive(f"GET_ESC_ID does not list the ESCs {multi_dut.nodes} (see 4.4.3): the result cannot be read")
    target = max(multi_dut.nodes) + 1
    sent = multi_dut.request("set_id", {"node_id": target, "throttle_channel": 1}, destination=multi_dut.nodes[0])
    answers = [f for f in multi_dut.frames("set_id", since=sent.sent.time) if f.kind is Kind.RESPONSE]
    multi_dut.record.observe("Set ID answers (source)", [f.source for f in answers])
    multi_dut.node_id = target
    sources = sorted(n for n, _ in esc_id_replies(multi_dut))
    assert sources == [target] * len(multi_dut.nodes), (
        f"{len(multi_dut.nodes)} ESCs ({multi_dut.nodes}) after Set ID {target}: GET_ESC_ID answered from {sources}")


@pytest.mark.requirement("4.4.18-4", "F7")
@pytest.mark.power_cycle
def test_at_0x7d_nothing_is_reported(dut, original):
    """'If the ID is set to 0x7D, data will not be reported actively.'"""
    node, channel = original
    s = dut.settings()
    longest = max(s["msg1_interval"], s["msg2_interval"], s["msg3_interval"]) * cat.INTERVAL_UNIT_S
    _open_window(dut)
    ex = dut.request("set_id", {"node_id": DEFAULT_ESC_NODE_ID, "throttle_channel": channel})
    dut.node_id = DEFAULT_ESC_NODE_ID
    if ex.response is None or ex.response.source != DEFAULT_ESC_NODE_ID:
        found = esc_ids(dut)
        if found != [(DEFAULT_ESC_NODE_ID, channel)]:
            raise Inconclusive(f"Set ID to 0x7D did not take (GET_ESC_ID answers {found}): silence cannot be judged")
    try:
        start = dut.now()
        dut.wait(2 * longest)
        sources = _report_sources(dut, start)
        assert not sources, f"at node id 0x7D reports came from {sorted(sources)}"
    finally:
        put_back(dut, node, channel)
        # 'if it is not 0x7D, data will be reported automatically on power-up': make sure it reports again
        start = dut.now()
        dut.wait(2 * s["msg1_interval"] * cat.INTERVAL_UNIT_S)
        if not dut.frames("msg1", since=start, source=node):
            dut.switch_power()


@pytest.mark.requirement("4.4.18-5", "R10", "R10-answer")
@pytest.mark.power_cycle
@pytest.mark.parametrize("value", ILLEGAL_IDS, ids=lambda v: f"id{v:#04x}")
def test_reserved_ids_change_nothing(dut, original, value):
    """0, 0x7E, 0x7F (and what does not fit 1..0x7D) are refused as a whole: neither the id nor the
    channel of the request is taken - now, and after a power cycle."""
    node, channel = original
    _open_window(dut)
    ex = dut.request("set_id", {"node_id": value, "throttle_channel": _other_channel(channel)})
    dut.record.observe("answer to the illegal Set ID (R10-answer)",
                       {"source": ex.response.source, **ex.response.fields} if ex.response else "none")
    assert esc_ids(dut) == [(node, channel)], f"Set ID {value:#04x} changed the DUT: GET_ESC_ID answers {esc_ids(dut)}"
    found = _proven_cycle(dut)
    assert found == [(node, channel)], f"after Set ID {value:#04x} and a power cycle GET_ESC_ID answers {found}"


@pytest.mark.requirement("4.4.18-6", "R4", "4.4.4-T")
@pytest.mark.power_cycle
@pytest.mark.parametrize("channel", [CHANNELS[0], CHANNELS[len(CHANNELS) // 2], CHANNELS[-1]], ids=lambda c: f"channel{c}")
def test_channel_selects_the_throttle_value(dut, original, channel):
    """After Set ID with channel c the DUT takes channel c's value from RawCommand_12b (all five
    groups sent, the DUT's own first, every channel a different value)."""
    node, _ = original
    _open_window(dut)
    dut.request("set_id", {"node_id": node, "throttle_channel": channel})
    values = RAW_12B_VALUES  # one distinct value per channel, inside 0..2000
    try:
        pwms = RAW_12B.output(dut, RAW_12B.frames(values, channel), nodes=[node])[node]
    finally:
        dut.zero_throttle()
    assert all(p == values[channel] for p in pwms), (
        f"after Set ID channel {channel} MSG1 pwm {pwms}, expected channel {channel}'s {values[channel]}")


@pytest.mark.requirement("4.4.18-7", "R13")
@pytest.mark.power_cycle
def test_id_and_channel_persist_across_power_cycle(dut, original):
    """'This parameter will be saved in FLASH ... will not be lost when power is turned off.'"""
    node, channel = original
    target, new_channel = _other_id(node), _other_channel(channel)
    _open_window(dut)
    dut.request("set_id", {"node_id": target, "throttle_channel": new_channel})
    dut.node_id = target
    if esc_ids(dut) != [(target, new_channel)]:
        raise Inconclusive(f"Set ID ({target}, {new_channel}) did not take: GET_ESC_ID answers {esc_ids(dut)}")
    found = _proven_cycle(dut)
    assert found == [(target, new_channel)], f"after a power cycle GET_ESC_ID answers {found}, set was {(target, new_channel)}"


@pytest.mark.requirement("4.4.18-8", "F4")
@pytest.mark.power_cycle
def test_requests_from_host_0_are_answered_to_0(dut, original):
    """'Host ID is 0, source node id=0 for frames sent to ESC': a Set ID from node 0 is answered to
    node 0 (same service and transfer id, F4)."""
    node, channel = original
    _open_window(dut)
    ex = dut.request("set_id", {"node_id": node, "throttle_channel": channel})
    if ex.sent.wire.arbitration_id & 0x7F != HOST_NODE_ID:
        raise HarnessError("the request did not go out from node 0")
    assert ex.response is not None, "no answer to a Set ID from host node 0"
    assert not ex.mismatch, f"answer to host node 0: {ex.mismatch}"
    assert ex.response.destination == HOST_NODE_ID, f"answer went to node {ex.response.destination}"


@pytest.mark.requirement("F6")
@pytest.mark.power_cycle
def test_observe_requests_from_a_non_zero_host(dut, original):
    """F6: does the DUT also obey and answer a host at another node id (ArduPilot's 10)?"""
    node, channel = original
    host = ARDUPILOT_NODE if ARDUPILOT_NODE != node else ARDUPILOT_NODE + 1
    other = HostProtocol(host, nibble_order=dut.profile.nibble_order)
    _open_window(dut)
    for name, fields in (("get_major_configuration", {"option": 0}),
                         ("set_id", {"node_id": node, "throttle_channel": _other_channel(channel)})):
        wire, _ = other.request(name, fields, destination=node, now=dut.now(), timeout=0.1)
        sent = dut.send_wire(wire)
        dut.wait(0.1)
        answers = [f for f in dut.frames(name, since=sent.time) if f.kind is Kind.RESPONSE]
        dut.record.observe(f"{name} from node {host}: answered to", [f.destination for f in answers] or "none")
    found = esc_ids(dut)
    dut.record.observe(f"Set ID from node {host} obeyed", found == [(node, _other_channel(channel))])
    assert found == [(node, _other_channel(channel))], f"Set ID from node {host} not obeyed: {found}"


@pytest.mark.requirement("R11")
@pytest.mark.power_cycle
@pytest.mark.window(INSIDE)
@pytest.mark.timeout(WINDOW_TEST_TIMEOUT_S)
def test_set_id_just_inside_the_window_is_obeyed(dut, original):
    """Sent a second before 120 s after power-up, Set ID takes effect."""
    node, channel = original
    epoch = dut.at_window_moment(INSIDE)
    target = _other_id(node)
    ex = dut.request("set_id", {"node_id": target, "throttle_channel": channel})
    dut.node_id = target
    dut.record.observe("sent at (s after power-on, at most)", round(ex.sent.time - epoch.on_earliest, 3))
    assert esc_ids(dut) == [(target, channel)], f"Set ID inside the window not obeyed: GET_ESC_ID answers {esc_ids(dut)}"


@pytest.mark.requirement("R11", "R10-answer")
@pytest.mark.power_cycle
@pytest.mark.window(AFTER)
@pytest.mark.timeout(WINDOW_TEST_TIMEOUT_S)
def test_set_id_after_the_window_is_ignored(dut, original):
    """Sent a second after 120 s from power-up, Set ID changes nothing."""
    node, channel = original
    epoch = dut.at_window_moment(AFTER)
    ex = dut.request("set_id", {"node_id": _other_id(node), "throttle_channel": channel})
    dut.record.observe("sent at (s after power-on, at least)", round(ex.sent.time - epoch.ready, 3))
    dut.record.observe("answer to the late Set ID", {"source": ex.response.source, **ex.response.fields} if ex.response else "none")
    assert esc_ids(dut) == [(node, channel)], (
        f"Set ID {ex.sent.time - epoch.ready:.1f} s after power-up obeyed: {esc_ids(dut)}")


@pytest.mark.requirement("R13", "4.4.18-7", "4.4.21-4", "4.4.22-6", "4.4.23-4", "4.4.22-2", "4.4.28-1")
@pytest.mark.power_cycle
def test_set_id_leaves_the_other_settings(dut, original):
    """Set ID (the DUT's own node id, another channel) rewrites nothing else: the other persisted settings, moved
    since this power-up, are as they were, at once and after a power cycle."""
    node, channel = original
    new_channel = _other_channel(channel)
    with neighbours_moved(dut) as moved:  # after its power cycle: the window of that power-up
        _open_window(dut)
        ex = dut.request("set_id", {"node_id": node, "throttle_channel": new_channel})
        if ex.response is None or esc_ids(dut) != [(node, new_channel)]:
            raise Inconclusive(f"Set ID ({node}, {new_channel}) inside the window did not take (see "
                               "test_set_id_gives_the_dut_its_id_and_channel): this test cannot be judged")
        check_neighbours_kept(dut, moved, f"Set ID (node id {node}, channel {new_channel})", {"throttle_channel": new_channel})


@pytest.mark.requirement("4.4.2-3", "R12", "R11")
@pytest.mark.power_cycle
def test_set_id_while_suspended_changes_nothing(dut, original):
    """'Parameter changes do not take effect when ... suspended' (4.4.2-3, R12): a Set ID inside the 120 s window
    (R11) while reporting is suspended moves the DUT neither then nor on resume (GET_ESC_ID, R1); the same Set ID
    after the resume, still inside the window, does (else the DUT ignores it anyway and nothing is shown:
    INCONCLUSIVE)."""
    node, channel = original
    target, new_channel = _other_id(node), _other_channel(channel)
    fields = {"node_id": target, "throttle_channel": new_channel}
    _open_window(dut)
    try:
        msg_control(dut, cat.MSG_CONTROL_SUSPEND)
        ex = dut.request("set_id", fields)
        dut.record.observe("answer to Set ID while suspended", ex.response.fields if ex.response else "none")
        during = esc_ids(dut)
        dut.record.observe("GET_ESC_ID while suspended", during)
    finally:  # a broadcast, obeyed at whatever id the DUT has now (``original`` puts the id back)
        msg_control(dut, cat.MSG_CONTROL_RESUME)
        dut.wait(cat.ANSWER_DELAY_MAX_S)
    assert (target, new_channel) not in during, (f"Set ID ({target}, {new_channel}) took effect while suspended: "
                                                 f"GET_ESC_ID answers {during}")
    after = esc_ids(dut)
    assert after == [(node, channel)], (f"Set ID ({target}, {new_channel}) sent while suspended took effect on "
                                        f"resume: GET_ESC_ID answers {after}, was {[(node, channel)]}")
    dut.request("set_id", fields)
    dut.node_id = target
    if (control := esc_ids(dut)) != [(target, new_channel)]:
        raise Inconclusive(f"Set ID ({target}, {new_channel}) does not take effect with reporting on either "
                           f"(GET_ESC_ID answers {control}): that it is ignored while suspended shows nothing")
