"""``ckesc soak --rig`` as a user runs it (issue #31 item 6): every bench of a rig soaked at once, each a ``ckesc soak``
process of its own; one console line per bench; the batch's report lists each bench's statement; the exit status is
the worst bench's. Simulated benches: seconds of wall time."""

from __future__ import annotations

import contextlib
import io
import json
import signal
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "harness"))
from procs import CKESC, env  # noqa: E402

from ckesc.reporting.exits import ExitStatus  # noqa: E402
from ckesc.soak import batch  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "fixtures" / "rigs" / "example.toml"


def soak(tmp: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CKESC, "soak", "--reports", str(tmp / "reports"), *args], cwd=tmp, env=env(tmp),
                          capture_output=True, text=True, timeout=300)


def batch_of(tmp: Path) -> tuple[Path, dict]:
    (where,) = (tmp / "reports").glob("*-soak-batch")
    return where, json.loads((where / "batch.json").read_text())


def _documented(name: str) -> tuple[str, str]:
    """Where docs/soak.md says a bench's report and its console go, as globs under the reports directory."""
    import re

    page = (ROOT / "docs" / "soak.md").read_text(encoding="utf-8")
    report = re.search(r"`reports/(<UTC>-soak-batch/<bench>/[^`]*)`", page).group(1)
    console = re.search(r"`(<bench>/console\.txt)`", page).group(1)
    glob = lambda p: p.replace("<UTC>", "*").replace("<bench>", name)  # noqa: E731
    return glob(report), "*-soak-batch/" + glob(console)


def test_the_example_rigs_simulated_benches_soaked_at_once(tmp_path):
    done = soak(tmp_path, "--rig", str(EXAMPLE), "--benches", "sim-a,sim-b", "--duration", "30s", "--rate", "50")
    assert done.returncode == 0, done.stdout + done.stderr
    where, doc = batch_of(tmp_path)
    assert doc["exit_status"] == 0 and [b["name"] for b in doc["benches"]] == ["sim-a", "sim-b"]
    for b in doc["benches"]:
        assert b["exit"] == 0 and b["status"] == "COMPLETED" and b["findings"] == 0, b
        assert b["command"].startswith("ckesc soak --dut emulator --lane simulated")
        assert len(b["statement"]) == 6 and (where / b["report_dir"] / "results.json").is_file()
        # the bench's own soak ran with the batch's soak options and its own bench options
        own = json.loads((where / b["report_dir"] / "results.json").read_text())
        assert own["duration_s"] == 30 and own["plan"]["rate_hz"] == 50
        report, console = _documented(b["name"])  # the paths the docs write are the paths on disk
        assert [p.parent for p in (tmp_path / "reports").glob(report + "results.json")] == [where / b["report_dir"]]
        assert list((tmp_path / "reports").glob(console)), console
        status = json.loads((where / b["name"] / "status.json").read_text())
        assert status["state"] == "COMPLETED" and status["frames"] == own["frames"]["total"]
    sim_b = json.loads((where / doc["benches"][1]["report_dir"] / "results.json").read_text())
    assert "report_timer=grid" in sim_b["bench"]["emulator_option"]
    out = done.stdout
    # the console: one line per bench (its start, then its end), then each bench's statement
    assert "soak sim-a: starting" in out and "soak sim-b: starting" in out
    assert "soak sim-a: exit 0, nothing found (completed, 30 s" in out and "soak sim-b: exit 0, nothing found" in out
    summary = (where / "summary.txt").read_text()
    assert summary in out and summary.count("0 resets in 30 s: the reset rate is below") == 2


