"""``ckesc check-log`` throughput and memory over a capture of a saturated 1 Mbit/s bus.

The capture is generated once by the emulator in simulated time and streamed to disk as a candump
log (cached under ``benchmarks/.cache/``, outside git): 38 ESCs reporting MSG1, MSG2 and MSG3 every 20 ms
(the shortest legal interval, set by Set/Get Freq writes the capture holds) and a host sending
RawCommand_12b at 400 Hz on all 5 groups plus GET_ESC_ID once a second: about 96 % bus load, 7,700
frames/s. A second capture, the first fifth of the first, shows that memory does not grow with the
capture's length.

Timed: ``python -m ckesc check-log FILE --complete`` in a fresh process per run (start-up included),
best of ``--repeat``: wall time, and the child's CPU time (user + sys, from its rusage), which other
processes on a shared machine disturb far less; peak RSS from the same rusage. Also timed, for the reader decision in
``ckesc/evidence/logs.py``: python-can's ``CanutilsLogReader`` alone and ours alone over the short
capture. Target: >= 160k frames/s (an hour of such a bus, 28 million frames, in under 3 minutes).
The run also checks that the faultless emulator's saturated bus breaks no rule (exit 0).

    python benchmarks/checklog.py [--frames 5000000] [--repeat 3] [--regenerate]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import can

from ckesc.emulator import sim_bus
from ckesc.evidence.logs import read_candump
from ckesc.protocol import TransferIdCounter, encode
from ckesc.protocol.host import HostProtocol

HERE = Path(__file__).parent
CACHE = HERE / ".cache"
TARGET = 160_000
ESCS = 38
BITRATE = 1_000_000
EPOCH = 1_700_000_000.0  # the capture's timestamps look like a real candump's
FASTEST = {"option": 1, "msg1_interval": 10, "msg2_interval": 10, "msg3_interval": 10}


def generate(path: Path, frames: int, short: Path, short_frames: int) -> dict:
    """Run the emulator and stream every frame on the bus (the host's own included) to ``path``."""
    channel = f"bench-checklog-{time.monotonic_ns()}"
    bus = can.Bus(interface="ckesc-sim", channel=channel, nodes=list(range(1, ESCS + 1)), bitrate=BITRATE,
                  esc_config={"baud_code": 0}, receive_own_messages=True, ignore_config=True)
    host = HostProtocol(0)
    tids = TransferIdCounter()
    tasks = []
    written = 0
    t0 = time.perf_counter()
    tmp, tmp_short = path.with_suffix(".tmp"), short.with_suffix(".tmp")
    with open(tmp, "w") as out, open(tmp_short, "w") as out_short:
        def drain(until: float) -> None:
            nonlocal written
            while written < frames and (msg := bus.recv(max(until - bus.now(), 0.0))) is not None:
                line = f"({EPOCH + msg.timestamp:.6f}) can0 {msg.arbitration_id:08X}#{msg.data.hex().upper()}\n"
                out.write(line)
                if written < short_frames:
                    out_short.write(line)
                written += 1

        drain(0.3)  # boot
        for node in range(1, ESCS + 1):
            wire, _ = host.request("set_freq", FASTEST, destination=node, now=bus.now(), timeout=0.1)
            bus.send(can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True))
            drain(bus.now() + 0.002)
        for group in range(1, 6):
            wire = encode("raw_command_12b", {"channels": [0] * 4, "group": group}, source=0)

            def bump(m: can.Message, key=group) -> None:  # a real host counts transfer ids (F3) and moves throttle
                n = tids.next(("raw12", key))
                m.data[0] = n * 7 & 0xFF
                m.data[7] = 0xC0 | n

            tasks.append(bus.send_periodic(can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True),
                                           1 / 400, modifier_callback=bump))
        query = host.message("get_esc_id", {"option": 0}, layout="query")
        tasks.append(bus.send_periodic(can.Message(arbitration_id=query.arbitration_id, data=query.data, is_extended_id=True),
                                       1.0, modifier_callback=lambda m: m.data.__setitem__(1, 0xC0 | tids.next("get_esc_id"))))
        while written < frames:
            drain(bus.now() + 10.0)
    load = bus.world.stats["busy_s"] / bus.now()
    seconds = bus.now()
    for t in tasks:
        t.stop()
    bus.shutdown()
    sim_bus.discard(channel)
    os.replace(tmp, path)
    os.replace(tmp_short, short)
    info = {"frames": written, "bus_seconds": round(seconds, 1), "bus_load": round(load, 3),
            "frames_per_bus_s": round(written / seconds), "generated_in_s": round(time.perf_counter() - t0, 1),
            "bytes": path.stat().st_size}
    path.with_suffix(".json").write_text(json.dumps(info, indent=1) + "\n")
    return info


