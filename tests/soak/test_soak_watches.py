"""The soak's watches (sans-IO), fed hand-made frame sequences: silent on a faultless ESC's, and each finds its own
defect, citing its requirement, with the frames around it. Also R19's reset judgements."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol import judgements as jd
from ckesc.protocol.frame import WireFrame, encode
from ckesc.protocol.histogram import Histogram
from ckesc.protocol.ids import Kind
from ckesc.soak.monitor import Monitor
from ckesc.soak.watch import AFTER_FRAMES, MAX_FINDINGS_PER_WATCH, WatchConfig

HOST, NODE = 0, 1
MSG1, MSG2, MSG3 = 0.020, 0.100, 0.500
CFG = WatchConfig(node_id=NODE, host_node=HOST, intervals={"msg1": MSG1, "msg2": MSG2, "msg3": MSG3})
SETTINGS = {"direction": 0, "throttle_source": 0, "throttle_channel": 1, "led_blink": 0, "led_color": 2,
            "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250, "reserved": 0}


@dataclass
class Esc:
    """A faultless ESC's side of a soak, frame by frame, and the defects a test switches on."""

    msg1_interval: float = MSG1
    reset_at: float | None = None  # MSG1 stops for 300 ms and its transfer ids start again at 0
    reset_all: bool = False  # ... and MSG2 and MSG3 with it, each on a grid from the restart
    counting_on: tuple[str, ...] = ()  # ... these but for their counters, which go on by one (one time in 32)
    back_at: float = 0.303  # when MSG2 and MSG3 come back after the reset (MSG1 at 0.301)
    held: bool = False  # the host alone: its stream waits in its queue through the reset, 10 frames come after MSG1
    flag_at: float | None = None  # one MSG1 shows the comm-loss flag while the stream runs
    answer_delay: float = 0.0025
    no_answer_at: float | None = None
    power_ups: list[int] = field(default_factory=lambda: [7])
    run_times: list[int] = field(default_factory=lambda: [0])
    led_after: float | None = None
    stops_at: dict[str, float] = field(default_factory=dict)  # a report (msg1..3) stops for good here
    extra: list[WireFrame] = field(default_factory=list)

    def frames(self, seconds: float) -> list[WireFrame]:
        out: list[WireFrame] = []
        tid = {"stream": 0, "msg1": 0, "msg2": 0, "msg3": 0, "q": 0, "241": 0, "242": 0}

        def nxt(key: str) -> int:
            tid[key] = (tid[key] + 1) % 32
            return (tid[key] - 1) % 32

        t, queued = 0.0, 0
        while t < seconds:  # the host's stream at 50 Hz
            if self.held and self.reset_at is not None and self.reset_at < t < self.reset_at + 0.301:
                queued += 1  # (no acknowledgement: the frame waits, the 11th and later are lost)
            else:
                for i in range(min(queued, 10)):  # the queue at the ESC's first MSG1, back to back
                    out.append(encode("raw_command_14b", {"channels": [0] * 4}, source=HOST, transfer_id=nxt("stream"),
                                      timestamp=self.reset_at + 0.3012 + 0.00025 * i))  # type: ignore[operator]
                queued = 0
                out.append(encode("raw_command_14b", {"channels": [0] * 4}, source=HOST, transfer_id=nxt("stream"),
                                  timestamp=t))
            t = round(t + 0.02, 9)
        t, k = 0.001, 0
        while t < min(seconds, self.stops_at.get("msg1", seconds)):
            if self.reset_at is not None and self.reset_at <= t < self.reset_at + 0.3:
                t = round(t + self.msg1_interval, 9)
                if t >= self.reset_at + 0.3:
                    tid["msg1"] = 0
                continue
            status = cat.Status.COMM_FAULT if self.flag_at is not None and abs(t - self.flag_at) < 0.01 else 0
            out.append(encode("msg1", {"speed": 0, "pwm": 0, "status": int(status)}, source=NODE,
                              transfer_id=nxt("msg1"), timestamp=t))
            k += 1
            t = round(0.001 + k * self.msg1_interval, 9)
        for name, interval, fields in (("msg2", MSG2, {"voltage": 1200, "current": 0, "temperature": 30}),
                                       ("msg3", MSG3, {"mos_t": 30, "cap_t": 30, "motor_t": 30, "mcu_t": 30})):
            n, origin = 0, 0.003
            while (t := origin + n * interval) < min(seconds, self.stops_at.get(name, seconds)):
                if self.reset_all and self.reset_at is not None and origin < self.reset_at <= t:
                    n, origin = 0, self.reset_at + self.back_at
                    tid[name] = tid[name] if name in self.counting_on else 0
                    continue
                out.append(encode(name, fields, source=NODE, transfer_id=nxt(name), timestamp=t))
                n += 1
        s = 0
        while (t := 0.005 + s) < seconds:  # GET_ESC_ID once a second, and its answer
            q = nxt("q")
            out.append(encode("get_esc_id", {"option": 0}, source=HOST, transfer_id=q, layout="query", timestamp=t))
            if self.no_answer_at is None or abs(t - self.no_answer_at) > 0.5:
                out.append(encode("get_esc_id", {"node_id": NODE, "throttle_channel": 1}, source=NODE, transfer_id=q,
                                  layout="reply", timestamp=t + self.answer_delay))
            s += 1
        r = 0
        while (t := 2.5 + r * 5.0) < seconds:  # 241 options 1 and 2 in turn, and 242 every 20 s
            option = 1 + r % 2
            q = nxt("241")
            out.append(encode("maintenance_information", {"option": option}, source=HOST, destination=NODE,
                              transfer_id=q, timestamp=t))
            if option == 1:
                value = self.run_times[min(r // 2, len(self.run_times) - 1)]
                answer = {"run_time": value, "runs": 0, "info_7": 1}
            else:
                value = self.power_ups[min(r // 2, len(self.power_ups) - 1)]
                answer = {"power_ups": value, "stops": 0, "fault_code": 0, "option": 2}
            out.append(encode("maintenance_information", answer, kind=Kind.RESPONSE, source=NODE, destination=HOST,
                              transfer_id=q, layout=f"response_option_{option}", timestamp=t + 0.004))
            if r % 4 == 0:
                q = nxt("242")
                out.append(encode("get_major_configuration", {"option": 0}, source=HOST, destination=NODE,
                                  transfer_id=q, timestamp=t + 0.5))
                led = 4 if self.led_after is not None and t > self.led_after else SETTINGS["led_color"]
                out.append(encode("get_major_configuration", {**SETTINGS, "led_color": led}, kind=Kind.RESPONSE,
                                  source=NODE, destination=HOST, transfer_id=q, timestamp=t + 0.504))
            r += 1
        out += self.extra
        return sorted(out, key=lambda w: w.timestamp)


def watch(esc: Esc, seconds: float = 65.0) -> Monitor:
    monitor = Monitor(CFG, t0=0.0)
    for frame in esc.frames(seconds):
        monitor.feed(frame)
    monitor.close(seconds)
    return monitor


def only(monitor: Monitor, name: str) -> list:
    others = [f.line() for f in monitor.findings if f.watch != name]
    assert not others, others
    mine = [f for f in monitor.findings if f.watch == name]
    assert mine, f"{name} found nothing"
    return mine


def test_a_faultless_esc_gives_no_finding_and_every_watch_judged():
    m = watch(Esc())
    assert [f.line() for f in m.findings] == []
    assert m.intervals.trials == 3 * 2  # MSG1..3 in the whole minute and in the last 5 s (enough gaps)
    assert m.intervals.series["msg1"] == [pytest.approx(20.0), pytest.approx(20.0)]
    assert m.answers.trials == 65 and m.answers.delays.n == 65
    assert m.resets.reads == {"power_ups": 6, "run_time": 7} and m.settings.trials == 4
    assert m.comm.trials > 3000


def test_a_report_interval_off_by_more_than_the_scheduling_tolerance_breaks_r9_in_every_minute():
    found = only(watch(Esc(msg1_interval=MSG1 + 1.5 * jd.SCHEDULING_TOLERANCE_S)), "report intervals")
    assert [f.rules for f in found] == [("R9", "R19")] * 2
    assert "msg1 every 21.500 ms" in found[0].message and found[0].t == pytest.approx(60.0)
    assert not watch(Esc(msg1_interval=MSG1 + 0.5 * jd.SCHEDULING_TOLERANCE_S), 61.0).findings


def test_a_reset_shows_as_a_report_gap_with_a_transfer_id_restart():
    m = watch(Esc(reset_at=30.0))
    found = [f for f in m.findings if f.watch == "resets"]
    assert len(found) == 1 and found[0].rules == ("R19", "R17") and "started again" in found[0].message
    assert found[0].t == pytest.approx(30.3, abs=0.03)
    assert len(found[0].before) > 10 and len(found[0].after) == AFTER_FRAMES  # the frames around it


def test_a_reset_is_found_once_as_a_reset_and_its_restart_gaps_leave_the_minutes_mean():
    """Every report restarts with the ESC (MSG3's gap across it 800 ms, not 500): the resets watch finds it once (the
    other reports' gaps counted as its signs), and the minute's MSG3 mean leaves out the gaps R9a leaves out (to and from the first report after the restart), so it
    is no R9 finding as well; the minute is still judged, on the gaps before and after."""
    m = watch(Esc(reset_at=30.0, reset_all=True))
    assert [f.watch for f in m.findings] == ["resets"], [f.line() for f in m.findings]
    assert m.findings[0].message.startswith("msg1 stopped") and m.resets.events == 1
    assert m.resets.statistics()["signs_of_resets_found"] == 2  # MSG2's and MSG3's gaps: the same reset
    assert m.intervals.series["msg3"][0] == pytest.approx(500.0) and m.intervals.trials == 3 * 2
    late = watch(Esc(reset_at=30.0, reset_all=True, msg1_interval=MSG1 + 1.5 * jd.SCHEDULING_TOLERANCE_S))
    assert [f.watch for f in late.findings if "msg1 every" in f.message] == ["report intervals"] * 2  # still judged


@pytest.mark.parametrize("seconds, stops_at", [(90.0, 70.0), (65.0, 55.0), (120.0, 100.0), (90.0, 89.0)])
def test_a_report_that_stops_before_the_run_ends_is_found(seconds, stops_at):
    """A report that stops inside the run's last minute, whole or partial, is found at the run's end (R9, R19): its
    silence since its last report is longer than a report may be absent even across a restart. Before, the last
    minute judged only the gaps heard in it, and a partial minute silent throughout was not judged at all."""
    m = watch(Esc(stops_at={"msg2": stops_at}), seconds)
    found = only(m, "report intervals")
    assert len(found) == 1 and found[0].rules == ("R9", "R19"), [f.line() for f in found]
    assert "msg2" in found[0].message and found[0].t == pytest.approx(seconds, abs=0.03), found[0].line()
    assert m.intervals.events <= m.intervals.trials


def test_a_report_stopped_for_minutes_is_found_once_a_minute_not_again_at_the_end():
    found = only(watch(Esc(stops_at={"msg3": 50.0}), 200.0), "report intervals")
    assert [f.message.split(" (")[0] for f in found] == ["no msg3 in minute 2", "no msg3 in minute 3"]


@pytest.mark.parametrize("seconds", [60.0, 90.0, 90.0005, 90.02])
def test_the_runs_end_cuts_no_report_short(seconds):
    """The host's stop is not the ESC's: reading stops at the run's end, however close to it each report's last
    one came, and a report not due yet is no silence."""
    m = watch(Esc(), seconds)
    assert [f.line() for f in m.findings] == []


def test_a_silence_after_the_bench_stopped_delivering_frames_is_not_the_escs():
    """The run's end is judged as far as the bus was heard: when the bench failed and delivered nothing more (an
    adapter gone), the run's end time comes later than its last frame, and the silence between is the bench's."""
    m = Monitor(CFG, t0=0.0)
    for frame in Esc().frames(80.0):
        m.feed(frame)
    m.close(90.0)
    assert [f.line() for f in m.findings] == []


@pytest.mark.parametrize("back_at", [0.303, 0.2995])  # MSG3 back after MSG1 shows the reset, or before it
def test_a_report_whose_counter_goes_on_across_a_reset_restarts_with_it(back_at):
    """MSG3's counter goes on by one across the reset (as one in 32 would by chance): it shows no restart of its own,
    but MSG1's gap shows the reset, and MSG3's gaps across it leave the minute's mean all the same."""
    m = watch(Esc(reset_at=30.0, reset_all=True, counting_on=("msg3",), back_at=back_at))
    assert [f.watch for f in m.findings] == ["resets"], [f.line() for f in m.findings]
    assert m.intervals.series["msg3"][0] == pytest.approx(500.0)


@pytest.mark.parametrize("esc, words", [
    (Esc(run_times=[100, 110, 3]), "went back from 110 s to 3 s"),
    (Esc(run_times=[100, 110, 500]), "jumped from 110 s to 500 s"),
])
def test_241_shows_a_reset(esc, words):
    found = only(watch(esc), "resets")
    assert len(found) == 1 and words in found[0].message


def test_the_power_up_count_shows_a_reset_across_a_silence_as_the_bus_rules_read_it():
    """The soak reads a reset as the bus rules do (one reader, #35): a power-up count grown across a silence of the
    ESC as long as a boot takes is a sign of the reset (counted with the report gaps that show it first); one grown
    while the ESC never fell silent counts something else (4.4.27-T's tests judge what), not a reset. The soak's own
    reading, any growth a reset, lost: it found the count grown with the ESC reporting all along."""
    assert not watch(Esc(power_ups=[7, 7, 8])).findings
    m = watch(Esc(reset_at=30.0, reset_all=True, power_ups=[7, 7, 7, 8]))  # read at 27.5 and 37.5 s
    assert [f.watch for f in m.findings] == ["resets"], [f.line() for f in m.findings]
    assert m.resets.statistics()["signs_of_resets_found"] == 3 and m.resets.statistics()["power_ups"] == 8


def test_the_run_time_may_stand_still_or_count_with_time():
    assert not watch(Esc(run_times=[100, 100, 110, 120]), 40.0).findings  # 10 s between two reads of option 1


def test_a_reset_while_the_host_is_alone_is_a_reset_and_no_comm_flag_glitch():
    """The ESC reboots and nobody acknowledges the host's stream meanwhile: the bus carries no command for 300 ms and
    the ESC's first MSG1 after it, without the flag, comes before the commands held for it. Its comm watchdog restarted
    with it: that MSG1 is no glitch (R8 counts from the restart), and the reset is found once."""
    m = watch(Esc(reset_at=30.0, held=True))
    assert [f.watch for f in m.findings] == ["resets"], [f.line() for f in m.findings]
    assert m.rules.longest_command_gap > 0.3  # (the stream's gap is there: a watch reading it alone would flag it)


def test_the_comm_flag_while_the_stream_runs_is_a_glitch():
    found = only(watch(Esc(flag_at=40.0)), "comm flag")
    assert len(found) == 1 and found[0].rules == ("R8", "R19") and "shows the comm-loss flag" in found[0].message


def test_an_answer_our_own_stream_delayed_is_not_late():
    """An answer at the end of its slot, pushed past it by one of the host's stream frames (highest priority) queued
    ahead of it, is the bench's traffic, not the DUT's lateness; two frames' worth past it is the DUT's."""
    from ckesc.protocol.frame import frame_bits

    slot_end = 2 * cat.ANSWER_SLOT_S  # node 1's slot ends at 4 ms
    one = frame_bits(8) / CFG.bitrate
    assert not watch(Esc(answer_delay=slot_end + one / 2), 3.0).findings
    found = only(watch(Esc(answer_delay=slot_end + 2 * one), 3.0), "GET_ESC_ID answers")
    assert "R2" in found[0].rules


def test_late_and_missing_answers():
    found = only(watch(Esc(answer_delay=0.080), 10.0), "GET_ESC_ID answers")
    assert len(found) == 10 and set(found[0].rules) == {"R2", "4.4.3-4"}
    m = watch(Esc(no_answer_at=20.005), 30.0)
    found = only(m, "GET_ESC_ID answers")
    assert len(found) == 1 and "no answer" in found[0].message and found[0].t == pytest.approx(21.005)
    assert m.answers.missing == 1


def test_a_changed_setting():
    found = only(watch(Esc(led_after=20.0)), "settings")
    assert len(found) == 1 and "led_color 2 -> 4" in found[0].message


def test_frames_the_esc_should_not_send():
    garbled = WireFrame(encode("msg1", {"speed": 0, "pwm": 0, "status": 0}, source=NODE).arbitration_id,
                        bytes(6) + b"\xE0", 31.0)  # toggle bit set in a single frame's tail (F2)
    reply = encode("get_esc_id", {"node_id": NODE, "throttle_channel": 1}, source=NODE, transfer_id=3, layout="reply",
                   timestamp=32.5)  # an answer to no query
    m = watch(Esc(extra=[garbled, reply]), 40.0)
    found = only(m, "unexpected frames")
    assert [f.rules for f in found] == [("F2",), ("R1",)], [f.line() for f in found]


FC = 10


def fc_query(t: float, tid: int) -> WireFrame:
    return encode("get_esc_id", {"option": 0}, source=FC, transfer_id=tid, layout="query", timestamp=t)


def esc_reply(t: float, tid: int) -> WireFrame:
    return encode("get_esc_id", {"node_id": NODE, "throttle_channel": 1}, source=NODE, transfer_id=tid,
                  layout="reply", timestamp=t)


def test_other_nodes_queries_and_their_answers_are_not_the_hosts():
    """A flight controller at node 10 asks GET_ESC_ID too (R17's foreign traffic): the ESC's replies to it answer no
    query of the host's, yet they are no R1 finding, nor the host's answer. One asked 2 ms before the host's is
    answered first: that reply may answer either query (not judged), the next one answers the host's (each query is
    answered once, in order); a reply long after every query still answers none."""
    extra = [f for s in range(10) for f in (fc_query(s + 0.633, s), esc_reply(s + 0.6355, s))]
    extra += [fc_query(5.003, 20), esc_reply(5.0055, 20)]  # just before the host's query at 5.005 (answered at 5.0075)
    m = watch(Esc(extra=extra), 10.0)
    assert [f.line() for f in m.findings] == []
    assert m.answers.foreign_queries == 11 and m.answers.foreign_answers == 10 and m.answers.trials == 10
    assert m.answers.ambiguous == 1
    found = only(watch(Esc(extra=[fc_query(3.2, 1), esc_reply(3.5, 1)]), 10.0), "unexpected frames")
    assert [f.rules for f in found] == [("R1",)]


def test_a_flight_controllers_query_the_esc_does_not_answer_does_not_take_the_hosts_answer():
    """The ESC need not answer another host's query (F6): one asked 2 ms before the host's and left unanswered does
    not take the host's answer, which then may answer either (not judged), and the host's query is not missing (the
    first-in-first-out reading gave the reply to the flight controller and found the host's query unanswered)."""
    extra = [fc_query(s + 0.003, s) for s in range(10)]
    m = watch(Esc(extra=extra), 10.0)
    assert [f.line() for f in m.findings] == []
    assert m.answers.missing == 0 and m.answers.ambiguous == 10 and m.answers.foreign_answers == 0


def test_a_second_reply_to_a_flight_controllers_query_answers_none():
    """Each query is answered once: a second reply 1 ms after the ESC's answer to the flight controller's query
    answers none (R1), though the query came within 64 ms of it (the reading "any other node's query in the 64 ms
    before" let it pass)."""
    extra = [fc_query(3.5, 1), esc_reply(3.5025, 1), esc_reply(3.5035, 2)]
    found = only(watch(Esc(extra=extra), 10.0), "unexpected frames")
    assert [f.rules for f in found] == [("R1",)]


def test_findings_are_bounded():
    m = watch(Esc(answer_delay=0.080), 60.0)
    assert len(m.findings) == MAX_FINDINGS_PER_WATCH and m.count == 60 and m.dropped == 60 - MAX_FINDINGS_PER_WATCH


def test_the_histogram_streams():
    h = Histogram(0.001, 10)
    for v in (0.0005, 0.0015, 0.0025, 0.0035, 0.5):
        h.add(v)
    doc = h.to_json()
    assert doc["count"] == 5 and doc["min_ms"] == 0.5 and doc["max_ms"] == 500.0 and doc["bins"][-1] == 1
    assert h.percentile(50) == pytest.approx(0.003) and h.percentile(100) == 0.5


# ------------------------------------------------------------------------------------------ R19's judgements
def test_r19_power_ups_wraps_and_grows():
    assert jd.r19_power_ups(7, 7) is None and jd.r19_power_ups(0xFFFF, 0xFFFF) is None
    assert jd.r19_power_ups(7, 8).rule == "R19" and jd.r19_power_ups(0xFFFF, 0).what == "power_ups"


def test_r19_run_time_back_jump_and_resolution():
    assert jd.r19_run_time(10, 9, 5.0) is not None
    assert jd.r19_run_time(10, 16, 5.0) is None  # two whole-second reads 5 s apart differ by up to 6
    assert jd.r19_run_time(10, 17, 5.0) is not None
    assert jd.r19_run_time(10, 17, 5.0, error=1.0) is None
    assert jd.r19_run_time(10, 10, 500.0) is None  # standing still: the motor does not run


def test_r19_report_restart():
    i = MSG1
    assert jd.r19_report_restart(i, i, jd.f3_step(5, 6)) is None
    assert jd.r19_report_restart(0.3, i, jd.f3_step(5, 0)) is not None  # a gap and a counter from 0
    assert jd.r19_report_restart(0.3, i, jd.f3_step(5, 6)) is None  # late, counting on: R9's
    assert jd.r19_report_restart(3 * i, i, jd.f3_step(5, 8)) is None  # two lost on the bus
    assert jd.r19_report_restart(1.2 * i, i, jd.f3_step(5, 0)) is None  # within the restart limit: not a gap


@pytest.mark.parametrize("stamp_lag, answer_delay, late_by", [
    (0.0105, 0.0125, None),  # the bench stamped the host's frames 10.5 ms late: an answer 12.5 ms late is the bench's
    (0.0001, 0.0125, "R2"),  # the bench stamped them at once: the same answer is the DUT's
    (0.0105, 0.0300, "R2"),  # the bench's lag does not excuse more than itself
])
def test_an_answer_as_late_as_the_bench_stamped_the_hosts_own_frames_is_not_the_dut(stamp_lag, answer_delay, late_by):
    """A loaded bench (a socketcand hub on a busy machine) stamps frames late: the host's own frames show by how much
    (their echo's stamp against the host's send). An answer late by no more than that is not judged (not a trial, not
    a finding, counted); one later than that, or with the host's frames stamped on time, is the DUT's."""
    m = Monitor(CFG, t0=0.0)

    def host(name: str, fields: dict, sent: float, stamp: float, **kw) -> WireFrame:
        wire = encode(name, fields, source=HOST, transfer_id=int(sent * 1000) % 32, timestamp=stamp, **kw)
        m.sent(wire.arbitration_id, wire.data, sent)
        return wire

    query = host("get_esc_id", {"option": 0}, 1.0, 1.0, layout="query")
    stream = host("raw_command_14b", {"channels": [0] * 4}, 1.002, 1.002 + stamp_lag)
    answer = encode("get_esc_id", {"node_id": NODE, "throttle_channel": 1}, source=NODE, transfer_id=0, layout="reply",
                    timestamp=1.0 + answer_delay)
    after = encode("msg1", {"speed": 0, "pwm": 0, "status": 0}, source=NODE, transfer_id=0, timestamp=1.05)
    # the hub read the answer and the host's late frame in one go: the answer first, the frame stamped with it after
    for frame in sorted([query, answer, stream], key=lambda w: w.timestamp) + [after]:
        m.feed(frame)
    m.close(1.1)
    found = [f for f in m.findings if f.watch == "GET_ESC_ID answers"]
    stats = m.answers.statistics()
    if late_by is None:
        assert not found and m.answers.trials == 0 and stats["not_judged_late_by_the_bench"] == 1
    else:
        assert len(found) == 1 and late_by in found[0].rules and m.answers.trials == 1
    assert m.bench_lag.n == 2 and m.bench_lag.hi == pytest.approx(stamp_lag)
