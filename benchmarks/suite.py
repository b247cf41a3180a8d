"""The whole conformance suite: wall time in the simulated lane, and the real-time lane against
the waits the protocol itself imposes, in both run orders side by side (issue #14).

In the simulated lane time advances only while the suite waits, so the run's simulated duration is
exactly the waiting the protocol imposes on it (answer windows, report intervals, the 200 ms comm-loss
flag, power cycles, the 120 s Set ID / Set Baud window). ``ckesc run --order collection`` runs every test in
collection order, each window test sitting its window out (the "before"); ``overlap`` (the default) runs
other tests while a window elapses. Targets: the whole run <= 600 s of simulated protocol time, and
<= 600 s wall in the real-time lane.

    python benchmarks/suite.py             # simulated lane, both orders (seconds)
    python benchmarks/suite.py --realtime  # also the real-time lane, overlap order (about 12 minutes)
    python benchmarks/suite.py --realtime --realtime-orders overlap,collection   # both (about 35 minutes)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def run(lane: str, order: str = "overlap") -> tuple[float, dict]:
    with tempfile.TemporaryDirectory(prefix="ckesc-bench-suite-") as tmp:
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "ckesc", "run", "--lane", lane, "--reports", tmp, "-q",
                               "--order", order], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        reports = sorted(Path(tmp).glob("*/results.json"))
        if not reports:
            raise SystemExit(f"ckesc run --lane {lane} wrote no report (exit {done.returncode}):\n{done.stdout[-2000:]}")
        return wall, json.loads(reports[-1].read_text())


def outcomes(doc: dict) -> dict[str, int]:
    out: dict[str, int] = {}
    for r in doc["results"]:
        out[r["outcome"]] = out.get(r["outcome"], 0) + 1
    return out


def verdicts(doc: dict) -> dict[str, str]:
    return {r["nodeid"]: r["outcome"] for r in doc["results"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--realtime", action="store_true", help="also run the real-time lane")
    ap.add_argument("--realtime-orders", default="overlap", help="run orders for the real-time lane (comma-separated)")
    ap.add_argument("--top", type=int, default=12, help="list the N tests with the longest protocol waits")
    args = ap.parse_args()
    out: dict = {"python": sys.version.split()[0]}
    docs = {}
    for order in ("collection", "overlap"):
        wall, doc = run("simulated", order)
        docs[order] = doc
        protocol = doc["info"]["lane_seconds"]
        out.setdefault("simulated", {})[order] = {
            "wall_s": round(wall, 2), "protocol_s": protocol, "tests": len(doc["results"]), "outcomes": outcomes(doc),
            "epochs": len(doc["info"].get("epochs", [])), "target_protocol_s": 600}
        print(f"simulated lane, order {order}: {len(doc['results'])} tests in {wall:.1f} s wall ({outcomes(doc)}); "
              f"the run takes {protocol:.1f} s of simulated protocol time")
    same = verdicts(docs["collection"]) == verdicts(docs["overlap"])
    out["simulated"]["same_verdicts"] = same
    print(f"same verdict for every test id in both orders: {same}")
    results = docs["collection"]["results"]
    print("longest protocol waits (collection order):")
    for r in sorted(results, key=lambda r: -r["lane_seconds"])[: args.top]:
        print(f"  {r['lane_seconds']:8.2f} s  {r['nodeid']}")
    if args.realtime:
        for order in args.realtime_orders.split(","):
            rt_wall, rt_doc = run("realtime", order)
            protocol = out["simulated"][order]["protocol_s"]
            entry = out.setdefault("realtime", {})[order] = {
                "wall_s": round(rt_wall, 1), "ratio_to_simulated": round(rt_wall / protocol, 2), "target_wall_s": 600,
                "outcomes": outcomes(rt_doc)}
            print(f"real-time lane, order {order}: {rt_wall:.1f} s wall = {rt_wall / protocol:.2f} x the simulated run")
            windows = {r["nodeid"].split("::")[1]: (round(r["lane_seconds"], 1), dict(r["observations"]).get("window", ""))
                       for r in rt_doc["results"] if "window" in r["nodeid"]}
            entry["window_tests"] = {k: {"lane_s": v[0], "window": v[1][:160]} for k, v in windows.items()}
            entry["lane_s"] = rt_doc["info"].get("lane_seconds")
            for name, (secs, how) in windows.items():  # shared: overlapped; opened by this test: sat it out
                print(f"  {secs:7.1f} s  {name}: {how[:100]}")
            odd = [r for r in rt_doc["results"] if r["outcome"] not in ("PASS", "OBSERVED")]
            entry["not_passed"] = [{"nodeid": r["nodeid"], "outcome": r["outcome"], "message": r["message"][:300]}
                                   for r in odd]
            for r in odd:  # INCONCLUSIVE (a margin under the lane's error), SKIPPED, FAIL, ERROR: which and why
                print(f"  {r['outcome']:<12} {r['nodeid']}: {r['message'][:200]}")
    Path(__file__).with_name("results").mkdir(exist_ok=True)
    (Path(__file__).with_name("results") / "suite.json").write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
