"""Robustness (R17): malformed and foreign frames are ignored.

For every frame type the ESC takes (the host's messages and the requests of the catalogue), a command that would
be valid and would show if it were taken (a setting moved, a suspend, CAN Test on, an answer, a comm refresh) is
sent malformed: as the start, a middle and the end frame of a multi-frame transfer, as a whole multi-frame transfer
with DroneCAN's CRC, empty, one byte short, one byte long (where CAN's 8 bytes allow), as a request to another node
and as a response frame. Then: no answer, nothing changed (the settings read, MSG1's state bits), no reset (241's
power-up count unmoved, no MSG1 gap after which its transfer ids count anew: ``conformance/resets.py``; the reports
going on), and, for the throttle frames, the comm-loss flag raised on time (R8) while only malformed RawCommands
arrive. A single frame with toggle 1 may be taken or ignored: recorded (OBSERVE). Each malformed frame of a burst has
its own transfer id, so that an answer names the frame it answers.

Set ID and Set Baud take effect only inside the 120 s window after a power-up (R11), so theirs are sent there, in
tests of their own (``power_cycle``: the run order lets the others run while some window elapses, and they must
send neither): a Set ID to another node id and channel, a Set Baud to another rate, each malformed, inside the
window of a proven power-up; then GET_ESC_ID must still name the DUT's node id and channel, and after the next
power-up (proven by its counter at whichever rate the DUT answers) the DUT must answer at its old rate. Set ID
ignores its destination (a pseudo-broadcast, R11), so its request to another node is not malformed and not sent.
Whatever a faulty DUT took, the node id and channel, or the bit rate (and the host with it), are put back and
verified after the test, as the Set ID and Set Baud sections do (``answers.original``, ``baud.rate0``).

Not sent: Clear Rec (taking it erases the ESC's temperature records, which nothing can put back). A non-zero
throttle in a malformed frame only with ``--allow-motor-spin``.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from ckesc.bench.dut import DutError
from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import Kind, Status
from ckesc.protocol import catalogue as cat
from ckesc.protocol import malformed as r17
from ckesc.protocol.ids import DEFAULT_ESC_NODE_ID, parse_can_id
from ckesc.protocol.judgements import r8_flag_due
from ckesc.protocol.malformed import Bad

from .answers import answers_another_node, esc_ids, original, put_back
from .baud import RATES, cycle, rate0
from .resets import reset_signs
from .settings import changes
from .showing import TAKEN, WINDOW_WRITERS, command, state_bits
from .telemetry import frame_start, interval_s, ms
from .throttle import STREAM_PERIOD_S, can_throttle, motor_stopped

SECTION = "robustness"
motor_stopped = motor_stopped  # autouse fixture: the motor stopped before and after each test
original = original  # fixture: the DUT's node id and channel, put back after a malformed Set ID
rate0 = rate0  # fixture: the DUT and the host put back at their bit rate after a malformed Set Baud

def _other_nodes(dut) -> list[int]:
    """Node ids no ESC of the bench has, each one bit away from the DUT's (:func:`ckesc.protocol.malformed.other_nodes`)."""
    return r17.other_nodes(dut.node_id, dut.nodes)


def malformed(dut, name: str, fields: dict, *, toggle_only: bool = False) -> list[Bad]:
    """``name``'s command ``fields`` in every malformed form R17 names (:func:`ckesc.protocol.malformed.malformed`),
    each with its own transfer id; only the single frame with toggle 1 (R17-toggle) when ``toggle_only``."""
    return r17.malformed(name, fields, source=dut.host_node, node_id=dut.node_id, others=_other_nodes(dut),
                         nibble_order=dut.profile.nibble_order, toggle_only=toggle_only)


@dataclass
class Effects:
    answers: list[str]
    changed: str
    resets: list[str]
    settings: dict  # the settings before the frames
    restarted: bool = False  # a reset shown (the power-up count moved, or MSG1 came back from a gap counting anew)

    def lines(self) -> list[str]:
        return ([f"answered: {'; '.join(self.answers)}"] if self.answers else []) + (
            [f"settings changed: {self.changed}"] if self.changed else []) + self.resets


