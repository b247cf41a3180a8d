"""Spec section 4.4.2: MSG Control (20010) - suspend / resume active reporting, MSG_EXP mode, the answer.

Also home of the helpers the report and broadcast modules share (4.4.1, 4.4.3 - 4.4.14): the answer
slot timing of R2, capturing what a DUT sends in MSG_EXP mode, and the :func:`bench` fixture.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Any

import pytest

from ckesc.harness.verdict import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.errors import TailError
from ckesc.protocol.frame import classify, frame_bits
from ckesc.protocol.ids import Kind

SECTION = "4.4.2"

INTERVALS = ("msg1_interval", "msg2_interval", "msg3_interval")
REPORTS = ("msg1", "msg2", "msg3")
EXP_FRAMES = tuple(s.name for s in cat.CATALOGUE if s.name.startswith("msg_exp"))
#: R2: the answer slots, (node_id % SLOTS) x ANSWER_SLOT_S, the last one ending at ANSWER_DELAY_MAX_S
SLOTS = round(cat.ANSWER_DELAY_MAX_S / cat.ANSWER_SLOT_S)
#: A test allowance, not a protocol fact: a frame that starts within this time of a command may
#: have been queued before the DUT could act on the command, and is not held against it. On a lane
#: with a stated timing error a frame may also leave that much late: see :func:`react_s`.
REACT_S = 0.005
#: The longest a reporting DUT can be silent: one MSG1 interval at its largest legal setting
REPORT_SILENCE_S = cat.REPORT_INTERVAL_RANGE[1] * cat.INTERVAL_UNIT_S + REACT_S
COMMANDS = {"suspend": cat.MSG_CONTROL_SUSPEND, "resume": cat.MSG_CONTROL_RESUME, "resume_exp": cat.MSG_CONTROL_RESUME_EXP}


# ------------------------------------------------------------------------------------------ helpers
def ms(seconds: float) -> float:
    """Seconds to milliseconds, rounded to the nanosecond (float noise must not decide a verdict)."""
    return round(seconds * 1000, 6)


def frame_start(dut, frame) -> float:
    """When a frame started on the bus: its timestamp is its end (SocketCAN, and the simulated lane,
    where an extended frame of n data bytes takes frame_bits(n) bit times; on a real bus stuff bits
    make it up to ~20 % longer, inside the lane's stated error)."""
    return frame.timestamp - frame_bits(len(frame.data)) / dut.lane.bitrate


def interval_s(settings: dict, which: str) -> float:
    return settings[f"{which}_interval"] * cat.INTERVAL_UNIT_S


def node_settings(dut, node: int) -> dict:
    """Report intervals of any node on the bus (Set/Get Freq read)."""
    return dut.ask("set_freq", {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0},
                   destination=node)


def longest_interval_s(dut, node: int | None = None) -> float:
    s = node_settings(dut, dut.node_id if node is None else node)
    return max(s[k] for k in INTERVALS) * cat.INTERVAL_UNIT_S


def msg_control(dut, command: int):
    return dut.broadcast("msg_control", {"option": 0, "command": command})


def resume(dut) -> None:
    """Normal reporting again (0xAAAAAAAA), and the DUT left reporting: if no report comes back within
    the longest interval there can be, the DUT is power-cycled where the lane can (suspension does not
    survive it, R13), so that one broken resume does not fail every later test for the wrong reason."""
    sent = msg_control(dut, cat.MSG_CONTROL_RESUME)
    dut.wait(cat.ANSWER_DELAY_MAX_S)
    if dut.wait_for("msg1", REPORT_SILENCE_S) is not None or reported(dut, sent.time, source=dut.node_id, names=REPORTS):
        return
    dut.record.observe("after 0xAAAAAAAA", f"no report in {ms(REPORT_SILENCE_S)} ms")
    if dut.lane.power.available:
        try:
            dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
            dut.record.observe("recovery", "power cycle to leave the DUT reporting")
        except Inconclusive as exc:
            dut.record.observe("recovery failed", str(exc))


def undecoded(dut) -> list:
    """The frames heard that did not decode, but for those whose only fault is the tail byte's
    start/end/toggle bits (F2): the harness reads those as the single frames they must be (they are in
    ``dut.trace`` too), and the framing tests (4.1) judge the tail."""
    return [g for g in dut.garbled if not isinstance(g.error, TailError)]


def garbled(dut, name: str, *, source: int, since: float | None = None) -> list:
    """Frames of message ``name`` from ``source`` that did not decode (wrong length, ...; see undecoded)."""
    return [g for g in dut.undecoded(name, source=source, since=since, kind=Kind.MESSAGE) if not isinstance(g.error, TailError)]


def describe_garbled(gs: list) -> str:
    return "; ".join(f"{len(g.msg.data)} data bytes: {g.error}" for g in gs[:3])


def reported(dut, since: float, *, source: int, names=REPORTS + EXP_FRAMES) -> list[tuple[str, float]]:
    """(name, start) of every report frame from ``source`` that started REACT_S or more after
    ``since``, decodable or not (a malformed report is still a report), in time order."""
    out = [(f.name, frame_start(dut, f)) for f in dut.frames(since=since, source=source) if f.name in names]
    for g in undecoded(dut):
        kind, _, src, _, spec = classify(g.msg.arbitration_id)
        if kind is Kind.MESSAGE and spec is not None and spec.name in names and src == source:
            out.append((spec.name, (g.msg.timestamp or 0.0) - frame_bits(len(g.msg.data)) / dut.lane.bitrate))
    return sorted((x for x in out if x[1] >= since + REACT_S), key=lambda x: x[1])


def need_decoded(dut, name: str, frames: list, since: float, what: str) -> list:
    """``frames`` (of ``name`` since ``since``), or INCONCLUSIVE when there are none because the DUT's
    ones do not decode (their own test fails that): ``what`` cannot be read from them."""
    if not frames:
        bad = garbled(dut, name, source=dut.node_id, since=since)
        if bad:
            raise Inconclusive(f"{cat.spec(name).title} frames do not decode ({describe_garbled(bad)}): {what} cannot be read")
    return frames


def report_starts(dut, name: str, since: float) -> list[float]:
    """Start times of the DUT's ``name`` reports since ``since``, decodable or not (timing is the question)."""
    return [t for n, t in reported(dut, since - REACT_S, source=dut.node_id, names=(name,))]


def react_s(dut) -> float:
    """REACT_S plus the lane's stated timing error: how long after a command a frame may still be one
    the DUT had due before it (on a lane that cannot time better, a frame may leave that much late)."""
    return REACT_S + dut.lane.timing_error


def answer_window_s(dut) -> float:
    """How long a test reads for the answer to a broadcast command: twice the 64 ms limit, plus the
    lane's stated timing error, so that an answer late by up to that error is seen and measured
    (INCONCLUSIVE there), not taken for no answer."""
    return 2 * cat.ANSWER_DELAY_MAX_S + dut.lane.timing_error


def settle(dut) -> None:
    """Let any answer to an earlier broadcast (the fixture's own MSG Control, a late one) arrive first."""
    dut.wait(2 * cat.ANSWER_DELAY_MAX_S)


def reference(dut, name: str, fields: dict | None = None, *, need: tuple[str, ...] = (), **kw) -> dict:
    """An answer the test compares with (not what it checks): none, one that does not decode, or one
    without the ``need``-ed fields makes the test INCONCLUSIVE rather than failing the frame under test."""
    ex = dut.request(name, fields, **kw)
    if ex.response is None or any(k not in ex.response.fields for k in need):
        raise Inconclusive(f"{name} {fields or ''}: no decodable answer to compare with")
    return ex.response.fields


def check_suspended(dut, since: float, settings: dict) -> None:
    """Precondition: MSG1 has stopped after 0x55555555 (else nothing about suspension can be shown)."""
    dut.wait(max(0.0, since + 2 * interval_s(settings, "msg1") + react_s(dut) - dut.now()))
    if reported(dut, since + dut.lane.timing_error, source=dut.node_id, names=("msg1",)):  # not held against it: react_s()
        raise Inconclusive("MSG1 continues after 0x55555555: the DUT is not suspended, nothing can be shown in that state")


def check_answer_slot(dut, answer, sent, node: int, what: str, max_requirement: str) -> None:
    """R2: an answer starts no earlier than (node_id % 32) x 2 ms after the request and ends within its
    2 ms slot; ``max_requirement`` (4.4.2-4 / 4.4.3-4): never later than 64 ms."""
    slot = (node % SLOTS) * cat.ANSWER_SLOT_S
    err = dut.lane.timing_error * 1000
    start, end = frame_start(dut, answer) - sent.time, answer.timestamp - sent.time
    rec = dut.record
    rec.measure(f"{what} node {node}: answer start after the request", ms(start), limit=ms(slot), op=">=", unit="ms",
                clock=dut.clock, error=err, requirement="R2", strength="READING")
    rec.measure(f"{what} node {node}: answer end after the request", ms(end), limit=ms(slot + cat.ANSWER_SLOT_S),
                unit="ms", clock=dut.clock, error=err, requirement="R2", strength="READING")
    rec.measure(f"{what} node {node}: answer delay", ms(end), limit=ms(cat.ANSWER_DELAY_MAX_S), unit="ms",
                clock=dut.clock, error=err, requirement=max_requirement)


@contextmanager
def exp_mode(dut):
    """MSG_EXP reporting (MSG Control 0xEEEEEEEE) for the ``with`` block; normal reporting after it, always."""
    try:
        yield msg_control(dut, cat.MSG_CONTROL_RESUME_EXP)
    finally:
        resume(dut)


def exp_capture(dut, seconds: float | None = None) -> tuple[list, list, float, float]:
    """Everything the DUT sends in ``seconds`` of MSG_EXP mode (default: twice the longest report
    interval): (decoded frames, garbled ones, window start, window length). Used by other modules too:
    keep its signature."""
    return exp_capture_during(dut, seconds)[:4]


def exp_capture_during(dut, seconds: float | None = None, during=None) -> tuple[list, list, float, float, object]:
    """:func:`exp_capture`, and what ``during(dut)`` returned: called at the end of the window, still in
    MSG_EXP mode, to read what the frames are compared with (before the resume, which may power-cycle)."""
    window = 2 * longest_interval_s(dut) + 2 * REACT_S if seconds is None else seconds
    with exp_mode(dut) as sent:
        dut.wait(window + dut.lane.timing_error)
        end = dut.now()
        seen = during(dut) if during is not None else None
    start = sent.time + react_s(dut)  # a frame that starts sooner may have been due before the command
    frames = [f for f in dut.frames(since=start, until=end, source=dut.node_id) if frame_start(dut, f) >= start]
    bad = [g for g in undecoded(dut) if start <= (g.msg.timestamp or 0.0) <= end and classify(g.msg.arbitration_id)[2] == dut.node_id]
    return frames, bad, start, window, seen


def exp_reports(dut, name: str, seconds: float | None = None, during=None) -> tuple[list, object]:
    """The ``name`` frames of an MSG_EXP mode capture, and what ``during`` returned (see exp_capture).
    Any frame that does not decode with its table layout fails the test; none at all makes it
    INCONCLUSIVE (which MSG_EXP frames come is OBSERVE, R9-exp)."""
    frames, bad, _, window, seen = exp_capture_during(dut, seconds, during)
    wrong = [g for g in bad if (s := classify(g.msg.arbitration_id)[4]) is not None and s.name == name]
    title = cat.spec(name).title
    assert not wrong, f"{len(wrong)} {title} frames do not decode with the table's layout: {describe_garbled(wrong)}"
    got = [f for f in frames if f.name == name]
    dut.record.observe(f"{title} frames in {window:.3f} s of MSG_EXP mode", len(got))
    if not got:
        raise Inconclusive(f"the DUT sent no {title} in {window:.3f} s of MSG_EXP mode (which MSG_EXP frames come is OBSERVE, R9-exp)")
    return got, seen


def with_emulator_faults(multi_dut, config):
    """``multi_dut`` with ``--emulator-faults`` switched on in its private emulated bench.

    Workaround: the plugin builds that bench without the run's faults, so no fault could make a
    multi_dut test fail. The faults go on after discovery (a GET_ESC_ID fault then fails the test
    instead of breaking the fixture). On a real bus, and in the real-time lane, this does nothing."""
    faults = [f for f in (config.getoption("emulator_faults") or "").split(",") if f]
    sim = getattr(multi_dut.lane, "sim", None)
    if faults and sim is not None and hasattr(sim, "set_fault"):
        for name in faults:
            sim.set_fault(name)
    for node in multi_dut.nodes:  # every node answers the requests the tests need: else an ERROR, not a FAIL
        node_settings(multi_dut, node)
        multi_dut.ask("get_major_configuration", {"option": 0}, destination=node)
    return multi_dut


@pytest.fixture
def bench(multi_dut, request):
    """Several ESCs on one bus (``multi_dut``), with the run's emulator faults."""
    return with_emulator_faults(multi_dut, request.config)


def several_escs(bench, what: str) -> list[int]:
    """The node ids on the bench, INCONCLUSIVE unless two or more answered GET_ESC_ID (``what`` is the
    clause's own words, e.g. 'all ESCs')."""
    if len(bench.nodes) < 2:
        raise Inconclusive(f"only node(s) {bench.nodes} answered GET_ESC_ID: '{what}' needs two or more")
    return bench.nodes


def _other(codes, current: int) -> int:
    return next(c for c in sorted(codes) if c != current)


def _change(name: str, before: dict) -> tuple[dict[str, Any], dict[str, int]]:
    """A legal request of ``name`` that changes a setting, and the settings it should change."""
    if name == "set_rotation":
        new = _other(cat.spec("set_rotation").response.field("rotation").codes, before["rotation"])
        return {"rotation": new}, {"rotation": new}
    if name == "throttle_select":
        new = _other(cat.spec("throttle_select").response.field("source").codes, before["throttle_source"])
        return {"source": new}, {"throttle_source": new}
    if name == "set_freq":
        lo, hi = cat.REPORT_INTERVAL_RANGE
        new = {k: before[k] for k in INTERVALS}
        new["msg1_interval"] = before["msg1_interval"] + 5 if before["msg1_interval"] + 5 <= hi else max(lo, before["msg1_interval"] - 5)
        return {"option": 1, **new}, new
    if name == "set_led":
        color = before["led_color"] ^ int(cat.LedColor.RED | cat.LedColor.GREEN | cat.LedColor.BLUE)
        return {"option": 0, "color": color, "blink": before["led_blink"]}, {"led_color": color}
    raise KeyError(name)


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("R2", "4.4.2-4", "4.4.2-T")
@pytest.mark.parametrize("command", list(COMMANDS))
def test_answer_is_command_zero_in_the_node_slot(dut, command):
    """Every command is answered once: a 20010 message with option 0 and command 0x00000000, from the
    DUT's node id, starting (node_id % 32) x 2 ms after the request and never later than 64 ms."""
    settle(dut)
    try:
        sent = msg_control(dut, COMMANDS[command])
        dut.wait(answer_window_s(dut))  # a late answer is seen, and measured
        answers = [f for f in dut.frames("msg_control", since=sent.time, source=dut.node_id)]
        bad = garbled(dut, "msg_control", source=dut.node_id, since=sent.time)
    finally:
        resume(dut)
    assert not bad, f"MSG Control answer does not decode: {describe_garbled(bad)}"
    assert answers, f"no answer to MSG Control {command} (0x{COMMANDS[command]:08X}) within {ms(answer_window_s(dut))} ms"
    assert len(answers) == 1, f"{len(answers)} answers to one MSG Control command: {answers}"
    a = answers[0]
    assert (a.fields["option"], a.fields["command"]) == (0, cat.MSG_CONTROL_ANSWER), (
        f"[R2 READING] the answer is option {a.fields['option']}, command 0x{a.fields['command']:08X}; "
        f"expected option 0, command 0x{cat.MSG_CONTROL_ANSWER:08X}")
    check_answer_slot(dut, a, sent, dut.node_id, "MSG Control", "4.4.2-4")


@pytest.mark.requirement("4.4.2-1", "4.4.2-T")
def test_suspend_stops_and_resume_restarts_reporting(dut):
    """0x55555555 stops MSG1/MSG2/MSG3 for as long as it lasts; 0xAAAAAAAA brings each back at once
    (its first frame within one of its intervals)."""
    s = dut.settings()
    longest = max(interval_s(s, w) for w in REPORTS)
    err = dut.lane.timing_error
    try:
        off = msg_control(dut, cat.MSG_CONTROL_SUSPEND)
        dut.wait(2 * longest + err)
        leaked = reported(dut, off.time + err, source=dut.node_id)  # not held against it: react_s()
        assert not leaked, f"{len(leaked)} reports while suspended, first {leaked[0][0]} {ms(leaked[0][1] - off.time)} ms after 0x55555555"
        on = msg_control(dut, cat.MSG_CONTROL_RESUME)
        dut.wait(longest + REACT_S + err)
        back = reported(dut, on.time - REACT_S, source=dut.node_id, names=REPORTS)
        for which in REPORTS:
            first = next((t for n, t in back if n == which), None)
            assert first is not None, f"no {which.upper()} within {ms(longest + REACT_S + err)} ms of 0xAAAAAAAA"
            dut.record.measure(f"first {which.upper()} after resume", ms(first - on.time), limit=ms(interval_s(s, which)),
                               unit="ms", clock=dut.clock, error=err * 1000, requirement="4.4.2-T")
    finally:
        resume(dut)


@pytest.mark.requirement("R13", "4.4.2-1")
@pytest.mark.power_cycle
def test_suspension_is_lost_at_power_off(dut):
    """MSG Control suspension is not persisted (R13): after 0x55555555 and a power cycle the ESC
    reports MSG1/MSG2/MSG3 again without being told to resume."""
    s = dut.settings()
    longest = max(interval_s(s, w) for w in REPORTS)
    try:
        off = msg_control(dut, cat.MSG_CONTROL_SUSPEND)
        check_suspended(dut, off.time, s)
        dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
        since = dut.now()
        dut.wait(2 * longest + dut.lane.timing_error)
        back = {n for n, _ in reported(dut, since, source=dut.node_id, names=REPORTS)}
        missing = [w.upper() for w in REPORTS if w not in back]
        assert not missing, (f"no {', '.join(missing)} within {ms(2 * longest)} ms after a power cycle that followed "
                             "0x55555555: the suspension survived power-off (R13: not persisted)")
    finally:
        resume(dut)


@pytest.mark.requirement("4.4.2-1", "4.4.2-2", "4.4.2-4", "R2")
def test_every_esc_answers_in_its_slot_and_obeys(bench):
    """All ESCs on the bus answer each command in their own slot and act on it."""
    nodes = several_escs(bench, "all ESCs")
    longest = max(longest_interval_s(bench, n) for n in nodes)
    settle(bench)
    try:
        for command in ("suspend", "resume"):
            sent = msg_control(bench, COMMANDS[command])
            bench.wait(2 * cat.ANSWER_DELAY_MAX_S)
            for node in nodes:
                answers = bench.frames("msg_control", since=sent.time, source=node)
                assert len(answers) == 1, f"node {node}: {len(answers)} answers to MSG Control {command} (4.4.2-2: all respond)"
                check_answer_slot(bench, answers[0], sent, node, f"MSG Control {command}", "4.4.2-4")
            bench.wait(longest + REACT_S)
            for node in nodes:
                reports = reported(bench, sent.time, source=node, names=REPORTS)
                if command == "suspend":
                    assert not reports, f"node {node} still reports after 0x55555555 (4.4.2-1)"
                else:
                    assert reports, f"node {node} does not report after 0xAAAAAAAA (4.4.2-1)"
    finally:
        resume(bench)


@pytest.mark.requirement("4.4.2-3", "R12")
@pytest.mark.parametrize("name", ["set_rotation", "set_freq", "throttle_select", "set_led"])
def test_settings_do_not_change_while_suspended(dut, name):
    """While reporting is suspended a change is not applied, neither then nor on resume; the same
    request after resume is (else the DUT ignores it anyway and nothing is shown: INCONCLUSIVE)."""
    if name == "set_led" and not dut.profile.has("led"):
        pytest.skip(f"the DUT profile {dut.profile.name!r} lacks capability 'led'")
    before = dut.settings()
    fields, expected = _change(name, before)
    try:
        off = msg_control(dut, cat.MSG_CONTROL_SUSPEND)
        dut.wait(2 * interval_s(before, "msg1") + REACT_S)
        dut.record.observe("MSG1 after 0x55555555", len(reported(dut, off.time, source=dut.node_id, names=("msg1",))))
        ex = dut.request(name, fields)
        dut.record.observe(f"answer to {name} while suspended", ex.response.fields if ex.response else "none")
        during = dut.settings()
    finally:
        resume(dut)
    after = dut.settings()
    for key in expected:
        assert during[key] == before[key], f"{name} {fields} took effect while suspended: {key} {before[key]} -> {during[key]}"
        assert after[key] == before[key], f"{name} {fields} sent while suspended took effect on resume: {key} {before[key]} -> {after[key]}"
    dut.ask(name, fields)
    control = dut.settings()
    if any(control[k] != v for k, v in expected.items()):
        raise Inconclusive(f"{name} {fields} does not take effect with reporting on either ({control}): "
                           "that it is ignored while suspended shows nothing")


@pytest.mark.requirement("4.4.2-T", "R9")
def test_exp_mode_replaces_msg1_to_msg3(dut):
    """0xEEEEEEEE: MSG1..MSG3 stop and MSG_EXP frames come instead; 0xAAAAAAAA brings MSG1 back."""
    frames, bad, start, window = exp_capture(dut)
    names = [f.name for f in frames] + [classify(g.msg.arbitration_id)[4].name for g in bad
                                        if classify(g.msg.arbitration_id)[4] is not None]
    normal = [n for n in names if n in REPORTS]
    exp = [n for n in names if n in EXP_FRAMES]
    dut.record.observe("MSG_EXP frames", sorted(set(exp)))
    assert not normal, f"{len(normal)} MSG1..MSG3 in MSG_EXP mode (first: {normal[0]}); R9: MSG_EXP frames replace them"
    assert exp, f"no MSG_EXP frame in {window:.3f} s after 0xEEEEEEEE"
    end = start + window  # 0xAAAAAAAA follows (exp_capture), and MSG1 within one interval of it
    if not report_starts(dut, "msg1", end):
        dut.wait(interval_s(dut.settings(), "msg1") + react_s(dut))
    assert report_starts(dut, "msg1", end), "no MSG1 after 0xAAAAAAAA ended MSG_EXP mode"


@pytest.mark.requirement("R9-exp")
def test_observe_exp_mode_reporting(dut):
    """Which MSG_EXP frames come in MSG_EXP mode, and how often: recorded."""
    frames, bad, start, window = exp_capture(dut, 3 * longest_interval_s(dut) + REACT_S)
    dut.record.observe("window", f"{ms(window)} ms")
    for name in EXP_FRAMES + REPORTS:
        stamps = [f.timestamp for f in frames if f.name == name]
        if not stamps:
            continue
        mean = (stamps[-1] - stamps[0]) / (len(stamps) - 1) if len(stamps) > 1 else None
        dut.record.observe(name, f"{len(stamps)} frames" + (f", mean interval {ms(mean)} ms" if mean else ""))
    if bad:
        dut.record.observe("undecodable frames", describe_garbled(bad))
    assert any(f.name in EXP_FRAMES for f in frames), "no MSG_EXP frame at all"
