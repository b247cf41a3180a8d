"""The soak faults (``faults.SOAK``, R19): each long-run defect shows after its onset and not before.

Each scenario flies a simulated bench as a flight controller would (a RawCommand stream without a break; for the run
time a spinning motor) and watches what a soak watches (the power-up count and the report gaps, the report intervals,
this run's time, the comm-loss flag): the conforming ESC shows nothing, the faulty one nothing before its onset and
the defect after it. The onsets are moved to seconds here (``EscConfig.onsets``: simulated time is cheap, but an hour
of it is not free); one slow test flies the default onsets for an hour, which is what ``ckesc soak`` must find them in.
The proof that the ten-minute suite misses them is the self-test's (tests/harness/test_selftest.py).
"""

from __future__ import annotations

import pytest

from ckesc.emulator.config import EscConfig
from ckesc.emulator.faults import FAULTS, GLITCH_EVERY_S, RUN_TIME_TICK_S, SOAK, WARM_CLOCK_RATE, onset
from ckesc.protocol import Status

SOAK_FAULTS = sorted(n for n, f in FAULTS.items() if f.kind == SOAK)
START = 0.3  # the stream starts once the ESC has booted (first report at 250 ms)
SLOW_REPORTS = {"option": 1, "msg1_interval": 250, "msg2_interval": 250, "msg3_interval": 250}  # every 0.5 s
STREAM = 0.01  # 100 Hz; 0.19 s (just inside the comm-loss time) where hours are flown


def fly(host, until: float, *, throttle: int = 0, period: float = STREAM):
    """A RawCommand stream from now to ``until`` (lane time); every frame the ESC sends meanwhile."""
    task = host.bus.send_periodic(host.message("raw_command_14b", {"channels": [throttle, 0, 0, 0]}), period)
    frames = host.collect(until)
    task.stop()
    return frames


def gaps(frames, name: str = "msg1") -> list[tuple[float, float, int]]:
    """(time of the later report, gap, its transfer id) for each pair of consecutive ``name`` reports."""
    reps = [f for f in frames if f.name == name and f.source]
    return [(b.timestamp, round(b.timestamp - a.timestamp, 6), b.transfer_id) for a, b in zip(reps, reps[1:])]


def bench(lane, fault: str | None, onsets: dict[str, float] | None = None):
    """A booted bench with ``fault`` on, its onset moved as ``onsets`` says (as NAME=SECONDS, what
    --emulator-faults takes)."""
    entry = f"{fault}={onsets[fault]}" if fault and onsets and fault in onsets else fault
    host = lane([1], faults=[entry] if fault else [])
    host.wait_until(START)
    return host


def power_ups(host) -> int:
    return host.call("maintenance_information", {"option": 2}).fields["power_ups"]


def test_every_soak_fault_has_a_scenario():
    assert SOAK_FAULTS == sorted(SCENARIOS), "a soak fault without a scenario here, or a scenario without its fault"


def test_default_onsets_lie_beyond_the_ten_minute_suite_and_within_an_hour():
    """Every default onset is longer than the whole suite (ten minutes), so the suite cannot meet it, and at most an
    hour, so a soak of an hour does (for run_time_wraps: an hour of motor running)."""
    for name in SOAK_FAULTS:
        assert 600 < onset(name) <= 3600, f"{name}: onset {onset(name)} s"
    assert onset("run_time_wraps") == 65536 * RUN_TIME_TICK_S  # a uint16 of 50 ms ticks
    with pytest.raises(ValueError, match="only soak faults"):
        EscConfig(onsets={"answer_late": 3})
    with pytest.raises(ValueError, match="only soak faults"):
        EscConfig(faults=frozenset({"answer_late=3"}))
    moved = EscConfig(faults=frozenset({"clock_drift_warm=60", "answer_late"}))
    assert moved.faults == {"clock_drift_warm", "answer_late"} and moved.onsets == {"clock_drift_warm": 60.0}
    assert onset("clock_drift_warm", moved.onsets) == 60.0 and onset("reset_after_streaming", moved.onsets) == 1200.0


