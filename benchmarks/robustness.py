"""Frames per second the robustness section (R17, issue #30) sends in real time: a script run by hand, not a test.

    python benchmarks/robustness.py                     # both benches (about 2 minutes), writes results/robustness.json
    python benchmarks/robustness.py --benches echo --out /tmp/robustness.json

Runs ``ckesc run robustness`` as a user does, traces written (BLF), on each bench: ``echo`` is ``--lane realtime``
(``ckesc emulate`` in its own process through socketcand, echoing the host's frames); ``no-echo`` is ``ckesc emulate
--no-echo-own`` reached as a bus (``--dut bus``, power and bit rate through its control channel), where the host's
frames are traced as it sent them. Every frame in each test's trace that is not the DUT's (node 1) is one the host
sent; the ones our decoder refuses (a multi-frame fragment, a wrong length) are counted as malformed, the rest (the
host's reads and restores, and the requests to another node and responses from one, which decode) are not. Per bench: the frames sent and the time
they span, summed over the tests (frames/s on average); the busiest 100 ms of any test (frames/s, and the share of
the bus's capacity those frames take at 500 kbit/s and 1 Mbit/s, stuff bits not counted: ``frame_bits``); the
verdicts (the faultless emulator: no FAIL, no ERROR). Figures only: no target.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path

import can

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ckesc.protocol.errors import DecodeError  # noqa: E402
from ckesc.protocol.frame import Decoder, frame_bits  # noqa: E402

HERE = Path(__file__).resolve().parent
DEFAULT_OUT = HERE / "results" / "robustness.json"
CKESC = [sys.executable, "-m", "ckesc"]
DUT_NODE = 1
WINDOW_S = 0.1  # the busiest window's length
BITRATES = (500_000, 1_000_000)


class Emulator:
    """``ckesc emulate --no-echo-own`` with socketcand and its control channel on 127.0.0.1."""

    def __init__(self, tmp: Path) -> None:
        self.proc = subprocess.Popen([*CKESC, "emulate", "--nodes", str(DUT_NODE), "--socketcand", "0", "--control", "0",
                                      "--no-echo-own"], cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        ports = {}
        while len(ports) < 2:
            line = self.proc.stdout.readline()  # type: ignore[union-attr]
            if not line:
                raise RuntimeError("ckesc emulate did not start")
            kind, _, addr = line.strip().partition(" ")
            if kind in ("socketcand", "control"):
                ports[kind] = int(addr.rsplit(":", 1)[1])
        self.port, self.control = ports["socketcand"], ports["control"]

    def bench(self, profile: Path) -> list[str]:
        control = shlex.join([*CKESC, "control", "--port", str(self.control)])
        return ["--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0", "--can-config", "host=127.0.0.1",
                "--can-config", f"port={self.port}", "--can-config", "tcp_tune=True", "--node-id", str(DUT_NODE),
                "--profile", str(profile), "--power", "command", "--power-off-cmd", f"{control} power off",
                "--power-on-cmd", f"{control} power on", "--can-bitrate-cmd", f"{control} bitrate {{bitrate}}"]

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=30)


def _realtime_profile(tmp: Path) -> Path:
    """The emulator's profile with the real-time lane's 2 ms stated error (as ``--lane realtime`` has it)."""
    import ckesc.bench

    text = (Path(ckesc.bench.__file__).parent / "profiles" / "emulator.toml").read_text()
    path = tmp / "emulator-realtime.toml"
    path.write_text(text.replace("error_s = 0.0 ", "error_s = 0.002 "))
    return path


def _busiest(stamps: list[tuple[float, int]]) -> tuple[int, int]:
    """(frames, bit times) in the busiest ``WINDOW_S`` of ``stamps`` ((time, dlc), in time order)."""
    best, lo, run_bits = (0, 0), 0, 0
    for hi, (t, dlc) in enumerate(stamps):
        run_bits += frame_bits(dlc)
        while stamps[lo][0] <= t - WINDOW_S:
            run_bits -= frame_bits(stamps[lo][1])
            lo += 1
        if (hi - lo + 1, run_bits) > best:
            best = (hi - lo + 1, run_bits)
    return best


def measure(name: str, bench: list[str], tmp: Path) -> dict:
    reports = tmp / f"reports-{name}"
    start = time.monotonic()
    done = subprocess.run([*CKESC, "run", "robustness", "-q", *bench, "--reports", str(reports)], cwd=tmp,
                          capture_output=True, text=True, timeout=1800)
    wall = time.monotonic() - start
    run = reports / "latest"
    doc = json.loads((run / "results.json").read_text())
    decoder = Decoder(track_requests=False)
    sent = malformed = 0
    span = 0.0
    busiest = {"frames": 0, "bits": 0, "test": ""}
    per_test = []
    for r in doc["results"]:
        trace = (r.get("traces") or {}).get("")
        if not trace:
            continue
        stamps = []
        bad = 0
        for m in can.BLFReader(str(run / trace)):
            if not m.is_extended_id or m.arbitration_id & 0x7F == DUT_NODE:
                continue  # the DUT's (its source node id), or not ours
            stamps.append((m.timestamp, m.dlc))
            try:
                decoder.decode(m)
            except DecodeError:
                bad += 1
        if len(stamps) < 2:
            continue
        stamps.sort()
        frames, bits = _busiest(stamps)
        if frames > busiest["frames"]:
            busiest = {"frames": frames, "bits": bits, "test": r["name"]}
        sent, malformed, span = sent + len(stamps), malformed + bad, span + stamps[-1][0] - stamps[0][0]
        per_test.append({"test": r["name"], "sent": len(stamps), "malformed": bad,
                         "span_s": round(stamps[-1][0] - stamps[0][0], 3)})
    return {
        "bench": name, "exit": done.returncode, "wall_s": round(wall, 1), "tests": len(doc["results"]),
        "verdicts": dict(sorted(Counter(r["outcome"] for r in doc["results"]).items())),
        "echo": doc["info"].get("echo"), "sent": sent, "malformed": malformed, "span_s": round(span, 2),
        "frames_per_s": round(sent / span, 1) if span else None,
        "malformed_per_s": round(malformed / span, 1) if span else None,
        "busiest": {"test": busiest["test"], "window_s": WINDOW_S, "frames_per_s": round(busiest["frames"] / WINDOW_S),
                    **{f"load_at_{b // 1000}k": round(busiest["bits"] / WINDOW_S / b, 4) for b in BITRATES}},
        "per_test": per_test,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--benches", nargs="+", default=["echo", "no-echo"], choices=["echo", "no-echo"])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = ap.parse_args()
    runs = []
    with tempfile.TemporaryDirectory(prefix="ckesc-robustness-") as d:
        tmp = Path(d)
        for name in args.benches:
            if name == "echo":
                runs.append(measure(name, ["--lane", "realtime"], tmp))
            else:
                emu = Emulator(tmp)
                try:
                    # --allow-motor-spin: as --lane realtime (an emulator, no motor) has it, so both run the same tests
                    runs.append(measure(name, [*emu.bench(_realtime_profile(tmp)), "--allow-motor-spin"], tmp))
                finally:
                    emu.close()
            r = runs[-1]
            print(f"{name:<8} {r['sent']} frames sent ({r['malformed']} malformed) over {r['span_s']} s of tests: "
                  f"{r['frames_per_s']} frames/s ({r['malformed_per_s']} malformed/s); busiest {WINDOW_S * 1000:g} ms "
                  f"{r['busiest']['frames_per_s']} frames/s in {r['busiest']['test']} ({r['busiest']['load_at_500k']:.1%} "
                  f"of 500 kbit/s); verdicts {r['verdicts']}; {r['wall_s']} s wall", flush=True)
    doc = {"when": datetime.now(UTC).isoformat(timespec="seconds"), "machine": platform.platform(),
           "cpus": os.cpu_count(), "python": platform.python_version(), "load_avg": os.getloadavg(), "runs": runs}
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0 if all(r["verdicts"].keys() <= {"PASS", "OBSERVED", "SKIPPED", "INCONCLUSIVE"} for r in runs) else 1


if __name__ == "__main__":
    raise SystemExit(main())
