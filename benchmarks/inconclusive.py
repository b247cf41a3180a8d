"""What the suite cannot judge, per lane (issue #20): the whole suite against the faultless emulator and against a
drawn conforming variant, in the simulated lane, in real time with the bus's echo, and in real time without it
(``ckesc emulate --no-echo-own`` behind socketcand, reached as a bus DUT: the host's own frames timed by the host
clock, +-4 ms on a 2 ms bench), with every INCONCLUSIVE listed with its reason and any FAIL or ERROR (on a conforming
emulator, the suite's bug, or the machine's load beyond the stated error).

    python benchmarks/inconclusive.py                         # every configuration (about 35 minutes)
    python benchmarks/inconclusive.py --configs sim sim-variant
    python benchmarks/inconclusive.py --seed 3 --out /tmp/inc.json

Writes ``benchmarks/results/inconclusive.json`` (per configuration: the counts, each INCONCLUSIVE's test and message,
every FAIL/ERROR, the load average around it) and prints a table.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "harness"))
from procs import CKESC, Emulator, env  # noqa: E402 - the tests' own way to start `ckesc emulate`

#: a 2 ms bench: the error a USB adapter's timestamps have; without an echo the host's own frames get +-2 ms more
BENCH_PROFILE = ('[dut]\nname = "ckesc emulate behind socketcand"\n[capabilities]\nled = true\nmotor = true\n'
                 'pwm_input = false\nmulti_node = true\n[timing]\nerror_s = 0.002\nboot_s = 0.5\noff_s = 0.5\n')

CONFIGS = ("sim", "sim-variant", "realtime", "realtime-variant", "noecho", "noecho-variant")


def _run(config: str, seed: int, tmp: Path) -> dict:
    where = tmp / config
    where.mkdir()
    reports = where / "reports"
    variant = ["--emulator-variants", str(seed)] if config.endswith("variant") else []
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    if config.startswith("noecho"):
        (where / "bench.toml").write_text(BENCH_PROFILE)
        with Emulator(where, "--no-echo-own", *(["--variants", str(seed)] if variant else [])) as emu:
            power = f"{sys.executable} -m ckesc control --port {emu.control} power"
            done = subprocess.run([*CKESC, "run", "-q", "--dut", "bus", "--can-interface", "socketcand", "--can-channel",
                                   "can0", "--can-config", "host=127.0.0.1", "--can-config", f"port={emu.port}",
                                   "--can-config", "tcp_tune=True", "--node-id", "1", "--profile", str(where / "bench.toml"),
                                   "--power", "command", "--power-off-cmd", f"{power} off", "--power-on-cmd", f"{power} on",
                                   "--can-bitrate-cmd", f"{sys.executable} -m ckesc control --port {emu.control} bitrate {{bitrate}}",
                                   "--allow-motor-spin", "--reports", str(reports), "--trace-format", "none"],
                                  cwd=where, env=env(where), capture_output=True, text=True)
    else:
        lane = "realtime" if config.startswith("realtime") else "simulated"
        done = subprocess.run([*CKESC, "run", "-q", "--lane", lane, *variant, "--reports", str(reports),
                               "--trace-format", "none"], cwd=where, env=env(where), capture_output=True, text=True)
    wall = time.perf_counter() - t0
    results = reports / "latest" / "results.json"
    if not results.is_file():
        return {"config": config, "problem": f"no report (exit {done.returncode}): {done.stdout[-1500:]}{done.stderr[-1500:]}"}
    doc = json.loads(results.read_text())
    counts: dict[str, int] = {}
    for r in doc["results"]:
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1

    def listed(outcomes: tuple[str, ...]) -> list[dict]:
        return [{"test": r["nodeid"].split("/", 1)[-1], "outcome": r["outcome"],
                 "why": (r["message"] or "").splitlines()[0][:300] if r["message"] else ""}
                for r in doc["results"] if r["outcome"] in outcomes]

    return {"config": config, "exit": done.returncode, "wall_s": round(wall, 1), "load_before": round(load, 2),
            "load_after": round(os.getloadavg()[0], 2), "variant": doc["info"].get("emulator_variants"),
            "echo": doc["info"].get("echo"), "timing_error_s": doc["info"].get("timing_error_s"), "counts": counts,
            "inconclusive": listed(("INCONCLUSIVE",)), "failed": listed(("FAIL", "ERROR"))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--configs", nargs="+", choices=CONFIGS, default=list(CONFIGS))
    ap.add_argument("--seed", type=int, default=1, help="the drawn conforming combination's seed (default 1)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "inconclusive.json"))
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="ckesc-bench-inconclusive-") as tmp:
        for config in args.configs:
            row = _run(config, args.seed, Path(tmp))
            rows.append(row)
            if "problem" in row:
                print(f"{config}: {row['problem']}", flush=True)
                continue
            print(f"{config}: {row['counts']} in {row['wall_s']} s (load {row['load_before']} -> {row['load_after']}; "
                  f"variant {row['variant']}; echo {row['echo']})", flush=True)
            for r in row["inconclusive"] + row["failed"]:
                print(f"  {r['outcome']} {r['test']}: {r['why']}", flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"seed": args.seed, "runs": rows}, indent=1) + "\n", encoding="utf-8")
    print(f"written: {args.out}")
    return 1 if any(r.get("failed") or "problem" in r for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
