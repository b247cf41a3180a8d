"""``ckesc soak`` in simulated time (issue #31, "How we will know"): each long-run emulator fault at its default
onset, found by a simulated soak that stops at its first finding (how long into the run, simulated time, and how
much wall time it took); and an 8-hour soak of the faultless emulator (exit 0, its wall time, the process's memory
at the start and the end, the trace on disk within its budget). The stream at 50 Hz, as a CI soak runs it
(docs/soak.md); the run_time_wraps fault counts motor running time, so its soak spins the motor at throttle 200.
In process, one run after another (``runner.run``, as ``ckesc soak`` calls it); the reports go to a temporary
directory. A script, not a timed test:

    nice python benchmarks/soak.py [--hours 8] [--faults-only | --faultless-only] [--rate 400]
    nice python benchmarks/soak.py --versus ../main-checkout [--hours 1] [--rounds 2]

``--versus DIR``: the faultless soak side by side with the code of another checkout (before a change, say): a
simulated hour each, this checkout's and that one's in turn, each in a process of its own (the machine is shared:
taking turns puts both under the same load), recorded under ``versus``.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ckesc.bench.station import BenchOptions
from ckesc.emulator.faults import FAULTS, SOAK
from ckesc.soak import runner

RATE_HZ = 50.0
#: how long after its onset a fault's soak may run before it counts as missed
AFTER_ONSET_S = 600.0
SPIN = {"run_time_wraps"}
OUT = Path(__file__).parent / "results" / "soak.json"


def one(reports: Path, faults: str, duration_s: float, spin: bool, stop: bool,
        rate_hz: float = RATE_HZ, processes: str = "auto") -> tuple[dict, float, float]:
    """One soak: its results.json, its wall time and its CPU time (s; this process's and, in two processes, the
    world's; on a shared machine the wall time grows with the other jobs' load, the CPU time much less)."""
    bench = BenchOptions(emulator_faults=faults, allow_motor_spin=spin)
    options = runner.SoakOptions(duration_s=duration_s, rate_hz=rate_hz, throttle=((0.0, 200),) if spin else (),
                                 stop_on_finding=stop, reports=str(reports), quiet=True, processes=processes)
    t0, c0 = time.perf_counter(), time.process_time()
    outcome = runner.run(bench, options, out=io.StringIO())
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    assert outcome.where is not None
    doc = json.loads((outcome.where / "results.json").read_text())
    return doc, wall, cpu + (doc["host"]["world_cpu_s"] or 0.0)


def load() -> float:
    """The machine's load average over the last 5 minutes (the machine is shared: it says how busy it was)."""
    return round(os.getloadavg()[1], 2)


