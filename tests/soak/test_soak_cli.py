"""``ckesc soak`` as a user runs it: a real process on the simulated lane (hours cost seconds), its exit statuses
and its reports; Ctrl-C mid-run; a set-up mistake. The 8-hour soak of the faultless emulator is ``slow``."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "harness"))
from procs import CKESC, env  # noqa: E402

PROPERTIES = {"resets", "report intervals", "comm flag", "GET_ESC_ID answers", "settings", "unexpected frames"}


def soak(tmp: Path, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([*CKESC, "soak", "--reports", str(tmp / "reports"), *args], cwd=tmp, env=env(tmp),
                          capture_output=True, text=True, timeout=timeout)


def reports(tmp: Path) -> tuple[dict, ET.Element, str]:
    (run,) = sorted((tmp / "reports").glob("*-soak"))
    return (json.loads((run / "results.json").read_text()), ET.parse(run / "junit.xml").getroot(),
            (run / "summary.txt").read_text())


def test_a_simulated_soak_of_the_faultless_emulator_passes_and_writes_its_reports(tmp_path):
    done = soak(tmp_path, "--duration", "3m", "--rate", "50")
    assert done.returncode == 0, done.stdout + done.stderr
    doc, junit, summary = reports(tmp_path)
    assert doc["status"] == "COMPLETED" and doc["ran_s"] == pytest.approx(180) and doc["findings"] == []
    assert doc["host"]["stream_frames"] == 50 * 180 and doc["host"]["stream_skipped"] == 0
    assert set(doc["watches"]) == PROPERTIES and all(w["trials"] for w in doc["watches"].values())
    assert len(doc["r9_per_minute_ms"]["msg1"]) == 3 and doc["r9_per_minute_ms"]["msg1"][0] == pytest.approx(20, abs=0.01)
    resets = next(s for s in doc["statement"] if s["watch"] == "resets")
    assert resets["text"] == "0 resets in 3 min: the reset rate is below 60 per hour at 95 % confidence"
    (suite,) = junit.iter("testsuite")
    assert suite.get("name") == "soak" and suite.get("failures") == "0"
    assert {c.get("name").split(" [")[0] for c in suite.iter("testcase")} == PROPERTIES
    assert summary.startswith("soak completed") and resets["text"] in summary and summary in done.stdout
    page = next((tmp_path / "reports").glob("*-soak/report.html")).read_text()
    assert 'id="trend"' in page and 'id="delays"' in page and page.count("<svg") == 2 and resets["text"] in page


def test_an_emulator_fault_soak_catches_is_a_finding_and_exit_1(tmp_path):
    done = soak(tmp_path, "--duration", "10m", "--rate", "50", "--emulator-faults", "report_interval_wrong",
                "--stop-on-finding")
    assert done.returncode == 1, done.stdout + done.stderr
    doc, junit, summary = reports(tmp_path)
    assert doc["status"] == "STOPPED" and doc["ran_s"] < 120  # the first minute's R9 stops it
    (first, *_) = doc["findings"]
    assert first["watch"] == "report intervals" and "R9" in first["rules"] and first["t_s"] == pytest.approx(60, abs=1)
    assert first["frames_before"] and first["frames_after"]
    case = next(c for c in junit.iter("testcase") if c.get("name").startswith("report intervals"))
    assert case.find("failure") is not None


@pytest.mark.parametrize("args, words", [
    (("--emulator-faults", "no_such_fault"), "no_such_fault"),
    (("--rate", "1000"), "50-500 Hz"),
    (("--throttle-profile", "0:100"), "--allow-motor-spin"),
])
def test_a_setup_mistake_is_exit_2_and_opens_nothing(tmp_path, args, words):
    done = soak(tmp_path, "--duration", "1m", *args, timeout=60)
    assert done.returncode == 2, done.stdout + done.stderr
    assert words in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "reports").exists()


def test_ctrl_c_stops_the_soak_with_exit_130_and_an_interrupted_report(tmp_path):
    proc = subprocess.Popen([*CKESC, "soak", "--reports", str(tmp_path / "reports"), "--duration", "8h", "--rate", "50"],
                            cwd=tmp_path, env=env(tmp_path), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    header = proc.stdout.readline()
    assert header.startswith("soak: 8 h of flight-like running"), header + proc.stderr.read()
    with pytest.raises(subprocess.TimeoutExpired):  # it soaks (8 h of simulated time take minutes)
        proc.wait(timeout=1.0)
    proc.send_signal(signal.SIGINT)
    rest, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, header + rest + err
    assert "Traceback" not in err
    doc, junit, summary = reports(tmp_path)
    assert doc["status"] == "INTERRUPTED" and 0 < doc["ran_s"] < 8 * 3600
    assert summary.startswith("soak INTERRUPTED") and "INTERRUPTED" in rest
    (suite,) = junit.iter("testsuite")
    assert {p.get("name"): p.get("value") for p in suite.iter("property")}["status"] == "INTERRUPTED"


@pytest.mark.slow
@pytest.mark.timeout(2400)  # 8 h simulated: about 120 s of CPU, more wall time on a loaded machine
def test_an_8_hour_simulated_soak_of_the_faultless_emulator(tmp_path):
    """Issue #31's "how we will know": 8 h in simulated time, exit 0, memory flat (the wall time and the memory at the
    start and the end are in its results.json, and printed here with -s)."""
    done = soak(tmp_path, "--duration", "8h", "--rate", "50", timeout=2300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    doc, _, summary = reports(tmp_path)
    assert doc["ran_s"] == pytest.approx(8 * 3600) and len(doc["r9_per_minute_ms"]["msg1"]) == 480
    assert "0 resets in 8 h: the reset rate is below 0.375 per hour at 95 % confidence" in summary
    memory = doc["memory"]
    print(f"8 h simulated: {doc['wall_s']} s wall, RSS {memory}")
    assert memory["rss_end_kb"] - memory["rss_start_kb"] < 20_000  # flat: no list grows with the run


def test_a_soak_with_a_flight_controllers_traffic_blames_the_esc_for_none_of_it(tmp_path):
    """--foreign-traffic ardupilot (``ckesc run``'s bench option) in a soak: node 10's GET_ESC_ID queries answered
    by the ESC, its SafetyState, NodeStatus and RawCommand, a battery's BatteryCells are no finding; the reports say
    what was played."""
    done = soak(tmp_path, "--duration", "30s", "--rate", "50", "--foreign-traffic", "ardupilot")
    assert done.returncode == 0, done.stdout + done.stderr
    doc, _, summary = reports(tmp_path)
    assert doc["status"] == "COMPLETED" and doc["findings"] == [] and doc["bench"]["foreign_traffic"] == "ardupilot"
    foreign = doc["foreign_traffic"]
    assert foreign["profile"] == "ardupilot" and foreign["frames"] > 400 * 30 and doc["frames"]["other"] > 400 * 30
    answers = doc["watches"]["GET_ESC_ID answers"]["statistics"]
    assert answers["other_nodes_queries"] == answers["answers_to_other_nodes"] >= 29 and answers["answers"] == 30
    assert "foreign traffic: ardupilot" in summary


def test_the_trace_stays_within_its_budget_and_keeps_each_findings_frames(tmp_path):
    """--trace-budget: the rolling candump log's oldest files deleted as the run goes on, the files together under the
    budget, and the finding's frames in a file of its own that survives the rolling; results.json names the files."""
    import can

    budget = 300_000
    done = soak(tmp_path, "--duration", "2m", "--rate", "50", "--emulator-faults", "report_interval_wrong",
                "--trace-budget", "300kB", "-q")
    assert done.returncode == 1, done.stdout + done.stderr
    doc, _, _ = reports(tmp_path)
    (run,) = sorted((tmp_path / "reports").glob("*-soak"))
    trace = doc["trace"]
    files = sorted(p.name for p in run.glob("*.log"))
    assert trace["budget_bytes"] == budget and trace["rolled_away"] > 0 and files == sorted(trace["rolling"] + trace["findings"])
    assert sum((run / f).stat().st_size for f in files) == trace["bytes"] <= budget
    first = doc["findings"][0]
    assert first["t_s"] == pytest.approx(60, abs=1) and first["frames_file"] in trace["findings"]
    frames = list(can.CanutilsLogReader(run / first["frames_file"]))  # candump's log format
    assert len(frames) == len(first["frames_before"]) + len(first["frames_after"])
    assert frames[0].timestamp < first["t_s"] < frames[-1].timestamp  # the frames around it, long rolled out of the log
    assert min(m.timestamp for m in can.CanutilsLogReader(run / trace["rolling"][0])) > first["t_s"]


def test_a_trace_budget_too_small_for_the_findings_is_a_setup_mistake(tmp_path):
    done = soak(tmp_path, "--trace-budget", "10kB")
    assert done.returncode == 2 and "--trace-budget" in done.stderr and not (tmp_path / "reports").exists()