def _leave_can_test(dut, since: int) -> None:
    """CAN Test off when the DUT sent CAN Test frames in ``dut.trace[since:]`` (the fixture's restore does not)."""
    if any(f.name == "can_test" for f in dut.trace[since:] if f.source == dut.node_id):
        dut.broadcast("can_test", {"option": cat.CAN_TEST_OFF})
        dut.wait(cat.ANSWER_DELAY_MAX_S)


def culprits(dut, bads: list[Bad], s: dict) -> list[str]:
    """Each malformed frame again on its own, the settings ``s`` restored before each: those after which the DUT
    sent something other than its reports, or a setting changed (for a failure's message: which frame it took)."""
    found = []
    for b in bads:
        dut.restore(s)
        heard = len(dut.trace)
        for w in b.frames:
            dut.send_wire(w)
        dut.wait(cat.ANSWER_DELAY_MAX_S + dut.lane.timing_error)
        sent = sorted({f.name for f in dut.trace[heard:] if f.source == dut.node_id and f.name not in cat.REPORT_FRAMES
                       and not answers_another_node(dut, f)})
        _leave_can_test(dut, heard)
        shown = ", ".join(filter(None, [f"sent {', '.join(sent)}" if sent else "", changes(s, dut.settings())]))
        if shown:
            found.append(f"{b}: {shown}")
    dut.restore(s)
    return found


def heard_answers(dut, heard: int, t0: float, bads: list[Bad]) -> list[str]:
    """What the DUT sent in ``dut.trace[heard:]`` (from lane time ``t0``) other than its reports, each answer named by
    the malformed frame whose transfer id it carries."""
    by_tid = {b.transfer_id: b for b in bads}
    answers = []
    for f in dut.trace[heard:]:
        if f.source != dut.node_id or f.name in cat.REPORT_FRAMES or answers_another_node(dut, f):
            continue
        cause = by_tid.get(f.transfer_id) if f.kind is Kind.RESPONSE else None
        answers.append(f"{f.name} {f.kind.label} {f.fields}" + (f" to the {cause}" if cause else ""))
    return answers + [f"an undecodable frame {g.msg.arbitration_id:08X}#{bytes(g.msg.data).hex().upper()}"
                      for g in dut.undecoded(since=t0, source=dut.node_id)]


def read_past(dut) -> float:
    """Now, once every MSG1 stamped before it is in: read on until the DUT's first MSG1 stamped later, at most the
    DUT's ready bound (boot time and a longest report interval). In real time a frame comes after its stamp (a
    loaded bench reads it late): judged before it came, its absence would pass for a silence of the DUT."""
    t1 = dut.now()
    if not any(f.timestamp > t1 for f in dut.frames("msg1", since=t1, source=dut.node_id)):
        dut.read_until(t1 + dut.ready_bound_s(),
                       stop=lambda f: f.name == "msg1" and f.source == dut.node_id and f.timestamp > t1)
    return t1


def send_bads(dut, bads: list[Bad]) -> None:
    """The malformed frames, a throttle stream's period apart, then the answer bound (64 ms and the bench's error)."""
    for b in bads:
        for w in b.frames:
            dut.send_wire(w)
        dut.wait(STREAM_PERIOD_S)
    dut.wait(cat.ANSWER_DELAY_MAX_S + dut.lane.timing_error)


