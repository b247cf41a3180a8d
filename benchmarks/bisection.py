"""``ckesc bisect`` in simulation, issue #37's scenarios: 32 emulator images, the fault from image 19 on, section
4.4.27 as the selection.

- ``clean``: one try per step, the canary at the end: found 19 in 5 steps (target: 5-6 steps, under 120 s of wall
  time for the whole bisect);
- ``flaky``: image 18 (the last good) shows the fault one run in three, its first run included, ``--tries 3``:
  still found 19, the flaky step decided by its majority;
- ``stateful``: a bench that keeps the fault once a bad image ran: the canary fails, no build is blamed (exit 1).

The flaky image and the stateful bench are played by the tests' stand-in flash tool (``tests/harness/sim_flash.py``).
Timed: the ``ckesc bisect`` process's wall time and its children's CPU time (user + sys, from rusage: every step's
``ckesc run``), which other processes on a shared machine disturb far less; the load average beside them.

    python benchmarks/bisection.py [--only clean,flaky,stateful] [--out benchmarks/results/bisection.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "harness"))
from firmware_images import FAULT, series  # noqa: E402

COUNT, BAD_FROM, FLAKY = 32, 19, 18
SECTION = "4.4.27"
TARGET_S = 120.0
SIM_FLASH = ROOT / "tests" / "harness" / "sim_flash.py"


def scenario(name: str, where: Path) -> dict:
    images = series(where, COUNT, bad_from=BAD_FROM)
    args = ["--images", str(where / "images.txt")]
    if name == "flaky":
        flaky = images[FLAKY - 1]
        flaky.write_text(flaky.read_text().replace("faults = []", f'faults = ["{FAULT}"]'))
        args += ["--tries", "3", "--flash-cmd", shlex.join([sys.executable, str(SIM_FLASH), "--flaky", flaky.name]) + " {image}"]
    elif name == "stateful":
        args += ["--flash-cmd", shlex.join([sys.executable, str(SIM_FLASH), "--sticky"]) + " {image}"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "ckesc", "bisect", *args, "--reports", str(where / "reports"), SECTION],
                          capture_output=True, text=True)
    wall = time.monotonic() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    doc = json.loads(next((where / "reports").glob("*-bisect/bisect.json")).read_text())
    return {"scenario": name, "exit": proc.returncode, "wall_s": round(wall, 1),
            "cpu_s": round(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, 1),
            "load_average": round(os.getloadavg()[0], 2), "ending": doc["ending"],
            "first_bad": (doc["first_bad"] or {}).get("number"), "bisect_steps": doc["bisect_steps"], "runs": doc["runs"],
            "steps": [[s["number"], s["canary"], [r["outcome"] for r in s["runs"]]] for s in doc["steps"]],
            "console_last": proc.stdout.strip().splitlines()[-4:]}


def met(r: dict) -> bool:
    if r["scenario"] == "stateful":
        return r["ending"] == "bench kept state" and r["exit"] == 1
    return r["first_bad"] == BAD_FROM and 5 <= r["bisect_steps"] <= 6 and r["exit"] == 0 and r["wall_s"] < TARGET_S


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--only", default="clean,flaky,stateful")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "bisection.json")
    a = p.parse_args()
    results = []
    for name in a.only.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            r = scenario(name, Path(tmp))
        r["target_met"] = met(r)
        results.append(r)
        print(f"{name}: {r['ending']}, first bad {r['first_bad']}, {r['bisect_steps']} steps, {r['runs']} runs, "
              f"{r['wall_s']} s wall, {r['cpu_s']} s CPU, load {r['load_average']}: "
              f"{'met' if r['target_met'] else 'NOT met'}", flush=True)
    out = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": sys.version.split()[0]},
           "images": COUNT, "bad_from": BAD_FROM, "flaky": FLAKY, "selection": SECTION, "target_s": TARGET_S,
           "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "results": results}
    a.out.write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0 if all(r["target_met"] for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