def run_checklog(path: Path) -> dict:
    """One ``ckesc check-log`` in a fresh process: wall time, peak RSS, exit code, violations."""
    out_json = CACHE / "result.json"
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "ckesc", "check-log", str(path), "--complete", "--bitrate", str(BITRATE),
                             "--tolerance", "0.002", "--json", str(out_json)], stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    doc = json.loads(out_json.read_text())
    cpu = usage.ru_utime + usage.ru_stime
    return {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "frames": doc["frames"], "frames_per_s": round(doc["frames"] / wall),
            "frames_per_cpu_s": round(doc["frames"] / cpu), "peak_rss_mb": round(usage.ru_maxrss / 1024, 1), "exit": proc.returncode,
            "violations": doc["violations"]["count"], "observations": len(doc["observations"])}


def time_readers(path: Path, repeat: int) -> dict:
    """The candump readers alone (no rules), CPU time of this process, best of ``repeat``: python-can's and ours."""
    out = {}
    for name, read in (("python_can_CanutilsLogReader", lambda: can.CanutilsLogReader(str(path))),
                       ("ckesc_read_candump", lambda: read_candump(str(path), lambda *a: None))):
        best = 0
        for _ in range(repeat):
            t0 = time.process_time()
            n = sum(1 for _ in read())
            best = max(best, round(n / (time.process_time() - t0)))
        out[f"{name}_frames_per_cpu_s"] = best
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=5_000_000, help="frames in the long capture (default 5,000,000)")
    ap.add_argument("--repeat", type=int, default=3, help="check-log runs per capture; the best is reported")
    ap.add_argument("--regenerate", action="store_true", help="generate the captures again")
    ap.add_argument("--out", default=str(HERE / "results" / "checklog.json"))
    args = ap.parse_args()
    CACHE.mkdir(exist_ok=True)
    (CACHE / ".gitignore").write_text("*\n")  # the cache stays out of git without touching the repo's .gitignore
    long, short = CACHE / f"saturated-{args.frames}.log", CACHE / f"saturated-{args.frames // 5}.log"
    meta = long.with_suffix(".json")  # what the generator said about the long capture
    if args.regenerate or not long.exists() or not short.exists() or not meta.exists():
        print(f"generating {args.frames:,} frames with the emulator ...", flush=True)
        capture = generate(long, args.frames, short, args.frames // 5)
    else:
        capture = json.loads(meta.read_text())
    print(json.dumps(capture), flush=True)
    results = {}
    for label, path in (("short", short), ("long", long)):
        runs = [run_checklog(path) for _ in range(args.repeat)]
        results[label] = {"best": max(runs, key=lambda r: r["frames_per_s"]), "runs": runs}
        print(label, json.dumps(results[label]["best"]), flush=True)
    readers = time_readers(short, args.repeat)
    print(json.dumps(readers), flush=True)
    best = results["long"]["best"]
    cpu_best = max(results["long"]["runs"], key=lambda r: r["frames_per_cpu_s"])
    doc = {"python": sys.version.split()[0], "python_can": can.__version__, "machine": platform.machine(),
           "cpus": os.cpu_count(), "load_average": os.getloadavg(), "capture": capture, "checklog": results,
           "readers": readers, "target_frames_per_s": TARGET, "met": best["frames_per_s"] >= TARGET,
           "met_in_cpu_time": cpu_best["frames_per_cpu_s"] >= TARGET,
           "hour_of_bus_s": round(28_000_000 / best["frames_per_s"], 1),
           "hour_of_bus_cpu_s": round(28_000_000 / cpu_best["frames_per_cpu_s"], 1)}
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    clean = all(r["exit"] == 0 and r["violations"] == 0 for res in results.values() for r in res["runs"])
    if not clean:
        print("the faultless emulator's capture broke a rule: a false alarm (see benchmarks/.cache/result.json)", file=sys.stderr)
    return 0 if clean and doc["met"] else 1


if __name__ == "__main__":
    sys.exit(main())