def send_and_look(dut, bads: list[Bad], name: str) -> Effects:
    """Send the malformed frames, then what came of them: answers (a frame from the DUT other than its reports, each
    named by the malformed frame whose transfer id it carries), changed settings and MSG1 state, resets."""
    s = dut.settings()
    interval = interval_s(s, "msg1")
    ups = dut.power_up_count()
    t0 = dut.now()
    heard = len(dut.trace)  # what comes after this is what the malformed frames may have caused
    send_bads(dut, bads)
    t1 = read_past(dut)
    answers = heard_answers(dut, heard, t0, bads)
    # MSG1 from two intervals before the first malformed frame, read once all is in: in real time a frame stamped
    # before t0 may be read after it (read before the frames were sent, it would be missing from both sides: a jump)
    seen = dut.frames("msg1", since=t0 - 2 * interval - dut.lane.timing_error, until=t1, source=dut.node_id)
    before, msg1 = [f for f in seen if f.timestamp < t0], [f for f in seen if f.timestamp >= t0]
    resets = reset_signs(dut, [*before[-1:], *msg1], interval)  # (a transfer id skipped without a gap: F3's)
    last = msg1[-1].timestamp if msg1 else None
    if last is None or t1 - last > cat.restart_limit_s(interval) + dut.lane.timing_error:
        resets.append(f"no MSG1 in the last {ms(t1 - (last or t0)):g} ms of the {ms(t1 - t0):g} ms after the first "
                      "malformed frame (MSG1 every " + f"{ms(interval):g} ms): reporting stopped")
    restarted = bool(resets)  # (no frame is then hunted alone: the ESC's restart is the verdict)
    if resets:  # an ESC that restarted is let boot before it is asked (its restart is the verdict, not its silence)
        dut.await_reports(t1, t1 + dut.ready_bound_s())
    _leave_can_test(dut, heard)
    try:
        after = dut.settings()
        ups_after = dut.power_up_count() if ups is not None else None
    except DutError as exc:  # an ESC that reset may reset again at its boot on the frames held for it (R20): silent
        after, ups_after, restarted = s, None, True
        resets.append(f"afterwards it did not answer: {exc}")
    grown = reset_signs(dut, [], interval, ups=(ups, ups_after))
    resets[:0] = grown
    state = []
    if before and msg1 and state_bits(before[-1]) != state_bits(msg1[-1]):
        state.append(f"MSG1 state bits 0x{state_bits(before[-1]):04X} -> 0x{state_bits(msg1[-1]):04X}")
    return Effects(answers, ", ".join(filter(None, [changes(s, after), *state])), resets, s, restarted or bool(grown))


def _check(dut, name: str, bads: list[Bad], effects: Effects) -> None:
    dut.record.observe("malformed frames sent", "; ".join(str(b) for b in bads))
    problems = effects.lines()
    if problems and not effects.restarted and len(bads) > 1:  # which frame did it (a restart is judged as it is)
        taken = culprits(dut, bads, effects.settings)
        problems.append("taken, one at a time: " + ("; ".join(taken) if taken else "none alone"))
    assert not problems, (f"{cat.spec(name).title}: after these malformed frames of a command that would show "
                          f"({'; '.join(b.what for b in bads)}): " + "; ".join(problems)
                          + " (R17: a malformed frame gets no answer, changes nothing and never resets the ESC)")


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("R17")
@pytest.mark.parametrize("name", TAKEN)
def test_malformed_frames_are_ignored(dut, name):
    """Each malformed form of a command that would show if taken: no answer, nothing changed, no reset."""
    s = dut.settings()
    fields = command(dut, name, s)
    if fields is None:
        pytest.skip(f"{name} cannot address the DUT's throttle channel {s['throttle_channel']}")
    bads = malformed(dut, name, fields)
    _check(dut, name, bads, send_and_look(dut, bads, name))


@pytest.mark.requirement("R17-toggle")
@pytest.mark.parametrize("name", [n for n in TAKEN if cat.spec(n).has_tail])
def test_single_frame_with_toggle_one(dut, name):
    """A single frame whose toggle bit is 1, of a command that would show: taken or ignored, recorded."""
    s = dut.settings()
    fields = command(dut, name, s)
    if fields is None:
        pytest.skip(f"{name} cannot address the DUT's throttle channel {s['throttle_channel']}")
    bads = malformed(dut, name, fields, toggle_only=True)
    effects = send_and_look(dut, bads, name)
    dut.record.observe("single frame with toggle 1", f"{bads[0]}: " + ("; ".join(effects.lines()) or "ignored"))


