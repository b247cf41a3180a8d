"""ckesc explore plays the bus as CAN hardware makes it (R20, issue #36 item 4): a bus short and a lone-host power cycle.

A ``short`` step shorts the bus (CANH to CANL) through the bench's bus-fault control for one of
:data:`~ckesc.explore.actions.BUS_SHORTS`; the judge holds the ESC to R20's recovery bound after it (its MSG1 again
within bus-off recovery + two MSG1 intervals + the bench's error), leaves what it sends in between OBSERVE (the reports
it held, their transfer-id sequence) and cites R20 for what follows (a reset shows in 241's counters and the reader's
R19). An ``alone`` step cycles the power with the host sending while the ESC is off: the simulated lane's CAN model
holds the frames until the ESC's controller is up, the ESC takes them at its boot (R20 allows it), and their answers
are OBSERVE. Here: both bus-off faults found from a fixed seed, the shrunk program keeping its short; the faultless
emulator and the conforming variants (which take held frames at boot, and recover without their transfer-id
sequence) give no finding, with bus steps drawn; the steps are drawn only when asked for, where the lane can play them.
"""

from __future__ import annotations

import pytest

from ckesc.bench import sim_lane
from ckesc.emulator import variants
from ckesc.emulator.faults import FAULTS
from ckesc.explore.actions import BUS_SHORTS, Action, ProgramBench, families, program_from_json, program_json
from ckesc.explore.engine import explore
from ckesc.explore.runner import Session
from ckesc.explore.selftest import find_faults
from ckesc.protocol import catalogue as cat
from ckesc.protocol.judgements import r20_bound_s

FAULTS_R20 = ("no_busoff_recovery", "busoff_recovery_resets")
SHORT = Action("short", seconds=0.3)
#: a stream, a short past what the ESC's mailboxes hold (its first reports after recovery skip transfer ids), a wait
#: long enough for the comm flag to show, then the stream goes on (its next command clears the flag)
STREAMED_SHORT = [Action("stream", "raw_command_14b"), Action("wait", seconds=0.3), Action("short", seconds=max(BUS_SHORTS)),
                  Action("wait", seconds=0.6)]
#: a lone-host power cycle: a settings write (which shows when taken: MSG1 every 40 ms) and a GET_ESC_ID query held
WRITE = {"option": 1, "msg1_interval": 20, "msg2_interval": 50, "msg3_interval": 250}
ALONE = Action("alone", fields={"frames": [{"name": "set_freq", "fields": WRITE},
                                           {"name": "get_esc_id", "fields": {"option": 0}}]})


def _run(options: dict, program: list[Action]):
    session = Session(options, bus=True)
    try:
        return session.run(program)
    finally:
        session.close()


def _texts(findings) -> str:
    return "\n".join(f.text() for f in findings)


def test_the_shorts_bracket_r20s_bound_and_r8s_timeout():
    """The durations drawn: one shorter than R20's bound at the catalogue's default MSG1 interval, one about it, one
    past R8's timeout, one past what the ESC's mailboxes hold (the figures the actions' comment gives)."""
    default = cat.DEFAULT_REPORT_INTERVALS["msg1_interval"] * cat.INTERVAL_UNIT_S
    bound = r20_bound_s(default, bitrate=cat.DEFAULT_BITRATE)
    assert min(BUS_SHORTS) < bound < sorted(BUS_SHORTS)[2]
    assert any(abs(t - bound) < 0.01 for t in BUS_SHORTS)
    assert max(BUS_SHORTS) > cat.COMM_LOSS_TIMEOUT_S


def test_bus_steps_are_drawn_only_when_asked_and_where_the_lane_can_play_them(monkeypatch):
    assert "bus" in families(ProgramBench(shorts=True)) and "bus" not in families(ProgramBench())
    for asked in (True, False):
        session = Session({}, bus=asked)
        try:
            assert session.bench.shorts is asked and session.bench.alone is asked and not session.bus_note
        finally:
            session.close()
    # a lane without the CAN model has no bus-fault control: no short drawn, said so; a replayed one skipped, said so
    monkeypatch.setattr(sim_lane, "SIM_CAN", {"ack": False, "txqueuelen": None})
    session = Session({}, bus=True)
    try:
        assert not session.bench.shorts and session.bench.alone and "no bus-fault control" in session.bus_note
        outcome = session.run([SHORT])
    finally:
        session.close()
    assert not outcome.findings and len(outcome.skipped) == 1 and "no bus-fault control" in outcome.skipped[0]


