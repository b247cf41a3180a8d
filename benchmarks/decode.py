#!/usr/bin/env python3
"""Decode throughput on a realistic bus: a script run by hand, not a unit test.

    python benchmarks/decode.py                 # 1,000,000 frames, best of 5; writes benchmarks/results/decode.json
    python benchmarks/decode.py --frames 100000 --repeat 3 --out /tmp/decode.json   # a quick look

The bus (F1-F3, R2, R4, R9 defaults): 20 ESCs (nodes 1..20) report MSG1 every 20 ms, MSG2 every 100 ms and
MSG3 every 500 ms (the default intervals 10/50/250 x 2 ms); the host (node 0) sends RawCommand_12b at 400 Hz on
groups 1..5 (channels 1..20) and GET_ESC_ID once a second, which every ESC answers after (node_id % 32) x 2 ms.
Frames are built with ``ckesc.protocol.encode`` (transfer ids from one TransferIdCounter per sender) into
``can.Message`` objects with increasing timestamps, then decoded from memory:

1. ``classify(can_id)`` alone, every frame;
2. ``Decoder.decode(msg)`` (id, tail byte, length and all fields), every frame;
3. the same on the Hobbywing-layout subset: ESC frames of 20013 (GET_ESC_ID reply), 20050/20051/20052
   (MSG1/MSG2/MSG3), against ``dronecan`` 1.0.27 decoding the same frames with its own DSDL:
   a. ``Transfer().from_frames([Frame(id, data)])`` - dronecan's public receive path (tail checks, data type
      lookup, DSDL unpack), then every field value read;
   b. the leanest path through dronecan's DSDL code: our own 3-line id/tail split, then
      ``datatype()._unpack(bits_from_bytes(payload))`` (a private API) and every field value read.
   Reading the values counts: dronecan keeps fields as bit strings until they are read. The host's own
   GET_ESC_ID queries are left out of the subset: sent from node 0 they are anonymous frames to a DroneCAN
   stack, which reads 20013 as dynamic_node_id.Allocation (dronecan-hobbywing-notes 4.4).

Every timing is the best of N runs over the whole list with the garbage collector off during the run (as
``timeit`` does); the loop (``for msg in frames: f(msg)``) is part of what is measured.
"""

from __future__ import annotations

import argparse
import gc
import heapq
import json
import math
import platform
import random
import sys
import time
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Callable, Sequence

import can

from ckesc.protocol import Decoder, Kind, TransferIdCounter, classify, encode
from ckesc.protocol import catalogue as cat

ESC_NODES = range(1, 21)
HOST = 0
T0 = 1_700_000_000.0  # wall-clock start of the synthetic capture (candump-style absolute timestamps)
US = 1e-6

# report and command periods in microseconds
MSG_PERIOD_US = {name: int(interval * cat.INTERVAL_UNIT_S * 1e6) for name, interval in cat.DEFAULT_REPORT_INTERVALS.items()}
THROTTLE_PERIOD_US = 2_500  # 400 Hz
GET_ESC_ID_PERIOD_US = 1_000_000  # 1 Hz, as ArduPilot does
WIRE_TIME_US = 130  # one 8-byte extended frame at 1 Mbit/s, stuff bits included
HOBBYWING_TYPES = (20013, 20050, 20051, 20052)

TARGETS = {"classify": 500_000, "decode": 200_000}  # frames/s

DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "decode.json"


# ---------------------------------------------------------------------------------------------------
# The bus