def test_a_soak_fault_switched_on_a_running_bench_takes_its_onset(lane):
    """bus.set_fault("NAME=SECONDS"): the fault on, its onset moved (here the glitch 20 s after power-up)."""
    host = bench(lane, None)
    host.bus.set_fault("comm_flag_glitch=20")
    assert host.esc(1).faults == {"comm_flag_glitch"} and host.esc(1).config.onsets == {"comm_flag_glitch": 20.0}
    frames = fly(host, 25.0)
    [at] = [f.timestamp for f in frames if f.name == "msg1" and f.fields["status"] & Status.COMM_FAULT]
    assert 20.0 <= at < 20.02, at


# ------------------------------------------------------------------------------------------------
# the scenarios: each returns what the fault changes, (before its onset, after it)


def reset_after_streaming(lane, fault):
    """A stream of 40 s with the onset at 30 s: the reset (a boot-long report gap whose MSG1 restarts its transfer
    ids; one power-up more) at 30 s of stream, not before; RAM state (an LED set with option 0) lost, the flash kept
    (report intervals written with Set Freq)."""
    host = bench(lane, fault, {fault: 30.0})
    host.call("set_freq", {"option": 1, "msg1_interval": 15, "msg2_interval": 50, "msg3_interval": 250})
    host.call("set_led", {"option": 0, "color": 4, "blink": 0})  # red, in RAM only
    t0 = host.now
    frames = fly(host, t0 + 40.0)
    resets = [(round(t - t0, 1), gap, tid) for t, gap, tid in gaps(frames) if gap > 0.0301]
    led = host.call("get_major_configuration", {"option": 0}).fields["led_color"]
    kept = {gap for _, gap, _ in gaps(frames)[-20:]}
    return resets, power_ups(host), led, kept


def test_reset_after_streaming(lane):
    assert reset_after_streaming(lane, None) == ([], 1, 4, {0.03})
    resets, ups, led, kept = reset_after_streaming(lane, "reset_after_streaming")
    [(at, gap, tid)] = resets
    assert 30.0 <= at <= 30.6 and 0.25 <= gap <= 0.3 and tid == 0, resets  # the boot, then transfer id 0
    assert (ups, led, kept) == (2, 2, {0.03}), "one power-up more; the LED back at green (RAM), the interval kept"


def test_a_stream_with_breaks_never_resets(lane):
    """Gaps longer than the comm-loss time end a stream: 12 s streams with 0.3 s breaks, three of them, never reach
    an onset of 20 s (36 s of commands in all)."""
    host = bench(lane, "reset_after_streaming", {"reset_after_streaming": 20.0})
    for _ in range(3):
        fly(host, host.now + 12.0)
        host.wait(0.3)
    assert power_ups(host) == 1


def clock_drift_warm(lane, fault):
    """MSG1 and MSG2 gaps over 40 s powered with the onset at 20 s; then after a power cycle (cold again)."""
    host = bench(lane, fault, {fault: 20.0})
    frames = fly(host, 40.0)
    out = {}
    for name in ("msg1", "msg2"):
        out[name] = (mean_gap(frames, name, 0, 20.0), mean_gap(frames, name, 20.2, 40.0))
    host.bus.power_cycle(0.5)
    out["cold"] = mean_gap(fly(host, host.now + 5.0), "msg1", host.now - 4.0, host.now)
    return out


def mean_gap(frames, name: str, start: float, end: float) -> float:
    """The mean gap of ``name`` reports heard from ``start`` to ``end`` (R9's measure: the bus may delay one report
    behind another, the mean stays)."""
    stamps = [f.timestamp for f in frames if f.name == name and f.source and start <= f.timestamp <= end]
    return round((stamps[-1] - stamps[0]) / (len(stamps) - 1), 5)


def test_clock_drift_warm(lane):
    off = clock_drift_warm(lane, None)
    assert off == {"msg1": (0.02, 0.02), "msg2": (0.1, 0.1), "cold": 0.02}
    on = clock_drift_warm(lane, "clock_drift_warm")
    assert on["msg1"][0] == 0.02 and on["msg2"][0] == 0.1, "fast before its onset"
    assert on["msg1"][1] == round(0.02 / WARM_CLOCK_RATE, 5) == 0.01875
    assert on["msg2"][1] == round(0.1 / WARM_CLOCK_RATE, 5)
    assert on["cold"] == 0.02, "a power cycle cools the board: its clock is right again"