@pytest.mark.requirement("R17", "R8")
@pytest.mark.parametrize("name", cat.THROTTLE_FRAMES)
def test_malformed_raw_commands_do_not_refresh_comm(dut, name):
    """After one valid zero-throttle command, only malformed ones (zero throttle, so taking one spins nothing): the
    comm-loss flag comes up as if nothing had arrived (R8), no later than 200 ms + one MSG1 interval."""
    s = can_throttle(dut)
    fields = command(dut, name, s)
    if fields is None:
        pytest.skip(f"{name} cannot address the DUT's throttle channel {s['throttle_channel']}")
    bads = malformed(dut, name, fields)
    interval = interval_s(s, "msg1")
    last = dut.broadcast(name, fields)
    dut.await_echo(last)
    # malformed commands at the stream's rate, through the whole R8 window and two MSG1 intervals beyond it
    until = last.time + cat.COMM_LOSS_TIMEOUT_S + 3 * interval + dut.profile.jitter_s + dut.lane.own_error
    i = 0
    while dut.now() < until:
        for w in bads[i % len(bads)].frames:
            dut.send_wire(w)
        i += 1
        dut.wait(STREAM_PERIOD_S)
    read_past(dut)
    due = [(f, r8_flag_due(frame_start(dut, f) - last.time, interval, jitter=dut.profile.jitter_s,
                           error=dut.lane.own_error)) for f in dut.frames("msg1", since=last.time, source=dut.node_id)]
    judged = [f for f, flag in due if flag]
    if not judged:
        raise Inconclusive(f"no MSG1 heard more than 200 ms + one MSG1 interval after the last valid command "
                           f"({ms(dut.now() - last.time):g} ms): the comm-loss flag cannot be judged")
    clear = [f for f in judged if not f.fields["status"] & Status.COMM_FAULT]
    dut.record.observe("malformed RawCommands sent", f"{i} frames cycling: " + "; ".join(b.what for b in bads))
    assert not clear, (f"bit13 (comm fault) clear in MSG1 {ms(frame_start(dut, clear[0]) - last.time):g} ms after the "
                       f"last valid {name}, while only malformed ones came ({'; '.join(b.what for b in bads)}): a "
                       "malformed RawCommand refreshed the comm timeout (R17, R8: set after 200 ms + one MSG1 interval)")


