"""The conforming variants of the comm-loss flag (R8) and of the answer's place in its slot (R2): each does
what ``ckesc/emulator/variants.py`` says, and stays inside what the requirement allows.

Driven sans-IO (``EscModel`` alone, polled at its own deadlines), so every time is exact: the ESC at node 5,
booted at 0, MSG1 every 20 ms from its boot on.
"""

from __future__ import annotations

import math

import pytest

from ckesc.emulator.model import EscConfig, EscModel, factory_nvm
from ckesc.emulator.variants import FREEDOMS
from ckesc.protocol import Decoder, encode
from ckesc.protocol.catalogue import ANSWER_SLOT_S, COMM_LOSS_TIMEOUT_S, INTERVAL_UNIT_S, Status
from ckesc.protocol.frame import frame_bits

NODE = 5
MSG1_S = 0.020
BITRATE = 500_000
EPS = 1e-9


def _esc(**config) -> EscModel:
    cfg = EscConfig(node_id=NODE, **config)
    nvm = factory_nvm(cfg)
    esc = EscModel(cfg, nvm)
    esc.power_on(0.0)
    return esc


def _run(esc: EscModel, until: float, trace: list) -> None:
    """Poll at every deadline up to ``until``: (time, comm fault, decoded frames due then) into ``trace``."""
    decoder = Decoder()
    while (t := esc.next_deadline()) is not None and t <= until:
        out = esc.poll(t)
        trace.append((t, esc.state.comm_fault, [decoder.decode(w) for w in out]))
    esc.poll(until)


def _command(esc: EscModel, t: float) -> None:
    esc.receive(encode("raw_command_12b", {"channels": [0, 0, 0, 0], "group": 2}, source=0, transfer_id=0), t)  # channel 5


def _flag_onset(check: str, phase: float) -> tuple[float, float]:
    """The last command at ``phase`` after an MSG1: (when the flag was raised, the first MSG1 carrying it),
    from the last command."""
    esc = _esc(comm_loss_check=check)
    trace: list = []
    boot = esc.state.ready_at
    _run(esc, boot + 0.2, trace)
    last = boot + 0.2 + phase
    _run(esc, last, trace)
    _command(esc, last)
    trace.clear()
    _run(esc, last + 0.5, trace)
    raised = next(t for t, fault, _ in trace if fault)
    msg1 = [(t, f) for t, _, frames in trace for f in frames if f.name == "msg1"]
    assert all(not f.fields["status"] & Status.COMM_FAULT for t, f in msg1 if t < raised), "a flag before it was raised"
    first = next(t for t, f in msg1 if f.fields["status"] & Status.COMM_FAULT)
    assert abs((first - boot) / MSG1_S - round((first - boot) / MSG1_S)) < 1e-6, "the flag shows in an MSG1 on its grid"
    return raised - last, first - last


PHASES = (0.0, 0.0003, 0.005, 0.0107, 0.0199)


@pytest.mark.parametrize("phase", PHASES)
@pytest.mark.parametrize("check", FREEDOMS["comm_loss_check"].choices)
def test_every_comm_loss_check_keeps_the_flag_inside_r8s_window(check, phase):
    """R8: raised no earlier than 200 ms after the last command, shown in the first MSG1 due at or after 200 ms
    (so no later than 200 ms + one MSG1 interval), at every phase of the last command against MSG1's grid."""
    raised, first = _flag_onset(check, phase)
    assert raised >= COMM_LOSS_TIMEOUT_S - EPS
    # the first MSG1 at or after 200 ms (MSG1 due at boot + k x 20 ms; the command came ``phase`` after one)
    expected = math.ceil(round((COMM_LOSS_TIMEOUT_S + phase) / MSG1_S, 9)) * MSG1_S - phase
    assert abs(first - expected) < 1e-6 and first <= COMM_LOSS_TIMEOUT_S + MSG1_S + EPS


