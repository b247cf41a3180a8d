"""The power-cycle sections on a bench where the host is alone on the bus while the ESC is off (R20, issue #36).

``ckesc emulate --host-alone hold`` plays what SocketCAN does then: the host's frames get no acknowledgement, the first
and the queue of 10 behind it wait for the ESC's controller and reach it at its power-up, the rest are lost. The
sections that switch the power (4.4.2, 4.4.21, 4.4.22, 4.4.27) must give a correct ESC no FAIL and no ERROR there,
with echo and without, as on such a bench: a frame held and sent late must never be judged as if sent on time. Today
they send nothing while the ESC is off, so nothing is held (the hub's counters say so in the failure message, should
a section start to).
"""

from __future__ import annotations

import json
import subprocess

import pytest
from procs import CKESC, Emulator, realtime_profile
from procs import env as _env

from ckesc.emulator.control import control_request

pytestmark = [pytest.mark.realtime, pytest.mark.slow]

SECTIONS = ("4.4.2", "4.4.21", "4.4.22", "4.4.27")


@pytest.mark.timeout(900)
@pytest.mark.parametrize("echo", [True, False], ids=["echo", "no-echo"])
def test_the_power_cycle_sections_pass_a_host_alone_bench(tmp_path, echo):
    with Emulator(tmp_path, "--host-alone", "hold", *([] if echo else ["--no-echo-own"])) as emu:
        reports = tmp_path / "reports"
        done = subprocess.run([*CKESC, "run", *emu.bench(realtime_profile(tmp_path)), "-q", "--trace-format", "none",
                               "--reports", str(reports), *SECTIONS], cwd=tmp_path, env=_env(tmp_path),
                              capture_output=True, text=True, timeout=800)
        status = control_request(emu.control, {"cmd": "status"})
    assert status["host_alone"] == "hold", status
    doc = json.loads((reports / "latest" / "results.json").read_text())
    assert doc["info"]["echo"] is echo
    held = {k: status["counters"][k] for k in ("host_held", "host_lost")}
    bad = [f"{r['nodeid']}: {r['outcome']} {r['message'][:300]}" for r in doc["results"] if r["outcome"] in ("FAIL", "ERROR")]
    assert not bad, f"host frames {held} while the ESC was off:\n" + "\n".join(bad)
    assert len(doc["results"]) > 40 and done.returncode == 0, done.stdout[-3000:]
