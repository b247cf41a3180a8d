"""Simulated-lane speed: simulated seconds per wall second.

20 ESCs at the default report rates (MSG1 20 ms, MSG2 100 ms, MSG3 500 ms) with the host sending
RawCommand_12b at 400 Hz on all 5 groups (2000 throttle frames/s), at 1 Mbit/s. Target: >= 20x
real time. A script, not a timed test:

    python benchmarks/sim.py [--seconds 30] [--repeat 3] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import platform
import pstats
import sys
import time
from pathlib import Path

import can

from ckesc.emulator import sim_bus
from ckesc.protocol import TransferIdCounter, encode


def run(seconds: float, seed: int = 0) -> dict:
    channel = f"bench-sim-{time.monotonic_ns()}"
    bus = can.Bus(interface="ckesc-sim", channel=channel, nodes=list(range(1, 21)), bitrate=1_000_000, seed=seed,
                  esc_config={"baud_code": 0}, ignore_config=True)  # ESCs set to 1 Mbit/s, like the host
    tids = TransferIdCounter()
    tasks = []
    for group in range(1, 6):
        wire = encode("raw_command_12b", {"channels": [400] * 4, "group": group}, source=0)
        msg = can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True)

        def bump(m: can.Message, key=group) -> None:  # a real host counts transfer ids (F3)
            m.data[7] = 0xC0 | tids.next(("raw12", key))

        tasks.append(bus.send_periodic(msg, 1 / 400, modifier_callback=bump))
    received = 0
    t0 = time.perf_counter()
    end = bus.now() + seconds
    while bus.now() < end:
        if bus.recv(end - bus.now()) is not None:
            received += 1
    wall = time.perf_counter() - t0
    frames = bus.world.stats["frames"]
    load = bus.world.stats["busy_s"] / bus.now()
    for t in tasks:
        t.stop()
    bus.shutdown()
    sim_bus.discard(channel)
    if received == 0:
        raise SystemExit("the host heard no ESC: the benchmark is misconfigured")
    return {"sim_seconds": seconds, "wall_seconds": round(wall, 3), "speedup": round(seconds / wall, 1),
            "bus_frames": frames, "frames_per_sim_s": round(frames / seconds), "host_received": received,
            "bus_load": round(load, 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=30.0, help="simulated seconds per run (default 30)")
    ap.add_argument("--repeat", type=int, default=3, help="runs; the best is reported (default 3)")
    ap.add_argument("--profile", action="store_true", help="cProfile one run and print the top functions")
    args = ap.parse_args()
    if args.profile:
        prof = cProfile.Profile()
        prof.runcall(run, args.seconds)
        pstats.Stats(prof).sort_stats("tottime").print_stats(18)
        return
    runs = [run(args.seconds) for _ in range(args.repeat)]
    best = max(runs, key=lambda r: r["speedup"])
    result = {"python": sys.version.split()[0], "machine": platform.machine(), "best": best, "runs": runs,
              "target_speedup": 20}
    print(json.dumps(result, indent=1))
    out = Path(__file__).parent / "results" / "sim.json"
    out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