@pytest.mark.parametrize("phase", PHASES)
def test_the_comm_loss_checks_differ_in_when_they_raise_the_flag(phase):
    """timer: at 200 ms exactly; msg1: at the first MSG1 due at or after it; tick: at the first 2 ms tick of
    MSG1's grid at or after it."""
    timer, _ = _flag_onset("timer", phase)
    msg1, first = _flag_onset("msg1", phase)
    tick, _ = _flag_onset("tick", phase)
    assert abs(timer - COMM_LOSS_TIMEOUT_S) < 1e-9
    assert abs(msg1 - first) < 1e-9
    assert COMM_LOSS_TIMEOUT_S - EPS <= tick < COMM_LOSS_TIMEOUT_S + INTERVAL_UNIT_S
    assert abs((tick + phase) / INTERVAL_UNIT_S - round((tick + phase) / INTERVAL_UNIT_S)) < 1e-6, "on the 2 ms tick"


def test_an_msg1_check_still_raises_the_flag_while_nothing_is_reported():
    """Reporting suspended (no MSG1 is due): the flag (and the lost-signal throttle cut) comes on its timer."""
    esc = _esc(comm_loss_check="msg1")
    trace: list = []
    _run(esc, esc.state.ready_at + 0.1, trace)
    _command(esc, esc.state.ready_at + 0.1)
    esc.receive(encode("msg_control", {"option": 0, "command": 0x55555555}, source=0, transfer_id=0), esc.state.ready_at + 0.1)
    trace.clear()
    _run(esc, esc.state.ready_at + 0.4, trace)
    raised = next(t for t, fault, _ in trace if fault)
    assert abs(raised - (esc.state.ready_at + 0.1 + COMM_LOSS_TIMEOUT_S)) < 1e-9


def _answer_delays(place: str, n: int = 8, bitrate: int = BITRATE) -> list[float]:
    """Request (GET_ESC_ID query) to answer (its due time: when it goes on the bus if the bus is free), ``n`` times."""
    esc = _esc(answer_place=place)
    esc.state.bitrate = bitrate
    trace: list = []
    out = []
    t = esc.state.ready_at + 0.0051
    for i in range(n):
        _run(esc, t, trace)
        esc.receive(encode("get_esc_id", {"option": 0}, source=0, transfer_id=i % 32, layout="query"), t)
        trace.clear()
        _run(esc, t + 0.07, trace)
        out += [ft - t for ft, _, frames in trace for f in frames if f.name == "get_esc_id"]
        t += 0.1
    return out


@pytest.mark.parametrize("bitrate", [1_000_000, 500_000, 125_000])
@pytest.mark.parametrize("place", FREEDOMS["answer_place"].choices)
def test_every_answer_place_starts_in_the_slot_and_ends_inside_it(place, bitrate):
    """R2: node 5's slot is 10..12 ms after the request; every answer starts in it, and ends inside it even
    behind one longest frame (8 data bytes) already on the bus."""
    slot = NODE * ANSWER_SLOT_S
    answer = frame_bits(3) / bitrate  # the GET_ESC_ID reply: 2 payload bytes + tail
    for d in _answer_delays(place, bitrate=bitrate):
        assert slot - EPS <= d
        assert d + frame_bits(8) / bitrate + answer <= slot + ANSWER_SLOT_S + EPS


def test_the_answer_places_differ():
    """start: at the slot's start; late: the latest start leaving room for one longest frame ahead; inside:
    different places between them."""
    slot = NODE * ANSWER_SLOT_S
    room = ANSWER_SLOT_S - 2 * frame_bits(8) / BITRATE
    assert all(abs(d - slot) < 1e-9 for d in _answer_delays("start"))
    assert all(abs(d - slot - room) < 1e-9 for d in _answer_delays("late"))
    inside = _answer_delays("inside")
    assert len({round(d, 6) for d in inside}) == len(inside) and all(slot < d < slot + room for d in inside)
