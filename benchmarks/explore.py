"""``ckesc explore``'s speed per lane (issue #22): steps per second, programs per second, lane seconds per wall second.

Explores the faultless emulator (nothing to find, so every program is generated, none shrunk) from a fixed seed
for a fixed number of programs in each lane: the simulated lane (CPU-bound: how fast the emulator, the oracle model
and the judge run) and real time against ``ckesc emulate`` (protocol-bound: power cycles, waits, answers). The
simulated lane's programs may wait out the 120 s Set ID window; real time leaves those out (a program would take
two minutes).

    python benchmarks/explore.py                            # both lanes (about 3 minutes)
    python benchmarks/explore.py --lanes simulated --programs 200
    python benchmarks/explore.py --out /tmp/explore.json

Writes ``benchmarks/results/explore.json`` (the machine, each lane's figures).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ckesc.explore.engine import explore  # noqa: E402
from ckesc.explore.runner import Session  # noqa: E402

PROGRAMS = {"simulated": 150, "realtime": 12}


def measure(lane: str, programs: int, seed: int) -> dict:
    session = Session({"lane": lane})
    start = time.monotonic()
    try:
        found, stats = explore(session, budget_s=3600, seed=seed, database=None, max_programs=programs)
    finally:
        session.close()
    wall = time.monotonic() - start
    return {"lane": lane, "programs": stats.programs, "steps": stats.steps, "wall_s": round(wall, 2),
            "lane_s": round(stats.lane, 1), "steps_per_s": round(stats.steps / wall, 2),
            "programs_per_s": round(stats.programs / wall, 3), "lane_s_per_wall_s": round(stats.lane / wall, 2),
            "feature_pairs": len(stats.pairs), "findings": [f.key for f in found]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lanes", nargs="+", default=list(PROGRAMS), choices=list(PROGRAMS))
    ap.add_argument("--programs", type=int, help="programs per lane (default: simulated 150, realtime 12)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "explore.json"))
    args = ap.parse_args()
    rows = []
    for lane in args.lanes:
        row = measure(lane, args.programs or PROGRAMS[lane], args.seed)
        rows.append(row)
        print(f"{lane:<10} {row['programs']} programs, {row['steps']} steps in {row['wall_s']} s: {row['steps_per_s']} "
              f"steps/s, {row['programs_per_s']} programs/s, {row['lane_s_per_wall_s']} lane s per wall s; "
              f"findings: {row['findings'] or 'none'}", flush=True)
    out = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform()},
           "seed": args.seed, "lanes": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    return 1 if any(r["findings"] for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
