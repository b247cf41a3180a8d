"""The DUT profile as a conformance statement, checked (issue #29 item 2), tried as a user meets it: real ``ckesc
profile`` and ``ckesc run`` processes against the emulator, in the simulated lane and once through ``ckesc
emulate`` on socketcand in real time.

* ``ckesc profile show NAME`` prints the profile's file; ``list`` names the profiles and the places looked in;
* ``ckesc profile init`` asks the DUT (reads only) and writes a profile that loads and whose claims match the
  emulator, leaving out an optional function an emulator with a fault lacks;
* ``ckesc profile check`` warns of a claim the DUT contradicts (exit 0, 1 with ``--strict``), and ``ckesc run``
  makes the same check at its start: a WARNING on the console, in results.json and in summary.txt, never a FAIL.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from procs import CKESC, Emulator, env

from ckesc.bench.profile import SHIPPED, DutProfile
from ckesc.bench.statement import Observed, Seen, contradictions


def ckesc(tmp: Path, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*CKESC, *args], cwd=tmp, env=env(tmp), capture_output=True, text=True, timeout=timeout)


def profile(tmp: Path, name: str, text: str) -> Path:
    path = tmp / name
    path.write_text(text)
    return path


# ------------------------------------------------------------------------------------------- show, list
def test_show_prints_a_shipped_profile_as_written(tmp_path):
    done = ckesc(tmp_path, "profile", "show", "emulator")
    assert done.returncode == 0, done.stderr
    assert done.stdout == SHIPPED.joinpath("emulator.toml").read_text(encoding="utf-8")


def test_show_of_an_unknown_profile_is_one_line_and_exit_2(tmp_path):
    done = ckesc(tmp_path, "profile", "show", "my_esc")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "no DUT profile 'my_esc'" in done.stderr and "ckesc-generic" in done.stderr


def test_list_names_the_places_looked_in_and_the_profiles_there(tmp_path):
    (tmp_path / "fixtures" / "duts").mkdir(parents=True)
    profile(tmp_path / "fixtures" / "duts", "emulator.toml", '[dut]\nname = "my own emulator"\n')
    done = ckesc(tmp_path, "profile", "list")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == f"{tmp_path / 'fixtures' / 'duts'}:"
    assert "my own emulator" in lines[1]
    shipped = next(i for i, line in enumerate(lines) if line.rstrip(":") == str(SHIPPED))
    assert any(line.split()[0] == "ckesc-generic" for line in lines[shipped + 1:])
    assert "hidden by the one above" in next(line for line in lines[shipped + 1:] if line.split()[0] == "emulator")


# ------------------------------------------------------------------------------------------- init
def test_init_writes_a_profile_that_loads_and_claims_what_the_emulator_has(tmp_path):
    done = ckesc(tmp_path, "profile", "init", "--dut", "emulator", "--modes", "-o", "mine.toml")
    assert done.returncode == 0, done.stderr
    written = DutProfile.load(str(tmp_path / "mine.toml"))
    shipped = DutProfile.load("emulator")
    assert written.absent == shipped.absent == ()  # every optional function answered
    for capability in ("motor_temperature", "multi_node"):  # what reads can show
        assert written.has(capability) == shipped.has(capability), capability
    text = (tmp_path / "mine.toml").read_text()
    assert "ESC Information (240): {'max_cells'" in text and "# state:" in text and "# measure:" in text
    again = ckesc(tmp_path, "profile", "init", "--dut", "emulator", "-o", "mine.toml")
    assert again.returncode == 2 and "exists" in again.stderr  # never overwritten unasked
    check = ckesc(tmp_path, "profile", "check", "--dut", "emulator", "--profile", "mine.toml", "--modes", "--strict")
    assert check.returncode == 0, check.stdout + check.stderr
    assert "WARNING" not in check.stdout and "no claim of the profile is contradicted" in check.stdout


@pytest.mark.parametrize("faults, modes, absent, untold", [
    ("expand_set_part_absent", False, ["expand_set_part"], []),
    # without Get Rec's records, Expand Set Part's record read cannot show anything: kept claimed, said so
    ("get_rec_absent,resume_exp_ignored", True, ["get_rec", "msg_exp_mode"], ["expand_set_part"]),
])
def test_init_leaves_out_a_function_the_emulator_lacks(tmp_path, faults, modes, absent, untold):
    done = ckesc(tmp_path, "profile", "init", "--dut", "emulator", "--emulator-faults", faults,
                 *(["--modes"] if modes else []))
    assert done.returncode == 0, done.stderr
    path = profile(tmp_path, "p.toml", done.stdout)
    assert sorted(DutProfile.load(str(path)).absent) == sorted(absent)
    for name in untold:
        assert f"# {name}: not learnt (kept claimed): cannot tell" in done.stdout


@pytest.mark.realtime
def test_init_through_ckesc_emulate_in_real_time(tmp_path):
    """On a real bus (socketcand) the same: reads only, and multi_node from who answers GET_ESC_ID."""
    with Emulator(tmp_path, "--faults", "get_rec_absent") as emu:
        done = ckesc(tmp_path, "profile", "init", "--dut", "bus", "--can-interface", "socketcand", "--can-channel",
                     "can0", "--can-config", "host=127.0.0.1", "--can-config", f"port={emu.port}", "-o", "rt.toml")
    assert done.returncode == 0, done.stderr
    written = DutProfile.load(str(tmp_path / "rt.toml"))
    assert written.absent == ("get_rec",) and not written.has("multi_node")
    assert "answered GET_ESC_ID" in (tmp_path / "rt.toml").read_text()


def test_init_on_a_bus_nobody_answers_is_exit_3(tmp_path):
    """The bench's problem, said in one line: nothing is written."""
    done = ckesc(tmp_path, "profile", "init", "--dut", "emulator", "--node-id", "5", "-o", "x.toml")
    assert done.returncode == 3 and "cannot use the bench" in done.stderr, done.stderr
    assert not (tmp_path / "x.toml").exists()


