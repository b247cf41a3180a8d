#!/usr/bin/env python3
"""``ckesc soak`` in real time (issue #31, "How we will know": against the emulator and the clean-room ESC, 10
minutes, exit 0, the host's stream jitter reported). A script run by hand, not a timed test:

    nice python benchmarks/soak_realtime.py                       # both DUTs at 400 and 50 Hz, 10 min each (40 min)
    nice python benchmarks/soak_realtime.py --rates 400           # how the figures were taken (20 min)
    python benchmarks/soak_realtime.py --duration 30s --duts emulator --out /tmp/s.json   # a quick look

Every part is a real process, as a bench meets it:

* ``emulator``: ``ckesc soak --lane realtime`` (its own ``ckesc emulate`` process, reached through socketcand, as
  ``ckesc run --lane realtime`` reaches it);
* ``clean-room``: the clean-room ESC (``tools/clean-room-esc``, an ESC we did not write) on a bare socketcand hub
  (``ckesc emulate --nodes none``), reached by ``ckesc soak --dut bus`` with its profile
  (``tools/clean-room-esc/clean-room.toml``), its power switched by signals (as
  ``tests/harness/test_clean_room_esc.py`` starts it).

Per run (DUT and stream rate): the soak's exit status and findings, its statement, and from its ``results.json``
the host's stream jitter (``host.send_lateness``: how late each RawCommand frame went out after it was due, and how
many were skipped because the host was late by more than a period), the host process's CPU (``host.cpu_percent``,
its own, not the DUT's), frames, memory at the start and the end; from outside, the DUT process's CPU
(``/proc/PID/stat``), the share of the machine's cores that was busy (``/proc/stat``) and the load average before
and after (the machine may be shared: its load is not controlled, only recorded). It writes
``benchmarks/results/soak-realtime.json`` (``runs.emulator_400hz``, ``runs.clean-room_50hz``, ...: a run of one rate keeps the others) and
exits 1 if a run did not exit 0.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from decode import cpu_model  # noqa: E402

CKESC = [sys.executable, "-m", "ckesc"]
CLEAN_ROOM = ROOT / "tools" / "clean-room-esc"
OUT = Path(__file__).parent / "results" / "soak-realtime.json"
DUTS = ("emulator", "clean-room")
#: how often the DUT process's CPU is read (its last reading before the soak ends counts)
SAMPLE_S = 1.0


def _env(tmp: Path) -> dict[str, str]:
    """A ``ckesc`` process's environment: unbuffered, no python-can configuration of the caller's."""
    (tmp / "tmp").mkdir(exist_ok=True)
    env = dict(os.environ, TMPDIR=str(tmp / "tmp"), PYTHONUNBUFFERED="1", PYTHONPATH=str(ROOT))
    for key in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        env.pop(key, None)
    return env


def cpu_seconds(pid: int) -> float | None:
    """A process's own CPU time so far (utime + stime, not its children's), None once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def children(pid: int) -> list[int]:
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


def machine_busy() -> tuple[int, int]:
    """(busy, total) jiffies of all CPUs so far (/proc/stat)."""
    values = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    idle = values[3] + values[4]
    return sum(values) - idle, sum(values)