def test_a_replay_file_keeps_the_bus_steps():
    program = [SHORT, ALONE]
    assert program_from_json(program_json(program)) == program
    assert "0.3 s" in SHORT.describe() and "set_freq" in ALONE.describe()


def test_a_short_on_the_faultless_emulator_is_recovered_without_a_finding():
    """Nothing found across a short of a streamed ESC, though it really was silenced, came back with its reports'
    transfer-id sequence broken (its mailboxes dropped some: R20 leaves it OBSERVE) and its comm flag raised (R8),
    which the next command cleared."""
    outcome = _run({}, STREAMED_SHORT)
    assert not outcome.findings, _texts(outcome.findings)
    start, end = (outcome.t0 + t for t in outcome.steps[2])
    msg1 = [f for f in outcome.dut if f.name == "msg1"]
    assert not [f for f in msg1 if start + 0.05 < f.timestamp < start + max(BUS_SHORTS)], "the ESC was not silenced"
    after = [f for f in outcome.dut if start < f.timestamp < end and f.name in cat.REPORT_FRAMES]
    skipped = {f.name for a, f in zip(after, after[1:]) if a.name == f.name and (a.transfer_id + 1) % 32 != f.transfer_id}
    assert skipped, "the ESC's reports kept their transfer-id sequence across an 0.8 s short"
    flags = [bool(f.fields["status"] & cat.Status.COMM_FAULT) for f in msg1 if start < f.timestamp <= end]
    assert True in flags, "the comm flag did not rise through the short"
    wait = [bool(f.fields["status"] & cat.Status.COMM_FAULT) for f in msg1 if outcome.t0 + outcome.steps[3][0] + 0.05
            < f.timestamp <= outcome.t0 + outcome.steps[3][1]]
    assert wait and not any(wait), "the stream going on after the short did not clear the comm flag"


def test_a_short_under_a_foreign_load_takes_the_load_off_for_it():
    """A load of half the bus (R18) is off while the bus is shorted and back once the reports settled: its backlog
    would hold the ESC's reports back past R20's bound (which says nothing of a loaded bus). Nothing found."""
    program = [Action("load", fields={"share": 0.5, "priority": "high"}), *STREAMED_SHORT]
    session = Session({}, bus=True, load=True)
    try:
        outcome = session.run(program)
    finally:
        session.close()
    assert not outcome.findings, _texts(outcome.findings)
    short = next(i for i, a in enumerate(program) if a.op == "short")
    wait = outcome.t0 + outcome.steps[short + 1][0], outcome.t0 + outcome.steps[short + 1][1]
    foreign = [m for m in outcome.messages if m.is_extended_id and (m.arbitration_id & 0x7F) not in (0, 1)]
    assert [m for m in foreign if wait[0] <= m.timestamp <= wait[1]], "the load was not put back after the short"


@pytest.mark.parametrize("fault", FAULTS_R20)
def test_each_bus_off_fault_shows_on_one_short_citing_r20(fault):
    session = Session({"emulator_faults": fault}, bus=True)
    try:
        findings = session.run([SHORT]).findings
        quiet = session.run([Action("wait", seconds=SHORT.seconds)]).findings  # the short removed: nothing shows
    finally:
        session.close()
    assert findings and all("R20-recovery" in f.requirements for f in findings), _texts(findings)
    assert not quiet, _texts(quiet)


def test_explore_finds_no_busoff_recovery_and_its_shrunk_program_keeps_the_short():
    """From seed 1 (found after 3 programs), shrunk to its end on the faulty bench: the short is needed."""
    session = Session({"emulator_faults": "no_busoff_recovery"}, bus=True)
    try:
        found, stats = explore(session, seed=1, database=None, budget_s=300, max_programs=10, stop_at_first=True)
        assert found, f"nothing found in {stats.programs} programs ({stats.line()})"
        first = found[0]
        assert set(first.finding.requirements) & set(FAULTS["no_busoff_recovery"].rules), first.finding.text()
        assert not first.cut
        shorts = [i for i, a in enumerate(first.program) if a.op == "short"]
        assert shorts, [a.describe() for a in first.program]
        for i in shorts:
            shorter = first.program[:i] + first.program[i + 1:]
            keys = {f.key for f in session.run(shorter).findings} if shorter else set()
            assert first.key not in keys, f"step {i + 1} ({first.program[i].describe()}) is not needed"
    finally:
        session.close()


