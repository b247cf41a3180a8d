#!/usr/bin/env python3
"""Quick self-check of the clean-room ESC: a bare socketcand hub (`ckesc emulate --nodes none`), the ESC on it,
then discovery, a few answers, report intervals and a power cycle, checked with python-can.

    python tools/clean-room-esc/selfcheck.py [--ckesc /work/main/.venv/bin/ckesc] [--defect NAME ...]
Exit 0 when every check held.
"""
import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

import can

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ckesc", default="ckesc")
    ap.add_argument("--defect", action="append", default=[])
    a = ap.parse_args()
    hub = subprocess.Popen([a.ckesc, "emulate", "--nodes", "none", "--socketcand", "0", "--control", "0"],
                           stdout=subprocess.PIPE, text=True)
    port = None
    for line in hub.stdout:
        m = re.match(r"socketcand 127\.0\.0\.1:(\d+)", line)
        if m:
            port = int(m.group(1))
        if line.startswith("ready"):
            break
    flash = tempfile.mktemp(suffix=".json")
    cmd = [sys.executable, os.path.join(HERE, "clean_room_esc.py"), "--bus-arg", "host=127.0.0.1",
           "--bus-arg", f"port={port}", "--node", "1", "--flash", flash]
    for d in a.defect:
        cmd += ["--defect", d]
    esc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    ready = esc.stdout.readline()
    assert ready.startswith("ready pid="), ready
    bus = can.Bus(interface="socketcand", channel="can0", host="127.0.0.1", port=port, tcp_tune=True)
    failures = []

    def check(cond, what):
        print(("ok   " if cond else "FAIL ") + what)
        if not cond:
            failures.append(what)

    def listen(d):
        end, out = time.time() + d, []
        while time.time() < end:
            m = bus.recv(0.01)
            if m:
                out.append(m)
        return out

    def of(ms, t):
        return [m for m in ms if not m.arbitration_id & 0x80 and (m.arbitration_id >> 8) & 0xFFFF == t
                and m.arbitration_id & 0x7F]

    def service(sid, payload, tid=5):
        bus.send(can.Message(arbitration_id=(16 << 24) | (sid << 16) | (1 << 15) | (1 << 8) | 0x80,
                             is_extended_id=True, data=bytes(payload) + bytes([0xC0 | tid])))
        for m in listen(0.08):
            c = m.arbitration_id
            if c & 0x80 and not (c >> 15) & 1 and (c >> 16) & 0xFF == sid:
                return m
        return None

    try:
        time.sleep(0.5)
        ms = listen(1.05)
        for t, iv in ((20050, 20), (20051, 100)):
            ts = [m.timestamp for m in of(ms, t)]
            mean = 1000 * (ts[-1] - ts[0]) / (len(ts) - 1) if len(ts) > 2 else 0
            check(abs(mean - iv) < 1.5, f"{t} mean interval {mean:.2f} ms ~ {iv} ms")
        bus.send(can.Message(arbitration_id=(16 << 24) | (20013 << 8), is_extended_id=True, data=b"\x00\xc0"))
        ans = of(listen(0.07), 20013)
        check(len(ans) == 1 and bytes(ans[0].data[:2]) == b"\x01\x01", f"GET_ESC_ID answered [1, 1]: {ans}")
        r = service(214, [0, 0, 0, 0])
        check(r is not None and bytes(r.data) == bytes([0, 10, 50, 250, 0xC5]), f"214 read {r}")
        r = service(240, [0])
        check(r is not None and len(r.data) == 8 and r.data[7] == 0xC5, f"240 answered {r}")
        p0 = service(241, [2]).data
        esc.send_signal(signal.SIGUSR1)
        listen(0.4)   # drain what was sent before the switch-off
        check(not of(listen(0.3), 20050), "silent while powered off")
        esc.send_signal(signal.SIGUSR2)
        time.sleep(0.6)
        p1 = service(241, [2]).data
        check(int.from_bytes(p1[0:2], "little") == int.from_bytes(p0[0:2], "little") + 1, "power-up counted once")
        check(len(of(listen(0.3), 20050)) >= 10, "reports again after power-up")
    finally:
        bus.shutdown()
        esc.send_signal(signal.SIGTERM)
        check(esc.wait(5) == 0, "SIGTERM: exit 0")
        hub.send_signal(signal.SIGTERM)
        hub.wait(5)
    print("self-check:", "FAILED " + "; ".join(failures) if failures else "passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
