"""``ckesc soak --lane realtime`` as a user runs it: a real process, the emulator in a ``ckesc emulate`` process of its
own reached through socketcand, on the wall clock. The host's own timing is reported (how late its stream frames
went out, how many it skipped, its CPU), and a short faultless soak finds nothing. The ten-minute runs against the
emulator and the clean-room ESC are ``benchmarks/soak_realtime.py``'s (docs/soak.md)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "harness"))
from procs import CKESC, env  # noqa: E402

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

SECONDS = 5
RATE_HZ = 400


def test_a_real_time_soak_of_the_emulator_reports_the_hosts_jitter_and_exits_0(tmp_path):
    done = subprocess.run([*CKESC, "soak", "--lane", "realtime", "--duration", f"{SECONDS}s", "--rate", str(RATE_HZ),
                           "--reports", str(tmp_path / "reports")], cwd=tmp_path, env=env(tmp_path), capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    (results,) = (tmp_path / "reports").glob("*-soak/results.json")
    doc = json.loads(results.read_text())
    assert doc["status"] == "COMPLETED" and doc["clock"] != "simulated" and doc["findings"] == []
    host = doc["host"]
    late = host["send_lateness"]
    # every stream tick is either sent (its lateness measured) or skipped: the wall clock's ticks, all accounted for
    assert late["count"] == host["stream_frames"] and abs(host["stream_frames"] + host["stream_skipped"]
                                                          - SECONDS * RATE_HZ) <= 2
    assert 0 <= late["p50_ms"] <= late["p99_ms"] <= late["max_ms"] and sum(late["bins"]) == late["count"]
    assert 0 < host["cpu_s"] < doc["wall_s"] and 0 < host["cpu_percent"] < 100
    assert doc["frames"]["dut"] > 0 and doc["frames"]["host"] >= host["stream_frames"]
    assert f"sent late by p50 {late['p50_ms']} ms, p99 {late['p99_ms']} ms, max {late['max_ms']} ms (the host's jitter)" \
        in done.stdout and "% of a CPU" in done.stdout
