"""R8's clock in the bus reader (``evidence/commands.py``): per ESC node, the last throttle command that carries its
throttle channel (R8, 4.4.4-3; 4.4.15-4, 4.4.16-3, 4.4.17-4), the channel as the bus says it (GET_ESC_ID reply, 242
answer, Set ID answer), never an answer that may echo a refused Set ID (R10-R12)."""

from __future__ import annotations

import pytest

from ckesc.evidence.commands import keys_for
from ckesc.evidence.events import EventLog
from ckesc.evidence.rules import BusRules
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import encode

NODE = 3


def _wire(name: str, fields: dict, *, source: int = 0, transfer_id: int = 0, **kw) -> tuple[int, bytes]:
    w = encode(name, fields, source=source, transfer_id=transfer_id, **kw)
    return w.arbitration_id, bytes(w.data)


def _command(name: str, group: int | None = None) -> tuple[int, bytes]:
    n = cat.FORMAT_CHANNELS[name]
    return _wire(name, {"channels": [0] * n, **({"group": group} if group is not None else {})})


def _reply(channel: int, node: int = NODE) -> tuple[int, bytes]:
    return _wire("get_esc_id", {"node_id": node, "throttle_channel": channel}, source=node, layout="reply")


def _set_id(node: int, channel: int, tid: int = 1) -> tuple[int, bytes]:
    return _wire("set_id", {"node_id": node, "throttle_channel": channel}, destination=NODE, transfer_id=tid)


def _set_id_answer(node: int, channel: int, tid: int = 1, source: int | None = None) -> tuple[int, bytes]:
    return _wire("set_id", {"node_id": node, "throttle_channel": channel}, kind="response", source=source or node,
                 destination=0, transfer_id=tid)


def _reader(*frames: tuple[float, tuple[int, bytes]], powered: float | None = -1.0) -> BusRules:
    """The reader fed ``frames``; the ESC powered up at ``powered`` (reported: Set ID's window, R11; None: not)."""
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    if powered is not None:
        rules.power_switched(powered)
    for t, (can_id, data) in frames:
        rules.feed(can_id, data, t, own=(can_id & 0x7F) == 0)
    return rules


@pytest.mark.parametrize("channel, carried_by", [
    (1, {"raw_command_14b", "raw_command_12b 1", "raw_command_10b"}),
    (5, {"raw_command_12b 2", "raw_command_10b"}),
    (6, {"raw_command_12b 2", "raw_command_10b"}),
    (7, {"raw_command_12b 2"}),
    (20, {"raw_command_12b 5"}),
])
def test_the_frames_that_carry_a_channel_are_the_catalogue_s(channel, carried_by):
    keys = {(cat.spec(n).type_id << 8) | g: f"{n} {g}" if g else n
            for n in cat.THROTTLE_FRAMES for g in ((0,) if n != "raw_command_12b" else cat.THROTTLE_GROUPS)}
    assert {keys[k] for k in keys_for(channel)} == carried_by


def test_no_channel_known_no_command_then_the_reply_says_it_and_every_command_since_counts():
    rules = _reader((0.10, _command("raw_command_14b")), (0.15, _reply(2)), (0.20, _command("raw_command_10b")))
    assert rules.clock.channel(NODE) == 2 and rules.clock.last(NODE) == 0.20
    assert _reader((0.10, _command("raw_command_14b"))).clock.last(NODE) is None  # channel not known: not judged
    assert _reader((0.10, _command("raw_command_14b")), (0.15, _reply(2))).clock.last(NODE) == 0.10  # no Set ID since


def test_a_12_bit_frame_carries_its_group_s_channels_only_and_a_malformed_frame_none():
    can_id, data = _command("raw_command_12b", group=2)
    short = (can_id, data[:-2] + data[-1:])  # a byte short: R17, ignored
    rules = _reader((0.0, _reply(7)), (0.10, (can_id, data)), (0.20, _command("raw_command_12b", group=1)),
                    (0.30, _command("raw_command_14b")), (0.40, short))
    assert rules.clock.last(NODE) == 0.10


