"""Every test module that starts a real-time DUT carries the ``realtime`` mark (tests/conftest.py): under
``-n auto`` an unmarked one would run beside another real-time test and each would judge the other's load."""

from __future__ import annotations

import re
from pathlib import Path

TESTS = Path(__file__).resolve().parent
#: what starts a DUT or a bench that keeps wall-clock time: `ckesc emulate` (procs.Emulator), the clean-room ESC,
#: the real-time lanes, a soak in real time, the VM
REAL_TIME = re.compile(r"\bEmulator\(|\bCleanRoom\(|RealtimeEmulatorLane\(|[\"']realtime[\"']|--lane[\"'], [\"']realtime|vm_ready")

#: modules that name the real-time lane without running it
NAMED_ONLY = {"soak/test_soak_rig.py": "`--lane realtime` only as an option a rig batch refuses"}


def test_modules_that_start_a_real_time_dut_are_marked():
    unmarked = [str(p.relative_to(TESTS)) for p in sorted(TESTS.rglob("test_*.py"))
                if REAL_TIME.search(text := p.read_text(encoding="utf-8")) and "pytest.mark.realtime" not in text and str(p.relative_to(TESTS)) not in NAMED_ONLY]
    assert not unmarked, f"mark them `pytestmark = pytest.mark.realtime` (or the real-time tests in them): {unmarked}"