def run_times(lane, fault):
    """241 option 1's run time after 8 s and 14 s of motor running, with the wrap moved to 10 s (200 ticks)."""
    host = bench(lane, fault, {fault: 10.0})
    t0 = host.now
    fly(host, t0 + 8.0, throttle=500)
    task = host.bus.send_periodic(host.message("raw_command_14b", {"channels": [500, 0, 0, 0]}), STREAM)
    before = host.call("maintenance_information", {"option": 1}).fields["run_time"]
    host.wait_until(t0 + 14.0)
    after = host.call("maintenance_information", {"option": 1}).fields["run_time"]
    task.stop()
    return before, after


def test_run_time_wraps(lane):
    assert run_times(lane, None) == (8, 14)
    assert run_times(lane, "run_time_wraps") == (8, 4), "after 10 s of running this run's time starts again at 0"


def glitches(lane, fault, *, until: float, onsets=None, period: float = STREAM, slow_reports: bool = False):
    """The times of the MSG1s carrying the comm-loss flag while the stream runs (from 0.3 s to ``until``)."""
    host = bench(lane, fault, onsets)
    if slow_reports:
        host.call("set_freq", SLOW_REPORTS)
    frames = fly(host, until, period=period)
    return [round(f.timestamp, 2) for f in frames if f.name == "msg1" and f.fields["status"] & Status.COMM_FAULT]


def test_comm_flag_glitch(lane):
    """One MSG1 with the flag, at the first MSG1 from the onset (20 s here) on; the stream runs without a break."""
    assert glitches(lane, None, until=40.0) == []
    [at] = glitches(lane, "comm_flag_glitch", until=40.0, onsets={"comm_flag_glitch": 20.0})
    assert 20.0 <= at < 20.02, at  # the first MSG1 from 20 s on (every 20 ms from 0.25 s: 20.01)


@pytest.mark.slow
def test_comm_flag_glitch_comes_once_an_hour(lane):
    """Over two hours (a sparse stream: a command every 0.19 s, within the comm-loss time; reports every 0.5 s) the
    glitches come at 20 s and an hour later, and only then."""
    found = glitches(lane, "comm_flag_glitch", until=GLITCH_EVERY_S + 60.0, onsets={"comm_flag_glitch": 20.0},
                     period=0.19, slow_reports=True)
    assert len(found) == 2 and 20.0 <= found[0] <= 20.5 and 3620.0 <= found[1] <= 3620.5, found


SCENARIOS = {"reset_after_streaming": test_reset_after_streaming, "clock_drift_warm": test_clock_drift_warm,
             "run_time_wraps": test_run_time_wraps, "comm_flag_glitch": test_comm_flag_glitch}


# ------------------------------------------------------------------------------------------------
# an hour at the default onsets: what a soak of an hour meets


@pytest.mark.slow
@pytest.mark.parametrize("fault", SOAK_FAULTS)
def test_an_hour_of_flight_shows_each_fault_at_its_default_onset(lane, fault):
    """An hour of a sparse stream (every 0.19 s; the motor spinning; reports every 0.5 s) at the default onsets: the
    defect shows at its onset and not before."""
    host = bench(lane, fault)
    host.call("set_freq", SLOW_REPORTS)
    hour = 3600.0
    task = host.bus.send_periodic(host.message("raw_command_14b", {"channels": [300, 0, 0, 0]}), 0.19)
    frames = host.collect(hour - 60)
    opt1 = host.call("maintenance_information", {"option": 1}).fields["run_time"]
    task.stop()
    if fault == "reset_after_streaming":  # the MSG1 transfer ids restart at each reset (20 min, and 20 min again)
        reps = [f for f in frames if f.name == "msg1"]
        restarts = [b.timestamp for a, b in zip(reps, reps[1:]) if b.transfer_id != (a.transfer_id + 1) % 32]
        assert len(restarts) == 2 and START + onset(fault) < restarts[0] < START + onset(fault) + 1, restarts
        assert power_ups(host) == 3
    elif fault == "clock_drift_warm":
        assert mean_gap(frames, "msg1", 0, onset(fault)) == 0.5
        assert mean_gap(frames, "msg1", onset(fault) + 1, hour) == round(0.5 / WARM_CLOCK_RATE, 5)
    elif fault == "run_time_wraps":
        ran = host.esc(1).run_time
        assert ran > onset(fault) and opt1 == int(ran - onset(fault)), (ran, opt1)  # wrapped once, counting again
    else:
        found = [f.timestamp for f in frames if f.name == "msg1" and f.fields["status"] & Status.COMM_FAULT]
        assert len(found) == 1 and onset(fault) <= found[0] < onset(fault) + 0.51, found