def faults(reports: Path) -> dict:
    out = {}
    for name in sorted(n for n, f in FAULTS.items() if f.kind == SOAK):
        onset = FAULTS[name].onset_s
        doc, wall, cpu = one(reports, name, onset + AFTER_ONSET_S, name in SPIN, stop=True)
        first = doc["findings"][0] if doc["findings"] else None
        out[name] = {"onset_s": onset, "found": first is not None, "found_at_s": first and round(first["t_s"], 3),
                     "after_onset_s": first and round(first["t_s"] - onset, 3), "watch": first and first["watch"],
                     "rules": first and first["rules"], "status": doc["status"], "ran_s": doc["ran_s"],
                     "wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "sim_per_wall": round(doc["ran_s"] / wall, 1)}
        print(name, json.dumps(out[name]), flush=True)
    return out


def faultless(reports: Path, hours: float, rate_hz: float = RATE_HZ, processes: str = "auto") -> dict:
    load_before = load()
    doc, wall, cpu = one(reports, "", hours * 3600, False, stop=False, rate_hz=rate_hz, processes=processes)
    mem = doc["memory"]
    world = doc["host"]["world_cpu_s"]
    out = {"hours": hours, "rate_hz": rate_hz, "processes": doc["host"]["processes"],
           "world_cpu_s": world and round(world, 1), "world_cpu_us_per_frame": world and round(world / doc["frames"]["total"] * 1e6, 1),
           "status": doc["status"], "findings": len(doc["findings"]) + doc["findings_not_kept"],
           "exit": 1 if doc["findings"] or doc["findings_not_kept"] else 0, "ran_s": doc["ran_s"],
           "wall_s": round(wall, 1), "sim_per_wall": round(doc["ran_s"] / wall, 1), "frames": doc["frames"]["total"],
           "cpu_s": round(cpu, 1), "wall_s_per_sim_hour": round(wall / hours, 1), "cpu_s_per_sim_hour": round(cpu / hours, 1),
           "wall_us_per_frame": round(wall / doc["frames"]["total"] * 1e6, 1),
           "cpu_us_per_frame": round(cpu / doc["frames"]["total"] * 1e6, 1),
           "load_average_5min": [load_before, load()],
           "rss_start_mb": round(mem["rss_start_kb"] / 1024, 1), "rss_end_mb": round(mem["rss_end_kb"] / 1024, 1),
           "peak_rss_mb": round(mem["peak_rss_kb"] / 1024, 1),
           "trace_mb": round(doc["trace"]["bytes"] / 1e6, 1), "trace_budget_mb": doc["trace"]["budget_bytes"] / 1e6,
           "trace_rolled_away": doc["trace"]["rolled_away"],
           "statement": {s["watch"]: s["text"] for s in doc["statement"]}}
    print("faultless", json.dumps(out), flush=True)
    return out


def versus(other: Path, hours: float, rounds: int) -> dict:
    """The faultless soak of ``hours``, in turn with this checkout's code and ``other``'s (``rounds`` times each)."""
    here = Path(__file__).resolve().parents[1]
    probe = ("import io, json, os, sys, tempfile, time; import ckesc; from ckesc.bench.station import BenchOptions; "
             "from ckesc.soak import runner\n"
             "with tempfile.TemporaryDirectory() as tmp:\n"
             f"    o = runner.SoakOptions(duration_s={hours * 3600!r}, rate_hz={RATE_HZ!r}, reports=tmp, quiet=True)\n"
             "    cpu = lambda: sum(os.times()[:4])  # (the world's process too, where a soak forks one)\n"
             "    w, c = time.perf_counter(), cpu()\n"
             "    runner.run(BenchOptions(), o, out=io.StringIO())\n"
             "    print(json.dumps([time.perf_counter() - w, cpu() - c, ckesc.__file__]))\n")
    runs: dict[str, list] = {"this": [], "versus": []}
    for _ in range(rounds):
        for name, code in (("versus", other.resolve()), ("this", here)):
            env = {**os.environ, "PYTHONPATH": str(code)}  # (and run from there: ``-c`` puts the directory first)
            done = subprocess.run([sys.executable, "-c", probe], env=env, cwd=code, capture_output=True, text=True,
                                  check=True)
            wall, cpu, where = json.loads(done.stdout.splitlines()[-1])
            assert Path(where).resolve().is_relative_to(code), f"{name}: ckesc imported from {where}, not {code}"
            runs[name].append({"wall_s_per_sim_hour": round(wall / hours, 1), "cpu_s_per_sim_hour": round(cpu / hours, 1),
                               "load_average_5min": load()})
            print(name, code, json.dumps(runs[name][-1]), flush=True)
    return {"hours": hours, "other_checkout": str(other), **runs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, help="the faultless soak's length (default 8; with --versus 1)")
    ap.add_argument("--faults-only", action="store_true")
    ap.add_argument("--faultless-only", action="store_true")
    ap.add_argument("--versus", type=Path, help="only the faultless soak side by side with this checkout's code")
    ap.add_argument("--rounds", type=int, default=2, help="--versus: runs of each (default 2)")
    ap.add_argument("--rate", type=float, default=RATE_HZ,
                    help=f"the faultless soak's stream rate (Hz; default {RATE_HZ:g}, a CI soak's): another rate, with "
                         "--faultless-only, is recorded beside it as faultless_<rate>hz with its own date (400: ckesc "
                         "soak's default, a flight controller's)")
    ap.add_argument("--processes", choices=("auto", "1", "2"), default="auto",
                    help="ckesc soak's --processes (default auto); with --rate, 1 is recorded as faultless_<rate>hz_1process")
    args = ap.parse_args()
    result: dict = json.loads(OUT.read_text()) if OUT.exists() else {}
    date = time.strftime("%Y-%m-%d", time.gmtime())
    if args.rate != RATE_HZ:  # a record of its own beside the others, with its own date (theirs stay as they were)
        if args.versus is not None or not args.faultless_only:
            ap.error("--rate: with --faultless-only only")
        key = f"faultless_{args.rate:g}hz" + ("_1process" if args.processes == "1" else "")
        with tempfile.TemporaryDirectory() as tmp:
            result[key] = {**faultless(Path(tmp), args.hours or 8.0, args.rate, args.processes), "date": date,
                           "python": sys.version.split()[0], "cores": len(os.sched_getaffinity(0))}
        OUT.write_text(json.dumps(result, indent=1) + "\n")
        print(f"written {OUT}")
        return
    result.update(python=sys.version.split()[0], machine=platform.machine(), rate_hz=RATE_HZ, date=date)
    if args.versus is not None:
        result["versus"] = versus(args.versus, args.hours or 1.0, args.rounds)
        OUT.write_text(json.dumps(result, indent=1) + "\n")
        print(f"written {OUT}")
        return
    with tempfile.TemporaryDirectory() as tmp:
        if not args.faultless_only:
            result["faults"] = faults(Path(tmp))
        if not args.faults_only:
            result["faultless"] = faultless(Path(tmp), args.hours or 8.0)
    OUT.write_text(json.dumps(result, indent=1) + "\n")
    print(f"written {OUT}")


if __name__ == "__main__":
    main()
