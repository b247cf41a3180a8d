"""ckesc explore plays a loaded bus (R18, issue #30 item 5): a load step sets the foreign load share.

A program's load step puts :class:`ckesc.protocol.load.LoadSource` on the simulated lane's bus at 10, 30 or 50 % of its
capacity (from then on), takes it off, or plays 70 % for the step's seconds (above half: OBSERVE). The judge holds the
DUT to R9 widened by R18's queueing, R2 and the 64 ms bound under it, and judges nothing above half. Here: the fault
``drops_reports_under_load`` shows on a two-step program and is found from a fixed seed (in CI the seed that finds it
soonest; shrunk to a program whose load step is needed, ``slow``; load steps are drawn when asked for, ``ckesc
explore --load``); the faultless emulator and the variant that drops
reports above half load (``above_half_load=drop``, which does drop them there) give no finding with load steps at
every share; a lane that cannot play a load (real time) draws no load step, and one replayed there is skipped, said so.
Random programs with load steps on every conforming variant: ``test_conforming_families.py`` (it explores with
``--load``).
"""

from __future__ import annotations

import pytest

from ckesc.emulator.faults import FAULTS
from ckesc.emulator.variants import ABOVE_HALF_WINDOW_S
from ckesc.explore.actions import ABOVE_HALF_SHARE, LOAD_SHARES, Action, ProgramBench, families, program_from_json, program_json
from ckesc.explore.engine import explore
from ckesc.explore.runner import Session
from ckesc.explore.selftest import find_faults
from ckesc.protocol.load import PRIORITIES

FAULT = "drops_reports_under_load"
HALF = Action("load", fields={"share": max(LOAD_SHARES), "priority": "high"})
#: the fault's shortest program: half load (R18's most), then long enough for every report to be due
SHOWS = [HALF, Action("wait", seconds=0.6)]
#: every load a program draws, each with a read and a stream under it, the last above half for a while
EVERY_LOAD = [Action("stream", "raw_command_14b"),
              *[step for share in LOAD_SHARES for priority in PRIORITIES for step in (
                  Action("load", fields={"share": share, "priority": priority}), Action("wait", seconds=0.25),
                  Action("send", "get_esc_id", {"option": 0}))],
              Action("load", fields={"share": ABOVE_HALF_SHARE, "priority": "high"}, seconds=0.6),
              Action("send", "get_esc_id", {"option": 0}), Action("wait", seconds=0.6), Action("stop"),
              Action("load", fields={"share": 0}), Action("wait", seconds=0.6)]


def _run(options: dict, program: list[Action]):
    session = Session(options)
    try:
        return session.run(program)
    finally:
        session.close()


def test_the_fault_shows_under_half_load_citing_r18_and_not_without_the_load():
    assert program_from_json(program_json(SHOWS)) == SHOWS  # (a replay file keeps the step)
    session = Session({"emulator_faults": FAULT})
    try:
        findings = session.run(SHOWS).findings
        assert findings, "drops_reports_under_load: no finding under half load"
        assert all("R18" in f.requirements for f in findings), [f.text() for f in findings]
        assert set(findings[0].requirements) & set(FAULTS[FAULT].rules), findings[0].text()
        quiet = session.run(SHOWS[1:]).findings  # the load step removed (as shrinking does): nothing shows
    finally:
        session.close()
    assert not quiet, [f.text() for f in quiet]


@pytest.mark.parametrize("variant", ["keep", "drop"])
def test_no_finding_under_any_load_on_a_conforming_emulator(variant):
    """The faultless emulator and the variant that drops reports above half load: nothing found under 10, 30, 50 %
    of any priority, nor across a 70 % stretch, though the variant dropped reports there (R18: OBSERVE)."""
    outcome = _run({"emulator_option": [f"above_half_load={variant}"]}, EVERY_LOAD)
    assert not outcome.findings, "\n".join(f.text() for f in outcome.findings)
    above = next(i for i, a in enumerate(EVERY_LOAD) if a.op == "load" and a.seconds)
    start = outcome.t0 + outcome.steps[above][0] + ABOVE_HALF_WINDOW_S  # (once the variant's window has filled)
    end = start - ABOVE_HALF_WINDOW_S + EVERY_LOAD[above].seconds
    dut = [f for f in outcome.dut if f.name == "msg1" and start <= f.timestamp <= end]
    model = [f for f in outcome.model if f.name == "msg1" and start <= f.timestamp <= end]
    assert (len(dut) < len(model) / 2) is (variant == "drop"), f"{variant}: {len(dut)} MSG1 at 70 %, the model {len(model)}"


#: in CI: from the seed that finds it in the fewest wall seconds (seed 4: after 7 programs, about 2 s; shrunk, its two
#: steps are a stream and a 30 % load; seed 1 after 5 programs of longer ones)
FAST = (4, 20)


def _found(seed: int, max_programs: int, shrink_s: float | None):
    session = Session({"emulator_faults": FAULT}, load=True)
    try:
        found, stats = explore(session, seed=seed, database=None, budget_s=600, max_programs=max_programs,
                               stop_at_first=True, shrink_s=shrink_s)
        assert found, f"{FAULT}: nothing found in {stats.programs} programs ({stats.line()})"
        first = found[0]
        assert set(first.finding.requirements) & set(FAULTS[FAULT].rules), first.finding.text()
        loads = [i for i, a in enumerate(first.program) if a.op == "load" and a.fields.get("share")]
        assert loads, [a.describe() for a in first.program]
        return session, first, loads
    except BaseException:
        session.close()
        raise


def test_the_self_test_finds_drops_reports_under_load():
    """``ckesc explore --selftest``: a fault that breaks R18 is explored with load steps (unasked), found from a fixed
    seed citing R18, in a program with a load in it (found is the point here; shrinking costs CI time, ``slow``)."""
    seed, max_programs = FAST
    [row] = find_faults([FAULT], seed=seed, max_programs=max_programs, budget_s=120, shrink_s=0.0)
    assert row.found and "R18" in row.requirements, row
    assert any(step.startswith("foreign load") for step in row.program), row.program


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_explore_shrinks_it_to_a_program_whose_load_step_is_needed():
    session, first, loads = _found(1, 40, shrink_s=300)  # (seed 1, shrunk to its end: 8 min on a busy 2-core machine)
    try:
        for i in loads:  # each load step of the shrunk program removed: the finding goes
            shorter = first.program[:i] + first.program[i + 1:]
            keys = {f.key for f in session.run(shorter).findings} if shorter else set()
            assert first.key not in keys, f"step {i + 1} ({first.program[i].describe()}) is not needed"
    finally:
        session.close()


def test_load_steps_are_drawn_only_when_asked_and_where_the_lane_can_play_them():
    assert "load" in families(ProgramBench(load=True)) and "load" not in families(ProgramBench())
    for asked in (True, False):
        session = Session({}, load=asked)
        try:
            assert session.bench.load is asked and not session.load_note  # (the simulated lane plays one)
        finally:
            session.close()


def test_a_load_step_the_lane_cannot_play_is_skipped_and_said(monkeypatch):
    """A replayed load step on a lane without a bus model (real time, here the simulated lane with its world taken
    away): nothing played, the step skipped and said why, no finding."""
    session = Session({}, load=True)
    try:
        monkeypatch.setattr(session, "_world", None)
        assert not session.bench.load
        outcome = session.run(SHOWS)
    finally:
        session.close()
    assert not outcome.findings and len(outcome.skipped) == 1 and "cannot play a foreign load" in outcome.skipped[0]
    assert not any((m.arbitration_id & 0x7F) not in (0, 1) for m in outcome.messages), "a load was played"
