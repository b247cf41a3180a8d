"""Spec section 4.4.4: MSG1 (20050) - speed, throttle output (PWM) and the status word."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

import pytest

from ckesc.bench.errors import HarnessError
from ckesc.bench.outcomes import Inconclusive, NotClaimed
from ckesc.protocol import catalogue as cat
from ckesc.protocol.catalogue import Status
from ckesc.protocol.frame import frame_bits
from ckesc.protocol.judgements import r8_onset
from ckesc.protocol.transfer import TRANSFER_ID_MODULO

from .settings import changes, listed
from .telemetry import REACT_S, describe_garbled, frame_start, garbled, interval_s, ms, need_decoded
from .throttle import FORMAT_CHANNELS, STREAM_PERIOD_S, can_throttle, command_for

SECTION = "4.4.4"

#: Test allowance for the motor and the ESC's throttle ramp to settle before MSG1 is compared
SPIN_SETTLE_S = 0.5
PAYLOAD = cat.spec("msg1").layouts[0].size


def _msg1_after(dut, t: float) -> list:
    return [f for f in dut.frames("msg1", source=dut.node_id) if frame_start(dut, f) >= t]


def _stream_pause_s(dut, name: str, since: float, until: float) -> float:
    """The longest time between ``since`` and ``until`` without a frame of the host's own ``name`` stream
    (their echoes' bus stamps; without an echo, the times the stream sent them, by the host clock). The
    stream is the harness's: a host starved of CPU may pause it."""
    stamps = [since, *(f.timestamp for f in dut.frames(name, since=since, until=until, source=dut.host_node)), until]
    return max(b - a for a, b in zip(stamps, stamps[1:]))


def _mid_interval_send(dut, msg1: list, interval: float, after: float = 0.0) -> float:
    """When to send a command so that ``after`` seconds from when the DUT hears it (the frame's end) lies half
    an MSG1 interval before an MSG1 of the DUT's own grid: the first such time from :data:`REACT_S` on,
    predicted from ``msg1`` (the MSG1s heard: the mean of their gaps, from the last one's start). For a
    comm-loss test's last command ``after`` is the 200 ms of R8: a flag raised on time then shows half an
    interval after 200 ms, one raised an interval early or late an interval from there, each decisively
    judged on a bench whose error is below a quarter interval."""
    starts = [frame_start(dut, f) for f in msg1]
    if len(starts) >= 2:
        interval = (starts[-1] - starts[0]) / (len(starts) - 1)
    heard = frame_bits(8) / dut.lane.bitrate  # every RawCommand is 8 data bytes
    mark = starts[-1] - interval / 2 - after - heard  # one such time; the others are an interval apart
    earliest = dut.now() + REACT_S
    return mark + math.ceil(max(earliest - mark, 0.0) / interval) * interval


def _comm_fault(f) -> bool:
    return bool(f.fields["status"] & Status.COMM_FAULT)


# ------------------------------------------------------------------------------------------ 4.4.4-1
@pytest.mark.requirement("4.4.4-1")
def test_msg1_is_six_bytes(dut):
    """Every MSG1 carries 6 payload bytes (7 data bytes with the tail)."""
    s = dut.settings()
    start = dut.now()
    frames = dut.reports("msg1", 4 * interval_s(s, "msg1"))
    bad = garbled(dut, "msg1", source=dut.node_id, since=start)
    assert not bad, f"{len(bad)} MSG1 frames are not {PAYLOAD} payload bytes + tail: {describe_garbled(bad)}"
    assert frames, f"no MSG1 in {ms(4 * interval_s(s, 'msg1'))} ms"
    lengths = sorted({len(f.data) - 1 for f in frames})
    assert lengths == [PAYLOAD], f"MSG1 payload lengths {lengths}, expected {PAYLOAD}"


# ------------------------------------------------------------------------------------------ 4.4.4-2, R7
def _check_direction(dut, frames: list, rotation: int, what: str, since: float) -> None:
    assert need_decoded(dut, "msg1", frames, since, "the direction bit"), f"{what}: no MSG1"
    source_pwm = dut.settings()["throttle_source"] == 1
    for f in frames:
        st = f.fields["status"]
        assert bool(st & Status.DIRECTION_CCW) == bool(rotation), (
            f"{what}: MSG1 status 0x{st:04X} bit15 (direction) = {int(bool(st & Status.DIRECTION_CCW))}, "
            f"the saved rotation is {rotation} (R7: bit15 direction, bit14 throttle source)")
        if not source_pwm:
            assert not st & Status.THROTTLE_PWM, f"{what}: MSG1 status 0x{st:04X} bit14 (PWM throttle) set under CAN throttle (R7)"


@pytest.mark.requirement("4.4.4-2", "R7")
def test_direction_bit_follows_the_rotation(dut):
    """Status bit 15 is the saved rotation (0 forward/CW, 1 reverse/CCW), both ways; bit 14 stays 0
    under CAN throttle."""
    s = dut.settings()
    codes = sorted(cat.spec("set_rotation").response.field("rotation").codes)
    for rotation in sorted(codes, key=lambda r: r == s["rotation"]):  # the other direction first, then back
        answer = dut.ask("set_rotation", {"rotation": rotation})
        t = dut.now()
        if dut.settings()["rotation"] != rotation:
            raise Inconclusive(f"Set Rotation {rotation} did not take effect (answered {listed(answer)}): cannot compare")
        dut.wait(3 * interval_s(s, "msg1"))
        _check_direction(dut, _msg1_after(dut, t + REACT_S), rotation, f"after Set Rotation {rotation}", t)


@pytest.mark.requirement("4.4.4-2", "R7", "R13")
@pytest.mark.power_cycle
def test_direction_reported_at_power_up_is_the_saved_one(dut):
    """After a power cycle, MSG1 reports the rotation saved before it, from the first frame on."""
    s = dut.settings()
    saved = next(c for c in sorted(cat.spec("set_rotation").response.field("rotation").codes) if c != s["rotation"])
    dut.ask("set_rotation", {"rotation": saved})
    if dut.settings()["rotation"] != saved:
        raise Inconclusive(f"Set Rotation {saved} did not take effect: nothing saved to report")
    t = dut.now()
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    dut.wait(2 * interval_s(s, "msg1"))
    frames = _msg1_after(dut, t)
    dut.record.observe("first MSG1 after power-up", frames[0].fields if frames else "none")
    _check_direction(dut, frames, saved, "after a power cycle", t)


def _require(dut, settings: dict) -> None:
    """Precondition: the settings a test made are in force (242), else INCONCLUSIVE."""
    if missed := changes(settings, dut.settings(), settings):
        raise Inconclusive(f"the DUT did not take the settings of the case (set -> 242: {missed}): the case cannot be set up")


def _pwm_input(dut):
    """The DUT's analog throttle input, where the lane can drive it: the emulated bench of the simulated
    lane (the harness has no call for it; real benches and the real-time lane have none)."""
    setter = getattr(getattr(getattr(dut.lane, "sim", None), "bench", None), "set_pwm_input", None)
    if setter is None:
        raise Inconclusive(f"the {dut.lane.name} lane cannot drive the DUT's PWM input")
    return lambda value: setter(value, dut.node_id)


@pytest.mark.requirement("R7", "4.4.4-T")
@pytest.mark.parametrize("source", ["CAN", "PWM"])
def test_throttle_source_bit(dut, source):
    """Bit 14 is 0 while the ESC takes CAN throttle - with the motor reversed too, as DroneCAN's GUI reads
    the direction from bit 14 - and 1 while it takes PWM throttle (PWM+CAN selected, a PWM signal at zero
    throttle present)."""
    s = dut.settings()
    codes = {v: k for k, v in cat.spec("throttle_select").response.field("source").codes.items()}
    interval = interval_s(s, "msg1")
    fields = command_for("raw_command_12b", s["throttle_channel"])
    if source == "CAN":
        reverse = {v: k for k, v in cat.spec("set_rotation").response.field("rotation").codes.items()}["reverse"]
        dut.ask("set_rotation", {"rotation": reverse})
        dut.ask("throttle_select", {"source": codes["CAN"]})
        _require(dut, {"throttle_source": codes["CAN"]})
        dut.throttle_stream("raw_command_12b", fields, STREAM_PERIOD_S)
        t = dut.now()
        dut.wait(3 * interval)
        dut.stop_throttle()
    else:
        if not dut.profile.has("pwm_input"):
            pytest.skip(f"the DUT profile {dut.profile.name!r} lacks capability 'pwm_input'")
        set_pwm = _pwm_input(dut)
        dut.ask("throttle_select", {"source": codes["PWM+CAN"]})
        _require(dut, {"throttle_source": codes["PWM+CAN"]})
        try:
            set_pwm(0)
            dut.wait(interval)
            t = dut.now()
            dut.wait(3 * interval)
        finally:
            set_pwm(None)
    frames = need_decoded(dut, "msg1", _msg1_after(dut, t + REACT_S), t, "the throttle source bit")
    assert frames, "no MSG1"
    bits = sorted({int(bool(f.fields["status"] & Status.THROTTLE_PWM)) for f in frames})
    assert bits == [int(source == "PWM")], f"MSG1 bit14 (throttle source) {bits} while the ESC takes {source} throttle (R7)"


# ------------------------------------------------------------------------------------------ 4.4.4-3, R8
@pytest.mark.requirement("4.4.4-3", "R8")
@pytest.mark.parametrize("name", list(FORMAT_CHANNELS), ids=lambda n: n.rsplit("_", 1)[1])
def test_comm_loss_flag_sets_after_200ms_and_clears(dut, name):
    """Under a zero-throttle stream bit 13 is clear; from the last command it is set no earlier than
    200 ms and no later than 200 ms + one MSG1 interval; the next command clears it."""
    s = can_throttle(dut)
    fields = command_for(name, s["throttle_channel"])
    if fields is None:
        pytest.skip(f"{name} cannot address the DUT's throttle channel {s['throttle_channel']}")
    _check_comm_loss(dut, s, name, fields)


#: R20-watchdog's other traffic: each frame once in this period, all through the comm-loss test
OTHER_TRAFFIC_PERIOD_S = 0.05
#: what the host asks the DUT meanwhile: (request, its fields); a function the profile declares absent is left out
OTHER_READS = (("get_major_configuration", {"option": 0}), ("maintenance_information", {"option": 2}),
               ("set_freq", cat.FREQ_READ))
#: the flight controller's DroneCAN frames played meanwhile (ckesc.bench.foreign's ArduPilot: its node, single frames)
OTHER_FOREIGN = ("uavcan.protocol.NodeStatus", "uavcan.equipment.esc.RawCommand")


@pytest.mark.requirement("R20-watchdog", "4.4.4-3", "R8")
def test_comm_loss_flag_sets_while_other_traffic_goes_on(dut):
    """As the comm-loss test, with a GET_ESC_ID query, reads (242, 241, Set/Get Freq) and a flight controller's
    DroneCAN frames (NodeStatus, its zero ESC command 1030) each every 50 ms from before the command stream stops
    until the flag has cleared: only RawCommand refreshes the comm watchdog (R20), so the flag rises within R8's
    bound all the same, and the next command clears it."""
    s = can_throttle(dut)
    name = next(n for n in FORMAT_CHANNELS if command_for(n, s["throttle_channel"]) is not None)
    with _other_traffic(dut) as what:
        _check_comm_loss(dut, s, name, command_for(name, s["throttle_channel"]), during=what)


@contextmanager
def _other_traffic(dut) -> Iterator[str]:
    """R20-watchdog's traffic, each stream every :data:`OTHER_TRAFFIC_PERIOD_S` in its own phase, while the block runs;
    yields what it is (for the messages)."""
    from ckesc.bench import foreign  # imports dronecan (about a second): only for this test

    # the run's own foreign traffic (--foreign-traffic) plays these already, from the same node: not twice
    played = [] if dut.lane.foreign_traffic is not None else [
        s for s in foreign.ardupilot().streams if s.name in OTHER_FOREIGN and s.node == foreign.FLIGHT_CONTROLLER_NODE]
    streams = [("get_esc_id", {"option": 0}, {"layout": "query"}),
               *((n, f, {"destination": dut.node_id}) for n, f in OTHER_READS),
               *((s.name, None, {"frames": [foreign.encode(s.make(t), source=s.node, priority=s.priority, transfer_id=t)[0]
                                            for t in range(TRANSFER_ID_MODULO)]}) for s in played)]
    phase = OTHER_TRAFFIC_PERIOD_S / len(streams)
    names = []
    with ExitStack() as stack:
        for n, fields, how in streams:
            try:
                stack.enter_context(dut.periodic(n, fields, OTHER_TRAFFIC_PERIOD_S, **how))
            except NotClaimed:
                continue  # the profile declares the function absent: the others go on
            names.append(n)
            dut.wait(phase)
        what = f"{', '.join(names)} each every {ms(OTHER_TRAFFIC_PERIOD_S):g} ms"
        if dut.lane.foreign_traffic is not None:
            what += f", and the run's foreign traffic ({dut.lane.foreign_traffic.name})"
        dut.record.observe("other traffic during the comm-loss test (R20)", what)
        yield what


def _check_comm_loss(dut, s: dict, name: str, fields: dict, during: str = "") -> None:
    """The comm-loss test's body: a zero-throttle ``name`` stream, the flag clear under it; the last command placed on
    the DUT's MSG1 grid, the flag's onset judged by R8; a new command clears it. ``during``: what other traffic goes
    on meanwhile (R20-watchdog), for the messages."""
    while_ = f" while {during} went on (R20: only RawCommand refreshes the comm watchdog)" if during else ""
    # the last command's time is the host's own frame's: its echo, or without one the host clock at send
    own_clock, own_err = dut.lane.own_clock, dut.lane.own_error * 1000
    t0 = dut.now()
    dut.throttle_stream(name, fields, STREAM_PERIOD_S)
    dut.wait(2 * interval_s(s, "msg1"))  # the first command clears a flag left from before the test
    t1 = dut.now()
    # four intervals, plus the lane's stated error: a DUT (or an emulator in a slow VM) that sends late
    # still shows two MSG1 under the stream
    dut.wait(4 * interval_s(s, "msg1") + dut.lane.timing_error)
    under = need_decoded(dut, "msg1", _msg1_after(dut, t1), t1, "the comm fault bit")
    assert len(under) >= 2, f"only {len(under)} MSG1 in {ms(dut.now() - t1)} ms"
    # the last command goes at a phase of the DUT's own MSG1 grid (learned from the MSG1s just heard), so that
    # its 200 ms mark lies half an interval before an MSG1: a flag raised on time shows half an interval after
    # 200 ms, decisively inside R8's window on a bench whose error is less than a quarter interval
    dut.stop_throttle()
    planned = _mid_interval_send(dut, under, interval_s(s, "msg1"), cat.COMM_LOSS_TIMEOUT_S)
    dut.read_until(planned)
    dut.broadcast(name, fields)
    flagged = [f for f in under if _comm_fault(f)]
    if flagged and (pause := _stream_pause_s(dut, name, t0, flagged[0].timestamp)) >= cat.COMM_LOSS_TIMEOUT_S - dut.lane.own_error:
        raise Inconclusive(f"bit13 (comm fault) set in MSG1 after the host's {STREAM_PERIOD_S * 1000} ms command stream "
                           f"paused {ms(pause)} ms (within the lane's error of the timeout, or longer): the flag may be right")
    assert not flagged, f"bit13 (comm fault) set in MSG1 under a {STREAM_PERIOD_S * 1000} ms command stream"
    dut.wait(REACT_S)  # the last command comes back from the bus (or, without an echo, from the lane)
    sent = dut.frames(name, since=t0, source=dut.host_node)
    if not sent:
        raise HarnessError("the throttle stream sent nothing")
    last = sent[-1].timestamp
    dut.record.observe("last command placed", "so that its 200 ms mark (R8) lies half an MSG1 interval before an MSG1 of "
                       f"the DUT's grid: heard {ms(last - planned):g} ms after its planned send (planned: "
                       f"{ms(frame_bits(8) / dut.lane.bitrate):g} ms, its time on the bus)")
    # "one MSG1 interval" (R8) is the DUT's own: the configured one, or the gap it actually leaves
    gaps = [frame_start(dut, b) - frame_start(dut, a) for a, b in zip(under, under[1:])]
    interval = max([interval_s(s, "msg1")] + gaps)
    first = dut.wait_for("msg1", 2 * cat.COMM_LOSS_TIMEOUT_S + 3 * interval, where=_comm_fault)  # a late flag is measured
    assert first is not None, (f"no MSG1 with bit13 (comm fault) within {ms(dut.now() - last)} ms of the last command "
                               f"(R8: set after {ms(cat.COMM_LOSS_TIMEOUT_S)} ms){while_}")
    before = [f for f in _msg1_after(dut, last) if f.timestamp < first.timestamp]
    if before:
        interval = max(interval, frame_start(dut, first) - frame_start(dut, before[-1]))
    # the flag was raised after the last MSG1 without it and no later than the first with it: the first with it
    # must not come before 200 ms (R8: set no earlier) nor after 200 ms + one MSG1 interval (its latest)
    onset = frame_start(dut, first) - last
    if before:
        dut.record.observe("comm fault flag raised between", f"{ms(frame_start(dut, before[-1]) - last):g} and {ms(onset):g} ms "
                           "after the last command (the last MSG1 without bit13, the first with it)")
    # the MSG1 that carries the flag may stray from its grid point by the DUT's declared jitter (profile jitter_s),
    # as a first report after a restart may (R9a): a flag raised on time onto a late MSG1 is no late flag
    for j in r8_onset(onset, interval, jitter=dut.profile.jitter_s, error=dut.lane.own_error):
        dut.record.measure("comm fault flag: first MSG1 with bit13 after the last command", ms(j.measured),
                           limit=ms(j.limit), op=j.op, unit="ms", clock=own_clock, error=own_err,
                           requirement=j.rule, strength="READING")
    # the new command too goes half an interval before an MSG1, which then shows the flag clear
    dut.read_until(_mid_interval_send(dut, [*before[-1:], first], interval))
    again = dut.broadcast(name, fields)
    cleared = dut.wait_for("msg1", 3 * interval, where=lambda f: not _comm_fault(f))
    assert cleared is not None, f"bit13 still set {ms(dut.now() - again.time)} ms after a new command (4.4.4-3: cleared){while_}"
    # the next MSG1 the DUT prepares after the command (REACT_S) shows the flag clear: within one interval
    dut.record.measure("comm fault flag: first MSG1 without bit13 after a new command", ms(frame_start(dut, cleared) - again.time),
                       limit=ms(interval + REACT_S), unit="ms", clock=again.clock, error=again.error * 1000,
                       requirement="4.4.4-3")


# ------------------------------------------------------------------------------------------ 4.4.4-T, R7
#: The throttle formats tried in turn, the recommended one (4.4.16-5) first, with the factor a value is
#: sent with (RawCommand_10b carries half the throttle, doubled by the ESC: 4.4.17-2)
FORMATS = (("raw_command_12b", 1), ("raw_command_14b", 1), ("raw_command_10b", cat.THROTTLE_10B_MAX / cat.THROTTLE_MAX))


def _spin(dut, name: str, fields: dict, zero: dict, interval: float) -> tuple[list, list]:
    """MSG1 at a throttle (after the settle time), then at zero throttle again."""
    dut.throttle_stream(name, fields, STREAM_PERIOD_S)
    dut.wait(SPIN_SETTLE_S)
    spinning = dut.reports("msg1", 3 * interval)
    dut.stop_throttle()
    dut.throttle_stream(name, zero, STREAM_PERIOD_S)
    dut.wait(SPIN_SETTLE_S)
    stopped = dut.reports("msg1", 2 * interval)
    dut.stop_throttle()
    assert spinning and stopped, f"no MSG1 while the {name} stream ran"
    return spinning, stopped


@pytest.mark.requirement("4.4.4-T", "R7")
@pytest.mark.spins_motor
@pytest.mark.parametrize("throttle", [100, 1000, cat.THROTTLE_MAX])
def test_pwm_field_follows_the_throttle(dut, throttle):
    """MSG1's PWM field is the commanded throttle of the DUT's channel; with a motor the speed rises
    and bit 8 (running) is set while it runs, clear at rest; back at zero throttle PWM is 0 again.
    Commanded in RawCommand_12b; should PWM differ, the other formats are tried: a DUT that shows the
    value from one of them reads the first format wrongly (that format's own tests judge it), and
    this test is INCONCLUSIVE; from none of them, it fails."""
    s = can_throttle(dut)
    interval = interval_s(s, "msg1")
    channel = s["throttle_channel"]
    motor = dut.profile.has("motor")
    t = dut.now()
    rest = need_decoded(dut, "msg1", dut.reports("msg1", 2 * interval), t, "the PWM field")
    assert rest, "no MSG1"
    if motor and rest[-1].fields["speed"] == 0:
        assert not rest[-1].fields["status"] & Status.RUNNING, f"bit8 (running) set at rest: status 0x{rest[-1].fields['status']:04X} (R7)"
    seen = {}
    for name, factor in FORMATS:
        fields = command_for(name, channel, round(throttle * factor))
        if fields is None:
            continue
        spinning, stopped = _spin(dut, name, fields, command_for(name, channel, 0), interval)
        seen[name] = sorted({f.fields["pwm"] for f in spinning})
        if seen[name] == [throttle]:
            break
    else:
        assert seen, f"no throttle format addresses channel {channel}"
        pytest.fail(f"MSG1 PWM {seen} (per format) while channel {channel} is commanded {throttle} (4.4.4-T)")
    if name != FORMATS[0][0]:
        raise Inconclusive(f"MSG1 PWM follows {name} but not {FORMATS[0][0]} ({seen}): the DUT reads {FORMATS[0][0]} "
                           "differently (its own section's tests judge that)")
    dut.record.observe("MSG1 at throttle", spinning[-1].physical())
    assert {f.fields["pwm"] for f in stopped} == {0}, f"MSG1 PWM {[f.fields['pwm'] for f in stopped]} at zero throttle"
    if motor:
        assert all(f.fields["speed"] > 0 for f in spinning), f"speed {[f.fields['speed'] for f in spinning]} rpm at throttle {throttle}"
        status = [f.fields["status"] for f in spinning]
        assert all(st & Status.RUNNING for st in status), f"bit8 (running) clear while the motor runs: {[hex(x) for x in status]} (R7)"