def end(proc: subprocess.Popen) -> None:
    """SIGTERM (a clean stop: the clean-room ESC writes its flash), SIGKILL after 30 s."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(30)


class CleanRoom:
    """The hub and the clean-room ESC, each its own process; ``bench``: the bench options that reach the ESC."""

    def __init__(self, tmp: Path) -> None:
        self.hub = subprocess.Popen([*CKESC, "emulate", "--nodes", "none", "--socketcand", "0", "--control", "0"],
                                    cwd=tmp, env=_env(tmp), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        assert self.hub.stdout is not None
        port = None
        while port is None:
            line = self.hub.stdout.readline()
            if not line:
                raise RuntimeError("the hub (ckesc emulate --nodes none) did not start")
            if line.startswith("socketcand "):
                port = int(line.strip().rsplit(":", 1)[1])
        rate = tmp / "bitrate"
        rate.write_text("500000\n")
        self.esc = subprocess.Popen(
            [sys.executable, str(CLEAN_ROOM / "clean_room_esc.py"), "--interface", "socketcand", "--channel", "can0",
             "--bus-arg", "host=127.0.0.1", "--bus-arg", f"port={port}", "--node", "1", "--flash", str(tmp / "flash.json"),
             "--bus-bitrate-file", str(rate)],
            cwd=tmp, env=_env(tmp), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        assert self.esc.stdout is not None
        line = self.esc.stdout.readline()
        m = re.match(r"ready pid=(\d+)", line)
        if not m:
            self.close()
            raise RuntimeError(f"the clean-room ESC did not start: {line!r}")
        self.pid = int(m.group(1))
        self.bench = ["--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0",
                      "--can-config", "host=127.0.0.1", "--can-config", f"port={port}", "--can-config", "tcp_tune=True",
                      "--profile", str(CLEAN_ROOM / "clean-room.toml"), "--power", "command",
                      "--power-off-cmd", f"kill -USR1 {self.pid}", "--power-on-cmd", f"kill -USR2 {self.pid}",
                      "--can-bitrate-cmd", f"sh -c 'echo {{bitrate}} > {rate}'"]

    def close(self) -> None:
        end(self.esc)
        end(self.hub)
        for pipe in (self.esc.stdout, self.hub.stdout):
            if pipe is not None:
                pipe.close()


class DutCpu:
    """The DUT process's CPU over the soak, read every :data:`SAMPLE_S` from outside: a known pid (the clean-room
    ESC), else the soak's child process (``--lane realtime``'s ``ckesc emulate``), found once it has started."""

    def __init__(self, soak_pid: int, pid: int | None) -> None:
        self.soak_pid, self.pid = soak_pid, pid
        self.first: tuple[float, float] | None = None  # (wall, cpu s)
        self.last: tuple[float, float] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(SAMPLE_S):
            if self.pid is None:
                kids = children(self.soak_pid)
                if not kids:
                    continue
                self.pid = kids[0]
            cpu = cpu_seconds(self.pid)
            if cpu is None:
                continue
            now = time.monotonic()
            if self.first is None:
                self.first = (now, cpu)
            self.last = (now, cpu)

    def percent(self) -> float | None:
        self._stop.set()
        self._thread.join(5)
        if self.first is None or self.last is None or self.last[0] <= self.first[0]:
            return None
        return round(100 * (self.last[1] - self.first[1]) / (self.last[0] - self.first[0]), 1)


def key(dut: str, rate: float) -> str:
    """A run's key in the results (no dot, no space: the docs' figures name it in a dotted path)."""
    return f"{dut}_{rate:g}hz"


def one(dut: str, rate: float, duration: str, reports: Path, tmp: Path) -> dict[str, Any]:
    where = reports / f"{dut}-{rate:g}hz"
    shutil.rmtree(where, ignore_errors=True)
    (tmp / f"cr-{rate:g}").mkdir(exist_ok=True)
    cr = CleanRoom(tmp / f"cr-{rate:g}") if dut == "clean-room" else None
    try:
        bench = cr.bench if cr is not None else ["--lane", "realtime"]
        cmd = [*CKESC, "soak", *bench, "--duration", duration, "--rate", f"{rate:g}", "--reports", str(where)]
        load0, busy0, t0 = os.getloadavg(), machine_busy(), time.monotonic()
        log = (reports / f"{dut}-{rate:g}hz.log").open("w")
        proc = subprocess.Popen(cmd, cwd=tmp, env=_env(tmp), stdout=log, stderr=subprocess.STDOUT)
        dut_cpu = DutCpu(proc.pid, cr.pid if cr is not None else None)
        code = proc.wait()
        wall = time.monotonic() - t0
        busy1, load1 = machine_busy(), os.getloadavg()
        dut_percent = dut_cpu.percent()
        log.close()
    finally:
        if cr is not None:
            cr.close()
    found = sorted(where.glob("*-soak/results.json"))
    out: dict[str, Any] = {
        "dut": dut, "rate_hz": rate, "command": shlex.join(cmd[2:]), "exit": code, "process_wall_s": round(wall, 1),
        "load_average_before": [round(v, 2) for v in load0], "load_average_after": [round(v, 2) for v in load1],
        "machine_busy_percent": round(100 * (busy1[0] - busy0[0]) / max(1, busy1[1] - busy0[1]), 1),
        "dut_cpu_percent": dut_percent,
    }
    if not found:
        out["error"] = (reports / f"{dut}-{rate:g}hz.log").read_text()[-3000:]
        return out
    out["report"] = str(found[-1].parent)
    out.update(figures(json.loads(found[-1].read_text())))
    return out


def figures(doc: dict[str, Any]) -> dict[str, Any]:
    """A soak's figures from its results.json."""
    host, late = doc["host"], doc["host"]["send_lateness"]
    answers = doc["watches"]["GET_ESC_ID answers"]["statistics"]
    comm = doc["watches"]["comm flag"]["statistics"]
    lag = host.get("bench_stamp_lag") or {}
    return {
        "status": doc["status"], "duration_s": doc["duration_s"], "ran_s": doc["ran_s"],
        "wall_s": doc["wall_s"], "profile": doc["profile"], "frames": doc["frames"],
        "findings": len(doc["findings"]) + doc["findings_not_kept"],
        "first_findings": [{k: f[k] for k in ("t_s", "watch", "rules", "message")} for f in doc["findings"][:10]],
        "stream": {"frames": host["stream_frames"], "skipped": host["stream_skipped"],
                   "skipped_percent": round(100 * host["stream_skipped"] / max(1, host["stream_frames"] + host["stream_skipped"]), 3),
                   **{k: late[k] for k in ("mean_ms", "p50_ms", "p90_ms", "p99_ms", "max_ms")}},
        "host_cpu_percent": host.get("cpu_percent"),
        "longest_command_gap_ms": comm["longest_command_gap_ms"],
        "host_stream_gaps_over_200ms": comm["host_stream_gaps_over_200ms"],
        "answer_delay_ms": {k: answers["delay"][k] for k in ("p50_ms", "p99_ms", "max_ms")}, "answers": answers["answers"],
        "answers_not_judged_late_by_the_bench": answers.get("not_judged_late_by_the_bench"),
        "bench_stamp_lag_ms": {k: lag.get(k) for k in ("p50_ms", "p99_ms", "max_ms")},
        "worst_r9_mean_error_ms": doc["watches"]["report intervals"]["statistics"]["worst_mean_error_ms"],
        "rss_start_mb": round(doc["memory"]["rss_start_kb"] / 1024, 1), "rss_end_mb": round(doc["memory"]["rss_end_kb"] / 1024, 1),
        "statement": {s["watch"]: s["text"] for s in doc["statement"]},
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", default="10m", help="each soak's --duration (default 10m)")
    ap.add_argument("--rates", default="400,50", help="stream rates, Hz (default 400,50)")
    ap.add_argument("--duts", default=",".join(DUTS), help=f"DUTs (default {','.join(DUTS)})")
    ap.add_argument("--reports", type=Path, default=None,
                    help="keep the soaks' reports and console logs here (default: a temporary directory, removed)")
    ap.add_argument("--out", type=Path, default=OUT, help="JSON result (default benchmarks/results/soak-realtime.json)")
    args = ap.parse_args()
    duts = [d.strip() for d in args.duts.split(",")]
    if unknown := set(duts) - set(DUTS):
        ap.error(f"unknown DUT {', '.join(sorted(unknown))}: {', '.join(DUTS)}")
    result: dict[str, Any] = json.loads(args.out.read_text()) if args.out.exists() else {}
    result.update(benchmark="soak-realtime", date=time.strftime("%Y-%m-%dT%H:%MZ", time.gmtime()),
                  python=sys.version.split()[0], platform=platform.platform(), cpu=cpu_model(), cpus=os.cpu_count(),
                  method="see benchmarks/soak_realtime.py docstring")
    runs = result.setdefault("runs", {})
    worst = 0
    with tempfile.TemporaryDirectory() as tmp:
        reports = args.reports or Path(tmp) / "reports"
        reports.mkdir(parents=True, exist_ok=True)
        for dut in duts:
            for rate in (float(r) for r in args.rates.split(",")):
                r = one(dut, rate, args.duration, reports, Path(tmp))
                if args.reports is None:
                    r.pop("report", None)
                runs[key(dut, rate)] = r
                worst = max(worst, r["exit"])
                print(json.dumps(r), flush=True)
                args.out.write_text(json.dumps(result, indent=1) + "\n")  # each run kept as it ends
    print(f"written {args.out}")
    return 1 if worst else 0


if __name__ == "__main__":
    sys.exit(main())
