"""Set Baud's section in real time, where the ESC holds what nobody acknowledges (R20, issue #36): its tests move the
ESC to another bit rate and reopen the host's bus at each rate to find it; the real-time hub (ckesc/emulator/hub_can.py)
acknowledges an ESC frame only while another node listens at its rate, so while the host is elsewhere (at another
rate: the real-time lane's ``bitrate`` command; its handle closed: a ``--dut bus`` bench's reopen) the ESC's
controller holds its reports and sends them back to back when the host comes. The section must still pass a
conforming ESC, with echo and without, and the traces show the held reports going back to back."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest
from procs import CKESC, Emulator, realtime_profile
from procs import env as _env

from ckesc.emulator.control import control_request
from ckesc.protocol.catalogue import BAUD_RATES
from ckesc.protocol.frame import frame_bits

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

SECTION = "4.4.19"
#: a queue the ESC held, as the traces show it: this many of its frames in a row, each starting at the end of the one
#: before at one bit rate of Set Baud's table (a queue sent as one; the reports alone are 10 ms apart or more)
HELD_RUN = 10
_LINE = re.compile(r"\((\d+\.\d+)\) \S+ ([0-9A-F]+)#([0-9A-F]*)")


def _longest_back_to_back(trace: Path) -> int:
    """The longest run of the ESC's frames (not the host's: node 1's, its id's low byte) back to back in ``trace``."""
    frames = [(float(m[1]), int(m[2], 16), len(m[3]) // 2) for m in map(_LINE.match, trace.read_text().splitlines()) if m]
    esc = [(ts, n) for ts, can_id, n in frames if can_id & 0xFF == 1]
    best = 0
    for rate in BAUD_RATES.values():
        run = 1
        for (t0, _), (t1, n1) in zip(esc, esc[1:]):
            run = run + 1 if abs(t1 - frame_bits(n1) / rate - t0) < 2e-6 else 1
            best = max(best, run)
    return best


def _run(tmp: Path, *args: str) -> tuple[int, dict]:
    reports = tmp / "reports"
    done = subprocess.run([*CKESC, "run", SECTION, "-q", "--trace-format", "log", "--reports", str(reports), *args],
                          cwd=tmp, env=_env(tmp), capture_output=True, text=True, timeout=1500)
    results = reports / "latest" / "results.json"
    assert results.exists(), done.stdout[-3000:] + done.stderr[-3000:]
    return done.returncode, json.loads(results.read_text())


def _judge(code: int, doc: dict, echo: bool, reports: Path) -> None:
    assert doc["info"]["echo"] is echo
    bad = [f"{r['nodeid']}: {r['outcome']} {(r.get('message') or '')[:600]}" for r in doc["results"]
           if r["outcome"] in ("FAIL", "ERROR")]
    assert not bad, "\n".join(bad)
    assert len(doc["results"]) >= 14 and code == 0
    runs = {t.name: _longest_back_to_back(t) for t in (reports / "latest" / "traces").glob("*.log")}
    assert max(runs.values()) >= HELD_RUN, runs  # the ESC's held reports met the host back to back


@pytest.mark.timeout(1600)
def test_set_baud_passes_on_the_realtime_lane_where_the_esc_holds_its_reports(tmp_path):
    """``--lane realtime``, echo: the host moves with the emulator's ``bitrate`` command; its handle stays open."""
    code, doc = _run(tmp_path, "--lane", "realtime")
    _judge(code, doc, True, tmp_path / "reports")


@pytest.mark.slow
@pytest.mark.timeout(1600)
def test_set_baud_passes_without_echo_where_the_hosts_handle_closes_at_each_reopen(tmp_path):
    """The emulator as a third-party DUT on a bus that does not echo; each reopen closes the host's socketcand
    connection and opens another (as python-can's bus is shut down and opened again), so the ESC holds its reports
    while the host is away as well as while it is at another rate."""
    with Emulator(tmp_path, "--no-echo-own") as emu:
        code, doc = _run(tmp_path, *emu.bench(realtime_profile(tmp_path)))
        status = control_request(emu.control, {"cmd": "status"})
    _judge(code, doc, False, tmp_path / "reports")
    assert status["bus_counters"]["esc_no_ack"] > 0 and status["counters"]["clients"] > 1, status