def test_the_batch_exits_with_its_worst_benchs_status(tmp_path):
    (tmp_path / "rig.toml").write_text('[bench.good]\n\n[bench.bad]\nemulator = { nodes = [1], faults = ["report_interval_wrong"] }\n')
    done = soak(tmp_path, "--rig", str(tmp_path / "rig.toml"), "--duration", "70s", "--rate", "50", "-q")
    assert done.returncode == 1 and done.stdout == "", done.stdout + done.stderr
    where, doc = batch_of(tmp_path)
    good, bad = doc["benches"]
    assert (good["name"], good["exit"], good["findings"]) == ("good", 0, 0)
    assert (bad["name"], bad["exit"]) == ("bad", 1) and bad["findings"] > 0 and "R9" in bad["first_findings"][0]
    assert "bench bad: exit 1, completed" in (where / "summary.txt").read_text()


def test_bench_options_with_a_rig_are_a_setup_mistake(tmp_path):
    done = soak(tmp_path, "--rig", str(EXAMPLE), "--lane", "realtime", "--duration", "10s")
    assert done.returncode == 2 and "--lane is set per bench in the rig file" in done.stderr, done.stderr
    assert not (tmp_path / "reports").exists()
    done = soak(tmp_path, "--rig", str(EXAMPLE), "--benches", "sim-z", "--duration", "10s")
    assert done.returncode == 2 and "no bench 'sim-z'" in done.stderr and "Traceback" not in done.stderr


def test_the_worst_status_ranks_interrupted_then_findings_then_benches_not_usable():
    assert batch.worst([0, 0]) == 0
    assert batch.worst([0, 1, 3]) == 1 and batch.worst([3, 2, 0]) == 3 and batch.worst([1, 130]) == 130
    assert batch.worst([0, -9]) == ExitStatus.ABORTED  # a bench's process killed: not a pass


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_on_a_terminal_the_benches_lines_are_rewritten_in_place(tmp_path):
    runs = [batch.BenchRun("a", "", [], tmp_path / "a"), batch.BenchRun("b", "", [], tmp_path / "b")]
    out = _Tty()
    console = batch.Console(out, False, clock=lambda: 0.0)
    console.refresh(runs, force=True)
    runs[0].figures = {"state": "running", "elapsed_s": 90, "left_s": 30, "frames": 1234, "findings": 0}
    runs[1].exit, runs[1].figures = 1, {"state": "STOPPED", "elapsed_s": 61, "left_s": 59, "frames": 999, "findings": 1}
    console.refresh(runs, force=True)
    first, second = out.getvalue().split("\x1b[2F")  # the second drawing goes back up over the two lines
    assert first == "\x1b[2Ksoak a: starting\n\x1b[2Ksoak b: starting\n"
    assert second == ("\x1b[2Ksoak a: 1 min 30 s elapsed, 30 s left, 1234 frames, 0 findings\n"
                      "\x1b[2Ksoak b: exit 1, FINDINGS (stopped, 1 min 1 s, 999 frames, 1 findings)\n")


def test_ctrl_c_stops_every_bench_with_its_report_and_exit_130(tmp_path):
    proc = subprocess.Popen([*CKESC, "soak", "--reports", str(tmp_path / "reports"), "--rig", str(EXAMPLE), "--benches",
                             "sim-a,sim-b", "--duration", "8h", "--rate", "50"], cwd=tmp_path, env=env(tmp_path),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    lines = [proc.stdout.readline() for _ in range(3)]  # the batch's start, then a line per bench
    # both benches soaking (each writes its status file once in its loop) before the operator's Ctrl-C
    (where,) = (tmp_path / "reports").glob("*-soak-batch")
    for _ in range(1200):
        if all((where / name / "status.json").exists() for name in ("sim-a", "sim-b")):
            break
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=0.1)
        assert proc.poll() is None, "".join(lines) + proc.stdout.read()
    proc.send_signal(signal.SIGINT)
    rest, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, "".join(lines) + rest + err
    doc = json.loads((where / "batch.json").read_text())
    assert doc["interrupted"] and doc["exit_status"] == 130
    assert [(b["exit"], b["status"]) for b in doc["benches"]] == [(130, "INTERRUPTED")] * 2
    assert "Traceback" not in err and "stopping every bench" in err