class _Bus:
    """A deterministic model of the bus: throttle commands, and ESCs whose reports follow them."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)
        self.command = [0] * 20  # channels 1..20, 0..2000
        self.temp = {n: 30.0 for n in ESC_NODES}
        self.tids: dict[int, TransferIdCounter] = {n: TransferIdCounter() for n in (HOST, *ESC_NODES)}

    def tid(self, node: int, type_id: int) -> int:
        return self.tids[node].next((Kind.MESSAGE, type_id))

    def step_throttle(self, t_us: int) -> None:
        # a slow sweep per channel plus a little noise: what a multicopter's mixer output looks like
        for i in range(20):
            base = 1100 + 500 * math.sin(t_us * 2e-6 + i * 0.3)
            self.command[i] = max(0, min(cat.THROTTLE_MAX, int(base + self.rng.randint(-15, 15))))

    def throttle(self, group: int) -> tuple[str, dict[str, Any], int]:
        channels = self.command[4 * group - 4 : 4 * group]
        return "raw_command_12b", {"channels": channels, "group": group}, HOST

    def msg1(self, node: int) -> tuple[str, dict[str, Any], int]:
        pwm = self.command[node - 1]
        status = int(cat.Status.RUNNING) if pwm else 0
        if node % 2 == 0:
            status |= int(cat.Status.DIRECTION_CCW)
        return "msg1", {"speed": pwm * 9 + self.rng.randint(0, 40), "pwm": pwm, "status": status}, node

    def msg2(self, node: int) -> tuple[str, dict[str, Any], int]:
        pwm = self.command[node - 1]
        self.temp[node] += (20 + pwm / 50 - self.temp[node]) * 0.01
        return (
            "msg2",
            {"voltage": 2520 - pwm // 20 + self.rng.randint(-5, 5), "current": pwm * 2 + self.rng.randint(0, 30), "temperature": int(self.temp[node])},
            node,
        )

    def msg3(self, node: int) -> tuple[str, dict[str, Any], int]:
        t = int(self.temp[node])
        return "msg3", {"mos_t": t, "cap_t": t - 3, "motor_t": t + 8, "mcu_t": t - 5}, node


def build_frames(n_frames: int, seed: int = 2024) -> list[can.Message]:
    """``n_frames`` frames of the bus above, in time order, as ``can.Message``."""
    bus = _Bus(seed)
    # (time us, tie-break, what): a heap of the next due event of every periodic source
    heap: list[tuple[int, int, tuple]] = []
    order = 0

    def push(t_us: int, what: tuple) -> None:
        nonlocal order
        order += 1
        heapq.heappush(heap, (t_us, order, what))

    push(0, ("throttle",))
    push(1_000, ("get_esc_id",))
    for node in ESC_NODES:
        phase = 731 * node  # the ESCs' clocks are not aligned
        push(phase, ("msg1", node))
        push(phase + 3_100, ("msg2", node))
        push(phase + 7_300, ("msg3", node))

    frames: list[can.Message] = []
    append = frames.append

    def emit(t_us: int, name: str, fields: dict[str, Any], source: int) -> None:
        wire = encode(name, fields, source=source, transfer_id=bus.tid(source, cat.BY_NAME[name].type_id))
        append(can.Message(timestamp=T0 + t_us * US, arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True))

    while len(frames) < n_frames:
        t_us, _, what = heapq.heappop(heap)
        kind = what[0]
        if kind == "throttle":  # one command cycle: groups 1..5 back to back (~130 us per frame at 1 Mbit/s)
            bus.step_throttle(t_us)
            for group in cat.THROTTLE_GROUPS:
                push(t_us + WIRE_TIME_US * (group - 1), ("group", group))
            push(t_us + THROTTLE_PERIOD_US, what)
        elif kind == "group":
            emit(t_us, *bus.throttle(what[1]))
        elif kind == "get_esc_id":
            emit(t_us, "get_esc_id", {"option": 0}, HOST)
            for node in ESC_NODES:
                push(t_us + int((node % 32) * cat.ANSWER_SLOT_S * 1e6) + 100, ("reply", node))  # R2
            push(t_us + GET_ESC_ID_PERIOD_US, what)
        elif kind == "reply":
            node = what[1]
            emit(t_us, "get_esc_id", {"node_id": node, "throttle_channel": node}, node)
        else:
            node = what[1]
            emit(t_us, *getattr(bus, kind)(node))
            push(t_us + MSG_PERIOD_US[f"{kind}_interval"], what)
    del frames[n_frames:]
    assert all(a.timestamp <= b.timestamp for a, b in zip(frames, frames[1:])), "timestamps must not go back"
    return frames


# ---------------------------------------------------------------------------------------------------
# Decoders under test


def run_classify(frames: Sequence[can.Message]) -> None:
    for msg in frames:
        classify(msg.arbitration_id)


def run_decode(frames: Sequence[can.Message]) -> None:
    decode = Decoder().decode
    for msg in frames:
        decode(msg)


def _dronecan():
    import dronecan
    from dronecan import transport

    kind = transport.dsdl.CompoundType.KIND_MESSAGE
    types = {dtid: dronecan.DATATYPES[(dtid, kind)] for dtid in HOBBYWING_TYPES}
    names = {dtid: tuple(f.name for f in t.fields) for dtid, t in types.items()}
    return dronecan, transport, types, names


def _dronecan_values(payload: Any, names: tuple[str, ...]) -> dict[str, Any]:
    out = {}
    for name in names:
        value = getattr(payload, name)
        out[name] = value if isinstance(value, int) else list(value)  # GetEscID's uint8[<=3] payload
    return out


def run_dronecan_transfer(frames: Sequence[can.Message]) -> None:
    _, transport, types, names = _dronecan()
    Transfer, Frame = transport.Transfer, transport.Frame
    for msg in frames:
        t = Transfer()
        t.from_frames([Frame(msg.arbitration_id, msg.data)])
        _dronecan_values(t.payload, names[t.data_type_id])


def run_dronecan_unpack(frames: Sequence[can.Message]) -> None:
    _, transport, types, names = _dronecan()
    bits_from_bytes = transport.bits_from_bytes
    for msg in frames:
        can_id = msg.arbitration_id
        data = msg.data
        if data[-1] & 0xE0 != 0xC0:  # single-frame tail, as ours checks
            raise ValueError("not a single frame")
        dtid = (can_id >> 8) & 0xFFFF
        payload = types[dtid]()
        payload._unpack(bits_from_bytes(data[:-1]), True)
        _dronecan_values(payload, names[dtid])


# ---------------------------------------------------------------------------------------------------
# Measurement


def best_of(fn: Callable[[Sequence[can.Message]], None], frames: Sequence[can.Message], repeat: int) -> dict[str, Any]:
    times = []
    for _ in range(repeat):
        gc.collect()
        gc.disable()
        try:
            start = time.perf_counter()
            fn(frames)
            times.append(time.perf_counter() - start)
        finally:
            gc.enable()
    best = min(times)
    return {
        "frames": len(frames),
        "repeat": repeat,
        "best_s": round(best, 4),
        "times_s": [round(t, 4) for t in times],
        "frames_per_s": round(len(frames) / best),
        "us_per_frame": round(best / len(frames) * 1e6, 3),
    }


def check(frames: Sequence[can.Message], subset: Sequence[can.Message]) -> None:
    """Not timed: every frame decodes, and dronecan reads the Hobbywing subset as we do."""
    decoder = Decoder()
    decoded = [decoder.decode(m) for m in frames]  # raises on any bad frame
    assert all(f.known for f in decoded)
    _, transport, _, names = _dronecan()
    ours = Decoder()
    for msg in subset[:: max(1, len(subset) // 20_000)]:
        t = transport.Transfer()
        t.from_frames([transport.Frame(msg.arbitration_id, msg.data)])
        theirs = _dronecan_values(t.payload, names[t.data_type_id])
        mine = ours.decode(msg).fields
        if t.data_type_id == 20013:
            assert theirs["payload"] == [mine["node_id"], mine["throttle_channel"]], (theirs, mine)
        else:  # same raw integers, field by field in layout order (MSG3: dronecan's 3 of our 7 bytes)
            assert list(theirs.values()) == list(mine.values())[: len(theirs)], (theirs, mine)


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=1_000_000, help="frames on the synthetic bus (default 1,000,000)")
    ap.add_argument("--repeat", type=int, default=5, help="runs per measurement, best kept (default 5)")
    ap.add_argument("--dronecan-repeat", type=int, default=3, help="runs per dronecan measurement (slow; default 3)")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON result (default benchmarks/results/decode.json)")
    ap.add_argument("--no-dronecan", action="store_true", help="skip the dronecan comparison")
    args = ap.parse_args(argv)

    t = time.perf_counter()
    frames = build_frames(args.frames)
    built_s = time.perf_counter() - t
    mix = Counter(Decoder().decode(m).name for m in frames)
    subset = [m for m in frames if (m.arbitration_id >> 8) & 0xFFFF in HOBBYWING_TYPES and m.arbitration_id & 0x7F != HOST and not m.arbitration_id & 0x80]
    bus_s = frames[-1].timestamp - frames[0].timestamp
    print(f"built {len(frames):,} frames ({bus_s:.1f} s of bus, {len(frames) / bus_s:,.0f} frames/s) in {built_s:.1f} s")
    print("mix: " + ", ".join(f"{name} {n:,}" for name, n in mix.most_common()))
    print(f"Hobbywing-layout subset (ESC frames of {', '.join(map(str, HOBBYWING_TYPES))}): {len(subset):,} frames")
    if not args.no_dronecan:
        check(frames, subset)

    results: dict[str, Any] = {}

    def measure(key: str, label: str, fn, data, repeat: int) -> None:
        r = best_of(fn, data, repeat)
        results[key] = {"what": label, **r}
        print(f"{label:<64} {r['frames_per_s']:>12,} frames/s  ({r['us_per_frame']:.3f} us/frame, best of {repeat})")

    measure("classify", "classify(can_id), all frames", run_classify, frames, args.repeat)
    measure("decode", "Decoder.decode(msg), all frames", run_decode, frames, args.repeat)
    measure("decode_hobbywing", "Decoder.decode(msg), Hobbywing-layout subset", run_decode, subset, args.repeat)
    if not args.no_dronecan:
        measure("dronecan_transfer", "dronecan Transfer().from_frames + read fields, subset", run_dronecan_transfer, subset, args.dronecan_repeat)
        measure("dronecan_unpack", "dronecan datatype()._unpack + read fields, subset", run_dronecan_unpack, subset, args.dronecan_repeat)
        fastest = max(("dronecan_transfer", "dronecan_unpack"), key=lambda k: results[k]["frames_per_s"])
        ratio = results["decode_hobbywing"]["frames_per_s"] / results[fastest]["frames_per_s"]
        results["speedup_vs_dronecan"] = {"against": fastest, "factor": round(ratio, 1)}
        print(f"Decoder.decode is {ratio:.1f}x the fastest dronecan path ({fastest}) on the same frames")

    met = {k: results[k]["frames_per_s"] >= v for k, v in TARGETS.items()}
    for k, v in TARGETS.items():
        print(f"target {k} >= {v:,} frames/s: {'met' if met[k] else 'MISSED'}")

    import dronecan

    report = {
        "benchmark": "decode",
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "python": sys.version.split()[0],
        "implementation": platform.python_implementation(),
        "platform": platform.platform(),
        "cpu": cpu_model(),
        "versions": {"python-can": can.__version__, "dronecan": getattr(dronecan, "__version__", "?")},
        "bus": {
            "frames": len(frames),
            "seconds": round(bus_s, 3),
            "esc_nodes": [ESC_NODES.start, ESC_NODES.stop - 1],
            "mix": dict(mix.most_common()),
            "hobbywing_subset": len(subset),
        },
        "method": "best of N, gc off during a run, loop included; see benchmarks/decode.py docstring",
        "results": results,
        "targets": {k: {"frames_per_s": v, "met": met[k]} for k, v in TARGETS.items()},
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(report, indent=2) + "\n")
    tmp.replace(args.out)
    print(f"wrote {args.out}")
    return 0 if all(met.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
