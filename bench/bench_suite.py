"""The whole conformance suite: wall time in the simulated lane, and the real-time lane against
the waits the protocol itself imposes.

In the simulated lane time advances only while the suite waits, so each test's simulated duration
is exactly the waiting the protocol imposes on it (answer windows, report intervals, the 200 ms
comm-loss flag, power cycles, the 120 s Set ID window). The real-time lane cannot be faster than
that sum; the target is to stay within 1.2x of it.

    python bench/bench_suite.py             # simulated lane only (target: < 60 s wall)
    python bench/bench_suite.py --realtime  # also the real-time lane (takes minutes)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def run(lane: str) -> tuple[float, dict]:
    with tempfile.TemporaryDirectory(prefix="ckesc-bench-suite-") as tmp:
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "ckesc", "run", "--lane", lane, "--reports", tmp, "-q"],
                              capture_output=True, text=True)
        wall = time.perf_counter() - t0
        reports = sorted(Path(tmp).glob("*/results.json"))
        if not reports:
            raise SystemExit(f"ckesc run --lane {lane} wrote no report (exit {done.returncode}):\n{done.stdout[-2000:]}")
        return wall, json.loads(reports[-1].read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--realtime", action="store_true", help="also run the real-time lane")
    ap.add_argument("--top", type=int, default=12, help="list the N tests with the longest protocol waits")
    args = ap.parse_args()
    wall, doc = run("simulated")
    results = doc["results"]
    waits = sum(r["lane_seconds"] for r in results)
    outcomes: dict[str, int] = {}
    for r in results:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    out = {"python": sys.version.split()[0], "tests": len(results), "outcomes": outcomes,
           "simulated": {"wall_s": round(wall, 2), "protocol_waits_s": round(waits, 2), "target_wall_s": 60}}
    print(f"simulated lane: {len(results)} tests in {wall:.1f} s wall ({outcomes}); "
          f"the protocol's waits add up to {waits:.1f} s")
    print("longest protocol waits:")
    for r in sorted(results, key=lambda r: -r["lane_seconds"])[: args.top]:
        print(f"  {r['lane_seconds']:8.2f} s  {r['nodeid']}")
    if args.realtime:
        rt_wall, rt_doc = run("realtime")
        ratio = rt_wall / waits if waits else float("nan")
        out["realtime"] = {"wall_s": round(rt_wall, 1), "ratio_to_waits": round(ratio, 2), "target_ratio": 1.2,
                           "outcomes": {o: sum(1 for r in rt_doc["results"] if r["outcome"] == o)
                                        for o in {r["outcome"] for r in rt_doc["results"]}}}
        print(f"real-time lane: {rt_wall:.1f} s wall = {ratio:.2f} x the protocol's waits (target <= 1.2)")
        odd = [r for r in rt_doc["results"] if r["outcome"] not in ("PASS", "OBSERVED")]
        out["realtime"]["not_passed"] = [{"nodeid": r["nodeid"], "outcome": r["outcome"], "message": r["message"][:300]}
                                         for r in odd]
        for r in odd:  # INCONCLUSIVE (a margin under the lane's error), SKIPPED, FAIL, ERROR: which and why
            print(f"  {r['outcome']:<12} {r['nodeid']}: {r['message'][:200]}")
    Path(__file__).with_name("results").mkdir(exist_ok=True)
    (Path(__file__).with_name("results") / "suite.json").write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
