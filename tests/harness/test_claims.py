"""What a conformance claim covers, and of what (issue #11 items 2, 3 and 7), tried with real
``ckesc run`` processes against the emulator:

* optional functions (R9b): a profile declaring functions absent turns their tests SKIPPED "not
  claimed" against an emulator that lacks them, every report says what the claim leaves out, and the
  same emulator FAILs when the functions are claimed; the core cannot be declared away;
* selecting sections by number or test modules by path; a selection of nothing is exit 2;
* the DUT's report-interval jitter allowance apart from the bench's error, in the interval tests and
  the live bus rules; every bench option in ``ckesc run --help``.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ckesc.bench.profile import DutProfile, ProfileError
from ckesc.evidence import BusRules
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import encode
from ckesc.protocol.functions import CORE, OPTIONAL
from ckesc.protocol.requirements import REQUIREMENTS
from ckesc.rigs.batch_report import bench_status

SUITE = Path(__file__).resolve().parents[2] / "conformance"
#: the emulator without Get Rec, Expand Set Part and MSG_EXP mode (an ESC model lacking them)
LACKING = "get_rec_absent,expand_set_part_absent,resume_exp_ignored"
ABSENT = ("get_rec", "expand_set_part", "msg_exp_mode")


def run(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("CAN_")}
    return subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


def latest(reports: Path) -> tuple[dict, ET.Element, str, str]:
    run_dir = reports / "latest"
    return (json.loads((run_dir / "results.json").read_text()), ET.parse(run_dir / "junit.xml").getroot(),
            (run_dir / "summary.txt").read_text(), (run_dir / "report.html").read_text())


def emulator_profile(tmp: Path, name: str, extra: str) -> Path:
    """The shipped emulator profile with ``extra`` TOML appended (a bench's own copy)."""
    text = (Path(__file__).resolve().parents[2] / "ckesc/bench/profiles/emulator.toml").read_text()
    path = tmp / name
    path.write_text(text.replace("[timing]\n", "[timing]\n" + extra) if extra.startswith("jitter_s") else text + extra)
    return path


# ----------------------------------------------------------------------------------------- the table
def test_each_optional_function_names_real_requirements_and_frames_and_no_core_one():
    core_sections = set(CORE.values())
    for f in OPTIONAL.values():
        assert f.requirements, f.name
        for rid in f.requirements:
            assert rid in REQUIREMENTS, (f.name, rid)
            assert REQUIREMENTS[rid].section not in core_sections - {"4.4.2"}, (f.name, rid)
        for frame in f.frames:
            assert cat.spec(frame).service or frame == "can_test", (f.name, frame)
    assert not set(OPTIONAL) & set(CORE)


@pytest.mark.parametrize("absent, words", [
    (["set_freq"], ["'set_freq' (4.4.22) cannot be declared absent", "R9b"]),
    (["raw_command_10b"], ["cannot be declared absent"]),
    (["get_recs"], ["unknown function 'get_recs'", "did you mean 'get_rec'"]),
])
def test_a_profile_cannot_declare_the_core_or_an_unknown_function_absent(tmp_path, absent, words):
    path = tmp_path / "p.toml"
    path.write_text(f"[functions]\nabsent = {json.dumps(absent)}\n")
    with pytest.raises(ProfileError) as exc:
        DutProfile.load(str(path))
    text = str(exc.value)
    assert text.startswith(f"{path}: functions.absent")
    for w in words:
        assert w in text


# ----------------------------------------------------------------------------------------- R9b, end to end
def test_functions_declared_absent_are_skipped_not_claimed_and_every_report_says_so(tmp_path):
    profile = emulator_profile(tmp_path, "lacking.toml", f"\n[functions]\nabsent = {json.dumps(list(ABSENT))}\n")
    sections = ("4.4.2", "4.4.7", "4.4.9", "4.4.14", "4.4.25", "4.4.24", "attachment")
    reports = tmp_path / "reports"
    done = run(tmp_path, *sections, "--profile", str(profile), "--emulator-faults", LACKING, "--reports", str(reports))
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    doc, junit, summary, page = latest(reports)
    by = {r["nodeid"]: r for r in doc["results"]}
    assert not [n for n, r in by.items() if r["outcome"] in ("FAIL", "ERROR", "INCONCLUSIVE")]
    skipped = {n: r["message"] for n, r in by.items() if r["outcome"] == "SKIPPED"}
    for function in ABSENT:
        assert any(m.startswith(f"not claimed: {function} (R9b)") for m in skipped.values()), function
    # a test that only compares MSG_EXP frames with other reports still runs without them
    assert by["conformance/test_attachment_fault_codes.py::test_reported_fault_codes_are_the_attachment_s"]["outcome"] == "PASS"
    assert all("not claimed" in skipped[n] for n in skipped if "expand_set_part" in n or "msg_exp" in n)
    for function in ABSENT:
        assert function in doc["info"]["not_claimed"]
        assert function in summary.split("claim: leaves out", 1)[1].splitlines()[0]
        assert function in page.split("<header>", 1)[1].split("</header>", 1)[0]
    props = [{p.get("name"): p.get("value") for p in s.find("properties")} for s in junit.iter("testsuite")]
    assert props and all(all(f in p["not_claimed"] for f in ABSENT) for p in props)


def test_the_same_emulator_fails_when_the_functions_are_claimed(tmp_path):
    reports = tmp_path / "reports"
    done = run(tmp_path, "4.4.2", "4.4.14", "4.4.25", "--emulator-faults", LACKING, "--reports", str(reports))
    assert done.returncode == 1, done.stdout[-3000:] + done.stderr
    doc, _, summary, _ = latest(reports)
    failed = {r["nodeid"].split("::")[1].split("[")[0] for r in doc["results"] if r["outcome"] == "FAIL"}
    assert {"test_get_rec_sends_each_record_once", "test_set_cmd_is_little_endian",
            "test_exp_mode_replaces_msg1_to_msg3"} <= failed
    assert doc["info"]["not_claimed"] == "" and "claim: every function" in summary


@pytest.mark.parametrize("fault, failing", [
    ("", set()),
    ("tail_toggle_set", {"test_tail_byte_marks_a_single_frame_transfer[provoked]",
                         "test_tail_byte_marks_a_single_frame_transfer[run]"}),
])
def test_the_core_framing_and_frame_table_tests_judge_whatever_the_claim_leaves_out(tmp_path, fault, failing):
    """R9b: a core test that also sends an absent function's frames (the provoked traffic: MSG_EXP mode, CAN
    Test, Get Rec) leaves them out and judges the rest: no 4.1 or 4.3 test is SKIPPED for a claim, and a
    framing fault still fails them against an emulator lacking every optional function but CAN Test."""
    profile = emulator_profile(tmp_path, "bare.toml", f"\n[functions]\nabsent = {json.dumps(list(OPTIONAL))}\n")
    reports = tmp_path / "reports"
    faults = ",".join(filter(None, (LACKING, fault)))
    done = run(tmp_path, "4.1", "4.3", "--profile", str(profile), "--emulator-faults", faults, "--reports", str(reports))
    assert done.returncode == (1 if failing else 0), done.stdout[-3000:] + done.stderr
    doc, *_ = latest(reports)
    by = {r["nodeid"].split("::", 1)[1]: r for r in doc["results"]}
    assert len(by) == 27 and all(r["section"] in ("4.1", "4.3") for r in by.values())
    skipped = {n: r["message"] for n, r in by.items() if r["outcome"] == "SKIPPED"}
    assert not skipped, skipped
    assert {n for n, r in by.items() if r["outcome"] not in ("PASS", "OBSERVED")} >= failing
    for n in failing:
        assert by[n]["outcome"] == "FAIL" and "toggle = 1" in by[n]["message"], by[n]


def test_a_bus_rule_broken_during_an_unclaimed_test_fails_the_run_against_the_rule_not_the_test(tmp_path):
    """R9b: a live bus rule broken while a test of an unclaimed function ran (it suspends reporting, then
    finds Expand Set Part absent: SKIPPED) is the rule's failure: the test stays SKIPPED, the rule is in
    results.json's ``rule_failures``, the causes grouping, summary.txt, JUnit and report.html, and the run
    exits 1 (never a silent pass)."""
    profile = emulator_profile(tmp_path, "lacking.toml", '\n[functions]\nabsent = ["get_rec", "expand_set_part"]\n')
    reports = tmp_path / "reports"
    done = run(tmp_path, "4.4.25", "--profile", str(profile), "--emulator-faults", "report_interval_wrong",
               "--reports", str(reports))
    assert done.returncode == 1, done.stdout[-3000:] + done.stderr
    doc, junit, summary, page = latest(reports)
    assert {r["outcome"] for r in doc["results"]} == {"SKIPPED"}
    name = "conformance/test_s4_4_25_expand_set_part.py::test_not_applied_while_reporting_is_suspended"
    seen = {r["nodeid"]: r for r in doc["results"]}[name]
    assert seen["message"].startswith("not claimed: expand_set_part (R9b)") and "R9" in seen["bus_rules"]
    [failure] = doc["rule_failures"]
    assert failure["test"] == name and failure["outcome"] == "SKIPPED" and "R9" in failure["rules"]
    assert "MSG1 of node 1 every 30 ms, not 20 ms" in {c["what"] for c in failure["causes"]}
    assert "bus rules broken while 1 test(s) without a FAIL of their own ran (R9" in summary
    assert re.search(r"\[FAIL SHALL\] R9 .*MSG1 of node 1 every 30 ms, not 20 ms - in 1 test", summary)
    assert "test_not_applied_while_reporting_is_suspended (SKIPPED: seen while it ran)" in summary
    assert "(SKIPPED: seen while it ran)" in page
    rule_cases = [c for c in junit.iter("testcase") if c.get("classname") == "ckesc.bus_rules"]
    assert len(rule_cases) == 1 and rule_cases[0].find("failure") is not None
    closing = done.stdout.splitlines()[-1]  # pytest's count: the test's verdict, not the rule's
    assert "skipped" in closing and "failed" not in closing, closing
    assert bench_status(doc) == ("FAIL", "bus rules broken while 1 SKIPPED test(s) ran")  # the bench of a batch too


# ----------------------------------------------------------------------------------------- selection
def _modules(doc: dict) -> set[str]:
    return {r["nodeid"].split("::")[0] for r in doc["results"]}


@pytest.mark.parametrize("how", [
    # CI: a section number and a relative path with a test; the other spellings behind -m slow
    "sections", pytest.param("relative", marks=pytest.mark.slow), "relative-with-test",
    pytest.param("absolute", marks=pytest.mark.slow), pytest.param("from-elsewhere", marks=pytest.mark.slow)])
def test_sections_and_module_paths_select_just_those(tmp_path, how):
    freq = "conformance/test_s4_4_22_set_freq.py"
    args, cwd = {
        "sections": (["4.4.22", "4.4.3"], tmp_path),
        "relative": ([freq], SUITE.parent),
        "relative-with-test": ([f"{freq}::test_read_answers_the_current_settings"], SUITE.parent),
        "absolute": ([str(SUITE / "test_s4_4_22_set_freq.py")], tmp_path),
        "from-elsewhere": ([os.path.relpath(SUITE / "test_s4_4_22_set_freq.py", tmp_path)], tmp_path),
    }[how]
    reports = tmp_path / "reports"
    done = run(cwd, "--reports", str(reports), *args)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    doc, junit, summary, _ = latest(reports)
    expect = {freq} | ({"conformance/test_s4_4_3_get_esc_id.py"} if how == "sections" else set())
    assert _modules(doc) == expect
    assert doc["info"]["complete"] is False and doc["info"]["incomplete"].startswith("subset")
    assert summary.startswith("SUBSET")


def test_options_after_a_section_are_ckesc_runs_and_pytest_options_follow(tmp_path):
    reports = tmp_path / "reports"
    done = run(tmp_path, "4.4.22", "--reports", str(reports), "--trace-format", "none", "--", "-k", "read_answers")
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    doc, *_ = latest(reports)
    assert [r["name"] for r in doc["results"]] == ["test_read_answers_the_current_settings"]
    assert not (reports / "latest" / "traces").exists()


@pytest.mark.parametrize("args, words", [
    (["4.4.99"], ["no conformance section '4.4.99'", "4.4.22"]),
    (["conformance/test_no_such_section.py"], ["no such file"]),
    (["/etc/hostname"], ["not part of the conformance suite"]),
    (["--", "-k", "no_test_is_called_this"], ["matches no conformance test"]),
])
def test_a_selection_of_nothing_is_one_line_exit_2_never_the_whole_suite(tmp_path, args, words):
    reports = tmp_path / "reports"
    done = run(tmp_path, "--reports", str(reports), *args)
    assert done.returncode == 2, done.stdout[-3000:] + done.stderr
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("ckesc run: error: "), done.stderr
    for w in words:
        assert w in lines[0]
    assert "passed" not in done.stdout
    assert not (reports / "latest").exists()


# ----------------------------------------------------------------------------------------- jitter and error
def test_the_dut_jitter_allowance_widens_single_intervals_and_their_mean_only_at_its_ends(tmp_path):
    """R9: the DUT's declared jitter widens each single interval in full (the live bus rules) and the mean a test
    judges only at its two ends, over the number of gaps: a test whose purpose is R9 reads enough gaps that the mean's
    bound stays within twice the scheduling tolerance, so the fault's drift still FAILs it; the emulator's conforming
    jitter (report_jitter_s, declared by the emulated DUT) passes."""
    reports = tmp_path / "reports"
    strict = run(tmp_path, "4.4.5", "4.4.22", "--emulator-faults", "report_jitter", "--reports", str(reports))
    assert strict.returncode == 1, strict.stdout[-3000:] + strict.stderr
    doc, *_ = latest(reports)
    fails = [r for r in doc["results"] if r["outcome"] == "FAIL"]
    assert any("R9" in r["bus_rules"] for r in fails) and any("interval" in r["message"] for r in fails)

    profile = emulator_profile(tmp_path, "jittery.toml", "jitter_s = 0.2\n")
    wide = run(tmp_path, "4.4.5", "4.4.22", "--profile", str(profile), "--emulator-faults", "report_jitter",
               "--reports", str(reports))
    doc, junit, summary, page = latest(reports)
    assert not [r for r in doc["results"] if r["bus_rules"]], "the allowance widens the live rule's single intervals"
    assert doc["info"]["jitter_s"] == 0.2 and doc["info"]["timing_error_s"] == 0.0
    assert re.search(r"stated error \+-0 ms \(the bench's\), report-interval jitter allowance 200 ms \(the DUT's\)", summary)
    assert "jitter allowance (the DUT&#x27;s)" in page
    means = [v for r in doc["results"] for k, v in r["properties"].items() if k.endswith(".limit") and "mean interval" in
             r["properties"].get(k.replace("limit", "name"), "")]
    # the jitter at the mean's two ends, over as many gaps as keep it within 1 ms more than the scheduling tolerance
    assert means and all(float(v.split()[1]) <= 2.01 for v in means), means
    fails = [r for r in doc["results"] if r["outcome"] == "FAIL"]  # the fault's +-30 % drifts: its mean is off
    assert wide.returncode == 1 and fails and all("mean interval error" in r["message"] for r in fails)

    jittery = run(tmp_path, "4.4.5", "4.4.22", "--emulator-option", "report_jitter_s=0.003", "--reports", str(reports))
    assert jittery.returncode == 0, jittery.stdout[-3000:] + jittery.stderr
    doc, *_ = latest(reports)
    assert doc["info"]["jitter_s"] == 0.003  # what the emulated ESC's vendor would declare
    assert {r["outcome"] for r in doc["results"]} <= {"PASS", "OBSERVED"}


def test_the_live_interval_rule_takes_the_jitter_allowance_on_top_of_the_error():
    def late_msg1(rules: BusRules) -> list:
        feed = rules.feed
        read = {"option": 0, "msg1_interval": 0, "msg2_interval": 0, "msg3_interval": 0}
        w = encode("set_freq", read, source=0, destination=1, transfer_id=0)
        feed(w.arbitration_id, w.data, 0.0)
        w = encode("set_freq", {"option": 0, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250},
                   kind="response", source=1, destination=0, transfer_id=0)
        feed(w.arbitration_id, w.data, 0.001)
        found = []
        for i, t in enumerate([0.01, 0.03, 0.053, 0.073]):  # one gap 3 ms long
            w = encode("msg1", {"speed": 0, "pwm": 0, "status": 0}, source=1, transfer_id=i)
            found += [v.check for v in feed(w.arbitration_id, w.data, t)]
        return found

    assert "report-interval" in late_msg1(BusRules(tolerance=0.001, complete=True))
    assert late_msg1(BusRules(tolerance=0.001, complete=True, jitter=0.003)) == []


def test_every_bench_option_of_the_plugin_is_in_ckesc_run_help():
    plugin = subprocess.run([sys.executable, "-m", "pytest", "--help", "-p", "no:cacheprovider"], capture_output=True,
                            text=True, timeout=120).stdout
    group = plugin.split("CKESC conformance", 1)[1].split("\n\n", 1)[0]
    options = set(re.findall(r"^\s+(--[a-z][a-z-]+)", group, re.M))
    assert "--can-bitrate-cmd" in options
    ours = subprocess.run([sys.executable, "-m", "ckesc", "run", "--help"], capture_output=True, text=True, timeout=60).stdout
    # the plugin's report options are ckesc run's --reports and --trace-format; --ckesc-summary and --ckesc-no-html
    # are set by ckesc run / ckesc selftest themselves
    renamed = {"--ckesc-reports": "--reports", "--ckesc-trace-format": "--trace-format", "--ckesc-order": "--order",
               "--ckesc-progress": "--progress", "--ckesc-durations": "--time-from", "--ckesc-strict": "--strict",
               "--ckesc-baseline": "--baseline", "--ckesc-baseline-threshold": "--baseline-threshold"}
    missing = [o for o in sorted(options) if o not in ("--ckesc-summary", "--ckesc-no-html")
               and renamed.get(o, o) not in ours]
    assert missing == []