def test_set_id_to_another_channel_counts_from_the_request_what_carried_the_old_one_before_it():
    """The ESC takes the channel at the request (its answer comes later): a frame carrying the old channel between the
    two is no command for it, one carrying the new channel is."""
    log = EventLog()
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    rules.power_switched(-1.0)
    rules.events = log
    for t, (can_id, data) in ((0.0, _reply(1)), (0.10, _command("raw_command_14b")), (0.20, _set_id(NODE, 20)),
                              (0.2002, _command("raw_command_14b")), (0.2005, _set_id_answer(NODE, 20)),
                              (0.30, _command("raw_command_14b")), (0.40, _command("raw_command_10b"))):
        rules.feed(can_id, data, t, own=(can_id & 0x7F) == 0)
    assert rules.clock.channel(NODE) == 20 and rules.clock.last(NODE) == 0.10
    rules.feed(*_command("raw_command_12b", group=5), 0.50, own=True)
    assert rules.clock.last(NODE) == 0.50
    assert log.commands[NODE] == [0.10, 0.2002, 0.50]  # (as heard: the answer came after the frame at 0.2002)


def test_a_frame_that_carried_the_new_channel_before_the_set_id_answer_is_told_when_the_answer_comes():
    log = EventLog()
    rules = _reader((0.0, _reply(1)), (0.10, _command("raw_command_14b")), (0.20, _set_id(NODE, 20)),
                    (0.201, _command("raw_command_12b", group=5)))
    rules.events = log
    rules.feed(*_set_id_answer(NODE, 20), 0.26)
    assert rules.clock.last(NODE) == 0.201 and log.commands[NODE] == [0.201]


@pytest.mark.parametrize("why", ["illegal node id", "suspended", "outside the window"])
def test_an_answer_that_may_echo_a_refused_set_id_teaches_nothing(why):
    """R10-R12: a refused request's answer may echo the request while nothing is applied."""
    node = 0 if why == "illegal node id" else NODE
    before: list = [(0.0, _reply(1))]
    if why == "suspended":
        before.append((0.05, _wire("msg_control", {"command": cat.MSG_CONTROL_SUSPEND})))
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    rules.power_switched(-cat.CONFIG_WINDOW_S - 1.0 if why == "outside the window" else -1.0)
    for t, (can_id, data) in [*before, (0.10, _command("raw_command_14b")), (0.20, _set_id(node, 20)),
                              (0.2005, _set_id_answer(node, 20, source=NODE))]:
        rules.feed(can_id, data, t, own=(can_id & 0x7F) == 0)
    assert rules.clock.channel(NODE) == 1 and rules.clock.last(NODE) == 0.10
    rules.feed(*_reply(20), 0.30)  # a read says the channel in force: it moved at that Set ID
    assert rules.clock.channel(NODE) == 20 and rules.clock.last(NODE) == 0.10


def test_an_answer_with_the_current_values_to_a_refused_set_id_is_the_esc_s_word():
    rules = _reader((0.0, _reply(1)), (0.10, _command("raw_command_14b")), (0.20, _set_id(0, 20)),
                    (0.2005, _set_id_answer(NODE, 1)), (0.30, _command("raw_command_14b")))
    assert rules.clock.channel(NODE) == 1 and rules.clock.last(NODE) == 0.30


def test_an_esc_moved_to_another_node_id_counts_from_the_set_id():
    rules = _reader((0.0, _reply(1)), (0.10, _command("raw_command_14b")), (0.20, _set_id(9, 2)),
                    (0.2005, _set_id_answer(9, 2)), (0.30, _command("raw_command_12b", group=5)))
    assert rules.clock.channel(9) == 2 and rules.clock.last(9) is None
    rules.feed(*_command("raw_command_10b"), 0.40, own=True)
    assert rules.clock.last(9) == 0.40


def test_where_the_power_up_is_not_known_an_answer_that_may_echo_the_set_id_leaves_the_channel_unknown_until_a_read():
    """Taken, or refused after the 120 s window and echoed (R11, R10-R12): the bus cannot tell, so R8 waits for a read."""
    frames = [(0.0, _reply(1)), (0.10, _command("raw_command_14b")), (0.20, _set_id(NODE, 20)),
              (0.2005, _set_id_answer(NODE, 20)), (0.30, _command("raw_command_14b"))]
    rules = _reader(*frames, powered=None)
    assert rules.clock.channel(NODE) is None and rules.clock.last(NODE) is None
    rules.feed(*_reply(1), 0.35)  # it was refused: the channel unchanged, every frame that carried it counts
    assert rules.clock.channel(NODE) == 1 and rules.clock.last(NODE) == 0.30
    known = _reader(*frames)  # powered a second before: inside the window, the answer is the ESC's word
    assert known.clock.channel(NODE) == 20 and known.clock.last(NODE) == 0.10
