"""A simulated soak on two cores (``--processes 2``, :mod:`ckesc.soak.split`): the world in a process of its own,
the reader in the soak's. It must end where the one-process soak ends (the first finding's stop decided by the
reader, the world ahead of it), and Ctrl-C must stop both processes with the report written and none left behind.
(The frames and findings of whole soaks in both modes: ``test_soak_sameness.py``.)"""

from __future__ import annotations

import io
import json
import marshal
import os
import signal
import subprocess
import sys

import pytest
from test_soak_sameness import soak_digest  # (this folder is on the path: pytest puts it there)

from ckesc.bench.station import BenchOptions
from ckesc.soak import runner, split


def test_the_world_runs_in_two_processes_only_for_a_simulated_soak_on_two_cores(monkeypatch):
    monkeypatch.setattr(split, "cores", lambda: 2)
    assert split.processes("auto", simulated=True) == 2 and split.processes("1", simulated=True) == 1
    assert split.processes("2", simulated=False) == 1  # a real bus is read as it comes
    monkeypatch.setattr(split, "cores", lambda: 1)
    assert split.processes("auto", simulated=True) == 1 and split.processes("2", simulated=True) == 2
    with pytest.raises(ValueError, match="--processes '3'"):
        split.processes("3", simulated=True)


def _stopped(tmp_path, processes: str) -> tuple[tuple[int, str], dict]:
    bench = BenchOptions(emulator_faults="reset_after_streaming=5")
    where = tmp_path / processes
    found = soak_digest(where, bench, {"duration_s": 60.0, "stop_on_finding": True, "processes": processes})
    (run,) = where.glob("*-soak")
    return found, json.loads((run / "results.json").read_text())


def test_the_first_finding_stops_two_processes_where_it_stops_one(tmp_path, monkeypatch):
    """The reader decides the stop; the world, handing over batches of 64 frames here, is ahead of it when it does:
    the trace, the findings, the time run, the host's stream and the statement end where the one-process soak's do."""
    monkeypatch.setattr(split, "BATCH_FRAMES", 64)
    one, one_doc = _stopped(tmp_path, "1")
    two, two_doc = _stopped(tmp_path, "2")
    assert one_doc["status"] == two_doc["status"] == "STOPPED" and one[0] >= 1
    assert one_doc["ran_s"] < 60 - 1  # (it did stop early)
    assert two == one
    for doc in (one_doc, two_doc):
        doc["host"] = {k: v for k, v in doc["host"].items() if k in ("stream_frames", "stream_skipped", "send_lateness",
                                                                    "bench_stamp_lag")}
    for key in ("ran_s", "frames", "host", "watches", "r9_per_minute_ms", "bus_reader", "statement"):
        assert two_doc[key] == one_doc[key], key
    assert one_doc["host"]["stream_frames"] > 0


def test_a_world_that_fails_is_the_soaks_abort_not_a_hang(tmp_path, monkeypatch):
    """The world's process ends without its last message (here: it raises at once): the soak is ABORTED, says so in
    one line, and its report is written."""
    def broken(out, control, *args):
        raise RuntimeError("the world broke")
    monkeypatch.setattr(split, "run_world", broken)
    outcome = runner.run(BenchOptions(), runner.SoakOptions(duration_s=5.0, reports=str(tmp_path), quiet=True,
                                                            processes="2"), out=io.StringIO())
    assert outcome.status == "ABORTED" and outcome.where is not None
    doc = json.loads((outcome.where / "results.json").read_text())
    assert doc["problem"].startswith("the simulated world's process ended without its last message")


def test_a_second_ctrl_c_ends_a_world_that_no_longer_answers():
    """The first SIGINT asks the world to stop; a world that does not (here: it asks for the signals itself, reads
    the reader's stop and then waits for ever) is ended by the second: the soak is INTERRUPTED, not hung."""
    def stuck(out, control):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        os.kill(os.getppid(), signal.SIGINT)
        out.send_bytes(b"B" + marshal.dumps(([(1.0, 0, [], 1, 0)], [])))  # one tick: the reader then sees its stop
        assert control.recv() == "INTERRUPTED"
        os.kill(os.getppid(), signal.SIGINT)
        while True:
            signal.pause()
    ticks: list[float] = []
    end = split.read_world(stuck, lambda m: None, None, lambda *a: None, lambda late: None,
                           lambda now, sent, skipped: ticks.append(now) is not None)
    assert end["status"] == "INTERRUPTED" and end["stopped_at"] == 1.0 and ticks == [1.0]


@pytest.mark.parametrize("to_group", [False, True], ids=["the soak's process", "its process group (a terminal)"])
def test_ctrl_c_stops_both_processes_with_exit_130_and_leaves_none(tmp_path, to_group):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.Popen([sys.executable, "-m", "ckesc", "soak", "--reports", str(tmp_path / "reports"),
                             "--duration", "8h", "--processes", "2", "--trace-budget", "0"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    assert proc.stdout is not None
    header = proc.stdout.readline()
    assert "the simulated world in a process of its own" in header, header + proc.stderr.read()
    with pytest.raises(subprocess.TimeoutExpired):  # it soaks (8 h of simulated time take minutes)
        proc.wait(timeout=1.0)
    if to_group:
        os.killpg(proc.pid, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGINT)
    rest, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, header + rest + err
    assert "Traceback" not in err
    with pytest.raises(ProcessLookupError):  # nobody left in the soak's session: the world's process ended too
        os.killpg(proc.pid, 0)
    (run,) = (tmp_path / "reports").glob("*-soak")
    doc = json.loads((run / "results.json").read_text())
    assert doc["status"] == "INTERRUPTED" and doc["host"]["processes"] == 2 and 0 < doc["ran_s"] < 8 * 3600
    assert doc["frames"]["total"] > 0 and doc["host"]["world_cpu_s"] > 0