def test_the_self_test_finds_busoff_recovery_resets_with_bus_steps_unasked():
    """``ckesc explore --selftest``: a fault that breaks R20 is explored with the bus steps, found from a fixed seed
    citing R20, in a program with a short."""
    [row] = find_faults(["busoff_recovery_resets"], seed=1, max_programs=10, budget_s=120, shrink_s=0.0)
    assert row.found and "R20-recovery" in row.requirements, row
    assert any(step.startswith("bus short") for step in row.program), row.program


def test_a_lone_host_power_cycle_is_held_and_taken_at_boot_without_a_finding():
    """The frames sent while the ESC was off went out at its power-up (their echo stamped then, not at their send),
    the ESC took them there (it answered both, and reports MSG1 every 40 ms after: R20 allows it), and the model
    followed: no finding, the answers not judged from their send."""
    outcome = _run({}, [ALONE, Action("wait", seconds=0.6)])
    assert not outcome.findings, _texts(outcome.findings)
    start, end = (outcome.t0 + t for t in outcome.steps[0])
    host = [m for m in outcome.messages if (m.arbitration_id & 0x7F) == 0 and start <= m.timestamp <= end
            and not m.is_error_frame]
    assert len(host) == 2, host
    up = next(f.timestamp for f in outcome.dut if f.name == "msg1" and f.timestamp > start)
    assert all(m.timestamp > start + 0.1 and abs(m.timestamp - up) < 0.3 for m in host), (host, up)
    answered = {f.name for f in outcome.dut if start <= f.timestamp <= end and f.name in ("set_freq", "get_esc_id")}
    assert answered == {"set_freq", "get_esc_id"}, answered
    msg1 = [f.timestamp for f in outcome.dut if f.name == "msg1" and f.timestamp > end + 0.1][:10]
    assert (msg1[-1] - msg1[0]) / (len(msg1) - 1) == pytest.approx(WRITE["msg1_interval"] * cat.INTERVAL_UNIT_S, abs=0.001)


@pytest.mark.parametrize("variant", [{}] + [pytest.param(v, marks=pytest.mark.slow) for v in variants.covering()],
                         ids=lambda v: variants.describe(v)[:40] or "faultless")
def test_explore_with_bus_steps_finds_nothing_on_a_conforming_emulator(variant):
    """The faultless emulator (which takes the frames held at its boot, and recovers from an 0.8 s short without its
    transfer-id sequence: the tests above show both) and, ``slow``, the combinations that play every alternative of
    every freedom, with shorts and lone-host power cycles drawn: no finding."""
    session = Session({"emulator_option": [f"{k}={v}" for k, v in variant.items()]}, bus=True)
    try:
        found, stats = explore(session, seed=1, database=None, budget_s=600, max_programs=40)
    finally:
        session.close()
    assert stats.programs >= 40
    drawn = sorted(f for f in stats.features if f.startswith(("short", "alone")))
    assert len(drawn) >= 3 and "alone" in drawn, drawn  # (shorts of two lengths at least, and a lone-host power cycle)
    assert not found, "\n".join(f.finding.text() + f"\n  program: {[a.describe() for a in f.program]}" for f in found)


@pytest.mark.realtime
def test_the_bus_steps_in_real_time_against_ckesc_emulate():
    """In real time against ``ckesc emulate`` (its own process, its hub playing the ESC's controller through the short,
    ``ckesc control bus``): a short of a streamed ESC and a lone-host power cycle give nothing on the faultless
    emulator; with ``no_busoff_recovery`` the short shows R20-recovery's finding."""
    for faults, expect in (("", False), ("no_busoff_recovery", True)):
        session = Session({"lane": "realtime", "emulator_faults": faults}, bus=True)
        try:
            assert session.bench.shorts and session.bench.alone, session.bus_note
            outcome = session.run([*STREAMED_SHORT[:2], SHORT, STREAMED_SHORT[-1]])
            held = session.run([Action("alone", fields={"frames": [{"name": "get_esc_id", "fields": {"option": 0}}]})])
        finally:
            session.close()
        assert not outcome.skipped and not held.findings, _texts(held.findings)
        keys = {f.key for f in outcome.findings}
        assert ("recovery|no MSG1 after a bus short" in keys) is expect, _texts(outcome.findings)
        if not expect:
            assert not outcome.findings, _texts(outcome.findings)