@pytest.mark.requirement("R17")
@pytest.mark.parametrize("name", cat.THROTTLE_FRAMES)
def test_malformed_throttle_does_not_spin(dut, name):
    """A non-zero throttle in malformed frames: the motor stays stopped (MSG1's PWM and running bit)."""
    if not dut.allow_motor_spin:
        pytest.skip("sends a non-zero throttle in malformed frames: taking one would spin the motor; run with "
                    "--allow-motor-spin (and the propeller off)")
    s = can_throttle(dut)
    fields = command(dut, name, s, value=cat.THROTTLE_MAX // 4)
    if fields is None:
        pytest.skip(f"{name} cannot address the DUT's throttle channel {s['throttle_channel']}")
    dut.throttled = True  # the fixture waits for the motor to stop, should one have been taken
    bads = malformed(dut, name, fields)
    t0 = dut.now()
    effects = send_and_look(dut, bads, name)
    moved = [f for f in dut.frames("msg1", since=t0, source=dut.node_id)
             if f.fields["pwm"] or f.fields["status"] & Status.RUNNING]
    problems = effects.lines() + ([f"MSG1 shows the motor driven (pwm {moved[0].fields['pwm']})"] if moved else [])
    assert not problems, (f"{name} malformed with throttle {cat.THROTTLE_MAX // 4} "
                          f"({'; '.join(b.what for b in bads)}): " + "; ".join(problems) + " (R17)")


# ------------------------------------------------------------------------------------------ Set ID, Set Baud (R11)
def _elsewhere(dut, b: Bad) -> bool:
    """Whether ``b`` is a request to a node other than the DUT."""
    return any((i := parse_can_id(w.arbitration_id)).kind is Kind.REQUEST and i.destination != dut.node_id
               for w in b.frames)


def window_malformed(dut, name: str, fields: dict) -> list[Bad]:
    """:func:`malformed` of a window writer: a pseudo-broadcast's (Set ID's) request to another node is one it takes
    (R11), so the builders leave it out (``malformed.applies``)."""
    bads = malformed(dut, name, fields)
    assert name not in cat.PSEUDO_BROADCAST or not any(_elsewhere(dut, b) for b in bads)
    return bads


def _set_id_look(dut, request) -> tuple[list[Bad], list[str]]:
    """A Set ID to another node id and channel, malformed, inside the window: GET_ESC_ID still names the DUT's, no
    answer, no reset. When it moved: each frame again alone, the DUT put back before each (which one it took)."""
    node, channel = request.getfixturevalue("original")  # put back after the test, whatever it took
    low, high = cat.spec("set_id").request.field("node_id").legal
    target = next(n for n in range(low, high + 1) if n not in {node, DEFAULT_ESC_NODE_ID, *dut.nodes})
    fields = {"node_id": target, "throttle_channel": cat.THROTTLE_CHANNELS[channel % len(cat.THROTTLE_CHANNELS)]}
    bads = window_malformed(dut, "set_id", fields)
    dut.open_window()
    ups = dut.power_up_count()
    interval = interval_s(dut.settings(), "msg1")
    heard, t0 = len(dut.trace), dut.now()
    send_bads(dut, bads)
    t1 = read_past(dut)
    answers = heard_answers(dut, heard, t0, bads)
    problems = [f"answered: {'; '.join(answers)}"] if answers else []
    msg1 = dut.frames("msg1", since=t0, until=t1, source=dut.node_id)
    problems += reset_signs(dut, msg1, interval)
    if not msg1 or t1 - msg1[-1].timestamp > cat.restart_limit_s(interval) + dut.lane.timing_error:
        problems.append(f"no MSG1 in the last {ms(t1 - (msg1[-1].timestamp if msg1 else t0)):g} ms (MSG1 every "
                        f"{ms(interval):g} ms): reporting stopped")
        dut.await_reports(t1, t1 + dut.ready_bound_s())  # a restarted ESC is let boot before it is asked
    found = esc_ids(dut)
    if found != [(node, channel)]:
        problems.append(f"GET_ESC_ID answers {found}, was {[(node, channel)]}")
        taken = []
        for b in bads:
            put_back(dut, node, channel)
            send_bads(dut, [b])
            if (now := esc_ids(dut)) != [(node, channel)]:
                taken.append(f"{b}: GET_ESC_ID answers {now}")
        problems.append("taken, one at a time: " + ("; ".join(taken) if taken else "none alone"))
    else:
        problems += reset_signs(dut, [], interval, ups=(ups, dut.power_up_count()))
    return bads, problems


def _set_baud_look(dut, request) -> tuple[list[Bad], list[str]]:
    """A Set Baud to another rate, malformed, inside the window: no answer, nothing changed, no reset, and after the
    next power-up (proven at whichever rate the DUT answers) the DUT at its old rate."""
    rate = request.getfixturevalue("rate0")  # the DUT and the host put back at it after the test, whatever it took
    code = next(c for c, r in RATES.items() if r != rate)
    bads = window_malformed(dut, "set_baud", {"baud": code})
    dut.open_window()
    problems = send_and_look(dut, bads, "set_baud").lines()
    try:
        after = cycle(dut, rate)
    except Inconclusive:
        if not problems:
            raise
        return bads, problems  # the FAIL stands; where the rate went is then not known
    if after != rate:
        problems.append(f"after the next power-up the DUT answers at {after} bit/s, not {rate}: it took a malformed "
                        f"Set Baud {code} ({RATES[code]} bit/s)")
    return bads, problems


#: each window writer's read-back (what it moves, looked at after its malformed frames): a writer added to the
#: catalogue's window settings without one fails here, at import
_WINDOW_LOOKS = {"set_id": _set_id_look, "set_baud": _set_baud_look}
if missing := sorted(WINDOW_WRITERS - set(_WINDOW_LOOKS)):
    raise KeyError(f"window writers {missing}: say in {__name__} how a malformed one taken shows")


@pytest.mark.requirement("R17")
@pytest.mark.power_cycle
@pytest.mark.parametrize("name", [s.writer for s in cat.PERSISTED_SETTINGS if s.window])
def test_malformed_window_writes_are_ignored(dut, name, request):
    """Set ID and Set Baud, each malformed in every form (but Set ID's to another node, which it takes), inside the
    120 s window of a proven power-up (R11), where a valid one is taken: no answer, the node id / the bit rate after
    the next power-up unchanged, no reset; the DUT put back whatever it took."""
    bads, problems = _WINDOW_LOOKS[name](dut, request)
    dut.record.observe("malformed frames sent", "; ".join(str(b) for b in bads))
    assert not problems, (f"{cat.spec(name).title}: inside the 120 s window (R11), after these malformed frames of a "
                          f"command that would show ({'; '.join(b.what for b in bads)}): " + "; ".join(problems)
                          + " (R17: a malformed frame gets no answer, changes nothing and never resets the ESC)")
