#!/usr/bin/env python3
"""The load the real-time load player reaches on this machine (R18): a script run by hand, not a unit test.

    python benchmarks/load.py                      # writes benchmarks/results/load.json
    python benchmarks/load.py --seconds 1 --out /tmp/load.json   # a quick look

``ckesc emulate --nodes 1 --socketcand 0`` is the bench (an ESC at node 1 on a socketcand hub on 127.0.0.1), as a
third-party adapter's python-can bus would be. The suite's load generator (:class:`ckesc.protocol.load.LoadSource`,
mixed priority) is played by :class:`ckesc.bench.traffic_player.TrafficPlayer` from a thread of this process on a
stock python-can socketcand client, as ``conformance/test_robustness_r18_load.py`` plays it, at each share of
:data:`SHARES` of a 500 kbit/s and a 1 Mbit/s bus for ``--seconds``; a second client counts what reached the bus.
Recorded per run: the share asked and reached (the player's own measure: its frames' bits over its run), frames
sent per second, how late they went out (mean, max), send errors, and the frames the listener heard.

Target: none (figures only); the suite judges R18 with the share its player reaches, and a share it cannot reach
is the bench's INCONCLUSIVE, never the DUT's FAIL.
"""

from __future__ import annotations

import argparse
import json
import logging
import platform
import subprocess
import sys
import tempfile
import threading
import time
from datetime import UTC, datetime
from pathlib import Path

import can

from ckesc.bench.traffic_player import TrafficPlayer
from ckesc.protocol.judgements import r18_queueing_s, r18_reached
from ckesc.protocol.load import LoadSource

HERE = Path(__file__).resolve().parent
DEFAULT_OUT = HERE / "results" / "load.json"
BITRATES = (500000, 1000000)
SHARES = (0.1, 0.3, 0.5, 0.7, 0.9)


class Hub:
    def __init__(self, tmp: Path) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "ckesc", "emulate", "--nodes", "1", "--socketcand", "0"],
                                     cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        line = self.proc.stdout.readline()  # type: ignore[union-attr]
        if not line.startswith("socketcand "):
            raise RuntimeError(f"ckesc emulate did not start: {line!r}")
        self.port = int(line.rsplit(":", 1)[1])

    def bus(self) -> can.BusABC:
        return can.Bus(interface="socketcand", host="127.0.0.1", port=self.port, channel="can0", tcp_tune=True)

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(30)
        self.proc.stdout.close()  # type: ignore[union-attr]


def _drain(bus: can.BusABC, stop: threading.Event, count: list[int], foreign: set[int]) -> None:
    """Read everything (the hub drops a client that does not read), counting the load's frames."""
    while not stop.is_set():
        msg = bus.recv(0.1)
        if msg is not None and msg.arbitration_id in foreign:
            count[0] += 1


def run(hub: Hub, bitrate: int, share: float, seconds: float, seed: int) -> dict:
    source = LoadSource(share, bitrate, priority="mixed", seed=seed, exclude_nodes=[1])
    ids = {f.arbitration_id for f in LoadSource(share, bitrate, priority="mixed", seed=seed, exclude_nodes=[1]).take_due(seconds + 1)}
    player_bus, listener = hub.bus(), hub.bus()
    stop, heard = threading.Event(), [0]
    threads = [threading.Thread(target=_drain, args=(b, stop, c, ids), daemon=True)
               for b, c in ((player_bus, [0]), (listener, heard))]
    for t in threads:
        t.start()
    time.sleep(0.2)  # the hub forwards to a client 50 ms after its rawmode
    try:
        player = TrafficPlayer(player_bus.send, [source], bitrate=bitrate).start()
        time.sleep(seconds)
        stats = player.stop()
        time.sleep(0.3)  # what is still on its way to the listener
    finally:
        stop.set()
        for t in threads:
            t.join(2)
        player_bus.shutdown()
        listener.shutdown()
    return {"bitrate": bitrate, "asked": share, "reached": round(stats.load, 4),
            "reached_enough": r18_reached(share, stats.load), "frames": stats.frames,
            "frames_per_s": round(stats.frames / stats.elapsed_s), "late_mean_us": round(stats.late_mean_s * 1e6),
            "late_max_us": round(stats.late_max_s * 1e6), "send_errors": stats.send_errors, "heard": heard[0],
            "r18_queueing_us": round(r18_queueing_s(min(share, 0.5), bitrate) * 1e6)}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = p.parse_args()
    logging.getLogger("can").setLevel(logging.ERROR)  # python-can warns of every partly read line at this rate
    runs = []
    loadavg = Path("/proc/loadavg").read_text().split()[:3] if Path("/proc/loadavg").exists() else []
    with tempfile.TemporaryDirectory(prefix="ckesc-load-") as tmp_name:
        hub = Hub(Path(tmp_name))
        try:
            for bitrate in BITRATES:
                for i, share in enumerate(SHARES):
                    r = run(hub, bitrate, share, args.seconds, seed=i + 1)
                    runs.append(r)
                    print(json.dumps(r), flush=True)
        finally:
            hub.close()
    best = {str(b): max((r for r in runs if r["bitrate"] == b), key=lambda r: r["reached"]) for b in BITRATES}
    doc = {"when": datetime.now(UTC).isoformat(timespec="seconds"), "machine": platform.platform(),
           "python": platform.python_version(), "python_can": can.__version__, "seconds": args.seconds,
           "loadavg_at_start": loadavg,  # the machine's other work: the player shares its 2 cores
           "bench": "ckesc emulate --nodes 1 --socketcand 0 on 127.0.0.1; the player on python-can's socketcand client",
           "runs": runs, "best": best,
           "half_load": {str(b): next(r for r in runs if r["bitrate"] == b and r["asked"] == 0.5) for b in BITRATES}}
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