# ------------------------------------------------------------------------------------------- check, run
NO_REC = '[dut]\nname = "no records"\n[capabilities]\nled = true\nmotor = true\n[functions]\nabsent = ["get_rec"]\n'


def test_check_warns_of_a_function_declared_absent_that_answers(tmp_path):
    path = profile(tmp_path, "no-rec.toml", NO_REC)
    done = ckesc(tmp_path, "profile", "check", "--dut", "emulator", "--profile", str(path))
    assert done.returncode == 0, done.stderr
    warnings = [line for line in done.stdout.splitlines() if line.startswith("WARNING")]
    assert len(warnings) == 1 and "declares get_rec" in warnings[0] and "the DUT answers" in warnings[0], done.stdout
    strict = ckesc(tmp_path, "profile", "check", "--dut", "emulator", "--profile", str(path), "--strict")
    assert strict.returncode == 1 and "declares get_rec" in strict.stdout


def test_check_warns_of_a_function_claimed_that_does_not_answer(tmp_path):
    done = ckesc(tmp_path, "profile", "check", "--dut", "emulator", "--emulator-faults", "expand_set_part_absent")
    assert done.returncode == 0, done.stderr
    assert "WARNING: the profile claims expand_set_part" in done.stdout and "its tests will FAIL" in done.stdout


def test_run_warns_of_the_contradicted_claim_on_the_console_and_in_the_reports(tmp_path):
    path = profile(tmp_path, "no-rec.toml", NO_REC)
    done = ckesc(tmp_path, "run", "4.4.26", "--profile", str(path), "--reports", "rep")
    assert done.returncode == 0, done.stdout[-3000:]  # a warning, never a FAIL
    assert "WARNING: the DUT profile: [functions] absent declares get_rec" in done.stdout
    run = tmp_path / "rep" / "latest"
    info = json.loads((run / "results.json").read_text())["info"]
    assert len(info["profile_warnings"]) == 1 and "declares get_rec" in info["profile_warnings"][0]
    assert "get_rec: Get Rec (223)" in info["profile_check"]
    assert "WARNING: the DUT profile: [functions] absent declares get_rec" in (run / "summary.txt").read_text()
    clean = ckesc(tmp_path, "run", "4.4.26", "--reports", "rep")
    assert clean.returncode == 0 and "WARNING" not in clean.stdout
    assert json.loads((run / "results.json").read_text())["info"]["profile_warnings"] == []


# ------------------------------------------------------------------------------------------- capabilities
def _observed(nodes, motor_t) -> Observed:
    return Observed(node_id=nodes[0], nodes=nodes, motor_t=motor_t, functions={"get_rec": Seen(None, "not asked")})


def test_capabilities_the_dut_shows_otherwise_are_warned_of(tmp_path):
    claims = DutProfile.load(str(profile(tmp_path, "c.toml", "[capabilities]\nmulti_node = true\nmotor_temperature = true\n")))
    none = DutProfile.load(str(profile(tmp_path, "n.toml", "[capabilities]\n")))
    said = contradictions(claims, _observed([1], 0), bus=True)
    assert len(said) == 2 and "only node 1 answers" in said[0] and "Motor_T = 0" in said[1]
    said = contradictions(none, _observed([1, 2], 31), bus=True)
    assert len(said) == 2 and "nodes 1, 2 answer" in said[0] and "Motor_T = 31" in said[1]
    assert contradictions(claims, _observed([1], 25), bus=False) == []  # the emulator lanes' multi bench is their own
    assert contradictions(none, _observed([1], None), bus=True) == []  # no MSG3 heard: nothing to say
